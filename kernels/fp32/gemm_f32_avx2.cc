// FP32 GEMM with this file's avx2 flags (cmake/ActLayer.cmake): the packed micro-kernels of
// gemm_f32_packed.inc on a 6x16 register tile.
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
using Winograd = WinogradTransforms<XsimdLanes<xsimd::fma3<xsimd::avx2>>>;
using Packed = PackedGemm<xsimd::fma3<xsimd::avx2>, 6, 2>;
void gemm_packed_avx2(const GemmF32PackedArgs& args) { Packed::run(Isa::kAvx2, args, elementwise_f32_table_avx2()->gelu); }
}  // namespace

const GemmF32Kernels* gemm_f32_table_avx2() {
  static const GemmF32Kernels table{Isa::kAvx2, "gemm_f32 6x16 avx2", Packed::kMr, Packed::NR, gemm_packed_avx2, Winograd::input,
                                    Winograd::output};
  return &table;
}
}  // namespace act::kernels
#else
namespace act::kernels {
const GemmF32Kernels* gemm_f32_table_avx2() { return nullptr; }
}  // namespace act::kernels
#endif
