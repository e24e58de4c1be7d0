// Channel max of int8 taps on AVX-512 BW (the kAvx512 variant): 64 channels per zmm; the ragged
// end uses masked loads and stores (masked-off bytes are neither read nor written), whole zmms plain
// ones (masked for every zmm, the stem's 240x320x64 pool took 0.201 ms here against the avx2
// variant's 0.152: a masked store to memory is slow on Zen 4 and 5).
// Rules for ISA files (kernels/gemm_s8/README.md): only intrinsics and internal-linkage code here.
#include "kernels/pool_s8/maxpool_s8_variants.h"

#if defined(__x86_64__)

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"  // GCC 12 _mm512_undefined_*()
#include <immintrin.h>
#pragma GCC diagnostic pop

// The same GCC 12 header idiom (`__m512 __Y = __Y;` as the pass-through of unmasked min/max,
// extract, reduce) is also reported at the call sites it is inlined into, as -Wuninitialized.
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"

namespace act::kernels {

namespace {

#include "kernels/pool_s8/maxpool_s8_taps.inc"

void max_taps_s8_avx512(const int8_t* const* taps_of_first, int ntaps, int pixels, size_t pixel_step, int channels,
                        int8_t* dst) {
  for_each_pixel(taps_of_first, pixels, pixel_step, channels, dst, [&](const auto& taps, int8_t* out) {
    int c = 0;
    for (; c + 64 <= channels; c += 64) {
      __m512i m = _mm512_loadu_si512(taps(0) + c);
      for (int t = 1; t < ntaps; ++t) m = _mm512_max_epi8(m, _mm512_loadu_si512(taps(t) + c));
      _mm512_storeu_si512(out + c, m);
    }
    if (c < channels) {
      const __mmask64 k = (__mmask64{1} << (channels - c)) - 1;
      __m512i m = _mm512_maskz_loadu_epi8(k, taps(0) + c);
      for (int t = 1; t < ntaps; ++t) m = _mm512_max_epi8(m, _mm512_maskz_loadu_epi8(k, taps(t) + c));
      _mm512_mask_storeu_epi8(out + c, k, m);
    }
  });
}

}  // namespace

const MaxPoolS8Kernels* maxpool_s8_table_avx512() {
  static constexpr MaxPoolS8Kernels kTable = {Isa::kAvx512, "max_taps_s8_avx512", max_taps_s8_avx512};
  return &kTable;
}

}  // namespace act::kernels

#else  // not x86-64

namespace act::kernels {
const MaxPoolS8Kernels* maxpool_s8_table_avx512() { return nullptr; }
}  // namespace act::kernels

#endif
