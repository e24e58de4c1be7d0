// FP32 GEMM variants: Eigen's GEMM compiled once per instruction set (baseline, AVX2+FMA, AVX-512),
// chosen once per process like the INT8 kernels (ACT_ISA applies). Eigen picks its SIMD width at
// compile time, so each ISA file compiles its own copy of Eigen in a renamed namespace (see
// gemm_f32_eigen.inc) — otherwise the linker could merge an AVX-512 instantiation into the
// baseline path.
#pragma once

#include <cstddef>
#include <string>

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

/// The variant compiled for `isa` on this target, or nullptr (not built for this architecture).
const GemmF32Kernels* gemm_f32_table_ref();
const GemmF32Kernels* gemm_f32_table_avx2();
const GemmF32Kernels* gemm_f32_table_avx512vnni();
/// The variant for `isa` if it is built and the CPU supports it, else nullptr.
const GemmF32Kernels* gemm_f32_kernels(Isa isa);

/// The variant ACT_ISA (or, without it, the best built & supported one) selects; `error` says why
/// there is none (e.g. ACT_ISA names an ISA this CPU lacks).
struct GemmF32Selection {
  const GemmF32Kernels* kernels = nullptr;
  std::string error;
};
GemmF32Selection gemm_f32_select();

/// The selection made once for this process (ACT_ISA read at first use; a bad ACT_ISA falls back
/// to nothing silently only here — callers validate with gemm_f32_select() first, as Engine does).
const GemmF32Kernels& gemm_f32_active();

}  // namespace act::kernels
