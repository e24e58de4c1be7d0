// The float element-wise family (LayerNorm, softmax, ReLU, GELU, add) per ISA, behind the public
// functions of fp32_kernels.h, which run the variant chosen once per process (ACT_ISA, else the
// best). The SIMD variants are one xsimd implementation (elementwise_f32_xsimd.inc) instantiated
// for each ISA's xsimd architecture in that ISA's own file; the reference is scalar C++.
//
// Agreement with the reference (test/kernels/test_elementwise_f32.cc checks these bounds):
//   relu, add         bit-exact (relu keeps NaN and -0 as the reference's compare does);
//   layernorm_rows    |y - y_ref| <= 1e-6 * (1 + |mean| / std) * (|y_ref| + 1) for |gamma|, |beta| <= 1
//                     (float two-pass statistics, the first pass shifted by x[0], against the
//                     reference's double ones; both round x - mean in float, whose error grows
//                     with |mean| / std);
//   softmax_rows      within 2e-6 relative of the reference or 1e-9 absolute (xsimd exp);
//   gelu              within 4 ulp of the reference or 1e-7 absolute (xsimd erf).
#pragma once

#include <cstddef>
#include <vector>

#include "kernels/common/isa.h"

namespace act::kernels {

struct ElementwiseF32Kernels {
  Isa isa;
  const char* layernorm_name;  ///< layernorm_rows_f32_<isa>, and so on
  const char* softmax_name;
  const char* relu_name;
  const char* gelu_name;
  const char* add_name;
  void (*layernorm_rows)(int rows, int cols, const float* x, size_t ldx, const float* gamma, const float* beta,
                         float eps, float* y, size_t ldy);
  void (*softmax_rows)(int rows, int cols, float* x, size_t ldx);
  void (*relu)(size_t n, float* x);
  void (*gelu)(size_t n, float* x);
  void (*add)(size_t n, const float* a, const float* b, float* y);
};

const ElementwiseF32Kernels* elementwise_f32_table_ref();
const ElementwiseF32Kernels* elementwise_f32_table_avx2();        ///< xsimd fma3<avx2>
const ElementwiseF32Kernels* elementwise_f32_table_avx512vnni();  ///< xsimd avx512bw
const ElementwiseF32Kernels* elementwise_f32_table_neondot();     ///< xsimd neon64

IsaMask elementwise_f32_built_isas();
const ElementwiseF32Kernels* elementwise_f32_kernels(Isa isa);
std::vector<Isa> elementwise_f32_available_isas();
const ElementwiseF32Kernels& elementwise_f32_active();

}  // namespace act::kernels
