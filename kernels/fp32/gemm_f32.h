// FP32 GEMM variants: Eigen's GEMM compiled once per instruction set (baseline, AVX2+FMA, AVX-512
// F/BW/VL); an Engine runs the one its KernelConfig chose. AArch64 has only the baseline build,
// which is already NEON. Eigen picks its SIMD width at
// compile time, so each ISA file compiles its own copy of Eigen in a renamed namespace (see
// gemm_f32_eigen.inc) — otherwise the linker could merge an AVX-512 instantiation into the
// baseline path.
#pragma once

#include <cstddef>

#include "kernels/common/isa.h"

namespace act::kernels {

struct GemmF32Kernels {
  Isa isa;
  const char* name;  ///< e.g. "gemm_f32_eigen_avx2"
  /// C[m x n] = A[m x k] * B^T, B stored [n x k]; overwrites C.
  void (*nt)(int m, int n, int k, const float* a, size_t lda, const float* b, size_t ldb, float* c, size_t ldc);
  /// C[m x n] = A[m x k] * B[k x n]; overwrites C.
  void (*nn)(int m, int n, int k, const float* a, size_t lda, const float* b, size_t ldb, float* c, size_t ldc);
};

/// The variant compiled for each ISA on this target, or nullptr (not built for this architecture).
const GemmF32Kernels* gemm_f32_table_ref();
const GemmF32Kernels* gemm_f32_table_avx2();
const GemmF32Kernels* gemm_f32_table_avx512();

}  // namespace act::kernels
