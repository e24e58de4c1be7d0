// The max-pool family's variants. The portable driver (maxpool_s8.cc) walks the pooling window
// once, in one place, and hands each output pixel's in-image taps (pointers to channel vectors, as
// XNNPACK's indirection buffers) to a per-ISA channel-max primitive, so padding and geometry are
// never re-implemented per ISA. Results are exact (integer max) in every variant.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "kernels/common/isa.h"

namespace act::kernels {

/// dst[c] = max over t < ntaps of taps[t][c], for c < channels. ntaps >= 1; dst may be one of the
/// taps (same address), never a partial overlap. Reads exactly `channels` bytes of each tap.
using MaxS8TapsFn = void (*)(const int8_t* const* taps, int ntaps, int channels, int8_t* dst);

struct MaxPoolS8Kernels {
  Isa isa;
  const char* max_taps_name;  ///< max_taps_s8_<isa>
  MaxS8TapsFn max_taps;
};

const MaxPoolS8Kernels* maxpool_s8_table_ref();
const MaxPoolS8Kernels* maxpool_s8_table_avx2();
const MaxPoolS8Kernels* maxpool_s8_table_avx512vnni();  ///< AVX-512 BW
const MaxPoolS8Kernels* maxpool_s8_table_neondot();     ///< plain NEON

IsaMask maxpool_s8_built_isas();
const MaxPoolS8Kernels* maxpool_s8_kernels(Isa isa);
std::vector<Isa> maxpool_s8_available_isas();
/// The variant maxpool_nhwc_s8 uses: chosen once per process (ACT_ISA, else the best).
const MaxPoolS8Kernels& maxpool_s8_active();

/// maxpool_nhwc_s8 with the given variant.
void maxpool_nhwc_s8_with(const MaxPoolS8Kernels& k, int in_h, int in_w, int channels, int kernel, int stride,
                          int pad, int out_w, const int8_t* input, int8_t* output, int row_begin, int row_end);

}  // namespace act::kernels
