// The max-pool driver shared by the int8 and float families: it walks each output pixel's window
// once, in one place, and hands the in-image taps (pointers to channel vectors, as XNNPACK's
// indirection buffers) to a per-ISA channel-max primitive, so that padding and geometry are never
// re-implemented per ISA or per type. Layout NHWC (batch 1).
#pragma once

#include <algorithm>
#include <cstddef>

namespace act::kernels {

/// A run of `pixels` windows whose taps lie at the same offsets from each window's first pixel,
/// pixel_step elements apart: dst[i * channels + c] = max over t < ntaps of taps[t][i * pixel_step +
/// c], for i < pixels and c < channels (ntaps >= 1). With one pixel, dst may be one of the taps
/// (never a partial overlap). One call per run of a row's inside windows: a call per window cost
/// the stem's 3x3/2 pool of 64 channels about 4x its loads and maxes.
template <typename T>
using MaxTapsFn = void (*)(const T* const* taps, int ntaps, int pixels, size_t pixel_step, int channels, T* dst);

/// The scalar MaxTapsFn, both families' reference: a tap replaces the running max only when greater
/// (for floats, a NaN never does and a NaN first tap stays).
template <typename T>
void max_taps_scalar(const T* const* taps, int ntaps, int pixels, size_t pixel_step, int channels, T* dst) {
  for (int i = 0; i < pixels; ++i, dst += channels) {
    const size_t at = static_cast<size_t>(i) * pixel_step;
    for (int c = 0; c < channels; ++c) {
      T m = taps[0][at + c];
      for (int t = 1; t < ntaps; ++t) m = taps[t][at + c] > m ? taps[t][at + c] : m;
      dst[c] = m;
    }
  }
}

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
  // The windows inside horizontally: ox in [inside_begin, inside_end).
  const int inside_begin = std::min(out_w, (pad + stride - 1) / stride);
  const int inside_end = std::max(inside_begin, std::min(out_w, in_w - kernel + pad >= 0 ? (in_w - kernel + pad) / stride + 1 : 0));
  const size_t pixel_step = static_cast<size_t>(stride) * static_cast<size_t>(channels);
  for (int oy = row_begin; oy < row_end; ++oy) {
    const int iy0 = oy * stride - pad;
    const bool rows_inside = window_taps <= kBatch && iy0 >= 0 && iy0 + kernel <= in_h;
    const bool run = rows_inside && inside_begin < inside_end;
    if (run) {
      const T* first = input + (static_cast<size_t>(iy0 - input_row0) * in_w + (inside_begin * stride - pad)) * channels;
      for (int t = 0; t < window_taps; ++t) taps[t] = first + offsets[t];
      max_taps(taps, window_taps, inside_end - inside_begin, pixel_step, channels,
               output + (static_cast<size_t>(oy) * out_w + inside_begin) * channels);
    }
    for (int ox = 0; ox < out_w; ++ox) {
      if (run && ox >= inside_begin && ox < inside_end) continue;  // in the run above
      T* dst = output + (static_cast<size_t>(oy) * out_w + ox) * channels;
      int n = 0;
      bool started = false;
      for (int ky = 0; ky < kernel; ++ky) {
        const int iy = oy * stride - pad + ky;
        if (iy < 0 || iy >= in_h) continue;  // padding never wins: skip it
        for (int kx = 0; kx < kernel; ++kx) {
          const int ix = ox * stride - pad + kx;
          if (ix < 0 || ix >= in_w) continue;
          if (n == kBatch) {
            max_taps(taps, n, 1, 0, channels, dst);
            started = true;
            taps[0] = dst;
            n = 1;
          }
          taps[n++] = input + (static_cast<size_t>(iy - input_row0) * in_w + ix) * channels;
        }
      }
      if (n > (started ? 1 : 0)) {
        max_taps(taps, n, 1, 0, channels, dst);
      } else if (!started) {
        std::fill(dst, dst + channels, empty);  // a window entirely in the padding
      }
    }
  }
}

}  // namespace act::kernels
