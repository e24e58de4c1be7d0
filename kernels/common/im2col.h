// Tiled im2col for the convolutions, float and int8: the patches of a tile of output pixels,
// gathered into a small per-thread buffer that the GEMM reads as A (never a whole-image buffer).
// Patch order is (ky, kx, c), the OHWI weight order.
#pragma once

#include <cstddef>
#include <cstdint>

#include "kernels/common/conv2d_shape.h"

namespace act::kernels {

/// Gathers the patches of output pixels [pixel_begin, pixel_begin + count) (row-major pixel index)
/// of an NHWC float input into `patches` [count x patch_size]; taps in the padding are 0.
void im2col_nhwc_f32(const Conv2dShape& s, const float* input, int pixel_begin, int count, float* patches);

/// The same for an int8 input, row i at patches + i * ld (ld >= patch_size). Taps in the padding get
/// `pad_value` — the input's zero point, the int8 code of 0.0, so padding contributes exactly nothing.
void im2col_nhwc_s8(const Conv2dShape& s, const int8_t* input, int8_t pad_value, int pixel_begin, int count,
                    int8_t* patches, size_t ld);

}  // namespace act::kernels
