// gemm_s8 on AVX-512 VNNI: the 6x64c4 micro-kernel. Compiled with -mavx512f/bw/vl/vnni on x86-64
// targets only; elsewhere this file is just the null table.
//
// vpdpbusd multiplies 4 unsigned bytes by 4 signed bytes per int32 lane and adds the 4 products to
// the accumulator without intermediate saturation (64 MACs per zmm instruction). The weights take
// the unsigned side: the packer stores W XOR 0x80 = W + 128 as u8 (padding stays 0), and A, signed,
// is broadcast from memory straight into vpdpbusd. Then
//   sum_k (W + 128) A = sum_k W A + 128 rowsum(A),
// so each row tile starts its accumulators at kbias - 128 * rowsum(A[m]), the row sums taken 64
// bytes per vpdpbusd against a vector of ones (K / 64 instructions per row, not K / 4). No XOR in
// the k loop: an XOR per broadcast competed with vpdpbusd for the same ports (about 20% of the
// peak), and flipping A into a buffer instead stalled on store forwarding when N <= 64.
// A stored unsigned (weights packed by pack_w_s8_64x4_goi_u8a, read in the header) swaps the
// sides: A's broadcast is the u8 operand, the weights the s8 one, and there are no row sums.
//
// Tile: 6 rows x 64 columns (4 zmm) x k-groups of 4. One k-group step = 4 weight loads, 6
// broadcasts (folded into vpdpbusd as {1to16} memory operands), 24 vpdpbusd; 24 accumulators + 4
// weights = 28 of the 32 zmm registers.
//
// Rules for ISA files (see README.md): only intrinsics and internal-linkage code here.
#include "kernels/gemm_s8/gemm_s8_variants.h"

#if defined(__x86_64__)

// GCC 12's _mm512_undefined_*() initialise a variable with itself, which -O3 reports as
// -Wmaybe-uninitialized or -Wuninitialized at the header's lines, depending on where it is inlined
// (fixed in GCC 13); silence it for the header only.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#include <immintrin.h>
#pragma GCC diagnostic pop

#include <algorithm>
#include <cstring>
#include <type_traits>

#include "kernels/common/check.h"

