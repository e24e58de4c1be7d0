// 2-D max-pool over NHWC int8. Max commutes with the (monotonic) affine quantization, so the
// output has the input's scale and zero point and the result is exact.
#pragma once

#include <cstddef>
#include <cstdint>

namespace act::kernels {

/// Output rows [row_begin, row_end). Padding never wins (it is skipped).
void maxpool_nhwc_s8(int in_h, int in_w, int channels, int kernel, int stride, int pad, int out_w,
                     const int8_t* input, int8_t* output, int row_begin, int row_end);

}  // namespace act::kernels
