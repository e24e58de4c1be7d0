// The kernel configuration of one Engine (XNNPACK's configs/, MLAS's platform table): the variant of
// every kernel family, chosen together, once, from the CPU's features and a requested ISA level.
// Nothing else in the library chooses a kernel; ops receive the configuration through the graph's
// RunContext, and weights are packed for its gemm_s8 variant.
//
// A family's variant for a level is its best variant at or below that level that the CPU runs
// (kernels/common/isa.h): at avx512, gemm_s8 (which has no AVX-512 variant without VNNI) runs avxvnni
// where the CPU has AVX-VNNI, else avx2, while quant, element-wise, max-pool and the FP32 GEMM run
// their avx512 variants; at avxvnni only gemm_s8 has its own variant, the rest run avx2.
#pragma once

#include <optional>
#include <string>
#include <string_view>

#include "kernels/common/isa.h"
#include "kernels/config/kernel_tuning.h"
#include "kernels/fp32/elementwise_f32.h"
#include "kernels/fp32/gemm_f32.h"
#include "kernels/gemm_s8/gemm_s8.h"
#include "kernels/pool_s8/maxpool_s8.h"
#include "kernels/quant/quant_s8.h"

namespace act::kernels {

/// Each family's variant compiled for exactly one ISA; null where the family has none for it (or
/// this target did not build it). Tests and benchmarks walk these to reach every variant.
struct IsaTables {
  const GemmS8Kernels* gemm_s8 = nullptr;
  const GemmF32Kernels* gemm_f32 = nullptr;
  const QuantS8Kernels* quant = nullptr;
  const ElementwiseF32Kernels* elementwise = nullptr;
  const MaxPoolS8Kernels* maxpool_s8 = nullptr;
};
/// `tuning` picks among a family's variants of one ISA (the avx512 float GEMM's B prefetch).
IsaTables isa_tables(Isa isa, const KernelTuning& tuning = kernel_tuning(cpu_features().uarch));

/// A family's variant for `level`: its table for the highest ISA at or below `level` that the CPU
/// runs (a level below may be missing: avx512 does not imply avxvnni; every family has a reference,
/// so there always is one). E.g. variant_for(Isa::kAvx512, &IsaTables::gemm_s8).
template <class Table>
const Table& variant_for(Isa level, const Table* IsaTables::*family,
                         const KernelTuning& tuning = kernel_tuning(cpu_features().uarch)) {
  for (std::optional<Isa> isa = level; isa; isa = isa_below(*isa)) {
    if (*isa != level && !cpu_supports(*isa)) continue;
    if (const Table* t = isa_tables(*isa, tuning).*family) return *t;
  }
  return *(isa_tables(Isa::kRef, tuning).*family);
}

struct KernelConfig {
  Isa isa;  ///< the level the variants were chosen for
  const KernelTuning& tuning;  ///< the core's row the variants were chosen with
  const GemmS8Kernels& gemm_s8;  ///< also decides how int8 weights are packed
  const GemmF32Kernels& gemm_f32;
  const QuantS8Kernels& quant;
  const ElementwiseF32Kernels& elementwise;
  const MaxPoolS8Kernels& maxpool_s8;

  /// The level, the tuning row and the variants in use, e.g. "avx512vnni, tuned for zen4: gemm_s8
  /// 6x64c4 avx512vnni, gemm_f32 6x64 avx512 (no B prefetch), ...".
  std::string describe() const;
};

/// The configuration of `level`: each family's best variant at or below it, tuned for `uarch`. The
/// caller makes sure the CPU runs `level` (kernel_config() checks; tests pass a level from
/// cpu_isa_mask()).
KernelConfig kernel_config_for(Isa level, Uarch uarch = cpu_features().uarch);

/// The configuration for a requested ISA, "auto" (the best level this CPU runs) or an ISA name, and
/// a requested tuning, "auto" (this core's) or a Uarch name (any: a tuning only picks among variants
/// the CPU runs). A name that is unknown, or a level this CPU cannot run, is an error — never a
/// silent fallback: `error` then says so and lists the choices, e.g.
///   unknown ISA 'bogus': this CPU runs ref, avx2, avx512, avx512vnni
struct KernelConfigChoice {
  std::optional<KernelConfig> config;  ///< empty on error
  std::string error;
  bool tuning_error = false;  ///< the error is the requested tuning's (else the ISA's)
};
KernelConfigChoice kernel_config(std::string_view requested_isa, std::string_view requested_uarch = "auto");

}  // namespace act::kernels
