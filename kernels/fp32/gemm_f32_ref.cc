// FP32 GEMM, Eigen at the target's baseline ISA (SSE2 on x86-64, NEON on AArch64).
#include "kernels/fp32/gemm_f32.h"

#define Eigen act_eigen_baseline
#include "kernels/fp32/gemm_f32_eigen.inc"
#undef Eigen

namespace act::kernels {

const GemmF32Kernels* gemm_f32_table_ref() {
  static const GemmF32Kernels table{Isa::kRef, "gemm_f32_eigen_ref", gemm_nt, gemm_nn};
  return &table;
}

}  // namespace act::kernels
