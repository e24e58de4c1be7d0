// gemm_s8 on AVX-VNNI: the 6x16c4 micro-kernel on ymm, for the cores that have the VEX-encoded
// vpdpbusd but no AVX-512 (Intel Alder Lake, Raptor Lake, Meteor Lake and the N100 / N150 mini
// PCs). Compiled with -mavx2 -mfma -mavxvnni on x86-64 targets only; elsewhere this file is just the
// null table.
//
// The avx512vnni kernel's scheme on 16 ymm registers: the packer stores W XOR 0x80 = W + 128 as
// vpdpbusd's unsigned operand (pack_w_s8_16x4_goi_x80, padding 0), A's signed 4-byte groups are
// broadcast (vpbroadcastd: VEX has no embedded broadcast), and each row block subtracts
// 128 * rowsum(A) once (gemm_s8_vnni_rows.inc; the sums 32 bytes per vpdpbusd against ones). A
// stored unsigned (weights packed as they are by pack_w_s8_16x4_goi, the 16x4 layout NEON's
// kernel reads) swaps the operands: no row sums.
//
// Tile: 6 rows x 16 columns (2 ymm of 8 int32) x k-groups of 4. One k-group step = 2 weight loads,
// 6 broadcasts, 12 vpdpbusd; 12 accumulators + 2 weights + 1 broadcast = 15 of the 16 ymm
// registers (4x16 ran 12-20 % slower). The epilogues are AVX2's, two vectors per row
// (gemm_s8_epilogue_ymm.inc). The table's packers are AVX2 twins of the portable ones (the int8
// attention packs its keys and values at every run).
//
// Rules for ISA files (see README.md): only intrinsics and internal-linkage code here.
#include "kernels/gemm_s8/gemm_s8_variants.h"

#if defined(__x86_64__)

#include <immintrin.h>

#include <algorithm>
#include <cstring>
#include <type_traits>

#include "kernels/common/check.h"

