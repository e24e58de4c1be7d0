// The float element-wise family (LayerNorm, softmax, ReLU, GELU, add) per ISA, one table each; an
// Engine runs the table its KernelConfig chose (kernels/config/kernel_config.h). The SIMD variants are one xsimd implementation (elementwise_f32_xsimd.inc) instantiated
// for each ISA's xsimd architecture in that ISA's own file; the reference is scalar C++.
//
// Agreement with the reference (test/kernels/test_elementwise_f32.cc checks these bounds):
//   relu, add         bit-exact (relu keeps NaN and -0 as the reference's compare does);
//   layernorm_rows    |y - y_ref| <= 1e-6 * (1 + |mean| / std) * (|y_ref| + 1) for |gamma|, |beta| <= 1
//                     (float two-pass statistics, the first pass shifted by x[0], against the
//                     reference's double ones; both round x - mean in float, whose error grows
//                     with |mean| / std);
//   softmax_rows      within 2e-6 relative of the reference or 1e-9 absolute (the SIMD exp is a
//                     degree-5 polynomial, 1.8e-7 relative; a NaN logit makes its row NaN);
//   softmax_rows_s8   row scales within 4e-6 relative, codes within 1 of the reference's (the SIMD
//                     variants' exp is a polynomial good to about 3e-6 relative, so a code can
//                     differ only where 255 e lies within 1e-3 of a rounding boundary);
//   gelu              within 4 ulp of the reference or 1e-7 absolute (xsimd erf).
#pragma once

#include <cstddef>
#include <cstdint>

#include "kernels/common/isa.h"

namespace act::kernels {

/// The zero point of softmax_rows_s8's codes.
inline constexpr int32_t kSoftmaxS8ZeroPoint = -128;

struct ElementwiseF32Kernels {
  Isa isa;
  const char* layernorm_name;  ///< layernorm_rows_f32_<isa>, and so on
  const char* softmax_name;
  const char* softmax_s8_name;
  const char* relu_name;
  const char* gelu_name;
  const char* add_name;
  const char* max_taps_name;
  /// Row-wise LayerNorm over `cols` values: (x - mean) / sqrt(biased var + eps) * gamma + beta.
  void (*layernorm_rows)(int rows, int cols, const float* x, size_t ldx, const float* gamma, const float* beta,
                         float eps, float* y, size_t ldy);
  /// In-place numerically stable softmax of each row.
  void (*softmax_rows)(int rows, int cols, float* x, size_t ldx);
  /// Softmax of each row straight into int8 for the GEMM (attention's probabilities), no float
  /// probabilities written: with e_c = exp(x_c - max x) in (0, 1] (the largest is exactly 1),
  /// y_c = round(255 e_c) - 128, so softmax(x)_c ~= row_scale * (y_c - kSoftmaxS8ZeroPoint) with
  /// row_scale = 1 / (255 sum_c e_c): all 256 codes cover [0, max p], the zero point is the same
  /// for every row.
  void (*softmax_rows_s8)(int rows, int cols, const float* x, size_t ldx, int8_t* y, size_t ldy, float* row_scale);
  void (*relu)(size_t n, float* x);
  /// Exact (erf) GELU, as torch.nn.functional.gelu with approximate="none".
  void (*gelu)(size_t n, float* x);
  /// y[i] = a[i] + b[i]; y may be a or b.
  void (*add)(size_t n, const float* a, const float* b, float* y);
  /// The max-pool's channel max over a run of windows (MaxTapsFn, kernels/common/maxpool_window.h):
  /// dst[i * channels + c] = the running max of taps[0][i * pixel_step + c], taps[1][...], ...
  /// where a tap replaces it only when greater (NaN never does, as a first tap it stays).
  /// Bit-exact in every variant.
  void (*max_taps)(const float* const* taps, int ntaps, int pixels, size_t pixel_step, int channels, float* dst);
};

/// The table compiled for each ISA (nullptr when that file compiled to nothing on this target).
const ElementwiseF32Kernels* elementwise_f32_table_ref();
const ElementwiseF32Kernels* elementwise_f32_table_avx2();    ///< xsimd fma3<avx2>
const ElementwiseF32Kernels* elementwise_f32_table_avx512();  ///< xsimd avx512f (AVX-512 F/BW/VL flags)
const ElementwiseF32Kernels* elementwise_f32_table_neon();    ///< xsimd neon64

}  // namespace act::kernels
