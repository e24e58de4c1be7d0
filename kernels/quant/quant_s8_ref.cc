// The reference (scalar) quant variant, choose_quant_s8, and the portable per-row driver.
#include <algorithm>
#include <cmath>
#include <limits>

#include "kernels/common/requant_ref.h"
#include "kernels/quant/quant_s8.h"
#include "kernels/quant/quant_s8_variants.h"

namespace act::kernels {

QuantS8 choose_quant_s8(float lo, float hi) {
  lo = std::min(lo, 0.0f);
  hi = std::max(hi, 0.0f);
  QuantS8 q;
  if (!(hi > lo)) return q;
  q.scale = (hi - lo) / 255.0f;
  // Degenerate ranges must still give a usable finite scale with a finite inverse: a span beyond
  // FLT_MAX (hi - lo overflows) is divided first; a span so small that 1 / scale would overflow
  // (or scale underflow to 0) is widened to the smallest normal float.
  if (!std::isfinite(q.scale)) q.scale = hi / 255.0f - lo / 255.0f;
  if (!(q.scale >= std::numeric_limits<float>::min())) q.scale = std::numeric_limits<float>::min();
  // lo maps to -128; rounding the zero point keeps 0 exact and moves both ends by < scale / 2.
  const float zp = -128.0f - lo / q.scale;
  q.zero_point = std::clamp(static_cast<int32_t>(std::nearbyint(zp)), int32_t{-128}, int32_t{127});
  return q;
}

void quantize_f32_s8_ref(size_t n, const float* x, float inv_scale, int32_t zero_point, int8_t* y) {
  for (size_t i = 0; i < n; ++i) {
    y[i] = ref::finish_s8(ref::fp_barrier(x[i] * inv_scale), zero_point, -128, 127);
  }
}

void dequantize_s8_f32_ref(size_t n, const int8_t* q, float scale, int32_t zero_point, float* y) {
  const float z = static_cast<float>(zero_point);
  for (size_t i = 0; i < n; ++i) y[i] = ref::fp_barrier(static_cast<float>(q[i]) - z) * scale;
}

void minmax_f32_ref(size_t n, const float* x, float* lo, float* hi) {
  float a = std::numeric_limits<float>::infinity(), b = -a;
  for (size_t i = 0; i < n; ++i) {
    a = x[i] < a ? x[i] : a;  // a NaN compares false and is skipped
    b = x[i] > b ? x[i] : b;
  }
  *lo = a;
  *hi = b;
}

void quantize_rows_symmetric_f32_s8_ref(int rows, int cols, const float* x, size_t ldx, int8_t* y, size_t ldy,
                                        float* row_scale) {
  quantize_rows_symmetric_with<minmax_f32_ref, quantize_f32_s8_ref>(rows, cols, x, ldx, y, ldy, row_scale);
}

void quantize_columns_symmetric_f32_s8_ref(int rows, int cols, const float* x, size_t ldx, int8_t* y, size_t ldy,
                                           float* col_scale) {
  for (int c = 0; c < cols; ++c) {
    float lo = std::numeric_limits<float>::infinity(), hi = -lo;
    for (int r = 0; r < rows; ++r) {
      const float v = x[static_cast<size_t>(r) * ldx + static_cast<size_t>(c)];
      lo = v < lo ? v : lo;  // NaNs skipped, as in minmax_f32_ref
      hi = v > hi ? v : hi;
    }
    float inv;
    col_scale[c] = symmetric_scale_s8(lo, hi, &inv);
    for (int r = 0; r < rows; ++r) {
      const size_t at = static_cast<size_t>(r) * ldx + static_cast<size_t>(c);
      quantize_f32_s8_ref(1, x + at, inv, 0, y + static_cast<size_t>(r) * ldy + static_cast<size_t>(c));
    }
  }
}

const QuantS8Kernels* quant_s8_table_ref() {
  static constexpr QuantS8Kernels kTable = {Isa::kRef,
                                            "quantize_f32_s8_ref",
                                            "dequantize_s8_f32_ref",
                                            "minmax_f32_ref",
                                            "quantize_rows_symmetric_f32_s8_ref",
                                            "quantize_columns_symmetric_f32_s8_ref",
                                            quantize_f32_s8_ref,
                                            dequantize_s8_f32_ref,
                                            minmax_f32_ref,
                                            quantize_rows_symmetric_f32_s8_ref,
                                            quantize_columns_symmetric_f32_s8_ref};
  return &kTable;
}

void quantize_rows_dynamic_f32_s8(const QuantS8Kernels& k, int rows, int cols, const float* x, size_t ldx, int8_t* y,
                                  size_t ldy, float* row_scale, int32_t* row_zero_point) {
  for (int r = 0; r < rows; ++r) {
    const float* xr = x + static_cast<size_t>(r) * ldx;
    float lo, hi;
    k.minmax(static_cast<size_t>(cols), xr, &lo, &hi);
    if (!std::isfinite(lo) || !std::isfinite(hi)) lo = hi = 0.0f;
    const QuantS8 q = choose_quant_s8(lo, hi);
    row_scale[r] = q.scale;
    row_zero_point[r] = q.zero_point;
    k.quantize(static_cast<size_t>(cols), xr, 1.0f / q.scale, q.zero_point, y + static_cast<size_t>(r) * ldy);
  }
}

}  // namespace act::kernels