namespace act::kernels {

namespace {

constexpr int kMR = 6;
constexpr int kNR = 16;
constexpr int kKR = 4;
constexpr Isa kIsa = Isa::kAvxVnni;
constexpr GemmS8Layout kLayout = GemmS8Layout::kVnni16x4;
// Unsigned activations: the 16x4 layout with W as it is (pack_w_s8_16x4_goi), A on the u8 side.
constexpr GemmS8Layout kLayoutU8A = GemmS8Layout::kNeon16x4;
constexpr bool own_layout(GemmS8Layout l) { return l == kLayout || l == kLayoutU8A; }
constexpr int kVecs = kNR / 8;
// Weight panels kept in L2 per sweep: half of the 1-2 MB L2 of these cores (the N100's 2 MB is
// shared by four).
constexpr size_t kPanelBlockBytes = size_t{512} << 10;
constexpr uint64_t kL1PanelBytes = 32 * 1024;  // a panel this small stays in L1 across row tiles
constexpr int kWeightPrefetchBytes = 2048;     // 32 k-groups ahead; 1024 measured the same but 2-4 % slower at K >= 2304

#include "kernels/gemm_s8/gemm_s8_driver.inc"

int32_t reduce_add(__m256i v) {
  __m128i s = _mm_add_epi32(_mm256_castsi256_si128(v), _mm256_extracti128_si256(v, 1));
  s = _mm_add_epi32(s, _mm_shuffle_epi32(s, 0x4e));
  s = _mm_add_epi32(s, _mm_shuffle_epi32(s, 0xb1));
  return _mm_cvtsi128_si32(s);
}

// 128 * sum_k A[r][k] for the R rows of a tile, side by side (R independent vpdpbusd chains): 32
// bytes at a time, then 8 (a segment is a multiple of 8 bytes, so nothing past it is read); the
// last 1-7 bytes of a plain row are read as 8 with the bytes past K masked off (inside the read
// slack), since padding weights are 0 and A's slack must not count.
template <int R>
void row_corrections(const GemmS8Args& g, int m, int32_t (&corr)[R]) {
  const __m256i ones = _mm256_set1_epi8(1);
  __m256i sum[R];
#pragma GCC unroll 6
  for (int r = 0; r < R; ++r) sum[r] = _mm256_setzero_si256();
  const int segments = segment_count(g), bytes = g.k / segments;
  for (int s = 0; s < segments; ++s) {
    const int8_t* rows[R];
    segment_rows<R>(g, m, s, rows);
    int i = 0;
    for (; i + 32 <= bytes; i += 32) {
#pragma GCC unroll 6
      for (int r = 0; r < R; ++r) {
        sum[r] = _mm256_dpbusd_avx_epi32(sum[r], ones, _mm256_loadu_si256(reinterpret_cast<const __m256i*>(rows[r] + i)));
      }
    }
    for (; i < bytes; i += 8) {
      const int left = bytes - i;
      const uint64_t keep = left >= 8 ? ~uint64_t{0} : (uint64_t{1} << (8 * left)) - 1;
#pragma GCC unroll 6
      for (int r = 0; r < R; ++r) {
        uint64_t quad;
        std::memcpy(&quad, rows[r] + i, 8);
        const __m256i v = _mm256_zextsi128_si256(_mm_cvtsi64_si128(static_cast<int64_t>(quad & keep)));
        sum[r] = _mm256_dpbusd_avx_epi32(sum[r], ones, v);
      }
    }
  }
#pragma GCC unroll 6
  for (int r = 0; r < R; ++r) corr[r] = static_cast<int32_t>(128u * static_cast<uint32_t>(reduce_add(sum[r])));
}

// out[r][j] = kbias - corr[r] + sum over k-groups of (W + 128) x A (or A x W for unsigned A),
// segment by segment; a local array copied out once, so that GCC keeps it in registers.
// kStreamWeights: the panel does not stay in L1 between tiles, so its bytes are prefetched ahead.
template <int R, bool kStreamWeights, bool kUnsignedA>
inline void accumulate(const GemmS8Args& g, int m, const uint8_t* panel, int kgroups, const int32_t (&corr)[R],
                       __m256i (&out)[R][kVecs]) {
  const uint8_t* w = panel + 8 * kNR;
  __m256i acc[R][kVecs];
#pragma GCC unroll 2
  for (int j = 0; j < kVecs; ++j) {
    const __m256i kbias = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(panel + 32 * j));
#pragma GCC unroll 6
    for (int r = 0; r < R; ++r) acc[r][j] = kUnsignedA ? kbias : _mm256_sub_epi32(kbias, _mm256_set1_epi32(corr[r]));
  }
  const int segments = segment_count(g), segment_groups = kgroups / segments;
  for (int s = 0; s < segments; ++s) {
    const int8_t* rows[R];
    segment_rows<R>(g, m, s, rows);
    const uint8_t* ws = w + static_cast<size_t>(s) * static_cast<size_t>(segment_groups) * (kNR * kKR);
    for (int gi = 0; gi < segment_groups; ++gi) {
      const uint8_t* wg = ws + static_cast<size_t>(gi) * (kNR * kKR);
      const __m256i w0 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(wg));
      const __m256i w1 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(wg + 32));
      if constexpr (kStreamWeights) _mm_prefetch(reinterpret_cast<const char*>(wg) + kWeightPrefetchBytes, _MM_HINT_T0);
#pragma GCC unroll 6
      for (int r = 0; r < R; ++r) {
        int32_t quad;
        std::memcpy(&quad, rows[r] + static_cast<size_t>(gi) * kKR, 4);
        const __m256i av = _mm256_set1_epi32(quad);
        if constexpr (kUnsignedA) {
          acc[r][0] = _mm256_dpbusd_avx_epi32(acc[r][0], av, w0);
          acc[r][1] = _mm256_dpbusd_avx_epi32(acc[r][1], av, w1);
        } else {
          acc[r][0] = _mm256_dpbusd_avx_epi32(acc[r][0], w0, av);
          acc[r][1] = _mm256_dpbusd_avx_epi32(acc[r][1], w1, av);
        }
      }
    }
  }
