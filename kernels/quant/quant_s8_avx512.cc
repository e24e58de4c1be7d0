// quant on AVX-512 (F/BW; the kAvx512 variant): 16 floats per vector, narrowed with
// vpmovsdb; ragged tails use masked loads and stores (masked-off lanes never fault).
// Rules for ISA files (kernels/gemm_s8/README.md): only intrinsics and internal-linkage code here.
#include "kernels/quant/quant_s8_variants.h"

#if defined(__x86_64__)

// GCC 12's _mm512_undefined_*() trip -Wmaybe-uninitialized at -O3 (see gemm_s8_avx512vnni.cc).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>
#pragma GCC diagnostic pop

#include <algorithm>

// The same GCC 12 header idiom (`__m512 __Y = __Y;` as the pass-through of unmasked min/max,
// extract, reduce) is also reported at the call sites it is inlined into, as -Wuninitialized.
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"

namespace act::kernels {

namespace {

__mmask16 tail_mask(size_t left) { return left >= 16 ? __mmask16(0xffff) : __mmask16((1u << left) - 1u); }

// The rule on 16 floats (maxps(v, lo) maps NaN to lo; cvtps2dq rounds half to even).
__m128i quantize16(__m512 x, __m512 inv, __m512 z, __m512 lo, __m512 hi) {
  __m512 v = _mm512_mul_ps(x, inv);
  v = _mm512_add_ps(v, z);
  v = _mm512_max_ps(v, lo);
  v = _mm512_min_ps(v, hi);
  return _mm512_cvtsepi32_epi8(_mm512_cvtps_epi32(v));
}

void quantize_f32_s8_avx512(size_t n, const float* x, float inv_scale, int32_t zero_point, int8_t* y) {
  const __m512 inv = _mm512_set1_ps(inv_scale), z = _mm512_set1_ps(static_cast<float>(zero_point));
  const __m512 lo = _mm512_set1_ps(-128.0f), hi = _mm512_set1_ps(127.0f);
  size_t i = 0;
  for (; i + 32 <= n; i += 32) {
    _mm_storeu_si128(reinterpret_cast<__m128i*>(y + i), quantize16(_mm512_loadu_ps(x + i), inv, z, lo, hi));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(y + i + 16), quantize16(_mm512_loadu_ps(x + i + 16), inv, z, lo, hi));
  }
  for (; i < n; i += 16) {
    const __mmask16 m = tail_mask(n - i);
    _mm_mask_storeu_epi8(y + i, m, quantize16(_mm512_maskz_loadu_ps(m, x + i), inv, z, lo, hi));
  }
}

void dequantize_s8_f32_avx512(size_t n, const int8_t* q, float scale, int32_t zero_point, float* y) {
  const __m512 z = _mm512_set1_ps(static_cast<float>(zero_point)), s = _mm512_set1_ps(scale);
  for (size_t i = 0; i < n; i += 16) {
    const __mmask16 m = tail_mask(n - i);
    const __m512 f = _mm512_cvtepi32_ps(_mm512_cvtepi8_epi32(_mm_maskz_loadu_epi8(m, q + i)));
    _mm512_mask_storeu_ps(y + i, m, _mm512_mul_ps(_mm512_sub_ps(f, z), s));
  }
}

// minps(x, acc) returns acc when x is NaN: NaNs are skipped like the reference's compare. Tail
// lanes keep the accumulator (mask_min).
void minmax_f32_avx512(size_t n, const float* x, float* lo, float* hi) {
  __m512 mn0 = _mm512_set1_ps(__builtin_inff()), mn1 = mn0;
  __m512 mx0 = _mm512_set1_ps(-__builtin_inff()), mx1 = mx0;
  size_t i = 0;
  for (; i + 32 <= n; i += 32) {
    const __m512 a = _mm512_loadu_ps(x + i), b = _mm512_loadu_ps(x + i + 16);
    mn0 = _mm512_min_ps(a, mn0);
    mx0 = _mm512_max_ps(a, mx0);
    mn1 = _mm512_min_ps(b, mn1);
    mx1 = _mm512_max_ps(b, mx1);
  }
  for (; i < n; i += 16) {
    const __mmask16 m = tail_mask(n - i);
    const __m512 a = _mm512_maskz_loadu_ps(m, x + i);
    mn0 = _mm512_mask_min_ps(mn0, m, a, mn0);
    mx0 = _mm512_mask_max_ps(mx0, m, a, mx0);
  }
  *lo = _mm512_reduce_min_ps(_mm512_min_ps(mn0, mn1));  // no NaN left in the accumulators
  *hi = _mm512_reduce_max_ps(_mm512_max_ps(mx0, mx1));
}

// Max over each of 16 vectors' lanes, one row per vector, into one vector (lane i: vector i's max):
// four levels of pairing, each halving the partial maxima per row (P per row -> P / 2) while one
// vector takes two vectors' rows, instead of a shuffle tree per row.
struct PairingIndices {
  alignas(64) int32_t lanes[4][2][16];  // per level: the lower and the upper half of each row's partials
  constexpr PairingIndices() : lanes{} {
    for (int level = 0, partials = 16; level < 4; ++level, partials /= 2) {
      const int half = partials / 2;
      for (int l = 0; l < 16; ++l) {  // lanes [0, 8) from the first vector's rows, [8, 16) from the second's
        lanes[level][0][l] = (l < 8 ? 0 : 16) + l % 8 / half * partials + l % 8 % half;
        lanes[level][1][l] = lanes[level][0][l] + half;
      }
    }
  }
};
constexpr PairingIndices kPairing;

__m512 lane_maxima16(__m512 (&v)[16]) {
  for (int level = 0, count = 16; level < 4; ++level, count /= 2) {
    const __m512i low = _mm512_load_si512(kPairing.lanes[level][0]), high = _mm512_load_si512(kPairing.lanes[level][1]);
    for (int i = 0; i < count / 2; ++i) {
      v[i] = _mm512_max_ps(_mm512_permutex2var_ps(v[2 * i], low, v[2 * i + 1]),
                           _mm512_permutex2var_ps(v[2 * i], high, v[2 * i + 1]));
    }
  }
  return v[0];
}

// Rows of up to 64 values (attention's heads), 16 at a time: each row's max |x| (maxps returns the
// accumulator for a NaN, which minmax skips too; masked-off lanes are 0) into a vector of its own,
// the 16 vectors reduced together (lane_maxima16), the one rule's scales for 16 rows at once (the
// same as symmetric_scale_s8 from [-max, max]: max(-lo, hi) is max |x|, a non-finite max gives 0,
// both divisions exact), then each row quantized with its inverse scale. A row at a time (a
// shuffle tree and the scalar rule per row) took about 50 cycles per 64-value row, so the last
// rows are a block of 16 too (the attention's key-row tasks of about 30 rows left 14 to that path).
void quantize_rows_symmetric_f32_s8_avx512(int rows, int cols, const float* x, size_t ldx, int8_t* y, size_t ldy,
                                           float* row_scale) {
  constexpr int kVectors = 4, kRows = 16;
  if (cols > 16 * kVectors) {
    quantize_rows_symmetric_with<minmax_f32_avx512, quantize_f32_s8_avx512>(rows, cols, x, ldx, y, ldy, row_scale);
    return;
  }
  const __m512 zero = _mm512_setzero_ps(), lo = _mm512_set1_ps(-128.0f), hi = _mm512_set1_ps(127.0f);
  __mmask16 m[kVectors];
  for (int j = 0; j < kVectors; ++j) m[j] = tail_mask(cols > 16 * j ? static_cast<size_t>(cols - 16 * j) : 0);
  // The last block may have fewer rows: its missing rows' maxima are 0 and nothing of them is stored.
  for (int r = 0; r < rows; r += kRows) {
    const int n = std::min(kRows, rows - r);
    __m512 amax[kRows];
    for (int i = 0; i < kRows; ++i) {
      amax[i] = zero;
      if (i >= n) continue;
      const float* xr = x + static_cast<size_t>(r + i) * ldx;
      for (int j = 0; j < kVectors; ++j) {
        amax[i] = _mm512_max_ps(_mm512_abs_ps(_mm512_maskz_loadu_ps(m[j], xr + 16 * j)), amax[i]);
      }
    }
    const __m512 row_max = lane_maxima16(amax);
    // symmetric_scale_s8: max |x| if finite (no NaN reaches it), else 0; scale at least FLT_MIN;
    // inverse 1 / scale where max |x| > 0, else 0.
    const __m512 float_max = _mm512_set1_ps(std::numeric_limits<float>::max());
    const __m512 float_min = _mm512_set1_ps(std::numeric_limits<float>::min());
    const __m512 absmax = _mm512_maskz_mov_ps(_mm512_cmp_ps_mask(row_max, float_max, _CMP_LE_OQ), row_max);
    const __m512 scale = _mm512_max_ps(_mm512_div_ps(absmax, _mm512_set1_ps(127.0f)), float_min);
    const __m512 inv = _mm512_maskz_div_ps(_mm512_cmp_ps_mask(absmax, zero, _CMP_GT_OQ), _mm512_set1_ps(1.0f), scale);
    _mm512_mask_storeu_ps(row_scale + r, tail_mask(static_cast<size_t>(n)), scale);
    alignas(64) float inv_of[kRows];
    _mm512_store_ps(inv_of, inv);
    for (int i = 0; i < n; ++i) {
      const float* xr = x + static_cast<size_t>(r + i) * ldx;
      int8_t* yr = y + static_cast<size_t>(r + i) * ldy;
      const __m512 inv_v = _mm512_set1_ps(inv_of[i]);
      for (int j = 0; j < kVectors; ++j) {
        const __m512 v = _mm512_maskz_loadu_ps(m[j], xr + 16 * j);
        _mm_mask_storeu_epi8(yr + 16 * j, m[j], quantize16(v, inv_v, zero, lo, hi));
      }
    }
  }
}

// 64 columns at a time (four vectors, a whole attention head): their minmax down the rows, 64
// scales, then the same rows quantized with four vectors of inverse scales. Each row is visited
// twice per block, not twice per vector: rows lie a page or more apart (the qkv output), and every
// visit costs a TLB lookup.
void quantize_columns_symmetric_f32_s8_avx512(int rows, int cols, const float* x, size_t ldx, int8_t* y, size_t ldy,
                                              float* col_scale) {
  constexpr int kVectors = 4, kBlock = 16 * kVectors;
  const __m512 zero = _mm512_setzero_ps(), lo = _mm512_set1_ps(-128.0f), hi = _mm512_set1_ps(127.0f);
  for (int c0 = 0; c0 < cols; c0 += kBlock) {
    const int width = cols - c0 < kBlock ? cols - c0 : kBlock;
    __mmask16 m[kVectors];
    __m512 mn[kVectors], mx[kVectors];
    for (int j = 0; j < kVectors; ++j) {
      m[j] = tail_mask(width > 16 * j ? static_cast<size_t>(width - 16 * j) : 0);
      mn[j] = _mm512_set1_ps(__builtin_inff());
      mx[j] = _mm512_set1_ps(-__builtin_inff());
    }
    for (int r = 0; r < rows; ++r) {
      const float* xr = x + static_cast<size_t>(r) * ldx + c0;
      for (int j = 0; j < kVectors; ++j) {
        const __m512 a = _mm512_maskz_loadu_ps(m[j], xr + 16 * j);
        mn[j] = _mm512_mask_min_ps(mn[j], m[j], a, mn[j]);  // minps(a, acc) skips a NaN, as minmax does
        mx[j] = _mm512_mask_max_ps(mx[j], m[j], a, mx[j]);
      }
    }
    float lo_c[kBlock], hi_c[kBlock], inv_c[kBlock] = {};
    for (int j = 0; j < kVectors; ++j) {
      _mm512_storeu_ps(lo_c + 16 * j, mn[j]);
      _mm512_storeu_ps(hi_c + 16 * j, mx[j]);
    }
    for (int c = 0; c < width; ++c) col_scale[c0 + c] = symmetric_scale_s8(lo_c[c], hi_c[c], &inv_c[c]);
    __m512 inv[kVectors];
    for (int j = 0; j < kVectors; ++j) inv[j] = _mm512_loadu_ps(inv_c + 16 * j);
    for (int r = 0; r < rows; ++r) {
      const float* xr = x + static_cast<size_t>(r) * ldx + c0;
      int8_t* yr = y + static_cast<size_t>(r) * ldy + c0;
      for (int j = 0; j < kVectors; ++j) {
        const __m512 a = _mm512_maskz_loadu_ps(m[j], xr + 16 * j);
        _mm_mask_storeu_epi8(yr + 16 * j, m[j], quantize16(a, inv[j], zero, lo, hi));
      }
    }
  }
}

}  // namespace

const QuantS8Kernels* quant_s8_table_avx512() {
  static constexpr QuantS8Kernels kTable = {Isa::kAvx512,
                                            "quantize_f32_s8_avx512",
                                            "dequantize_s8_f32_avx512",
                                            "minmax_f32_avx512",
                                            "quantize_rows_symmetric_f32_s8_avx512",
                                            "quantize_columns_symmetric_f32_s8_avx512",
                                            quantize_f32_s8_avx512,
                                            dequantize_s8_f32_avx512,
                                            minmax_f32_avx512,
                                            quantize_rows_symmetric_f32_s8_avx512,
                                            quantize_columns_symmetric_f32_s8_avx512};
  return &kTable;
}

}  // namespace act::kernels

#else  // not x86-64

namespace act::kernels {
const QuantS8Kernels* quant_s8_table_avx512() { return nullptr; }
}  // namespace act::kernels

#endif
