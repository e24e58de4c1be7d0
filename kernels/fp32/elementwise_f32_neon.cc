// The float element-wise kernels on AArch64 NEON (the kNeon variant): elementwise_f32_xsimd.inc instantiated for xsimd's
// xsimd::neon64. Rules for ISA files (kernels/gemm_s8/README.md): internal linkage only.
// (xsimd 8.1's NEON wrappers, e.g. xsimd::kernel::wrap::vreinterpretq_*, are plain inline functions
// and so weak symbols here; harmless: the only other file including xsimd on AArch64,
// gemm_f32_neon.cc, has the same baseline flags.)
#include "kernels/fp32/elementwise_f32.h"

#if defined(__aarch64__)

#include <arm_neon.h>

#include <xsimd/xsimd.hpp>

namespace act::kernels {

#include "kernels/fp32/elementwise_f32_xsimd.inc"

namespace {
using Arch = xsimd::neon64;

// The low byte of each int32 lane (already in [-128, 127]): two narrowing moves, one 4-byte store.
template <>
void store_low_bytes<Arch>(int8_t* p, const xsimd::batch<int32_t, Arch>& v) {
  const int16x4_t halves = vmovn_s32(v);
  const int8x8_t bytes = vmovn_s16(vcombine_s16(halves, halves));
  vst1_lane_s32(reinterpret_cast<int32_t*>(p), vreinterpret_s32_s8(bytes), 0);
}
}  // namespace

const ElementwiseF32Kernels* elementwise_f32_table_neon() {
  static constexpr ElementwiseF32Kernels kTable = table_xs<Arch>(
      Isa::kNeon, {"layernorm_rows_f32_neon", "softmax_rows_f32_neon", "softmax_rows_s8_neon", "relu_f32_neon",
                   "gelu_f32_neon", "add_f32_neon", "max_taps_f32_neon"});
  return &kTable;
}

}  // namespace act::kernels

#else

namespace act::kernels {
const ElementwiseF32Kernels* elementwise_f32_table_neon() { return nullptr; }
}  // namespace act::kernels

#endif