namespace act::kernels {

namespace {

constexpr int kMR = 6;
constexpr int kNR = 64;
constexpr int kKR = 4;
constexpr Isa kIsa = Isa::kAvx512Vnni;
constexpr GemmS8Layout kLayout = GemmS8Layout::kVnni64x4;
// Unsigned activations (pack_w_s8_64x4_goi_u8a): A takes vpdpbusd's u8 side as it is, the weights
// the s8 side, the zero point (in [0, 255]) folded into kbias: no row sums.
constexpr GemmS8Layout kLayoutU8A = GemmS8Layout::kVnni64x4U8A;
constexpr bool own_layout(GemmS8Layout l) { return l == kLayout || l == kLayoutU8A; }
constexpr int kVecs = kNR / 16;
constexpr size_t kPanelBlockBytes = size_t{1} << 20;  // weight panels kept in L2 per sweep
constexpr uint64_t kL1PanelBytes = 32 * 1024;          // a panel this small stays in L1 across row tiles
constexpr int kWeightPrefetchBytes = 2048;             // 8 k-groups ahead; 1024 and 4096 measured the same

#include "kernels/gemm_s8/gemm_s8_driver.inc"

// The lanes of vector j (columns [16j, 16j + 16) of the panel) that fall inside [lo, hi).
__mmask16 vec_mask(int j, int lo, int hi) {
  const int a = lo - 16 * j < 0 ? 0 : lo - 16 * j;
  const int b = hi - 16 * j > 16 ? 16 : hi - 16 * j;
  if (b <= a) return 0;
  return static_cast<__mmask16>(((1u << b) - 1u) & ~((1u << a) - 1u));
}

// 128 * sum_k A[r][k] for the R rows of a tile (exactly K bytes each: masked loads read nothing
// past a row or segment, and padding weights are 0 so A's slack bytes never count). The rows side
// by side: R independent chains of vpdpbusd, not one chain after another.
template <int R>
void row_corrections(const GemmS8Args& g, int m, int32_t (&corr)[R]) {
  const __m512i ones = _mm512_set1_epi8(1);
  __m512i sum[R];
#pragma GCC unroll 6
  for (int r = 0; r < R; ++r) sum[r] = _mm512_setzero_si512();
  const int segments = segment_count(g), bytes = g.k / segments;
  for (int s = 0; s < segments; ++s) {
    const int8_t* rows[R];
    segment_rows<R>(g, m, s, rows);
    for (int i = 0; i < bytes; i += 64) {
      const int left = bytes - i;
      const __mmask64 mask = left >= 64 ? ~__mmask64{0} : (__mmask64{1} << left) - 1;
#pragma GCC unroll 6
      for (int r = 0; r < R; ++r) sum[r] = _mm512_dpbusd_epi32(sum[r], ones, _mm512_maskz_loadu_epi8(mask, rows[r] + i));
    }
  }
#pragma GCC unroll 6
  for (int r = 0; r < R; ++r) corr[r] = static_cast<int32_t>(128u * static_cast<uint32_t>(_mm512_reduce_add_epi32(sum[r])));
}

// out[r][j] = kbias - corr[r] + sum over k-groups of (W + 128) x A, segment by segment. The
// accumulators are a local array (copied out once) so that GCC keeps them in registers; an
// out-parameter array would be stored every iteration.
// kStreamWeights: the panel does not stay in L1 between tiles (see row_tile), so its bytes are
// prefetched kWeightPrefetchBytes ahead (past its end: the next panel's, which the sweep reads next).
template <int R, bool kStreamWeights, bool kUnsignedA>
inline void accumulate(const GemmS8Args& g, int m, const uint8_t* panel, int kgroups, const int32_t (&corr)[R],
                       __m512i (&out)[R][kVecs]) {
  const uint8_t* w = panel + 8 * kNR;
  __m512i acc[R][kVecs];
#pragma GCC unroll 4
  for (int j = 0; j < kVecs; ++j) {
    const __m512i kbias = _mm512_loadu_si512(panel + 64 * j);
#pragma GCC unroll 6
    for (int r = 0; r < R; ++r) acc[r][j] = kUnsignedA ? kbias : _mm512_sub_epi32(kbias, _mm512_set1_epi32(corr[r]));
  }
  const int segments = segment_count(g), segment_groups = kgroups / segments;
  for (int s = 0; s < segments; ++s) {
    const int8_t* rows[R];
    segment_rows<R>(g, m, s, rows);
    const uint8_t* ws = w + static_cast<size_t>(s) * static_cast<size_t>(segment_groups) * (kNR * kKR);
    for (int gi = 0; gi < segment_groups; ++gi) {
      const uint8_t* wg = ws + static_cast<size_t>(gi) * (kNR * kKR);
      const __m512i w0 = _mm512_loadu_si512(wg);
      const __m512i w1 = _mm512_loadu_si512(wg + 64);
      const __m512i w2 = _mm512_loadu_si512(wg + 128);
      const __m512i w3 = _mm512_loadu_si512(wg + 192);
      if constexpr (kStreamWeights) {
        const char* ahead = reinterpret_cast<const char*>(wg) + kWeightPrefetchBytes;
        _mm_prefetch(ahead, _MM_HINT_T0);
        _mm_prefetch(ahead + 64, _MM_HINT_T0);
        _mm_prefetch(ahead + 128, _MM_HINT_T0);
        _mm_prefetch(ahead + 192, _MM_HINT_T0);
      }
#pragma GCC unroll 6
      for (int r = 0; r < R; ++r) {
        int32_t quad;
        std::memcpy(&quad, rows[r] + static_cast<size_t>(gi) * kKR, 4);
        const __m512i av = _mm512_set1_epi32(quad);
        if constexpr (kUnsignedA) {
          acc[r][0] = _mm512_dpbusd_epi32(acc[r][0], av, w0);
          acc[r][1] = _mm512_dpbusd_epi32(acc[r][1], av, w1);
          acc[r][2] = _mm512_dpbusd_epi32(acc[r][2], av, w2);
          acc[r][3] = _mm512_dpbusd_epi32(acc[r][3], av, w3);
        } else {
          acc[r][0] = _mm512_dpbusd_epi32(acc[r][0], w0, av);
          acc[r][1] = _mm512_dpbusd_epi32(acc[r][1], w1, av);
          acc[r][2] = _mm512_dpbusd_epi32(acc[r][2], w2, av);
          acc[r][3] = _mm512_dpbusd_epi32(acc[r][3], w3, av);
        }
      }
    }
  }
#pragma GCC unroll 6
  for (int r = 0; r < R; ++r) {
#pragma GCC unroll 4
    for (int j = 0; j < kVecs; ++j) out[r][j] = acc[r][j];
  }
}

struct EpiS8 {
  const GemmS8OutS8& o;
  __m512 scale[kVecs]{}, bias[kVecs]{};
  __mmask16 mask[kVecs]{};
  bool full_panel = false;

