// FP32 NHWC convolution on the int8 convolution's tiling: one tile of output pixels per call, its
// patches gathered (im2col) into a small per-thread buffer, never a whole-image one; a 1x1 stride-1
// conv reads its input in place, and so does every other undilated one, kernel row by kernel row
// (the GEMM's a_segments; rows across the image's edge copied with their padding): the stem's and
// layer1's patch copies cost a quarter of the product. Either way the same bits. The product is the
// packed gemm_f32 with its fused epilogue.
#pragma once

#include <cstddef>

#include "kernels/common/conv2d_shape.h"
#include "kernels/fp32/gemm_f32.h"

namespace act::kernels {

struct ConvF32 {
  Conv2dShape shape;
  const GemmF32Kernels* kernels = nullptr;
  /// OHWI weights [out_c x patch_size] packed by gemm_f32_pack for kernels->nr.
  const float* packed_w = nullptr;
};

/// The lcm of every gemm_f32 variant's MR (1, 6, 8): tiles of output pixels start on multiples of it.
inline constexpr int kConvF32TileQuantum = 24;
/// Output pixels per tile at most: a multiple of kConvF32TileQuantum, at most 192 (small images
/// still split into several tiles for the pool); 192 when the conv reads its input in place, else
/// what keeps the patch buffer near 256 KB (L2-resident while the weights stream past it).
int conv_f32_tile_pixels(const Conv2dShape& s);
/// Floats of scratch conv_f32 needs for tiles of `tile_pixels` pixels (0 when it reads in place).
size_t conv_f32_scratch_floats(const Conv2dShape& s, int tile_pixels);

/// Output pixels [pixel_begin, pixel_begin + count) of y = act(conv(x) + bias + residual), y and the
/// residual [pixels x out_c] from pixel out_pixel0 on (a band of the output held elsewhere; 0: all
/// of it). `epilogue`: bias one row (ld 0), residual ld out_c.
void conv_f32(const ConvF32& conv, const float* input, float* y, const GemmF32Epilogue& epilogue, int pixel_begin,
              int count, float* scratch, int out_pixel0 = 0);

}  // namespace act::kernels
