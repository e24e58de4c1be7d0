#include "kernels/pool_s8/maxpool_s8.h"

#include <algorithm>
#include <cstring>

namespace act::kernels {

void maxpool_nhwc_s8(int in_h, int in_w, int channels, int kernel, int stride, int pad, int out_w,
                     const int8_t* input, int8_t* output, int row_begin, int row_end) {
  for (int oy = row_begin; oy < row_end; ++oy) {
    for (int ox = 0; ox < out_w; ++ox) {
      int8_t* dst = output + (static_cast<size_t>(oy) * out_w + ox) * channels;
      std::memset(dst, -128, static_cast<size_t>(channels));
      for (int ky = 0; ky < kernel; ++ky) {
        const int iy = oy * stride - pad + ky;
        if (iy < 0 || iy >= in_h) continue;
        for (int kx = 0; kx < kernel; ++kx) {
          const int ix = ox * stride - pad + kx;
          if (ix < 0 || ix >= in_w) continue;
          const int8_t* src = input + (static_cast<size_t>(iy) * in_w + ix) * channels;
          for (int c = 0; c < channels; ++c) dst[c] = std::max(dst[c], src[c]);
        }
      }
    }
  }
}

}  // namespace act::kernels