  void begin_panel(int n, int lo, int hi) {
    full_panel = lo == 0 && hi == kNR;
    for (int j = 0; j < kVecs; ++j) {
      mask[j] = vec_mask(j, lo, hi);
      scale[j] = _mm512_maskz_loadu_ps(mask[j], o.scale + n + 16 * j);
      if (o.bias != nullptr) bias[j] = _mm512_maskz_loadu_ps(mask[j], o.bias + n + 16 * j);
    }
  }
  // Nothing to fetch ahead (see EpiF32): an int8 residual is a block's input, written one or two
  // convs before and still in cache; prefetching it measured the same.
  void prefetch_rows(int, int, int) const {}
  void row(int m, int n, const __m512i (&acc)[kVecs]) const {
    // The options read once, before this row's store: an int8 store may alias anything, so a test
    // of o's fields after one would load them again, per vector.
    const float* row_scale = o.a_row_scale;
    const int8_t* residual = o.residual;
    const bool has_bias = o.bias != nullptr;
    const __m512 zo = _mm512_set1_ps(static_cast<float>(o.out_zero_point));
    const __m512 qmax = _mm512_set1_ps(static_cast<float>(o.qmax));
    __m512i q[kVecs];
    if (row_scale == nullptr && residual == nullptr && !has_bias) {
      // Per-tensor requantization, no residual (the stem, most convs, the FFN hidden layers).
      for (int j = 0; j < kVecs; ++j) q[j] = finish(_mm512_mul_ps(_mm512_cvtepi32_ps(acc[j]), scale[j]), zo, qmax);
    } else {
      const __m512 residual_scale = _mm512_set1_ps(o.residual_scale);
      const __m512i residual_zero_point = _mm512_set1_epi32(o.residual_zero_point);
      const int8_t* rp = residual != nullptr ? residual + static_cast<size_t>(m) * o.ldr + n : nullptr;
      for (int j = 0; j < kVecs; ++j) {
        const __m512 s = row_scale != nullptr ? _mm512_mul_ps(_mm512_set1_ps(row_scale[m]), scale[j]) : scale[j];
        __m512 v = _mm512_mul_ps(_mm512_cvtepi32_ps(acc[j]), s);
        if (has_bias) v = _mm512_add_ps(v, bias[j]);
        if (rp != nullptr) {
          const __m512i r = _mm512_sub_epi32(_mm512_cvtepi8_epi32(_mm_maskz_loadu_epi8(mask[j], rp + 16 * j)),
                                             residual_zero_point);
          v = _mm512_add_ps(v, _mm512_mul_ps(_mm512_cvtepi32_ps(r), residual_scale));
        }
        q[j] = finish(v, zo, qmax);
      }
    }
    store(o.c + static_cast<size_t>(m) * o.ldc + n, q);
  }

  // + z_out, then v < qmax ? v : qmax, a NaN kept (minps returns its second operand on NaN),
  // rounded half to even (MXCSR default). The low clamp comes after narrowing, on the bytes
  // (store): rounding is monotone and qmin an integer, so max(round(v), qmin) = round(max(v, qmin)),
  // and a NaN or anything below -2^31 converts to INT32_MIN, which the saturating narrowing takes to
  // -128 and the max to qmin, as requant_ref.h's float clamp does.
  static __m512i finish(__m512 v, __m512 zo, __m512 qmax) {
    return _mm512_cvtps_epi32(_mm512_min_ps(qmax, _mm512_add_ps(v, zo)));
  }

