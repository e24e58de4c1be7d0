#include "kernels/quant/quant_s8.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "kernels/common/requant_ref.h"

namespace act::kernels {

QuantS8 choose_quant_s8(float lo, float hi) {
  lo = std::min(lo, 0.0f);
  hi = std::max(hi, 0.0f);
  QuantS8 q;
  if (!(hi > lo)) return q;
  q.scale = (hi - lo) / 255.0f;
  // lo maps to -128; rounding the zero point keeps 0 exact and moves both ends by < scale / 2.
  const float zp = -128.0f - lo / q.scale;
  q.zero_point = std::clamp(static_cast<int32_t>(std::nearbyint(zp)), int32_t{-128}, int32_t{127});
  return q;
}

void quantize_f32_s8(size_t n, const float* x, float inv_scale, int32_t zero_point, int8_t* y) {
  for (size_t i = 0; i < n; ++i) {
    y[i] = ref::finish_s8(ref::fp_barrier(x[i] * inv_scale), zero_point, -128, 127);
  }
}

void dequantize_s8_f32(size_t n, const int8_t* q, float scale, int32_t zero_point, float* y) {
  const float z = static_cast<float>(zero_point);
  for (size_t i = 0; i < n; ++i) y[i] = ref::fp_barrier(static_cast<float>(q[i]) - z) * scale;
}

void minmax_f32(size_t n, const float* x, float* lo, float* hi) {
  float a = std::numeric_limits<float>::infinity(), b = -a;
  for (size_t i = 0; i < n; ++i) {
    a = x[i] < a ? x[i] : a;  // a NaN compares false and is skipped
    b = x[i] > b ? x[i] : b;
  }
  *lo = a;
  *hi = b;
}

void quantize_rows_dynamic_f32_s8(int rows, int cols, const float* x, size_t ldx, int8_t* y, size_t ldy,
                                  float* row_scale, int32_t* row_zero_point) {
  for (int r = 0; r < rows; ++r) {
    const float* xr = x + static_cast<size_t>(r) * ldx;
    float lo, hi;
    minmax_f32(static_cast<size_t>(cols), xr, &lo, &hi);
    if (!std::isfinite(lo) || !std::isfinite(hi)) lo = hi = 0.0f;
    const QuantS8 q = choose_quant_s8(lo, hi);
    row_scale[r] = q.scale;
    row_zero_point[r] = q.zero_point;
    quantize_f32_s8(static_cast<size_t>(cols), xr, 1.0f / q.scale, q.zero_point, y + static_cast<size_t>(r) * ldy);
  }
}

}  // namespace act::kernels
