// FP32 GEMM with this file's avx512 flags (cmake/ActLayer.cmake): the packed micro-kernels of
// gemm_f32_packed.inc on a 6x64 register tile (24 accumulators: per k, 4 loads of B and 6
// broadcasts of A for 24 fused multiply-adds; 8x32 needed 10 loads for 16 and its A broadcast twice
// for a 64-channel conv), with B prefetched 1 KB ahead (4 k steps) or not (gemm_f32.h says which CPU
// runs which).
#include "kernels/fp32/gemm_f32.h"

#if defined(__x86_64__)
#include <algorithm>

// GCC 12's AVX-512 headers initialise their pass-through operands with themselves, reported as
// (maybe-)uninitialized wherever xsimd's wrappers inline them (as in elementwise_f32_avx512.cc).
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <xsimd/xsimd.hpp>

#include "kernels/common/check.h"
#include "kernels/fp32/elementwise_f32.h"

namespace act::kernels {

#include "kernels/fp32/gemm_f32_packed.inc"
#include "kernels/fp32/winograd_f32_transforms.inc"

namespace {
template <>
xsimd::batch<float, xsimd::avx512f> multiply_add<xsimd::avx512f>(const xsimd::batch<float, xsimd::avx512f>& a,
                                                               const xsimd::batch<float, xsimd::avx512f>& b,
                                                               const xsimd::batch<float, xsimd::avx512f>& c) {
  return _mm512_fmadd_ps(a, b, c);
}

using Winograd = WinogradTransforms<XsimdLanes<xsimd::avx512f>>;
using Prefetching = PackedGemm<xsimd::avx512f, 6, 4, 1024>;
using Plain = PackedGemm<xsimd::avx512f, 6, 4, 0>;
template <class Gemm>
void gemm_packed(const GemmF32PackedArgs& args) { Gemm::run(Isa::kAvx512, args, elementwise_f32_table_avx512()->gelu); }
}  // namespace

const GemmF32Kernels* gemm_f32_table_avx512(bool software_prefetch) {
  static const GemmF32Kernels prefetching{Isa::kAvx512, "gemm_f32 6x64 avx512", Prefetching::kMr, Prefetching::NR,
                                          gemm_packed<Prefetching>, Winograd::input, Winograd::output};
  static const GemmF32Kernels plain{Isa::kAvx512, "gemm_f32 6x64 avx512 (no B prefetch)", Plain::kMr, Plain::NR,
                                    gemm_packed<Plain>, Winograd::input, Winograd::output};
  return software_prefetch ? &prefetching : &plain;
}
}  // namespace act::kernels
#else
namespace act::kernels {
const GemmF32Kernels* gemm_f32_table_avx512(bool) { return nullptr; }
}  // namespace act::kernels
#endif
