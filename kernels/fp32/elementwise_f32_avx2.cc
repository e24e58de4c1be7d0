// The float element-wise kernels on AVX2 + FMA: elementwise_f32_xsimd.inc instantiated for xsimd's
// xsimd::fma3<xsimd::avx2>. Rules for ISA files (kernels/gemm_s8/README.md): internal linkage only.
#include "kernels/fp32/elementwise_f32.h"

#if defined(__x86_64__)

#include <xsimd/xsimd.hpp>

namespace act::kernels {

#include "kernels/fp32/elementwise_f32_xsimd.inc"

namespace {
using Arch = xsimd::fma3<xsimd::avx2>;
}  // namespace

const ElementwiseF32Kernels* elementwise_f32_table_avx2() {
  static constexpr ElementwiseF32Kernels kTable = {
      Isa::kAvx2,
      "layernorm_rows_f32_avx2", "softmax_rows_f32_avx2", "softmax_rows_s8_avx2", "relu_f32_avx2", "gelu_f32_avx2", "add_f32_avx2",
      layernorm_rows_xs<Arch>, softmax_rows_xs<Arch>, softmax_rows_s8_xs<Arch>, relu_xs<Arch>, gelu_xs<Arch>, add_xs<Arch>,
  };
  return &kTable;
}

}  // namespace act::kernels

#else

namespace act::kernels {
const ElementwiseF32Kernels* elementwise_f32_table_avx2() { return nullptr; }
}  // namespace act::kernels

#endif