#pragma GCC unroll 6
  for (int r = 0; r < R; ++r) {
#pragma GCC unroll 2
    for (int j = 0; j < kVecs; ++j) out[r][j] = acc[r][j];
  }
}

#include "kernels/gemm_s8/gemm_s8_epilogue_ymm.inc"

// One R x 16 micro-tile starting at row m.
template <int R, bool kUnsignedA, class Epi>
void tile(const GemmS8Args& g, const GemmS8PackedHeader& h, const int32_t (&corr)[R], const uint8_t* panel, int m,
          int n, int lo, int hi, Epi& epi, bool stream_weights) {
  __m256i acc[R][kVecs];
  if (stream_weights) {
    accumulate<R, true, kUnsignedA>(g, m, panel, h.kp / kKR, corr, acc);
  } else {
    accumulate<R, false, kUnsignedA>(g, m, panel, h.kp / kKR, corr, acc);
  }
  if (g.a_row_zero_point != nullptr) subtract_row_zero_points<R>(g, h, panel, m, acc);
  epi.begin_panel(n, lo, hi);
#pragma GCC unroll 6
  for (int r = 0; r < R; ++r) epi.row(m + r, n, lo, hi, acc[r]);
}

#include "kernels/gemm_s8/gemm_s8_vnni_rows.inc"

// The byte lanes of a vector below `count` (0..32) set to 0xff.
__m256i first_bytes(int count) {
  const __m256i idx = _mm256_setr_epi8(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22,
                                       23, 24, 25, 26, 27, 28, 29, 30, 31);
  return _mm256_cmpgt_epi8(_mm256_set1_epi8(static_cast<char>(count)), idx);
}

// `bytes` (1..32) bytes from p, XOR 0x80 (W + 128), the lanes past them 0: nothing past them is read.
__m256i load_plus128(const int8_t* p, int bytes) {
  const __m256i flip = _mm256_set1_epi8(static_cast<char>(0x80));
  if (bytes >= 32) return _mm256_xor_si256(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(p)), flip);
  alignas(32) int8_t staged[32] = {};
  std::memcpy(staged, p, static_cast<size_t>(bytes));
  return _mm256_xor_si256(_mm256_load_si256(reinterpret_cast<const __m256i*>(staged)), _mm256_and_si256(flip, first_bytes(bytes)));
}

// Eight vectors of 8 int32 transposed in registers: afterwards v[c] holds element c of each input.
void transpose8x8_epi32(__m256i (&v)[8]) {
  __m256i t[8];
  for (int i = 0; i < 8; i += 2) {
    t[i] = _mm256_unpacklo_epi32(v[i], v[i + 1]);
    t[i + 1] = _mm256_unpackhi_epi32(v[i], v[i + 1]);
  }
  __m256i u[8];
  for (int i = 0; i < 8; i += 4) {
    u[i] = _mm256_unpacklo_epi64(t[i], t[i + 2]);
    u[i + 1] = _mm256_unpackhi_epi64(t[i], t[i + 2]);
    u[i + 2] = _mm256_unpacklo_epi64(t[i + 1], t[i + 3]);
    u[i + 3] = _mm256_unpackhi_epi64(t[i + 1], t[i + 3]);
  }
  for (int i = 0; i < 4; ++i) {
    v[i] = _mm256_permute2x128_si256(u[i], u[i + 4], 0x20);
    v[i + 4] = _mm256_permute2x128_si256(u[i], u[i + 4], 0x31);
  }
}

