#include "kernels/config/kernel_tuning.h"

namespace act::kernels {

namespace {

// In Uarch order. Rows without a field measured both ways keep the defaults. Intel: the prefetch
// was measured to gain on its two FMA ports. Zen 5 (two FMA ports too): without it the default
// model's FP32 moved -1 % on one thread and +2.5 % on two, inside the host's noise, so it stays on.
constexpr KernelTuning kRows[kUarchCount] = {
    {Uarch::kGeneric},
    {Uarch::kZen4, /*gemm_f32_b_prefetch=*/false},
    {Uarch::kZen5},
    {Uarch::kGoldenCove},
    {Uarch::kGracemont},
    {Uarch::kCortexA76},
};
static_assert(kRows[kUarchCount - 1].uarch == Uarch::kCortexA76, "one row per Uarch, in order");

}  // namespace

const KernelTuning& kernel_tuning(Uarch uarch) {
  const auto i = static_cast<unsigned>(uarch);
  return kRows[i < kUarchCount ? i : 0];
}

}  // namespace act::kernels
