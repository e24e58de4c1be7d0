// The one place that maps the CPU's features (and ACT_ISA) to a gemm_s8 variant: its kernels, its
// packer and its tile. A variant is usable when its ISA file was compiled for this target
// (gemm_s8_table_<isa>() is non-null) and the CPU supports the ISA.
#include "kernels/gemm_s8/gemm_s8_variants.h"

namespace act::kernels {

namespace {

const GemmS8Kernels* built_table(Isa isa) {
  switch (isa) {
    case Isa::kRef: return gemm_s8_table_ref();
    case Isa::kAvx2: return gemm_s8_table_avx2();
    case Isa::kAvx512Vnni: return gemm_s8_table_avx512vnni();
    case Isa::kNeonDot: return gemm_s8_table_neondot();
  }
  return nullptr;
}

}  // namespace

IsaMask gemm_s8_built_isas() {
  IsaMask mask = 0;
  for (int i = 0; i < kIsaCount; ++i) {
    if (built_table(static_cast<Isa>(i)) != nullptr) mask |= isa_bit(static_cast<Isa>(i));
  }
  return mask;
}

std::vector<Isa> gemm_s8_available_isas() {
  std::vector<Isa> out;
  for (int i = 0; i < kIsaCount; ++i) {
    if (gemm_s8_kernels(static_cast<Isa>(i)) != nullptr) out.push_back(static_cast<Isa>(i));
  }
  return out;
}

const GemmS8Kernels* gemm_s8_kernels(Isa isa) {
  return cpu_supports(isa) ? built_table(isa) : nullptr;
}

GemmS8Selection gemm_s8_select() {
  GemmS8Selection s;
  const IsaChoice choice = choose_isa_from_env(gemm_s8_built_isas());
  if (!choice.ok()) {
    s.error = "gemm_s8: " + choice.error;
    return s;
  }
  s.kernels = gemm_s8_kernels(choice.isa);
  return s;
}

}  // namespace act::kernels