  void store(int8_t* cp, const __m512i (&q)[kVecs]) const {
    const __m512i qmin = _mm512_set1_epi8(static_cast<char>(o.qmin));
    if (full_panel) {
      // 64 columns narrowed by two saturating packs into one store (after the low clamp); the packs
      // interleave 128-bit lanes, dword 4l + j holding lane l of q[j], which the permute puts back.
      const __m512i bytes = _mm512_packs_epi16(_mm512_packs_epi32(q[0], q[1]), _mm512_packs_epi32(q[2], q[3]));
      const __m512i order = _mm512_setr_epi32(0, 4, 8, 12, 1, 5, 9, 13, 2, 6, 10, 14, 3, 7, 11, 15);
      _mm512_storeu_si512(cp, _mm512_permutexvar_epi32(order, _mm512_max_epi8(bytes, qmin)));
      return;
    }
    for (int j = 0; j < kVecs; ++j) {
      const __m128i bytes = _mm_max_epi8(_mm512_cvtsepi32_epi8(q[j]), _mm512_castsi512_si128(qmin));
      _mm_mask_storeu_epi8(cp + 16 * j, mask[j], bytes);
    }
  }
};

struct EpiF32 {
  const GemmS8OutF32& o;
  __m512 w_scale[kVecs]{}, bias[kVecs]{};
  __mmask16 mask[kVecs]{};

  void begin_panel(int n, int lo, int hi) {
    for (int j = 0; j < kVecs; ++j) {
      mask[j] = vec_mask(j, lo, hi);
      w_scale[j] = _mm512_maskz_loadu_ps(mask[j], o.w_scale + n + 16 * j);
      bias[j] = o.bias != nullptr ? _mm512_maskz_loadu_ps(mask[j], o.bias + n + 16 * j) : _mm512_setzero_ps();
    }
  }
  // The residual rows this tile's epilogue reads (4 lines each), fetched while its k loop runs: a
  // per-token table (the qkv linears' 1.2 MB of position terms) is read once per inference, cold,
  // 256 bytes per row, which the hardware prefetchers do not hide (the encoder's qkv GEMM took
  // 0.77 ms with the table cold, 0.68 ms with it read just before).
  void prefetch_rows(int m, int rows, int n) const {
    if (o.residual == nullptr) return;
    for (int r = 0; r < rows; ++r) {
      const char* line = reinterpret_cast<const char*>(o.residual + static_cast<size_t>(m + r) * o.ldr + n);
      for (int j = 0; j < kVecs; ++j) _mm_prefetch(line + 64 * j, _MM_HINT_T0);
    }
  }
  void row(int m, int n, const __m512i (&acc)[kVecs]) const {
    const __m512 a_scale = _mm512_set1_ps(o.a_row_scale != nullptr ? o.a_row_scale[m] : o.a_scale);
    float* cp = o.c + static_cast<size_t>(m) * o.ldc + n;
    for (int j = 0; j < kVecs; ++j) {
      if (mask[j] == 0) continue;
      const __m512 s = _mm512_mul_ps(a_scale, w_scale[j]);
      __m512 y = _mm512_mul_ps(_mm512_cvtepi32_ps(acc[j]), s);
      y = _mm512_add_ps(y, bias[j]);
      if (o.residual != nullptr) {
        y = _mm512_add_ps(y, _mm512_maskz_loadu_ps(mask[j], o.residual + static_cast<size_t>(m) * o.ldr + n + 16 * j));
      }
      if (o.relu) y = _mm512_max_ps(y, _mm512_setzero_ps());  // y > 0 ? y : 0
      _mm512_mask_storeu_ps(cp + 16 * j, mask[j], y);
    }
  }
};

struct EpiS32 {
  const GemmS8OutS32& o;
  __mmask16 mask[kVecs]{};

