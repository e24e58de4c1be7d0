// 2-D max-pool over NHWC int8. Max commutes with the (monotonic) affine quantization, so the
// output has the input's scale and zero point and the result is exact.
//
// One portable driver (kernels/common/maxpool_window.h, shared with the float max-pool) walks the
// pooling window once, in one place, and hands each output pixel's in-image taps (pointers to
// channel vectors, as XNNPACK's indirection buffers) to a per-ISA channel-max primitive, so padding
// and geometry are never re-implemented per ISA.
#pragma once

#include <cstddef>
#include <cstdint>

#include "kernels/common/isa.h"
#include "kernels/common/maxpool_window.h"

namespace act::kernels {

/// MaxTapsFn (maxpool_window.h) over int8. Reads exactly `channels` bytes of each tap per pixel.
using MaxS8TapsFn = MaxTapsFn<int8_t>;

/// One variant of the family (maxpool_s8_variants.h lists them; an Engine runs its KernelConfig's).
struct MaxPoolS8Kernels {
  Isa isa;
  const char* max_taps_name;  ///< max_taps_s8_<isa>
  MaxS8TapsFn max_taps;
};

/// Output rows [row_begin, row_end) with the variant `k`. Padding never wins (it is skipped).
/// `input` holds the image's rows from input_row0 on (a band of them: those the output rows read).
void maxpool_nhwc_s8(const MaxPoolS8Kernels& k, int in_h, int in_w, int channels, int kernel, int stride, int pad,
                     int out_w, const int8_t* input, int8_t* output, int row_begin, int row_end, int input_row0 = 0);

}  // namespace act::kernels
