// quant on AVX2: 32 floats per step (4 ymm), packed to bytes with signed saturation. Ragged tails go
// through a 32-element stack buffer and the same vector code (quant_s8_tail.inc).
// Rules for ISA files (kernels/gemm_s8/README.md): only intrinsics and internal-linkage code here.
#include "kernels/quant/quant_s8_variants.h"

#if defined(__x86_64__)

#include <immintrin.h>

#include <cstring>

namespace act::kernels {

namespace {

#include "kernels/quant/quant_s8_tail.inc"

constexpr size_t kStep = 32;

// The quantization rule on 8 floats: x * inv + z, clamped (NaN -> lo: maxps returns its second
// operand when either is NaN), rounded half to even (cvtps2dq in the default MXCSR mode).
__m256i quantize8(const float* x, __m256 inv, __m256 z, __m256 lo, __m256 hi) {
  __m256 v = _mm256_mul_ps(_mm256_loadu_ps(x), inv);
  v = _mm256_add_ps(v, z);
  v = _mm256_max_ps(v, lo);
  v = _mm256_min_ps(v, hi);
  return _mm256_cvtps_epi32(v);
}

// 32 codes from four vectors of 8 to bytes in order.
void store32(__m256i q0, __m256i q1, __m256i q2, __m256i q3, int8_t* y) {
  // packs works within 128-bit lanes: bytes come out as dwords [0 2 4 6 1 3 5 7]; permute back.
  const __m256i b = _mm256_packs_epi16(_mm256_packs_epi32(q0, q1), _mm256_packs_epi32(q2, q3));
  const __m256i order = _mm256_setr_epi32(0, 4, 1, 5, 2, 6, 3, 7);
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(y), _mm256_permutevar8x32_epi32(b, order));
}

void quantize32(const float* x, __m256 inv, __m256 z, __m256 lo, __m256 hi, int8_t* y) {
  store32(quantize8(x, inv, z, lo, hi), quantize8(x + 8, inv, z, lo, hi), quantize8(x + 16, inv, z, lo, hi),
          quantize8(x + 24, inv, z, lo, hi), y);
}

// The same with an inverse scale per lane (inv[0..32), per column).
void quantize32_per_lane(const float* x, const float* inv, __m256 z, __m256 lo, __m256 hi, int8_t* y) {
  store32(quantize8(x, _mm256_loadu_ps(inv), z, lo, hi), quantize8(x + 8, _mm256_loadu_ps(inv + 8), z, lo, hi),
          quantize8(x + 16, _mm256_loadu_ps(inv + 16), z, lo, hi), quantize8(x + 24, _mm256_loadu_ps(inv + 24), z, lo, hi),
          y);
}

void quantize_f32_s8_avx2(size_t n, const float* x, float inv_scale, int32_t zero_point, int8_t* y) {
  const __m256 inv = _mm256_set1_ps(inv_scale), z = _mm256_set1_ps(static_cast<float>(zero_point));
  const __m256 lo = _mm256_set1_ps(-128.0f), hi = _mm256_set1_ps(127.0f);
  blocks_zero_padded<kStep>(n, x, y, [&](const float* xb, int8_t* yb) { quantize32(xb, inv, z, lo, hi, yb); });
}

void dequantize16(const int8_t* q, __m256 z, __m256 scale, float* y) {
  const __m128i b = _mm_loadu_si128(reinterpret_cast<const __m128i*>(q));
  const __m256 f0 = _mm256_cvtepi32_ps(_mm256_cvtepi8_epi32(b));
  const __m256 f1 = _mm256_cvtepi32_ps(_mm256_cvtepi8_epi32(_mm_srli_si128(b, 8)));
  _mm256_storeu_ps(y, _mm256_mul_ps(_mm256_sub_ps(f0, z), scale));
  _mm256_storeu_ps(y + 8, _mm256_mul_ps(_mm256_sub_ps(f1, z), scale));
}

void dequantize_s8_f32_avx2(size_t n, const int8_t* q, float scale, int32_t zero_point, float* y) {
  const __m256 z = _mm256_set1_ps(static_cast<float>(zero_point)), s = _mm256_set1_ps(scale);
  blocks_zero_padded<16>(n, q, y, [&](const int8_t* qb, float* yb) { dequantize16(qb, z, s, yb); });
}

// minps(x, acc) returns acc when x is NaN, so NaNs are skipped like the reference's compare; the
// tail is padded with NaN for the same reason.
void minmax_f32_avx2(size_t n, const float* x, float* lo, float* hi) {
  __m256 mn0 = _mm256_set1_ps(__builtin_inff()), mn1 = mn0;
  __m256 mx0 = _mm256_set1_ps(-__builtin_inff()), mx1 = mx0;
  blocks_nan_padded<16>(n, x, [&](const float* xb) {
    const __m256 a = _mm256_loadu_ps(xb), b = _mm256_loadu_ps(xb + 8);
    mn0 = _mm256_min_ps(a, mn0);
    mx0 = _mm256_max_ps(a, mx0);
    mn1 = _mm256_min_ps(b, mn1);
    mx1 = _mm256_max_ps(b, mx1);
  });
  __m256 mn = _mm256_min_ps(mn0, mn1), mx = _mm256_max_ps(mx0, mx1);  // no NaN left in accumulators
  __m128 m4 = _mm_min_ps(_mm256_castps256_ps128(mn), _mm256_extractf128_ps(mn, 1));
  __m128 x4 = _mm_max_ps(_mm256_castps256_ps128(mx), _mm256_extractf128_ps(mx, 1));
  m4 = _mm_min_ps(m4, _mm_movehl_ps(m4, m4));
  x4 = _mm_max_ps(x4, _mm_movehl_ps(x4, x4));
  m4 = _mm_min_ss(m4, _mm_shuffle_ps(m4, m4, 1));
  x4 = _mm_max_ss(x4, _mm_shuffle_ps(x4, x4, 1));
  *lo = _mm_cvtss_f32(m4);
  *hi = _mm_cvtss_f32(x4);
}

void quantize_rows_symmetric_f32_s8_avx2(int rows, int cols, const float* x, size_t ldx, int8_t* y, size_t ldy,
                                         float* row_scale) {
  quantize_rows_symmetric_with<minmax_f32_avx2, quantize_f32_s8_avx2>(rows, cols, x, ldx, y, ldy, row_scale);
}

// 32 columns at a time (four vectors): their minmax down the rows, 32 scales, then the same rows
// quantized with four vectors of inverse scales; each row is visited twice per block (attention's
// rows lie pages apart: a visit is a TLB lookup). A ragged block loads through vmaskmovps
// (masked-off lanes read as 0 and never fault; the minmax keeps its accumulator there) and stores
// through a stack copy.
void quantize_columns_symmetric_f32_s8_avx2(int rows, int cols, const float* x, size_t ldx, int8_t* y, size_t ldy,
                                            float* col_scale) {
  constexpr int kVectors = 4, kBlock = 8 * kVectors;
  const __m256 zero = _mm256_setzero_ps(), lo = _mm256_set1_ps(-128.0f), hi = _mm256_set1_ps(127.0f);
  const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  for (int c0 = 0; c0 < cols; c0 += kBlock) {
    const int width = cols - c0 < kBlock ? cols - c0 : kBlock;
    __m256i m[kVectors];
    __m256 mn[kVectors], mx[kVectors];
    for (int j = 0; j < kVectors; ++j) {
      m[j] = _mm256_cmpgt_epi32(_mm256_set1_epi32(width - 8 * j), lane);
      mn[j] = _mm256_set1_ps(__builtin_inff());
      mx[j] = _mm256_set1_ps(-__builtin_inff());
    }
    // minps(a, acc) skips a NaN, as minmax does. Whole blocks take plain loads and no blends.
    if (width == kBlock) {
      for (int r = 0; r < rows; ++r) {
        const float* xr = x + static_cast<size_t>(r) * ldx + c0;
        for (int j = 0; j < kVectors; ++j) {
          const __m256 a = _mm256_loadu_ps(xr + 8 * j);
          mn[j] = _mm256_min_ps(a, mn[j]);
          mx[j] = _mm256_max_ps(a, mx[j]);
        }
      }
    } else {
      for (int r = 0; r < rows; ++r) {
        const float* xr = x + static_cast<size_t>(r) * ldx + c0;
        for (int j = 0; j < kVectors; ++j) {
          const __m256 a = _mm256_maskload_ps(xr + 8 * j, m[j]);
          const __m256 keep = _mm256_castsi256_ps(m[j]);
          mn[j] = _mm256_blendv_ps(mn[j], _mm256_min_ps(a, mn[j]), keep);
          mx[j] = _mm256_blendv_ps(mx[j], _mm256_max_ps(a, mx[j]), keep);
        }
      }
    }
    float lo_c[kBlock], hi_c[kBlock], inv_c[kBlock] = {};
    for (int j = 0; j < kVectors; ++j) {
      _mm256_storeu_ps(lo_c + 8 * j, mn[j]);
      _mm256_storeu_ps(hi_c + 8 * j, mx[j]);
    }
    for (int c = 0; c < width; ++c) col_scale[c0 + c] = symmetric_scale_s8(lo_c[c], hi_c[c], &inv_c[c]);
    for (int r = 0; r < rows; ++r) {
      const float* xr = x + static_cast<size_t>(r) * ldx + c0;
      int8_t* yr = y + static_cast<size_t>(r) * ldy + c0;
      blocks_zero_padded<kBlock>(static_cast<size_t>(width), xr, yr, [&](const float* xb, int8_t* yb) {
        quantize32_per_lane(xb, inv_c, zero, lo, hi, yb);
      });
    }
  }
}

}  // namespace

const QuantS8Kernels* quant_s8_table_avx2() {
  static constexpr QuantS8Kernels kTable = {Isa::kAvx2,
                                            "quantize_f32_s8_avx2",
                                            "dequantize_s8_f32_avx2",
                                            "minmax_f32_avx2",
                                            "quantize_rows_symmetric_f32_s8_avx2",
                                            "quantize_columns_symmetric_f32_s8_avx2",
                                            quantize_f32_s8_avx2,
                                            dequantize_s8_f32_avx2,
                                            minmax_f32_avx2,
                                            quantize_rows_symmetric_f32_s8_avx2,
                                            quantize_columns_symmetric_f32_s8_avx2};
  return &kTable;
}

}  // namespace act::kernels

#else  // not x86-64

namespace act::kernels {
const QuantS8Kernels* quant_s8_table_avx2() { return nullptr; }
}  // namespace act::kernels

#endif
