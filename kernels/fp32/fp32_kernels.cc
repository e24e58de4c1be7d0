#include "kernels/fp32/fp32_kernels.h"

#include <limits>

#include "kernels/common/maxpool_window.h"

namespace act::kernels {

void maxpool_nhwc_f32(const ElementwiseF32Kernels& k, int in_h, int in_w, int channels, int kernel, int stride, int pad,
                      int out_w, const float* input, float* output, int row_begin, int row_end, int input_row0) {
  maxpool_nhwc_with<float>(k.max_taps, in_h, in_w, channels, kernel, stride, pad, out_w, input, output, row_begin, row_end,
                           input_row0, -std::numeric_limits<float>::infinity());
}

}  // namespace act::kernels
