// FP32 GEMM, Eigen compiled with this file's avx512vnni flags (cmake/ActLayer.cmake).
#include "kernels/fp32/gemm_f32.h"

#if defined(__x86_64__)
#define Eigen act_eigen_avx512vnni
#include "kernels/fp32/gemm_f32_eigen.inc"
#undef Eigen

namespace act::kernels {
const GemmF32Kernels* gemm_f32_table_avx512vnni() {
  static const GemmF32Kernels table{Isa::kAvx512Vnni, "gemm_f32_eigen_avx512vnni", gemm_nt, gemm_nn};
  return &table;
}
}  // namespace act::kernels
#else
namespace act::kernels {
const GemmF32Kernels* gemm_f32_table_avx512vnni() { return nullptr; }
}  // namespace act::kernels
#endif
