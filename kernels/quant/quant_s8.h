// Float <-> int8 conversions around the INT8 kernels: static (per tensor) quantization, dynamic
// per-row (per-token) quantization of transformer activations, dequantization, and the range
// reduction that calibration and dynamic quantization need. Raw pointers, no allocation, no threads.
//
// Affine int8: real = scale * (q - zero_point), q in [-128, 127], zero_point in [-128, 127].
// Quantization rule (every variant gives these bits):
//   v = x * inv_scale            (one float multiply; inv_scale = 1 / scale computed by the caller)
//   v = v + float(zero_point)
//   v = clamp(v, -128, 127)      (as floats; a NaN becomes -128)
//   q = round_half_to_even(v)
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>

#include "kernels/common/isa.h"

namespace act::kernels {

struct QuantS8 {
  float scale = 1.0f;      ///< > 0
  int32_t zero_point = 0;  ///< in [-128, 127]
};

/// Asymmetric parameters that cover [min(lo, 0), max(hi, 0)] (0 is always exactly representable,
/// so zero padding stays exact). A degenerate range gives scale 1, zero point 0. `lo`, `hi` finite.
/// The scale is always finite and at least FLT_MIN, so 1 / scale is finite too (a span wider than
/// FLT_MAX is computed without overflowing; one so narrow that the inverse would overflow is
/// widened to FLT_MIN).
QuantS8 choose_quant_s8(float lo, float hi);

/// One variant of the family (quant_s8_variants.h lists them; an Engine runs its KernelConfig's).
struct QuantS8Kernels {
  Isa isa;
  const char* quantize_name;    ///< quantize_f32_s8_<isa>
  const char* dequantize_name;  ///< dequantize_s8_f32_<isa>
  const char* minmax_name;      ///< minmax_f32_<isa>
  const char* rows_symmetric_name;     ///< quantize_rows_symmetric_f32_s8_<isa>
  const char* columns_symmetric_name;  ///< quantize_columns_symmetric_f32_s8_<isa>
  /// y[i] = quantize(x[i]) by the rule above.
  void (*quantize)(size_t n, const float* x, float inv_scale, int32_t zero_point, int8_t* y);
  /// y[i] = scale * (float(q[i]) - float(zero_point)).
  void (*dequantize)(size_t n, const int8_t* q, float scale, int32_t zero_point, float* y);
  /// Smallest and largest value of x[0..n) (n >= 1; NaNs are ignored, all-NaN gives +inf/-inf).
  void (*minmax)(size_t n, const float* x, float* lo, float* hi);
  /// Symmetric per-row quantization, the gemm_s8 weight side (values in [-127, 127], zero point 0),
  /// for operands made at run time (attention's queries and keys): for each of `rows` rows of
  /// `cols` values (row stride ldx), row_scale[r] = symmetric_scale_s8(minmax of the row) and the
  /// row quantized with it into y (row stride ldy). One call for all rows.
  void (*quantize_rows_symmetric)(int rows, int cols, const float* x, size_t ldx, int8_t* y, size_t ldy,
                                  float* row_scale);
  /// The same per column: col_scale[c] from the minmax of column c over the rows, y[r][c] quantized
  /// with it (y keeps x's orientation). Attention's values, one scale per channel, read straight
  /// from the strided projection output.
  void (*quantize_columns_symmetric)(int rows, int cols, const float* x, size_t ldx, int8_t* y, size_t ldy,
                                     float* col_scale);
};

/// The symmetric scale of values whose minmax is [lo, hi]: max |x| / 127, at least FLT_MIN (so its
/// inverse is finite); *inv_scale receives the multiplier to quantize with, 0 when max |x| is 0 or
/// the range is not finite (such rows quantize as zeros). The one rule every variant calls; inline,
/// since attention calls it for every row of every head (out of line it was 2 % of the op).
inline float symmetric_scale_s8(float lo, float hi, float* inv_scale) {
  const float absmax = std::isfinite(lo) && std::isfinite(hi) ? std::max(-lo, hi) : 0.0f;
  const float scale = std::max(absmax / 127.0f, std::numeric_limits<float>::min());
  // 1 / scale may round so that max |x| lands a hair past 127: the clamp keeps it at 127, and
  // -max |x| cannot reach -128.
  *inv_scale = absmax > 0.0f ? 1.0f / scale : 0.0f;
  return scale;
}

/// The row loop of every variant's quantize_rows_symmetric, with that variant's own minmax and
/// quantize as template arguments (each row: minmax, symmetric_scale_s8, quantize with zero point 0).
template <void (*Minmax)(size_t, const float*, float*, float*),
          void (*Quantize)(size_t, const float*, float, int32_t, int8_t*)>
void quantize_rows_symmetric_with(int rows, int cols, const float* x, size_t ldx, int8_t* y, size_t ldy,
                                  float* row_scale) {
  for (int r = 0; r < rows; ++r) {
    const float* xr = x + static_cast<size_t>(r) * ldx;
    float lo, hi, inv;
    Minmax(static_cast<size_t>(cols), xr, &lo, &hi);
    row_scale[r] = symmetric_scale_s8(lo, hi, &inv);
    Quantize(static_cast<size_t>(cols), xr, inv, 0, y + static_cast<size_t>(r) * ldy);
  }
}

/// Dynamic per-row quantization with the variant `k`: for each of `rows` rows of `cols` values, the
/// parameters choose_quant_s8(row min, row max) and the row quantized with them. row_scale[r] and
/// row_zero_point[r] receive the parameters (what the gemm_s8 f32-out epilogue and per-row zero
/// points take).
void quantize_rows_dynamic_f32_s8(const QuantS8Kernels& k, int rows, int cols, const float* x, size_t ldx, int8_t* y,
                                  size_t ldy, float* row_scale, int32_t* row_zero_point);

}  // namespace act::kernels
