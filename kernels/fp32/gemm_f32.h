// FP32 GEMM variants, one table per instruction set (baseline, AVX2+FMA, AVX-512 F/BW/VL, NEON);
// an Engine runs the one its KernelConfig chose. Two kinds of product:
//
//   packed  C = act(A B^T + bias + residual) with B (a layer's weights, [n x k]) packed once at load
//           into the micro-kernel's panels (gemm_f32_pack): the float convolutions and linears.
//           Our own micro-kernels (gemm_f32_packed.inc, written once with xsimd) of mr x nr
//           register tiles, blocked for the caches; the scalar reference is the plain triple loop.
//   nt, nn  both operands computed at run time (attention's q k^T and p v, the encoder's position
//           table): Eigen's GEMM compiled per ISA. Eigen picks its SIMD width at compile time, so
//           each ISA file compiles its own copy of Eigen in a renamed namespace (see
//           gemm_f32_eigen.inc) — otherwise the linker could merge an AVX-512 instantiation into
//           the baseline path. AArch64's baseline Eigen is already NEON; the neon table reuses it.
//
// Numerics (test_gemm_f32.cc): each SIMD variant computes every output as one chain of fused
// multiply-adds in k order (then bias, residual, activation), whatever its tile and blocking, so
// they all give the same bits; the reference multiplies and adds separately. Against the exact
// product, |c - c_exact| <= 4 k eps sum_p |a_p b_p| (plus the epilogue's own rounding; GELU is the
// element-wise table's of the same ISA, elementwise_f32.h).
#pragma once

#include <cstddef>

#include "kernels/common/covered_paths.h"
#include "kernels/common/isa.h"

namespace act::kernels {

enum class GemmF32Activation { kNone, kRelu, kGelu };

/// What the packed GEMM adds to the product, in this order: C = act(A B^T + bias + residual).
/// Pointers are at the call's C(0, 0); element (r, c) at p[r * ld + c] (ld 0: one row for every r).
struct GemmF32Epilogue {
  const float* bias = nullptr;
  size_t bias_ld = 0;
  const float* residual = nullptr;
  size_t residual_ld = 0;
  GemmF32Activation activation = GemmF32Activation::kNone;
};

/// C[m x n] (overwritten) = epilogue(A[m x k] B^T) for columns [col0, col0 + n) of a B [N x k]
/// packed by gemm_f32_pack for this variant's nr; col0 is a multiple of nr.
struct GemmF32PackedArgs {
  int m = 0, n = 0, k = 0;
  const float* a = nullptr;
  size_t lda = 0;
  const float* packed_b = nullptr;
  int col0 = 0;
  float* c = nullptr;
  size_t ldc = 0;
  GemmF32Epilogue epilogue;
  CoveredPaths* covered = nullptr;  ///< when set, records the tiles that ran (full, row tail, partial columns)
};

struct GemmF32Kernels {
  Isa isa;
  const char* name;  ///< of nt / nn, e.g. "gemm_f32_eigen_avx2"
  /// C[m x n] = A[m x k] * B^T, B stored [n x k]; overwrites C.
  void (*nt)(int m, int n, int k, const float* a, size_t lda, const float* b, size_t ldb, float* c, size_t ldc);
  /// C[m x n] = A[m x k] * B[k x n]; overwrites C.
  void (*nn)(int m, int n, int k, const float* a, size_t lda, const float* b, size_t ldb, float* c, size_t ldc);
  int mr, nr;               ///< the packed product's register tile (nr: columns per packed panel)
  const char* packed_name;  ///< e.g. "gemm_f32 14x32 avx512"
  void (*packed)(const GemmF32PackedArgs& args);
};

/// Floats of B [n x k] packed in panels of nr columns (n rounded up to nr, the padding zero).
size_t gemm_f32_packed_floats(int nr, int n, int k);
/// Packs B [n x k] (row stride ldb): panel j holds columns [j nr, j nr + nr) as k rows of nr floats.
void gemm_f32_pack(int nr, int n, int k, const float* b, size_t ldb, float* packed);
/// The same panels from B^T stored [k x n] (row stride ldb), e.g. attention's values for P V.
void gemm_f32_pack_transposed(int nr, int n, int k, const float* bt, size_t ldb, float* packed);

/// The variant compiled for each ISA on this target, or nullptr (not built for this architecture).
const GemmF32Kernels* gemm_f32_table_ref();
const GemmF32Kernels* gemm_f32_table_avx2();
const GemmF32Kernels* gemm_f32_table_avx512();
const GemmF32Kernels* gemm_f32_table_neon();

}  // namespace act::kernels
