// Tiled im2col for the INT8 convolutions: the patches of a tile of output pixels, gathered into a
// small per-thread buffer that the gemm_s8 kernels read as A (never a whole-image buffer).
#pragma once

#include <cstddef>
#include <cstdint>

#include "kernels/fp32/fp32_kernels.h"  // Conv2dShape

namespace act::kernels {

/// Gathers the patches of output pixels [pixel_begin, pixel_begin + count) (row-major pixel index)
/// of an NHWC int8 input into `patches` (row i at patches + i * ld, ld >= patch_size) with patch
/// order (ky, kx, c), the OHWI weight order. Taps in the padding get `pad_value` — the input's zero
/// point, the int8 code of 0.0, so padding contributes exactly nothing.
void im2col_nhwc_s8(const Conv2dShape& s, const int8_t* input, int8_t pad_value, int pixel_begin, int count,
                    int8_t* patches, size_t ld);

}  // namespace act::kernels