// Eight columns' sums and folded bias (slot 0 or 8 of the panel) from `sums` (lane c: sum of W + 128
// over k for column slot + c): kbias = bias - a_zero_point * sum W, modulo 2^32 as pack.cc computes
// it; the columns past `cols` 0, their bias not read.
void store_panel_sums(uint8_t* panel, int slot, int cols, __m256i sums, int k, const int32_t* bias, int32_t a_zero_point) {
  const __m256i valid = _mm256_cmpgt_epi32(_mm256_set1_epi32(cols), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
  const __m256i column_sums = _mm256_and_si256(valid, _mm256_sub_epi32(sums, _mm256_set1_epi32(128 * k)));
  const __m256i b = bias != nullptr && cols > 0 ? _mm256_maskload_epi32(bias, valid) : _mm256_setzero_si256();
  const __m256i kbias = _mm256_and_si256(valid, _mm256_sub_epi32(b, _mm256_mullo_epi32(_mm256_set1_epi32(a_zero_point), column_sums)));
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(panel + 4 * slot), kbias);
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(panel + 4 * (kNR + slot)), column_sums);
}

// The packers' common start: checks the buffer, writes the header, returns it.
GemmS8PackedHeader begin_packing(int n, int k, int32_t a_zero_point, void* packed) {
  ACT_DCHECK(n >= 1 && k >= 1 && k <= kGemmS8MaxK, "bad weight shape");
  ACT_DCHECK(reinterpret_cast<uintptr_t>(packed) % kGemmS8PackedAlign == 0, "packed buffer must be 64-byte aligned");
  const GemmS8PackedHeader h = gemm_s8_packed_header(kLayout, n, k, a_zero_point);
  std::memcpy(packed, &h, sizeof h);
  return h;
}

uint8_t* panel_of(void* packed, const GemmS8PackedHeader& h, int c) {
  return static_cast<uint8_t*>(packed) + sizeof h + static_cast<size_t>(c / kNR) * h.panel_bytes;
}

// pack_w_s8_16x4_goi_x80's bytes (a test compares them on ragged shapes), 8 columns by 32 bytes of
// K at a time: the 8 rows of W loaded + 128, their 8 x 8 four-byte k-groups transposed so that each
// k-group's 8 columns are one store, the column sums by vpdpbusd against ones. The int8 attention
// packs every head's keys with it at every run.
void pack_w_s8_16x4_goi_x80_avxvnni(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias, int32_t a_zero_point,
                                    void* packed) {
  ACT_DCHECK(ldw >= static_cast<size_t>(k), "W's rows overlap");
  const GemmS8PackedHeader h = begin_packing(n, k, a_zero_point, packed);
  const int groups = h.kp / kKR;
  const int columns = (n + kNR - 1) / kNR * kNR;  // whole panels: columns past n are written as 0
  const __m256i ones = _mm256_set1_epi8(1);
  for (int c0 = 0; c0 < columns; c0 += 8) {
    uint8_t* panel = panel_of(packed, h, c0);
    const int slot = c0 % kNR, cols = std::max(0, std::min(8, n - c0));
    __m256i sums = _mm256_setzero_si256();
    for (int g0 = 0; g0 < groups; g0 += 8) {
      const int k0 = kKR * g0, bytes = std::min(32, k - k0);
      __m256i v[8];
      for (int i = 0; i < 8; ++i) v[i] = i < cols ? load_plus128(w + static_cast<size_t>(c0 + i) * ldw + k0, bytes) : _mm256_setzero_si256();
      transpose8x8_epi32(v);
      for (int g = 0; g < 8 && g0 + g < groups; ++g) {
        sums = _mm256_dpbusd_avx_epi32(sums, v[g], ones);
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(panel + 8 * kNR + static_cast<size_t>(g0 + g) * (kNR * kKR) + 4 * slot), v[g]);
      }
    }
    store_panel_sums(panel, slot, cols, sums, k, bias != nullptr ? bias + c0 : nullptr, a_zero_point);
  }
}

