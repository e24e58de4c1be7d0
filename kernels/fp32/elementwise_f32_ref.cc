// The scalar reference of the float element-wise family (elementwise_f32.h).
#include <algorithm>
#include <cmath>

#include "kernels/common/maxpool_window.h"
#include "kernels/fp32/elementwise_f32.h"

namespace act::kernels {

namespace {

void layernorm_rows_f32_ref(int rows, int cols, const float* x, size_t ldx, const float* gamma, const float* beta,
                        float eps, float* y, size_t ldy) {
  for (int r = 0; r < rows; ++r) {
    const float* xr = x + static_cast<size_t>(r) * ldx;
    float* yr = y + static_cast<size_t>(r) * ldy;
    // Two passes in double: the mean and variance of a row of a few hundred values, exact enough that
    // only the final float rounding differs from PyTorch.
    double sum = 0.0;
    for (int c = 0; c < cols; ++c) sum += xr[c];
    const double mean = sum / cols;
    double sq = 0.0;
    for (int c = 0; c < cols; ++c) {
      const double d = xr[c] - mean;
      sq += d * d;
    }
    const float inv_std = static_cast<float>(1.0 / std::sqrt(sq / cols + static_cast<double>(eps)));
    const float mean_f = static_cast<float>(mean);
    for (int c = 0; c < cols; ++c) yr[c] = (xr[c] - mean_f) * inv_std * gamma[c] + beta[c];
  }
}

void softmax_rows_f32_ref(int rows, int cols, float* x, size_t ldx) {
  for (int r = 0; r < rows; ++r) {
    float* xr = x + static_cast<size_t>(r) * ldx;
    float max_v = xr[0];
    for (int c = 1; c < cols; ++c) max_v = std::max(max_v, xr[c]);
    float sum = 0.0f;
    for (int c = 0; c < cols; ++c) {
      xr[c] = std::exp(xr[c] - max_v);
      sum += xr[c];
    }
    const float inv = 1.0f / sum;
    for (int c = 0; c < cols; ++c) xr[c] *= inv;
  }
}

void softmax_rows_s8_ref(int rows, int cols, const float* x, size_t ldx, int8_t* y, size_t ldy, float* row_scale) {
  for (int r = 0; r < rows; ++r) {
    const float* xr = x + static_cast<size_t>(r) * ldx;
    int8_t* yr = y + static_cast<size_t>(r) * ldy;
    float max_v = xr[0];
    for (int c = 1; c < cols; ++c) max_v = std::max(max_v, xr[c]);
    float sum = 0.0f;
    for (int c = 0; c < cols; ++c) {
      const float e = std::exp(xr[c] - max_v);
      sum += e;
      yr[c] = static_cast<int8_t>(std::nearbyint(255.0f * e) + static_cast<float>(kSoftmaxS8ZeroPoint));
    }
    row_scale[r] = 1.0f / (255.0f * sum);
  }
}

void relu_f32_ref(size_t n, float* x) {
  for (size_t i = 0; i < n; ++i) x[i] = std::max(x[i], 0.0f);
}

void gelu_f32_ref(size_t n, float* x) {
  constexpr float kInvSqrt2 = 0.70710678118654752f;
  for (size_t i = 0; i < n; ++i) x[i] = 0.5f * x[i] * (1.0f + std::erf(x[i] * kInvSqrt2));
}

void add_f32_ref(size_t n, const float* a, const float* b, float* y) {
  for (size_t i = 0; i < n; ++i) y[i] = a[i] + b[i];
}

}  // namespace

const ElementwiseF32Kernels* elementwise_f32_table_ref() {
  static constexpr ElementwiseF32Kernels kTable = {
      Isa::kRef,
      "layernorm_rows_f32_ref", "softmax_rows_f32_ref", "softmax_rows_s8_ref", "relu_f32_ref", "gelu_f32_ref", "add_f32_ref",
      "max_taps_f32_ref",
      layernorm_rows_f32_ref, softmax_rows_f32_ref, softmax_rows_s8_ref, relu_f32_ref, gelu_f32_ref, add_f32_ref,
      max_taps_scalar<float>,
  };
  return &kTable;
}

}  // namespace act::kernels
