#include "kernels/config/kernel_config.h"

#include "kernels/gemm_s8/gemm_s8_variants.h"
#include "kernels/pool_s8/maxpool_s8_variants.h"
#include "kernels/quant/quant_s8_variants.h"

namespace act::kernels {

IsaTables isa_tables(Isa isa, const KernelTuning& tuning) {
  switch (isa) {
    case Isa::kRef:
      return {gemm_s8_table_ref(), gemm_f32_table_ref(), quant_s8_table_ref(), elementwise_f32_table_ref(),
              maxpool_s8_table_ref()};
    case Isa::kAvx2:
      return {gemm_s8_table_avx2(), gemm_f32_table_avx2(), quant_s8_table_avx2(), elementwise_f32_table_avx2(),
              maxpool_s8_table_avx2()};
    case Isa::kAvx512:
      return {nullptr, gemm_f32_table_avx512(tuning.gemm_f32_b_prefetch), quant_s8_table_avx512(),
              elementwise_f32_table_avx512(),
              maxpool_s8_table_avx512()};
    case Isa::kAvx512Vnni:
      return {gemm_s8_table_avx512vnni(), nullptr, nullptr, nullptr, nullptr};
    case Isa::kAvxVnni:
      return {gemm_s8_table_avxvnni(), nullptr, nullptr, nullptr, nullptr};
    case Isa::kAmx:
      return {gemm_s8_table_amx(), nullptr, nullptr, nullptr, nullptr};
    case Isa::kNeon:
      return {nullptr, gemm_f32_table_neon(), quant_s8_table_neon(), elementwise_f32_table_neon(), maxpool_s8_table_neon()};
    case Isa::kNeonDot:
      return {gemm_s8_table_neondot(), nullptr, nullptr, nullptr, nullptr};
  }
  return {};
}

std::string KernelConfig::describe() const {
  return std::string(isa_name(isa)) + ", tuned for " + uarch_name(tuning.uarch) + ": gemm_s8 " + std::to_string(gemm_s8.mr) + "x" + std::to_string(gemm_s8.nr) +
         "c" + std::to_string(gemm_s8.kr) + " " + isa_name(gemm_s8.isa) + ", " + gemm_f32.name + ", quant " +
         isa_name(quant.isa) + ", elementwise " + isa_name(elementwise.isa) + ", maxpool_s8 " +
         isa_name(maxpool_s8.isa);
}

KernelConfig kernel_config_for(Isa level, Uarch uarch) {
  const KernelTuning& tuning = kernel_tuning(uarch);
  return {level,
          tuning,
          variant_for(level, &IsaTables::gemm_s8, tuning),
          variant_for(level, &IsaTables::gemm_f32, tuning),
          variant_for(level, &IsaTables::quant, tuning),
          variant_for(level, &IsaTables::elementwise, tuning),
          variant_for(level, &IsaTables::maxpool_s8, tuning)};
}

KernelConfigChoice kernel_config(std::string_view requested_isa, std::string_view requested_uarch) {
  KernelConfigChoice choice;
  std::optional<Uarch> uarch = cpu_features().uarch;
  if (requested_uarch != "auto") uarch = parse_uarch(requested_uarch);
  if (!uarch) {
    choice.error = "unknown tuning '" + std::string(requested_uarch) + "': choose auto or one of " + uarch_names();
    choice.tuning_error = true;
    return choice;
  }
  std::optional<Isa> isa = best_cpu_isa();
  const std::string runs = "this CPU runs " + isa_mask_names(cpu_isa_mask());
  if (requested_isa != "auto") isa = parse_isa(requested_isa);
  if (!isa) {
    choice.error = "unknown ISA '" + std::string(requested_isa) + "': " + runs;
  } else if (!cpu_supports(*isa)) {
    choice.error = "ISA '" + std::string(requested_isa) + "' is not supported by this CPU: " + runs;
    if (*isa == Isa::kAmx && cpu_features().amx_refused != nullptr) {
      choice.error.append(" (the CPU has AMX-INT8, but ").append(cpu_features().amx_refused).append(")");
    }
  } else {
    choice.config.emplace(kernel_config_for(*isa, *uarch));
  }
  return choice;
}

}  // namespace act::kernels
