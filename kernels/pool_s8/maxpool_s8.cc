// The portable max-pool driver and the reference channel-max primitive.
#include "kernels/pool_s8/maxpool_s8.h"

#include <cstring>

#include "kernels/pool_s8/maxpool_s8_variants.h"

namespace act::kernels {

namespace {

void max_taps_s8_ref(const int8_t* const* taps, int ntaps, int channels, int8_t* dst) {
  for (int c = 0; c < channels; ++c) {
    int8_t m = taps[0][c];
    for (int t = 1; t < ntaps; ++t) m = taps[t][c] > m ? taps[t][c] : m;
    dst[c] = m;
  }
}

}  // namespace

const MaxPoolS8Kernels* maxpool_s8_table_ref() {
  static constexpr MaxPoolS8Kernels kTable = {Isa::kRef, "max_taps_s8_ref", max_taps_s8_ref};
  return &kTable;
}

void maxpool_nhwc_s8(const MaxPoolS8Kernels& k, int in_h, int in_w, int channels, int kernel, int stride, int pad,
                     int out_w, const int8_t* input, int8_t* output, int row_begin, int row_end, int input_row0) {
  // Taps are gathered in batches; a window larger than one batch folds the running max (dst) in
  // as the first tap of the next batch.
  constexpr int kBatch = 32;
  const int8_t* taps[kBatch];
  for (int oy = row_begin; oy < row_end; ++oy) {
    for (int ox = 0; ox < out_w; ++ox) {
      int8_t* dst = output + (static_cast<size_t>(oy) * out_w + ox) * channels;
      int n = 0;
      bool started = false;
      for (int ky = 0; ky < kernel; ++ky) {
        const int iy = oy * stride - pad + ky;
        if (iy < 0 || iy >= in_h) continue;  // padding never wins: skip it
        for (int kx = 0; kx < kernel; ++kx) {
          const int ix = ox * stride - pad + kx;
          if (ix < 0 || ix >= in_w) continue;
          if (n == kBatch) {
            k.max_taps(taps, n, channels, dst);
            started = true;
            taps[0] = dst;
            n = 1;
          }
          taps[n++] = input + (static_cast<size_t>(iy - input_row0) * in_w + ix) * channels;
        }
      }
      if (n > (started ? 1 : 0)) {
        k.max_taps(taps, n, channels, dst);
      } else if (!started) {
        std::memset(dst, -128, static_cast<size_t>(channels));  // a window entirely in the padding
      }
    }
  }
}

}  // namespace act::kernels
