// FP32 GEMM, Eigen compiled with this file's avx512 flags (cmake/ActLayer.cmake).
#include "kernels/fp32/gemm_f32.h"

#if defined(__x86_64__)
#define Eigen act_eigen_avx512
#include "kernels/fp32/gemm_f32_eigen.inc"
#undef Eigen

namespace act::kernels {
const GemmF32Kernels* gemm_f32_table_avx512() {
  static const GemmF32Kernels table{Isa::kAvx512, "gemm_f32_eigen_avx512", gemm_nt, gemm_nn};
  return &table;
}
}  // namespace act::kernels
#else
namespace act::kernels {
const GemmF32Kernels* gemm_f32_table_avx512() { return nullptr; }
}  // namespace act::kernels
#endif
