// gemm_s8 on AVX2: the 2x8c8 micro-kernel. Compiled with -mavx2 -mfma on x86-64 targets only;
// elsewhere this file is just the null table.
//
// Why vpmaddwd and not vpmaddubsw: vpmaddubsw adds two u8 x s8 products into a *saturating* int16,
// which clips for full-range operands (2 x 255 x 127 > 32767). Sign-extending both operands to
// int16 and using vpmaddwd gives exact int32 pair sums (XNNPACK's qs8 MRx8c8-avx2, ruy's AVX2
// kernel), at half the MACs per instruction.
//
// One k-group of 8 per step: each A row's 8 bytes are broadcast to both 128-bit halves and widened
// ([a0..a7 | a0..a7] as int16); each 16-byte weight load widens to [col j, k0..7 | col j+4, k0..7]
// (the pair4 packing), so vpmaddwd yields 4 partial sums for column j in the low half and for j+4
// in the high half. After the K loop three rounds of vphaddd leave the 8 columns in natural order.
//
// Why 2 rows: 3 rows need 17 ymm registers (12 accumulators, 3 A, the widened weight, the
// product) and GCC 12 spilled accumulators in every iteration (1.5-2x slower, measured); 2 rows
// use 12 and compile to the ideal loop: 2 widen + 4 widen-load + 8 vpmaddwd + 8 vpaddd per 128 MACs.
// (Weights pre-widened to int16 at pack time, read as vpmaddwd memory operands, were no faster:
// they double the L2 traffic of the large-K layers.)
//
// Rules for ISA files (see README.md): only intrinsics and internal-linkage code here; no inline
// functions or templates from shared headers, whose out-of-line copies would carry AVX2 code.
#include "kernels/gemm_s8/gemm_s8_variants.h"

#if defined(__x86_64__)

#include <immintrin.h>

#include <cstring>
#include <type_traits>

#include "kernels/common/check.h"

namespace act::kernels {

namespace {

constexpr int kMR = 2;
constexpr int kNR = 8;
constexpr int kKR = 8;
constexpr Isa kIsa = Isa::kAvx2;
constexpr GemmS8Layout kLayout = GemmS8Layout::kAvx2_8x8;
constexpr bool own_layout(GemmS8Layout l) { return l == kLayout; }
// Weight panels processed per sweep over the rows: keep them in L2 while every row block reuses them.
constexpr size_t kPanelBlockBytes = size_t{512} << 10;

#include "kernels/gemm_s8/gemm_s8_driver.inc"

template <int R>
using TileAcc = __m256i[R][1];  // one vector of 8 columns per row

// out[r] = the 8 int32 accumulators of row r (natural column order), kbias included, A walked
// segment by segment. The accumulators are a local array (copied out once) so that GCC keeps them
// in registers.
template <int R>
inline void accumulate(const GemmS8Args& g, int m, const uint8_t* panel, int kp, __m256i (&out)[R][1]) {
  const int kgroups = kp / kKR;
  const auto* w = reinterpret_cast<const int8_t*>(panel + 8 * kNR);
  __m256i acc[R][4];
#pragma GCC unroll 2
  for (int r = 0; r < R; ++r) {
#pragma GCC unroll 4
    for (int j = 0; j < 4; ++j) acc[r][j] = _mm256_setzero_si256();
  }
  const int segments = segment_count(g), segment_groups = kgroups / segments;
  for (int s = 0; s < segments; ++s) {
    const int8_t* rows[R];
    segment_rows<R>(g, m, s, rows);
    const int8_t* ws = w + static_cast<size_t>(s) * static_cast<size_t>(segment_groups) * (kNR * kKR);
    for (int gi = 0; gi < segment_groups; ++gi) {
      __m256i av[R];
#pragma GCC unroll 2
      for (int r = 0; r < R; ++r) {
        int64_t bytes;
        std::memcpy(&bytes, rows[r] + static_cast<size_t>(gi) * kKR, 8);
        av[r] = _mm256_cvtepi8_epi16(_mm_set1_epi64x(bytes));
      }
      const int8_t* wg = ws + static_cast<size_t>(gi) * (kNR * kKR);
#pragma GCC unroll 4
      for (int j = 0; j < 4; ++j) {
        const __m256i wv = _mm256_cvtepi8_epi16(_mm_loadu_si128(reinterpret_cast<const __m128i*>(wg + j * 16)));
#pragma GCC unroll 2
        for (int r = 0; r < R; ++r) {
          acc[r][j] = _mm256_add_epi32(acc[r][j], _mm256_madd_epi16(av[r], wv));
          // Pins the sum to its register here; without it GCC issues all vpmaddwd first, runs out of
          // registers for the products and adds moves (and spills) to the loop.
          __asm__("" : "+x"(acc[r][j]));
        }
      }
    }
  }
  const __m256i kbias = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(panel));
#pragma GCC unroll 2
  for (int r = 0; r < R; ++r) {
    const __m256i h0 = _mm256_hadd_epi32(acc[r][0], acc[r][1]);  // j=0,1 | j+4=4,5, two partials each
    const __m256i h1 = _mm256_hadd_epi32(acc[r][2], acc[r][3]);
    out[r][0] = _mm256_add_epi32(_mm256_hadd_epi32(h0, h1), kbias);  // [c0 c1 c2 c3 | c4 c5 c6 c7]
  }
}

#include "kernels/gemm_s8/gemm_s8_epilogue_ymm.inc"
#include "kernels/gemm_s8/gemm_s8_tiles.inc"

}  // namespace

const GemmS8Kernels* gemm_s8_table_avx2() {
  static constexpr GemmS8Kernels kTable = variant_table<EpiS8, EpiF32, EpiS32>(
      {"pack_w_s8_8x8_goi_pair4", "gemm_s8s8_s8out_2x8c8_avx2", "gemm_s8s8_f32out_2x8c8_avx2", "gemm_s8s8_s32out_2x8c8_avx2"},
      pack_w_s8_8x8_goi_pair4, pack_wt_s8_8x8_goi_pair4);
  return &kTable;
}

}  // namespace act::kernels

#else  // not x86-64: nothing to build

namespace act::kernels {
const GemmS8Kernels* gemm_s8_table_avx2() { return nullptr; }
}  // namespace act::kernels

#endif
