// The one place that maps the CPU's features (and ACT_ISA) to an FP32 GEMM variant.
#include "kernels/fp32/gemm_f32.h"

namespace act::kernels {

namespace {

const GemmF32Kernels* built_table(Isa isa) {
  switch (isa) {
    case Isa::kRef: return gemm_f32_table_ref();
    case Isa::kAvx2: return gemm_f32_table_avx2();
    case Isa::kAvx512Vnni: return gemm_f32_table_avx512vnni();
    case Isa::kNeonDot: return nullptr;  // AArch64's baseline Eigen already uses NEON
  }
  return nullptr;
}

IsaMask built_isas() {
  IsaMask mask = 0;
  for (int i = 0; i < kIsaCount; ++i) {
    if (built_table(static_cast<Isa>(i)) != nullptr) mask |= isa_bit(static_cast<Isa>(i));
  }
  return mask;
}

}  // namespace

const GemmF32Kernels* gemm_f32_kernels(Isa isa) { return cpu_supports(isa) ? built_table(isa) : nullptr; }

GemmF32Selection gemm_f32_select() {
  // ACT_ISA=neondot means "the NEON build" for FP32 too: its GEMM is the baseline one.
  const IsaChoice choice = choose_isa_from_env(built_isas() | (cpu_supports(Isa::kNeonDot) ? isa_bit(Isa::kNeonDot) : 0));
  GemmF32Selection s;
  if (!choice.ok()) {
    s.error = "gemm_f32: " + choice.error;
    return s;
  }
  s.kernels = choice.isa == Isa::kNeonDot ? gemm_f32_table_ref() : gemm_f32_kernels(choice.isa);
  return s;
}

const GemmF32Kernels& gemm_f32_active() {
  static const GemmF32Kernels* active = [] {
    const GemmF32Selection s = gemm_f32_select();
    return s.kernels ? s.kernels : gemm_f32_table_ref();
  }();
  return *active;
}

}  // namespace act::kernels
