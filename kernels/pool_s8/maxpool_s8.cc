// The int8 max-pool (kernels/common/maxpool_window.h's driver) and its reference variant (the
// driver's max_taps_scalar, shared with the float family's).
#include "kernels/pool_s8/maxpool_s8.h"

#include "kernels/common/maxpool_window.h"
#include "kernels/pool_s8/maxpool_s8_variants.h"

namespace act::kernels {

const MaxPoolS8Kernels* maxpool_s8_table_ref() {
  static constexpr MaxPoolS8Kernels kTable = {Isa::kRef, "max_taps_s8_ref", max_taps_scalar<int8_t>};
  return &kTable;
}

void maxpool_nhwc_s8(const MaxPoolS8Kernels& k, int in_h, int in_w, int channels, int kernel, int stride, int pad,
                     int out_w, const int8_t* input, int8_t* output, int row_begin, int row_end, int input_row0) {
  maxpool_nhwc_with<int8_t>(k.max_taps, in_h, in_w, channels, kernel, stride, pad, out_w, input, output, row_begin, row_end,
                            input_row0, -128);
}

}  // namespace act::kernels
