// FP32 GEMM on AArch64 NEON: the packed micro-kernels of gemm_f32_packed.inc on an 8x12 register
// tile (24 accumulators of 4 floats, 3 of B).
#include "kernels/fp32/gemm_f32.h"

#if defined(__aarch64__)
#include <algorithm>

#include <xsimd/xsimd.hpp>

#include "kernels/common/check.h"
#include "kernels/fp32/elementwise_f32.h"

namespace act::kernels {

#include "kernels/fp32/gemm_f32_packed.inc"
#include "kernels/fp32/winograd_f32_transforms.inc"

namespace {
using Winograd = WinogradTransforms<XsimdLanes<xsimd::neon64>>;
using Packed = PackedGemm<xsimd::neon64, 8, 3>;
void gemm_packed_neon(const GemmF32PackedArgs& args) { Packed::run(Isa::kNeon, args, elementwise_f32_table_neon()->gelu); }
}  // namespace

const GemmF32Kernels* gemm_f32_table_neon() {
  static const GemmF32Kernels table{Isa::kNeon, "gemm_f32 8x12 neon", Packed::kMr, Packed::NR, gemm_packed_neon, Winograd::input,
                                    Winograd::output};
  return &table;
}
}  // namespace act::kernels
#else
namespace act::kernels {
const GemmF32Kernels* gemm_f32_table_neon() { return nullptr; }
}  // namespace act::kernels
#endif
