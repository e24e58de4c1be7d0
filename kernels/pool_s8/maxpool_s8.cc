// The int8 max-pool (kernels/common/maxpool_window.h's driver) and the reference channel-max primitive.
#include "kernels/pool_s8/maxpool_s8.h"

#include "kernels/common/maxpool_window.h"
#include "kernels/pool_s8/maxpool_s8_variants.h"

namespace act::kernels {

namespace {

void max_taps_s8_ref(const int8_t* const* taps, int ntaps, int pixels, size_t pixel_step, int channels, int8_t* dst) {
  for (int i = 0; i < pixels; ++i, dst += channels) {
    const size_t at = static_cast<size_t>(i) * pixel_step;
    for (int c = 0; c < channels; ++c) {
      int8_t m = taps[0][at + c];
      for (int t = 1; t < ntaps; ++t) m = taps[t][at + c] > m ? taps[t][at + c] : m;
      dst[c] = m;
    }
  }
}

}  // namespace

const MaxPoolS8Kernels* maxpool_s8_table_ref() {
  static constexpr MaxPoolS8Kernels kTable = {Isa::kRef, "max_taps_s8_ref", max_taps_s8_ref};
  return &kTable;
}

void maxpool_nhwc_s8(const MaxPoolS8Kernels& k, int in_h, int in_w, int channels, int kernel, int stride, int pad,
                     int out_w, const int8_t* input, int8_t* output, int row_begin, int row_end, int input_row0) {
  maxpool_nhwc_with<int8_t>(k.max_taps, in_h, in_w, channels, kernel, stride, pad, out_w, input, output, row_begin, row_end,
                            input_row0, -128);
}

}  // namespace act::kernels