// pack_wt_s8_16x4_goi_x80's bytes from W^T [k x n] (a test compares them), a panel's 16 columns by
// one k-group at a time: the group's four rows of W^T loaded + 128 (rows past k 0), their bytes
// interleaved column by column by unpacks, two stores, the column sums as above. The int8 attention
// packs every head's values with it at every run.
void pack_wt_s8_16x4_goi_x80_avxvnni(int n, int k, const int8_t* wt, size_t ldw, const int32_t* bias,
                                     int32_t a_zero_point, void* packed) {
  ACT_DCHECK(ldw >= static_cast<size_t>(n), "W^T's rows overlap");
  const GemmS8PackedHeader h = begin_packing(n, k, a_zero_point, packed);
  const int groups = h.kp / kKR;
  const __m256i ones = _mm256_set1_epi8(1);
  for (int c0 = 0; c0 < n; c0 += kNR) {
    uint8_t* panel = panel_of(packed, h, c0);
    uint8_t* data = panel + 8 * kNR;
    const int cols = std::min(kNR, n - c0);
    __m256i sums_low = _mm256_setzero_si256(), sums_high = _mm256_setzero_si256();
    for (int g = 0; g < groups; ++g) {
      __m128i row[kKR];
      for (int r = 0; r < kKR; ++r) {
        const int i = kKR * g + r;
        const int8_t* src = wt + static_cast<size_t>(i) * ldw + c0;
        if (i >= k) {
          row[r] = _mm_setzero_si128();
        } else if (cols == kNR) {
          row[r] = _mm_xor_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(src)), _mm_set1_epi8(static_cast<char>(0x80)));
        } else {
          row[r] = _mm256_castsi256_si128(load_plus128(src, cols));
        }
      }
      // Columns 0-7 then 8-15, each its four rows' bytes in order.
      const __m128i pairs01_low = _mm_unpacklo_epi8(row[0], row[1]), pairs01_high = _mm_unpackhi_epi8(row[0], row[1]);
      const __m128i pairs23_low = _mm_unpacklo_epi8(row[2], row[3]), pairs23_high = _mm_unpackhi_epi8(row[2], row[3]);
      const __m256i low = _mm256_set_m128i(_mm_unpackhi_epi16(pairs01_low, pairs23_low), _mm_unpacklo_epi16(pairs01_low, pairs23_low));
      const __m256i high = _mm256_set_m128i(_mm_unpackhi_epi16(pairs01_high, pairs23_high), _mm_unpacklo_epi16(pairs01_high, pairs23_high));
      sums_low = _mm256_dpbusd_avx_epi32(sums_low, low, ones);
      sums_high = _mm256_dpbusd_avx_epi32(sums_high, high, ones);
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(data + static_cast<size_t>(g) * (kNR * kKR)), low);
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(data + static_cast<size_t>(g) * (kNR * kKR) + 32), high);
    }
    store_panel_sums(panel, 0, cols, sums_low, k, bias != nullptr ? bias + c0 : nullptr, a_zero_point);
    store_panel_sums(panel, 8, cols - 8, sums_high, k, bias != nullptr && cols > 8 ? bias + c0 + 8 : nullptr, a_zero_point);
  }
}

}  // namespace

const GemmS8Kernels* gemm_s8_table_avxvnni() {
  static constexpr GemmS8Kernels kTable = variant_table<EpiS8, EpiF32, EpiS32>(
      {"pack_w_s8_16x4_goi_x80", "gemm_s8s8_s8out_6x16c4_avxvnni", "gemm_s8s8_f32out_6x16c4_avxvnni",
       "gemm_s8s8_s32out_6x16c4_avxvnni"},
      pack_w_s8_16x4_goi_x80_avxvnni, pack_wt_s8_16x4_goi_x80_avxvnni, "pack_w_s8_16x4_goi", pack_w_s8_16x4_goi);
  return &kTable;
}

}  // namespace act::kernels

#else  // not x86-64: nothing to build

namespace act::kernels {
const GemmS8Kernels* gemm_s8_table_avxvnni() { return nullptr; }
}  // namespace act::kernels

#endif
