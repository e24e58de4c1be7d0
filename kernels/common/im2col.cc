#include "kernels/common/im2col.h"

#include <algorithm>
#include <cstring>

namespace act::kernels {

void im2col_nhwc_f32(const Conv2dShape& s, const float* input, int pixel_begin, int count, float* patches) {
  const size_t patch = static_cast<size_t>(s.patch_size());
  const size_t run = static_cast<size_t>(s.in_c);
  for (int i = 0; i < count; ++i) {
    const int pixel = pixel_begin + i;
    const int oy = pixel / s.out_w;
    const int ox = pixel % s.out_w;
    float* dst = patches + static_cast<size_t>(i) * patch;
    const int ix0 = ox * s.stride - s.pad;
    for (int ky = 0; ky < s.kernel_h; ++ky) {
      const int iy = oy * s.stride - s.pad + ky * s.dilation;
      if (s.dilation == 1 && iy >= 0 && iy < s.in_h) {
        // Undilated taps of one kernel row are adjacent input pixels: one copy for those inside the
        // image (the stem's 7 taps of 3 channels in one go), zeros either side.
        const int kx0 = std::clamp(-ix0, 0, s.kernel_w), kx1 = std::clamp(s.in_w - ix0, kx0, s.kernel_w);
        std::memset(dst, 0, static_cast<size_t>(kx0) * run * sizeof(float));
        if (kx1 > kx0) {
          std::memcpy(dst + static_cast<size_t>(kx0) * run,
                      input + (static_cast<size_t>(iy) * s.in_w + static_cast<size_t>(ix0 + kx0)) * run,
                      static_cast<size_t>(kx1 - kx0) * run * sizeof(float));
        }
        std::memset(dst + static_cast<size_t>(kx1) * run, 0, static_cast<size_t>(s.kernel_w - kx1) * run * sizeof(float));
        dst += static_cast<size_t>(s.kernel_w) * run;
        continue;
      }
      for (int kx = 0; kx < s.kernel_w; ++kx, dst += run) {
        const int ix = ix0 + kx * s.dilation;
        if (iy < 0 || iy >= s.in_h || ix < 0 || ix >= s.in_w) {
          std::memset(dst, 0, run * sizeof(float));
        } else {
          std::memcpy(dst, input + (static_cast<size_t>(iy) * s.in_w + ix) * run, run * sizeof(float));
        }
      }
    }
  }
}

void im2col_nhwc_s8(const Conv2dShape& s, const int8_t* input, int8_t pad_value, int pixel_begin, int count,
                    int8_t* patches, size_t ld) {
  const size_t run = static_cast<size_t>(s.in_c);
  for (int i = 0; i < count; ++i) {
    const int pixel = pixel_begin + i;
    const int oy = pixel / s.out_w;
    const int ox = pixel % s.out_w;
    int8_t* dst = patches + static_cast<size_t>(i) * ld;
    const int ix0 = ox * s.stride - s.pad;
    // Without dilation a kernel row inside the image is kernel_w consecutive NHWC pixels: one copy
    // (the 7x7 stem with 3 channels would otherwise copy 3 bytes at a time).
    const bool row_inside = s.dilation == 1 && ix0 >= 0 && ix0 + s.kernel_w <= s.in_w;
    for (int ky = 0; ky < s.kernel_h; ++ky) {
      const int iy = oy * s.stride - s.pad + ky * s.dilation;
      if (row_inside || iy < 0 || iy >= s.in_h) {
        const size_t bytes = run * static_cast<size_t>(s.kernel_w);
        if (iy < 0 || iy >= s.in_h) {
          std::memset(dst, pad_value, bytes);
        } else {
          std::memcpy(dst, input + (static_cast<size_t>(iy) * s.in_w + ix0) * run, bytes);
        }
        dst += bytes;
        continue;
      }
      for (int kx = 0; kx < s.kernel_w; ++kx, dst += run) {
        const int ix = ox * s.stride - s.pad + kx * s.dilation;
        if (ix < 0 || ix >= s.in_w) {  // rows outside the image were handled above
          std::memset(dst, pad_value, run);
        } else {
          std::memcpy(dst, input + (static_cast<size_t>(iy) * s.in_w + ix) * run, run);
        }
      }
    }
  }
}

}  // namespace act::kernels
