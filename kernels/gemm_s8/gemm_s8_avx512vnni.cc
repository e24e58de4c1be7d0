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

#include "kernels/gemm_s8/gemm_s8_epilogue_avx512.inc"

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

#include "kernels/gemm_s8/gemm_s8_pack_avx512.inc"

}  // namespace

const GemmS8Kernels* gemm_s8_table_avx512vnni() {
  static constexpr GemmS8Kernels kTable = variant_table<EpiS8, EpiF32, EpiS32>(
      {"pack_w_s8_64x4_goi_x80", "gemm_s8s8_s8out_6x64c4_avx512vnni", "gemm_s8s8_f32out_6x64c4_avx512vnni",
       "gemm_s8s8_s32out_6x64c4_avx512vnni"},
      pack_w_64x4<kLayout, true>, pack_wt_64x4<kLayout, true>, "pack_w_s8_64x4_goi_u8a", pack_w_64x4<kLayoutU8A, false>);
  return &kTable;
}

}  // namespace act::kernels

#else  // not x86-64: nothing to build

namespace act::kernels {
const GemmS8Kernels* gemm_s8_table_avx512vnni() { return nullptr; }
}  // namespace act::kernels

#endif
