// The max-pool driver shared by the int8 and float families: it walks each output pixel's window
// once, in one place, and hands the in-image taps (pointers to channel vectors, as XNNPACK's
// indirection buffers) to a per-ISA channel-max primitive, so that padding and geometry are never
// re-implemented per ISA or per type. Layout NHWC (batch 1).
#pragma once

#include <algorithm>
#include <cstddef>

namespace act::kernels {

/// dst[c] = max over t < ntaps of taps[t][c], for c < channels (ntaps >= 1; dst may be one of the
/// taps, never a partial overlap).
template <typename T>
using MaxTapsFn = void (*)(const T* const* taps, int ntaps, int channels, T* dst);

/// Output rows [row_begin, row_end) of a max-pool with the primitive `max_taps`. Padding never wins
/// (it is skipped); a window entirely in the padding gives `empty`. `input` holds the image's rows
/// from input_row0 on (a band of them: those the output rows read).
template <typename T>
void maxpool_nhwc_with(MaxTapsFn<T> max_taps, int in_h, int in_w, int channels, int kernel, int stride, int pad, int out_w,
                       const T* input, T* output, int row_begin, int row_end, int input_row0, T empty) {
  // Taps are gathered in batches; a window larger than one batch folds the running max (dst) in
  // as the first tap of the next batch.
  constexpr int kBatch = 32;
  const T* taps[kBatch];
  // A window inside the image (all but the border's) takes its taps at fixed offsets from its
  // first pixel: no bounds to check tap by tap.
  const int window_taps = kernel * kernel;
  size_t offsets[kBatch];
  if (window_taps <= kBatch) {
    for (int ky = 0, t = 0; ky < kernel; ++ky) {
      for (int kx = 0; kx < kernel; ++kx, ++t) offsets[t] = (static_cast<size_t>(ky) * in_w + kx) * channels;
    }
  }
  for (int oy = row_begin; oy < row_end; ++oy) {
    const int iy0 = oy * stride - pad;
    const bool rows_inside = window_taps <= kBatch && iy0 >= 0 && iy0 + kernel <= in_h;
    for (int ox = 0; ox < out_w; ++ox) {
      T* dst = output + (static_cast<size_t>(oy) * out_w + ox) * channels;
      const int ix0 = ox * stride - pad;
      if (rows_inside && ix0 >= 0 && ix0 + kernel <= in_w) {
        const T* first = input + (static_cast<size_t>(iy0 - input_row0) * in_w + ix0) * channels;
        for (int t = 0; t < window_taps; ++t) taps[t] = first + offsets[t];
        max_taps(taps, window_taps, channels, dst);
        continue;
      }
      int n = 0;
      bool started = false;
      for (int ky = 0; ky < kernel; ++ky) {
        const int iy = oy * stride - pad + ky;
        if (iy < 0 || iy >= in_h) continue;  // padding never wins: skip it
        for (int kx = 0; kx < kernel; ++kx) {
          const int ix = ox * stride - pad + kx;
          if (ix < 0 || ix >= in_w) continue;
          if (n == kBatch) {
            max_taps(taps, n, channels, dst);
            started = true;
            taps[0] = dst;
            n = 1;
          }
          taps[n++] = input + (static_cast<size_t>(iy - input_row0) * in_w + ix) * channels;
        }
      }
      if (n > (started ? 1 : 0)) {
        max_taps(taps, n, channels, dst);
      } else if (!started) {
        std::fill(dst, dst + channels, empty);  // a window entirely in the padding
      }
    }
  }
}

}  // namespace act::kernels
