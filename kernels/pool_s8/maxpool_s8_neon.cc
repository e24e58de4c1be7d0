// Channel max of int8 taps on AArch64 NEON (the kNeon variant): 16 channels per q register
// (smax), then 8, then scalar.
// Rules for ISA files (kernels/gemm_s8/README.md): only intrinsics and internal-linkage code here.
#include "kernels/pool_s8/maxpool_s8_variants.h"

#if defined(__aarch64__)

#include <arm_neon.h>

namespace act::kernels {

namespace {

#include "kernels/pool_s8/maxpool_s8_taps.inc"

void max_taps_s8_neon(const int8_t* const* taps_of_first, int ntaps, int pixels, size_t pixel_step, int channels,
                      int8_t* dst) {
  for_each_pixel(taps_of_first, pixels, pixel_step, channels, dst, [&](const auto& taps, int8_t* out) {
    int c = 0;
    for (; c + 16 <= channels; c += 16) {
      int8x16_t m = vld1q_s8(taps(0) + c);
      for (int t = 1; t < ntaps; ++t) m = vmaxq_s8(m, vld1q_s8(taps(t) + c));
      vst1q_s8(out + c, m);
    }
    for (; c + 8 <= channels; c += 8) {
      int8x8_t m = vld1_s8(taps(0) + c);
      for (int t = 1; t < ntaps; ++t) m = vmax_s8(m, vld1_s8(taps(t) + c));
      vst1_s8(out + c, m);
    }
    max_channels_scalar(taps, ntaps, c, channels, out);
  });
}

}  // namespace

const MaxPoolS8Kernels* maxpool_s8_table_neon() {
  static constexpr MaxPoolS8Kernels kTable = {Isa::kNeon, "max_taps_s8_neon", max_taps_s8_neon};
  return &kTable;
}

}  // namespace act::kernels

#else  // not AArch64

namespace act::kernels {
const MaxPoolS8Kernels* maxpool_s8_table_neon() { return nullptr; }
}  // namespace act::kernels

#endif
