// The float32 max-pool: kernels/common/maxpool_window.h's driver (shared with the int8 max-pool)
// over the channel-max primitive of an element-wise variant (elementwise_f32.h). The FP32 path's
// other kernels are per ISA too: GEMM in gemm_f32.h, LayerNorm, softmax and activations in
// elementwise_f32.h; its im2col is in kernels/common/im2col.h. Pure compute on raw pointers, one
// tile of output rows per call.
//
// Layout: images are NHWC (batch 1): element (y, x, c) at (y * width + x) * channels + c.
#pragma once

#include <cstddef>

#include "kernels/fp32/elementwise_f32.h"

namespace act::kernels {

/// 2-D max-pool over NHWC for output rows [row_begin, row_end) with the variant `k`. Padding never
/// wins (it is skipped); a window entirely in the padding gives -inf. `input` holds the image's
/// rows from input_row0 on (a band of them: those the output rows read).
void maxpool_nhwc_f32(const ElementwiseF32Kernels& k, int in_h, int in_w, int channels, int kernel, int stride, int pad,
                      int out_w, const float* input, float* output, int row_begin, int row_end, int input_row0 = 0);

}  // namespace act::kernels
