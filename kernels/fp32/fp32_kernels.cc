#include "kernels/fp32/fp32_kernels.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "kernels/fp32/gemm_f32.h"

namespace act::kernels {

void gemm_f32_nt(int m, int n, int k, const float* a, size_t lda, const float* b, size_t ldb, float* c,
                 size_t ldc) {
  gemm_f32_active().nt(m, n, k, a, lda, b, ldb, c, ldc);
}

void gemm_f32_nn(int m, int n, int k, const float* a, size_t lda, const float* b, size_t ldb, float* c,
                 size_t ldc) {
  gemm_f32_active().nn(m, n, k, a, lda, b, ldb, c, ldc);
}

void im2col_nhwc_f32(const Conv2dShape& s, const float* input, int pixel_begin, int count, float* patches) {
  const size_t patch = static_cast<size_t>(s.patch_size());
  const size_t run = static_cast<size_t>(s.in_c);
  for (int i = 0; i < count; ++i) {
    const int pixel = pixel_begin + i;
    const int oy = pixel / s.out_w;
    const int ox = pixel % s.out_w;
    float* dst = patches + static_cast<size_t>(i) * patch;
    for (int ky = 0; ky < s.kernel_h; ++ky) {
      const int iy = oy * s.stride - s.pad + ky * s.dilation;
      for (int kx = 0; kx < s.kernel_w; ++kx, dst += run) {
        const int ix = ox * s.stride - s.pad + kx * s.dilation;
        if (iy < 0 || iy >= s.in_h || ix < 0 || ix >= s.in_w) {
          std::memset(dst, 0, run * sizeof(float));
        } else {
          std::memcpy(dst, input + (static_cast<size_t>(iy) * s.in_w + ix) * run, run * sizeof(float));
        }
      }
    }
  }
}

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
