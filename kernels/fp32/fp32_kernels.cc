#include "kernels/fp32/fp32_kernels.h"

#include <algorithm>
#include <limits>

namespace act::kernels {

void maxpool_nhwc_f32(int in_h, int in_w, int channels, int kernel, int stride, int pad, int out_h, int out_w,
                      const float* input, float* output, int row_begin, int row_end) {
  (void)out_h;
  for (int oy = row_begin; oy < row_end; ++oy) {
    for (int ox = 0; ox < out_w; ++ox) {
      float* dst = output + (static_cast<size_t>(oy) * out_w + ox) * channels;
      std::fill(dst, dst + channels, -std::numeric_limits<float>::infinity());
      for (int ky = 0; ky < kernel; ++ky) {
        const int iy = oy * stride - pad + ky;
        if (iy < 0 || iy >= in_h) continue;
        for (int kx = 0; kx < kernel; ++kx) {
          const int ix = ox * stride - pad + kx;
          if (ix < 0 || ix >= in_w) continue;
          const float* src = input + (static_cast<size_t>(iy) * in_w + ix) * channels;
          for (int c = 0; c < channels; ++c) dst[c] = std::max(dst[c], src[c]);
        }
      }
    }
  }
}

}  // namespace act::kernels
