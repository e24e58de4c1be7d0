// Channel max of int8 taps on AVX2: 32 channels per ymm (vpmaxsb), then 16 with SSE4.1, then scalar.
// Rules for ISA files (kernels/gemm_s8/README.md): only intrinsics and internal-linkage code here.
#include "kernels/pool_s8/maxpool_s8_variants.h"

#if defined(__x86_64__)

#include <immintrin.h>

namespace act::kernels {

namespace {

#include "kernels/pool_s8/maxpool_s8_taps.inc"

void max_taps_s8_avx2(const int8_t* const* taps_of_first, int ntaps, int pixels, size_t pixel_step, int channels,
                      int8_t* dst) {
  for_each_pixel(taps_of_first, pixels, pixel_step, channels, dst, [&](const auto& taps, int8_t* out) {
    int c = 0;
    for (; c + 32 <= channels; c += 32) {
      __m256i m = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(taps(0) + c));
      for (int t = 1; t < ntaps; ++t) m = _mm256_max_epi8(m, _mm256_loadu_si256(reinterpret_cast<const __m256i*>(taps(t) + c)));
      _mm256_storeu_si256(reinterpret_cast<__m256i*>(out + c), m);
    }
    for (; c + 16 <= channels; c += 16) {
      __m128i m = _mm_loadu_si128(reinterpret_cast<const __m128i*>(taps(0) + c));
      for (int t = 1; t < ntaps; ++t) m = _mm_max_epi8(m, _mm_loadu_si128(reinterpret_cast<const __m128i*>(taps(t) + c)));
      _mm_storeu_si128(reinterpret_cast<__m128i*>(out + c), m);
    }
    max_channels_scalar(taps, ntaps, c, channels, out);
  });
}

}  // namespace

const MaxPoolS8Kernels* maxpool_s8_table_avx2() {
  static constexpr MaxPoolS8Kernels kTable = {Isa::kAvx2, "max_taps_s8_avx2", max_taps_s8_avx2};
  return &kTable;
}

}  // namespace act::kernels

#else  // not x86-64

namespace act::kernels {
const MaxPoolS8Kernels* maxpool_s8_table_avx2() { return nullptr; }
}  // namespace act::kernels

#endif