  void begin_panel(int, int lo, int hi) {
    for (int j = 0; j < kVecs; ++j) mask[j] = vec_mask(j, lo, hi);
  }
  void prefetch_rows(int, int, int) const {}
  void row(int m, int n, const __m512i (&acc)[kVecs]) const {
    int32_t* cp = o.c + static_cast<size_t>(m) * o.ldc + n;
    for (int j = 0; j < kVecs; ++j) _mm512_mask_storeu_epi32(cp + 16 * j, mask[j], acc[j]);
  }
};

// One R x 64 micro-tile starting at row m.
template <int R, bool kUnsignedA, class Epi>
void tile(const GemmS8Args& g, const GemmS8PackedHeader& h, const int32_t (&corr)[R], const uint8_t* panel, int m,
          int n, int lo, int hi, Epi& epi, bool stream_weights) {
  __m512i acc[R][kVecs];
  epi.prefetch_rows(m, R, n);
  if (stream_weights) {
    accumulate<R, true, kUnsignedA>(g, m, panel, h.kp / kKR, corr, acc);
  } else {
    accumulate<R, false, kUnsignedA>(g, m, panel, h.kp / kKR, corr, acc);
  }
  if (g.a_row_zero_point != nullptr) {
    // acc -= (z_row - z_packed) * ksum: the packed kbias assumed z_packed.
    for (int j = 0; j < kVecs; ++j) {
      const __m512i ksum = _mm512_loadu_si512(panel + 4 * kNR + 64 * j);
      for (int r = 0; r < R; ++r) {
        const __m512i dz = _mm512_set1_epi32(g.a_row_zero_point[m + r] - h.a_zero_point);
        acc[r][j] = _mm512_sub_epi32(acc[r][j], _mm512_mullo_epi32(dz, ksum));
      }
    }
  }
  epi.begin_panel(n, lo, hi);
#pragma GCC unroll 6
  for (int r = 0; r < R; ++r) epi.row(m + r, n, acc[r]);
}

#include "kernels/gemm_s8/gemm_s8_vnni_rows.inc"

// o[L] = lane L (128 bits) of a, of b, of c and of d, in that order: a 4 x 4 transpose of lanes.
void transpose_lanes(const __m512i& a, const __m512i& b, const __m512i& c, const __m512i& d, __m512i& o0,
                     __m512i& o1, __m512i& o2, __m512i& o3) {
  const __m512i ab_low = _mm512_shuffle_i32x4(a, b, 0x44), ab_high = _mm512_shuffle_i32x4(a, b, 0xEE);  // a0 a1 b0 b1 | a2 a3 b2 b3
  const __m512i cd_low = _mm512_shuffle_i32x4(c, d, 0x44), cd_high = _mm512_shuffle_i32x4(c, d, 0xEE);
  o0 = _mm512_shuffle_i32x4(ab_low, cd_low, 0x88);  // every other lane: a0 b0 c0 d0
  o1 = _mm512_shuffle_i32x4(ab_low, cd_low, 0xDD);
  o2 = _mm512_shuffle_i32x4(ab_high, cd_high, 0x88);
  o3 = _mm512_shuffle_i32x4(ab_high, cd_high, 0xDD);
}

// Sixteen vectors of 16 int32 transposed in registers: afterwards v[c] holds element c of each
// input vector, in input order. Unpacks transpose 4 x 4 blocks within 128-bit lanes, then the
// lanes of the four groups of four inputs are transposed.
void transpose16x16_epi32(__m512i (&v)[16]) {
  __m512i quads[16];  // quads[4 * group + j], lane L: element 4L + j of inputs 4 group .. 4 group + 3
  for (int group = 0; group < 4; ++group) {
    const __m512i* in = v + 4 * group;
    const __m512i lo01 = _mm512_unpacklo_epi32(in[0], in[1]), hi01 = _mm512_unpackhi_epi32(in[0], in[1]);
    const __m512i lo23 = _mm512_unpacklo_epi32(in[2], in[3]), hi23 = _mm512_unpackhi_epi32(in[2], in[3]);
    quads[4 * group + 0] = _mm512_unpacklo_epi64(lo01, lo23);
    quads[4 * group + 1] = _mm512_unpackhi_epi64(lo01, lo23);
    quads[4 * group + 2] = _mm512_unpacklo_epi64(hi01, hi23);
    quads[4 * group + 3] = _mm512_unpackhi_epi64(hi01, hi23);
  }
  for (int j = 0; j < 4; ++j) transpose_lanes(quads[j], quads[4 + j], quads[8 + j], quads[12 + j], v[j], v[4 + j], v[8 + j], v[12 + j]);
}

// A panel's column sums and folded bias from `sums` (vector j: sum of W + 128 over k for columns
// [16j, 16j + 16) of the panel, k bytes each): kbias = bias - a_zero_point * sum W, modulo 2^32 as
// pack.cc and the kernels compute it; columns past n: 0.
void store_panel_sums(uint8_t* panel, int slot, int cols, const __m512i& sums, int k, const int32_t* bias, int32_t a_zero_point) {
  const __mmask16 valid = static_cast<__mmask16>((1u << std::max(0, std::min(16, cols))) - 1u);
  const __m512i column_sums = _mm512_maskz_sub_epi32(valid, sums, _mm512_set1_epi32(128 * k));
  const __m512i b = bias != nullptr ? _mm512_maskz_loadu_epi32(valid, bias) : _mm512_setzero_si512();
  const __m512i kbias = _mm512_maskz_sub_epi32(valid, b, _mm512_mullo_epi32(_mm512_set1_epi32(a_zero_point), column_sums));
  _mm512_store_si512(panel + 4 * slot, kbias);
  _mm512_store_si512(panel + 4 * (kNR + slot), column_sums);
}

// The packers' common start: checks the buffer, writes the header, returns it.
GemmS8PackedHeader begin_packing(int n, int k, int32_t a_zero_point, void* packed) {
  ACT_DCHECK(n >= 1 && k >= 1 && k <= kGemmS8MaxK, "bad weight shape");
  ACT_DCHECK(reinterpret_cast<uintptr_t>(packed) % kGemmS8PackedAlign == 0, "packed buffer must be 64-byte aligned");
  const GemmS8PackedHeader h = gemm_s8_packed_header(kLayout, n, k, a_zero_point);
  std::memcpy(packed, &h, sizeof h);
  return h;
}

// The panel that holds column c.
uint8_t* panel_of(void* packed, const GemmS8PackedHeader& h, int c) {
  return static_cast<uint8_t*>(packed) + sizeof h + static_cast<size_t>(c / kNR) * h.panel_bytes;
}

// pack_w_s8_64x4_goi_x80's bytes (a test compares them on ragged shapes), 16 columns by 64 bytes of
// K at a time: the 16 rows of W loaded (XOR 0x80 on the bytes inside K, so padding stays 0), their
// 16 x 16 four-byte k-groups transposed so that each k-group's 16 columns are one aligned store, and
// the column sums taken from the stored bytes by vpdpbusd against ones (sum (W + 128) = sum W +
// 128 K). The attention packs every head's keys with it at every run: the portable packer, a byte
// at a time, took 8.7 % of the int8 attention (0.57 ms, one thread).
void pack_w_s8_64x4_goi_x80_avx512vnni(int n, int k, const int8_t* w, size_t ldw, const int32_t* bias,
                                       int32_t a_zero_point, void* packed) {
  ACT_DCHECK(ldw >= static_cast<size_t>(k), "W's rows overlap");
  const GemmS8PackedHeader h = begin_packing(n, k, a_zero_point, packed);
  const int groups = h.kp / kKR;
  const int columns = (n + kNR - 1) / kNR * kNR;  // whole panels: columns past n are written as 0
  const __m512i ones = _mm512_set1_epi8(1), flip = _mm512_set1_epi8(static_cast<char>(0x80));
  const __m512i zero = _mm512_setzero_si512();
  for (int c0 = 0; c0 < columns; c0 += 16) {
    uint8_t* panel = panel_of(packed, h, c0);
    const int slot = c0 % kNR, cols = std::max(0, std::min(16, n - c0));
    __m512i sums = zero;
    for (int g0 = 0; g0 < groups; g0 += 16) {
      const int k0 = kKR * g0, bytes = std::min(64, k - k0);
      const __mmask64 inside = bytes >= 64 ? ~__mmask64{0} : (__mmask64{1} << bytes) - 1;
      const __m512i flip_inside = _mm512_maskz_mov_epi8(inside, flip);
      __m512i v[16];
      for (int i = 0; i < 16; ++i) {
        v[i] = i < cols ? _mm512_xor_si512(_mm512_maskz_loadu_epi8(inside, w + static_cast<size_t>(c0 + i) * ldw + k0), flip_inside)
                        : zero;
      }
      transpose16x16_epi32(v);
      for (int g = 0; g < 16 && g0 + g < groups; ++g) {
        sums = _mm512_dpbusd_epi32(sums, v[g], ones);
        _mm512_store_si512(panel + 8 * kNR + static_cast<size_t>(g0 + g) * (kNR * kKR) + 4 * slot, v[g]);
      }
    }
    store_panel_sums(panel, slot, cols, sums, k, bias != nullptr ? bias + c0 : nullptr, a_zero_point);
  }
}

// pack_wt_s8_64x4_goi_x80's bytes (W^T [k x n] in, the same bytes as the packer of W; a test
// compares them), a panel's 64 columns by one k-group at a time: the group's four rows of W^T
// loaded (XOR 0x80 on the columns inside n, rows past k zero), their bytes interleaved column by
// column (unpacks within 128-bit lanes, then a transpose of lanes), four aligned stores, the column
// sums by vpdpbusd as above. The attention packs every head's values with it at every run (the
// portable packer took 3 % of the int8 attention).
void pack_wt_s8_64x4_goi_x80_avx512vnni(int n, int k, const int8_t* wt, size_t ldw, const int32_t* bias,
                                        int32_t a_zero_point, void* packed) {
  ACT_DCHECK(ldw >= static_cast<size_t>(n), "W^T's rows overlap");
  const GemmS8PackedHeader h = begin_packing(n, k, a_zero_point, packed);
  const int groups = h.kp / kKR;
  const __m512i ones = _mm512_set1_epi8(1), flip = _mm512_set1_epi8(static_cast<char>(0x80)), zero = _mm512_setzero_si512();
  for (int c0 = 0; c0 < n; c0 += kNR) {
    uint8_t* panel = panel_of(packed, h, c0);
    uint8_t* data = panel + 8 * kNR;
    const int cols = std::min(kNR, n - c0);
    const __mmask64 inside = cols >= 64 ? ~__mmask64{0} : (__mmask64{1} << cols) - 1;
    const __m512i flip_inside = _mm512_maskz_mov_epi8(inside, flip);
    __m512i sums[kVecs] = {zero, zero, zero, zero};
    for (int g = 0; g < groups; ++g) {
      __m512i row[kKR];
      for (int r = 0; r < kKR; ++r) {
        const int i = kKR * g + r;
        row[r] = i < k ? _mm512_xor_si512(_mm512_maskz_loadu_epi8(inside, wt + static_cast<size_t>(i) * ldw + c0), flip_inside) : zero;
      }
      // Lane L of quad[j]: columns 16L + 4j .. 16L + 4j + 3, each its four rows' bytes in order.
      const __m512i pairs01_low = _mm512_unpacklo_epi8(row[0], row[1]), pairs01_high = _mm512_unpackhi_epi8(row[0], row[1]);
      const __m512i pairs23_low = _mm512_unpacklo_epi8(row[2], row[3]), pairs23_high = _mm512_unpackhi_epi8(row[2], row[3]);
      const __m512i quad0 = _mm512_unpacklo_epi16(pairs01_low, pairs23_low), quad1 = _mm512_unpackhi_epi16(pairs01_low, pairs23_low);
      const __m512i quad2 = _mm512_unpacklo_epi16(pairs01_high, pairs23_high), quad3 = _mm512_unpackhi_epi16(pairs01_high, pairs23_high);
      __m512i out[kVecs];
      transpose_lanes(quad0, quad1, quad2, quad3, out[0], out[1], out[2], out[3]);
      for (int j = 0; j < kVecs; ++j) {
        sums[j] = _mm512_dpbusd_epi32(sums[j], out[j], ones);
        _mm512_store_si512(data + static_cast<size_t>(g) * (kNR * kKR) + 64 * j, out[j]);
      }
    }
    for (int j = 0; j < kVecs; ++j) {
      store_panel_sums(panel, 16 * j, cols - 16 * j, sums[j], k, bias != nullptr ? bias + c0 + 16 * j : nullptr, a_zero_point);
    }
  }
}

}  // namespace

const GemmS8Kernels* gemm_s8_table_avx512vnni() {
  static constexpr GemmS8Kernels kTable = variant_table<EpiS8, EpiF32, EpiS32>(
      {"pack_w_s8_64x4_goi_x80", "gemm_s8s8_s8out_6x64c4_avx512vnni", "gemm_s8s8_f32out_6x64c4_avx512vnni",
       "gemm_s8s8_s32out_6x64c4_avx512vnni"},
      pack_w_s8_64x4_goi_x80_avx512vnni, pack_wt_s8_64x4_goi_x80_avx512vnni, "pack_w_s8_64x4_goi_u8a", pack_w_s8_64x4_goi_u8a);
  return &kTable;
}

}  // namespace act::kernels

#else  // not x86-64: nothing to build

namespace act::kernels {
const GemmS8Kernels* gemm_s8_table_avx512vnni() { return nullptr; }
}  // namespace act::kernels

#endif
