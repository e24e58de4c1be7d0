// The float element-wise kernels on AVX2 + FMA: elementwise_f32_xsimd.inc instantiated for xsimd's
// xsimd::fma3<xsimd::avx2>. Rules for ISA files (kernels/gemm_s8/README.md): internal linkage only.
#include "kernels/fp32/elementwise_f32.h"

#if defined(__x86_64__)

#include <xsimd/xsimd.hpp>

namespace act::kernels {

#include "kernels/fp32/elementwise_f32_xsimd.inc"

namespace {
using Arch = xsimd::fma3<xsimd::avx2>;

// The low byte of every int32 gathered into the first 4 bytes of each 128-bit half, the two halves'
// words side by side, then one 8-byte store.
template <>
void store_low_bytes<Arch>(int8_t* p, const xsimd::batch<int32_t, Arch>& v) {
  const __m256i low_bytes = _mm256_shuffle_epi8(v, _mm256_setr_epi8(0, 4, 8, 12, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1,
                                                                     0, 4, 8, 12, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1));
  const __m256i packed = _mm256_permutevar8x32_epi32(low_bytes, _mm256_setr_epi32(0, 4, 1, 1, 1, 1, 1, 1));
  _mm_storel_epi64(reinterpret_cast<__m128i*>(p), _mm256_castsi256_si128(packed));
}
}  // namespace

const ElementwiseF32Kernels* elementwise_f32_table_avx2() {
  static constexpr ElementwiseF32Kernels kTable = table_xs<Arch>(
      Isa::kAvx2, {"layernorm_rows_f32_avx2", "softmax_rows_f32_avx2", "softmax_rows_s8_avx2", "relu_f32_avx2",
                   "gelu_f32_avx2", "add_f32_avx2", "max_taps_f32_avx2"});
  return &kTable;
}

}  // namespace act::kernels

#else

namespace act::kernels {
const ElementwiseF32Kernels* elementwise_f32_table_avx2() { return nullptr; }
}  // namespace act::kernels

#endif
