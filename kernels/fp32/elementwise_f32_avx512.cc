// The float element-wise kernels on AVX-512 (F/BW; the kAvx512 variant): elementwise_f32_xsimd.inc instantiated for xsimd's
// xsimd::avx512f. Rules for ISA files (kernels/gemm_s8/README.md): internal linkage only.
#include "kernels/fp32/elementwise_f32.h"

#if defined(__x86_64__)

// GCC 12's AVX-512 headers initialise their pass-through operands with themselves
// (`__m512 __Y = __Y;`), reported as (maybe-)uninitialized wherever xsimd's wrappers inline them.
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <xsimd/xsimd.hpp>

namespace act::kernels {

#include "kernels/fp32/elementwise_f32_xsimd.inc"

namespace {
using Arch = xsimd::avx512f;

template <>
BatchF<Arch> multiply_add<Arch>(const BatchF<Arch>& a, const BatchF<Arch>& b, const BatchF<Arch>& c) {
  return _mm512_fmadd_ps(a, b, c);
}

// GCC's reductions fold the halves onto each other in registers: lane_tree's order, so its bits.
template <>
float lane_tree_max<Arch>(const BatchF<Arch>& v) {
  return _mm512_reduce_max_ps(v);
}
template <>
float lane_tree_sum<Arch>(const BatchF<Arch>& v) {
  return _mm512_reduce_add_ps(v);
}

// 2^t as vscalefps(2^f, n): n by vrndscaleps, the exponent added by the instruction (two integer
// operations and the rounding-bias pair fewer than the generic form). The clamp keeps a NaN.
template <int Degree>
BatchF<Arch> exp2_by_scalef(const BatchF<Arch>& t_in) {
  const __m512 t = _mm512_max_ps(_mm512_set1_ps(kExp2Lowest), t_in);
  const __m512 n = _mm512_roundscale_ps(t, _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
  return _mm512_scalef_ps(exp2_fraction<Arch, Degree>(BatchF<Arch>(_mm512_sub_ps(t, n))), n);
}
template <>
BatchF<Arch> exp2_nonpositive<Arch, 4>(const BatchF<Arch>& t) {
  return exp2_by_scalef<4>(t);
}
template <>
BatchF<Arch> exp2_nonpositive<Arch, 5>(const BatchF<Arch>& t) {
  return exp2_by_scalef<5>(t);
}

// vpmovdb into a register, then one 16-byte store (the store form of vpmovdb is several times slower).
template <>
void store_low_bytes<Arch>(int8_t* p, const xsimd::batch<int32_t, Arch>& v) {
  _mm_storeu_si128(reinterpret_cast<__m128i*>(p), _mm512_cvtepi32_epi8(v));
}
}  // namespace

const ElementwiseF32Kernels* elementwise_f32_table_avx512() {
  static constexpr ElementwiseF32Kernels kTable = table_xs<Arch>(
      Isa::kAvx512, {"layernorm_rows_f32_avx512", "softmax_rows_f32_avx512", "softmax_rows_s8_avx512", "relu_f32_avx512",
                   "gelu_f32_avx512", "add_f32_avx512", "max_taps_f32_avx512"});
  return &kTable;
}

}  // namespace act::kernels

#else

namespace act::kernels {
const ElementwiseF32Kernels* elementwise_f32_table_avx512() { return nullptr; }
}  // namespace act::kernels

#endif
