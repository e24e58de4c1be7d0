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
using TileAcc = __m256i[R];

// out[r] = the 8 int32 accumulators of row r (natural column order), kbias included, A walked
// segment by segment. The accumulators are a local array (copied out once) so that GCC keeps them
// in registers.
template <int R>
inline void accumulate(const GemmS8Args& g, int m, const uint8_t* panel, int kp, __m256i (&out)[R]) {
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
    out[r] = _mm256_add_epi32(_mm256_hadd_epi32(h0, h1), kbias);  // [c0 c1 c2 c3 | c4 c5 c6 c7]
  }
}

__m256i lane_mask(int lo, int hi) {
  const __m256i idx = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  return _mm256_and_si256(_mm256_cmpgt_epi32(idx, _mm256_set1_epi32(lo - 1)),
                          _mm256_cmpgt_epi32(_mm256_set1_epi32(hi), idx));
}

// Per-column float parameters of a panel, zero outside [lo, hi) so nothing past N is read.
__m256 load_cols(const float* p, int n, int lo, int hi) {
  if (lo == 0 && hi == kNR) return _mm256_loadu_ps(p + n);
  return _mm256_maskload_ps(p + n, lane_mask(lo, hi));
}

struct EpiS8 {
  const GemmS8OutS8& o;
  __m256 scale{}, bias{}, zo{}, qmin{}, qmax{}, rscale{};
  __m256i rzp{};

  void begin_panel(int n, int lo, int hi) {
    scale = load_cols(o.scale, n, lo, hi);
    if (o.bias != nullptr) bias = load_cols(o.bias, n, lo, hi);
    zo = _mm256_set1_ps(static_cast<float>(o.out_zero_point));
    qmin = _mm256_set1_ps(static_cast<float>(o.qmin));
    qmax = _mm256_set1_ps(static_cast<float>(o.qmax));
    rscale = _mm256_set1_ps(o.residual_scale);
    rzp = _mm256_set1_epi32(o.residual_zero_point);
  }
  void row(int m, int n, int lo, int hi, __m256i acc) const {
    const bool full = lo == 0 && hi == kNR;
    const __m256 s = o.a_row_scale != nullptr ? _mm256_mul_ps(_mm256_set1_ps(o.a_row_scale[m]), scale) : scale;
    __m256 v = _mm256_mul_ps(_mm256_cvtepi32_ps(acc), s);
    if (o.bias != nullptr) v = _mm256_add_ps(v, bias);
    if (o.residual != nullptr) {
      const int8_t* rp = o.residual + static_cast<size_t>(m) * o.ldr + n;
      int64_t bytes = 0;
      if (full) {
        std::memcpy(&bytes, rp, 8);
      } else {
        int8_t tmp[8] = {};
        std::memcpy(tmp + lo, rp + lo, static_cast<size_t>(hi - lo));
        std::memcpy(&bytes, tmp, 8);
      }
      const __m256i r = _mm256_sub_epi32(_mm256_cvtepi8_epi32(_mm_cvtsi64_si128(bytes)), rzp);
      v = _mm256_add_ps(v, _mm256_mul_ps(_mm256_cvtepi32_ps(r), rscale));
    }
    v = _mm256_add_ps(v, zo);
    v = _mm256_max_ps(v, qmin);  // v > qmin ? v : qmin, as requant_ref.h
    v = _mm256_min_ps(v, qmax);
    const __m256i q32 = _mm256_cvtps_epi32(v);  // round half to even (MXCSR default)
    const __m128i q16 = _mm_packs_epi32(_mm256_castsi256_si128(q32), _mm256_extracti128_si256(q32, 1));
    const __m128i q8 = _mm_packs_epi16(q16, q16);  // exact: values are already in [qmin, qmax]
    int8_t* cp = o.c + static_cast<size_t>(m) * o.ldc + n;
    if (full) {
      _mm_storel_epi64(reinterpret_cast<__m128i*>(cp), q8);
    } else {
      int8_t tmp[16];
      _mm_storeu_si128(reinterpret_cast<__m128i*>(tmp), q8);
      std::memcpy(cp + lo, tmp + lo, static_cast<size_t>(hi - lo));
    }
  }
};

struct EpiF32 {
  const GemmS8OutF32& o;
  __m256 w_scale{}, bias{};

  void begin_panel(int n, int lo, int hi) {
    w_scale = load_cols(o.w_scale, n, lo, hi);
    bias = o.bias != nullptr ? load_cols(o.bias, n, lo, hi) : _mm256_setzero_ps();
  }
  void row(int m, int n, int lo, int hi, __m256i acc) const {
    const bool full = lo == 0 && hi == kNR;
    const __m256i mask = full ? _mm256_set1_epi32(-1) : lane_mask(lo, hi);
    const float a_scale = o.a_row_scale != nullptr ? o.a_row_scale[m] : o.a_scale;
    const __m256 s = _mm256_mul_ps(_mm256_set1_ps(a_scale), w_scale);
    __m256 y = _mm256_mul_ps(_mm256_cvtepi32_ps(acc), s);
    y = _mm256_add_ps(y, bias);
    if (o.residual != nullptr) {
      const float* rp = o.residual + static_cast<size_t>(m) * o.ldr + n;
      y = _mm256_add_ps(y, full ? _mm256_loadu_ps(rp) : _mm256_maskload_ps(rp, mask));
    }
    if (o.relu) y = _mm256_max_ps(y, _mm256_setzero_ps());  // y > 0 ? y : 0
    float* cp = o.c + static_cast<size_t>(m) * o.ldc + n;
    if (full) {
      _mm256_storeu_ps(cp, y);
    } else {
      _mm256_maskstore_ps(cp, mask, y);
    }
  }
};

struct EpiS32 {
  const GemmS8OutS32& o;
  void begin_panel(int, int, int) {}
  void row(int m, int n, int lo, int hi, __m256i acc) const {
    int32_t* cp = o.c + static_cast<size_t>(m) * o.ldc + n;
    if (lo == 0 && hi == kNR) {
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(cp), acc);
    } else {
      _mm256_maskstore_epi32(cp, lane_mask(lo, hi), acc);
    }
  }
};

// acc -= (z_row - z_packed) * ksum (the driver's per-row zero points).
template <int R>
void subtract_row_zero_points(const GemmS8Args& g, const GemmS8PackedHeader& h, const uint8_t* panel, int m,
                              __m256i (&acc)[R]) {
  const __m256i ksum = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(panel + 4 * kNR));
  for (int r = 0; r < R; ++r) {
    const __m256i dz = _mm256_set1_epi32(g.a_row_zero_point[m + r] - h.a_zero_point);
    acc[r] = _mm256_sub_epi32(acc[r], _mm256_mullo_epi32(dz, ksum));
  }
}

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
