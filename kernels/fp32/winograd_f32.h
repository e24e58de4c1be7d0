// FP32 Winograd F(2x2, 3x3) convolution (Lavin & Gray, "Fast Algorithms for Convolutional Neural
// Networks") for the ResNet blocks' 3x3 stride-1 convs: each 2x2 block of output pixels (a tile)
// from the 4x4 input patch under it, as 16 products of transformed channels instead of 36, so
// 2.25x fewer multiply-adds. Per block of tiles: the input transform (V = B^T d B per channel,
// into 16 matrices [tiles x in_c]), 16 packed gemm_f32 calls against the weights transformed at
// load (U = G g G^T, [out_c x in_c] each), the output transform (A^T M A) with the conv's bias,
// residual and ReLU. The transforms are one implementation for every ISA
// (winograd_f32_transforms.inc, in each gemm_f32 table).
//
// Numerics (test_winograd_f32.cc): not the direct conv's bits. The transforms only add and
// subtract (the weights' halves are exact), so the error is the GEMM's over the transformed
// operands, a few times the direct conv's: within 8 k eps sum |x w| of the exact conv, k = 9 in_c.
#pragma once

#include <cstddef>

#include "kernels/common/conv2d_shape.h"
#include "kernels/fp32/gemm_f32.h"

namespace act::kernels {

inline constexpr int kWinogradPoints = 16;
/// Tiles per block: its 16 transformed input and output matrices stay in L2 at 64 channels.
inline constexpr int kWinogradBlockTiles = 96;

/// A 3x3, stride 1, padding 1, undilated conv whose channel counts are multiples of 16 (every lane
/// width's), with no activation but ReLU.
bool winograd_f32_applies(const Conv2dShape& s, GemmF32Activation activation);
/// Tiles of the output, row-major: ceil(out_h / 2) x ceil(out_w / 2).
int winograd_f32_tiles(const Conv2dShape& s);
/// Floats of the 16 transformed weight matrices, each packed by gemm_f32_pack for `nr`.
size_t winograd_f32_packed_floats(int nr, const Conv2dShape& s);
/// The transformed weights of OHWI weights w [out_c, 3, 3, in_c] (computed in double).
void winograd_f32_pack(int nr, const Conv2dShape& s, const float* w, float* packed);
/// Floats of scratch one winograd_f32 call needs.
size_t winograd_f32_scratch_floats(const Conv2dShape& s);

/// Output tiles [tile_begin, tile_begin + count) of y = act(conv(x) + bias + residual) (epilogue as
/// conv_f32's: bias one row, ld 0; residual ld out_c), with `kernels`' GEMM and transforms.
void winograd_f32(const GemmF32Kernels& kernels, const Conv2dShape& s, const float* packed_weights, const float* x,
                  float* y, const GemmF32Epilogue& epilogue, int tile_begin, int count, float* scratch);

}  // namespace act::kernels
