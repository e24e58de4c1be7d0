// FP32 GEMM variants, one table per instruction set (baseline, AVX2+FMA, AVX-512 F/BW/VL, NEON);
// an Engine runs the one its KernelConfig chose. C = act(A B^T + bias + residual) with B packed
// into the micro-kernel's panels (gemm_f32_pack): a layer's weights once at load (convolutions,
// linears), attention's keys and values per run. Our own micro-kernels (gemm_f32_packed.inc,
// written once with xsimd) of mr x nr register tiles, blocked for the caches; the scalar reference
// is the plain triple loop.
//
// Numerics (test_gemm_f32.cc): each SIMD variant computes every output as one chain of fused
// multiply-adds in k order (then bias, residual, activation), whatever its tile and blocking, so
// they all give the same bits; the reference multiplies and adds separately. Against the exact
// product, |c - c_exact| <= 4 k eps sum_p |a_p b_p| (plus the epilogue's own rounding; GELU is the
// element-wise table's of the same ISA, elementwise_f32.h).
#pragma once

#include <cstddef>

#include "kernels/common/conv2d_shape.h"
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
/// packed by gemm_f32_pack for this variant's nr; col0 is a multiple of nr. n may reach past N to
/// the end of the last panel, whose padding columns are zero.
struct GemmF32PackedArgs {
  int m = 0, n = 0, k = 0;
  const float* a = nullptr;
  size_t lda = 0;
  /// Instead of a and lda, A's rows in segments of segment_k floats (a convolution's kernel rows,
  /// read in place): row i's segment s at a_segments[i * (k / segment_k) + s]. segment_k >= 8 and
  /// divides k.
  const float* const* a_segments = nullptr;
  int segment_k = 0;
  const float* packed_b = nullptr;
  int col0 = 0;
  float* c = nullptr;
  size_t ldc = 0;
  GemmF32Epilogue epilogue;
  CoveredPaths* covered = nullptr;  ///< when set, records the tiles that ran (full, row tail, partial columns)
};

/// Winograd F(2x2, 3x3)'s input transform (winograd_f32.h) of tiles [tile_begin, tile_begin + count):
/// point p of tile tile_begin + i, channel c, at v[p * ld_point + i * in_c + c].
struct WinogradF32InputArgs {
  const Conv2dShape* shape = nullptr;
  const float* x = nullptr;  ///< the input [in_h, in_w, in_c]
  int tile_begin = 0, count = 0;
  float* v = nullptr;
  size_t ld_point = 0;
};
/// Its output transform: the tiles' output pixels from the 16 products m (laid out as v, with
/// out_c channels), then the epilogue (bias a vector, ld 0; residual [out_h * out_w, out_c]; ReLU).
struct WinogradF32OutputArgs {
  const Conv2dShape* shape = nullptr;
  const float* m = nullptr;
  size_t ld_point = 0;
  int tile_begin = 0, count = 0;
  float* y = nullptr;  ///< the output [out_h, out_w, out_c]
  GemmF32Epilogue epilogue;
};

struct GemmF32Kernels {
  Isa isa;
  const char* name;  ///< e.g. "gemm_f32 6x64 avx512"
  int mr, nr;        ///< the register tile (nr: columns per packed panel)
  void (*packed)(const GemmF32PackedArgs& args);
  void (*winograd_input)(const WinogradF32InputArgs& args);
  void (*winograd_output)(const WinogradF32OutputArgs& args);
};

/// Floats of B [n x k] packed in panels of nr columns (n rounded up to nr, the padding zero).
size_t gemm_f32_packed_floats(int nr, int n, int k);
/// Packs B [n x k] (row stride ldb): panel j holds columns [j nr, j nr + nr) as k rows of nr floats.
void gemm_f32_pack(int nr, int n, int k, const float* b, size_t ldb, float* packed);
/// B [n x k] (row stride k) back from its panels, exactly: what a packed layer's weights were.
void gemm_f32_unpack(int nr, int n, int k, const float* packed, float* b);
/// The same panels from B^T stored [k x n] (row stride ldb), e.g. attention's values for P V.
void gemm_f32_pack_transposed(int nr, int n, int k, const float* bt, size_t ldb, float* packed);

/// The variant compiled for each ISA on this target, or nullptr (not built for this architecture).
const GemmF32Kernels* gemm_f32_table_ref();
const GemmF32Kernels* gemm_f32_table_avx2();
/// AVX-512 with B prefetched 1 KB ahead in software (two 512-bit FMA ports take a panel from L2
/// faster than the hardware prefetchers bring it: a Xeon's float GEMMs 10-20 % faster) or without
/// (a Zen 4's layer4 3x3 conv 7-14 % faster, its other float convs within a few %, its linears
/// 0-3 % slower).
/// isa_tables() holds the one for this CPU (without on Zen 4); the tests run both.
const GemmF32Kernels* gemm_f32_table_avx512(bool software_prefetch = true);
const GemmF32Kernels* gemm_f32_table_neon();

}  // namespace act::kernels
