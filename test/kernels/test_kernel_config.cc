// The kernel configuration (kernels/config/kernel_config.h): one variant per family, chosen for an
// ISA level ("auto" or a name), each the family's best variant at or below the level; an unknown ISA
// or one this CPU cannot run is an error listing what it runs.
#include <gtest/gtest.h>

#include <cstdlib>
#include <optional>
#include <string>

#include "kernels/config/kernel_config.h"
#include "kernels/peak/peak_probe.h"
#include "test/kernels/kernel_test_util.h"

namespace act::kernels {
namespace {

// True when `variant` is at or below `level` in level's chain.
bool at_or_below(Isa variant, Isa level) {
  for (std::optional<Isa> isa = level; isa; isa = isa_below(*isa)) {
    if (*isa == variant) return true;
  }
  return false;
}

TEST(KernelConfig, AutoIsTheBestLevelThisCpuRuns) {
  const KernelConfigChoice c = kernel_config("auto");
  ASSERT_TRUE(c.config.has_value()) << c.error;
  EXPECT_EQ(c.config->isa, best_cpu_isa());
  EXPECT_TRUE(cpu_supports(c.config->isa));
  const std::string described = c.config->describe();
  EXPECT_EQ(described.rfind(std::string(isa_name(c.config->isa)) + ", tuned for " + uarch_name(cpu_features().uarch) +
                                ": gemm_s8 ",
                            0),
            0u)
      << described;
  EXPECT_EQ(&c.config->tuning, &kernel_tuning(cpu_features().uarch));
  EXPECT_NE(described.find(c.config->gemm_f32.name), std::string::npos) << described;
#if defined(__x86_64__)
  if (cpu_supports(Isa::kAvx2)) {
    EXPECT_NE(c.config->isa, Isa::kRef) << "an AVX2 CPU chose the scalar reference";
  }
#elif defined(__aarch64__)
  EXPECT_NE(c.config->isa, Isa::kRef) << "an AArch64 CPU chose the scalar reference";
#endif
}

TEST(KernelConfig, EveryLevelTakesEachFamilysBestVariantAtOrBelowIt) {
  for (Isa level : cpu_isas()) {
    const KernelConfigChoice c = kernel_config(isa_name(level));
    ASSERT_TRUE(c.config.has_value()) << c.error;
    const KernelConfig& k = *c.config;
    EXPECT_EQ(k.isa, level);
    for (Isa family_isa : {k.gemm_s8.isa, k.gemm_f32.isa, k.quant.isa, k.elementwise.isa, k.maxpool_s8.isa}) {
      EXPECT_TRUE(at_or_below(family_isa, level)) << isa_name(family_isa) << " chosen at " << isa_name(level);
      EXPECT_TRUE(cpu_supports(family_isa));
    }
    EXPECT_EQ(&k.quant, &variant_for(level, &IsaTables::quant));
    EXPECT_EQ(&k.gemm_s8, &variant_for(level, &IsaTables::gemm_s8));
  }
}

#if defined(__x86_64__)
// AVX-512 without VNNI: the families that need only F/BW/VL run their AVX-512 code, gemm_s8 (whose
// AVX-512 kernel needs VNNI) its AVX-VNNI one where the CPU has AVX-VNNI (avx512 does not imply it),
// else its AVX2 one.
TEST(KernelConfig, Avx512LevelUsesAvxVnniOrAvx2GemmS8AndAvx512ForTheRest) {
  const KernelConfig k = kernel_config_for(Isa::kAvx512);
  EXPECT_EQ(k.gemm_s8.isa, cpu_supports(Isa::kAvxVnni) ? Isa::kAvxVnni : Isa::kAvx2);
  EXPECT_EQ(k.gemm_f32.isa, Isa::kAvx512);
  EXPECT_EQ(k.quant.isa, Isa::kAvx512);
  EXPECT_EQ(k.elementwise.isa, Isa::kAvx512);
  EXPECT_EQ(k.maxpool_s8.isa, Isa::kAvx512);
  const KernelConfig vnni = kernel_config_for(Isa::kAvx512Vnni);
  EXPECT_EQ(vnni.gemm_s8.isa, Isa::kAvx512Vnni);
  EXPECT_EQ(vnni.quant.isa, Isa::kAvx512);
}

// AVX-VNNI (Intel's cores without AVX-512): its own gemm_s8, AVX2 for every other family.
TEST(KernelConfig, AvxVnniLevelUsesAvxVnniGemmS8AndAvx2ForTheRest) {
  if (!cpu_supports(Isa::kAvxVnni)) GTEST_SKIP() << "this CPU has no AVX-VNNI";
  const KernelConfig k = kernel_config_for(Isa::kAvxVnni);
  EXPECT_EQ(k.gemm_s8.isa, Isa::kAvxVnni);
  EXPECT_EQ(k.gemm_s8.layout, GemmS8Layout::kVnni16x4);
  EXPECT_EQ(k.gemm_f32.isa, Isa::kAvx2);
  EXPECT_EQ(k.quant.isa, Isa::kAvx2);
  EXPECT_EQ(k.elementwise.isa, Isa::kAvx2);
  EXPECT_EQ(k.maxpool_s8.isa, Isa::kAvx2);
}
#endif

#if defined(__aarch64__)
// Plain NEON (no dot product): NEON quant / element-wise / max-pool, the reference gemm_s8.
TEST(KernelConfig, NeonLevelUsesNeonForAllButGemmS8) {
  const KernelConfig k = kernel_config_for(Isa::kNeon);
  EXPECT_EQ(k.gemm_s8.isa, Isa::kRef);
  EXPECT_EQ(k.quant.isa, Isa::kNeon);
  EXPECT_EQ(k.elementwise.isa, Isa::kNeon);
  EXPECT_EQ(k.maxpool_s8.isa, Isa::kNeon);
  EXPECT_EQ(kernel_config_for(Isa::kNeonDot).gemm_s8.isa, Isa::kNeonDot);
}
#endif

// act_bench's "% of peak" at a level is against the int8 probe of the gemm_s8 variant that level
// runs (avx512 without VNNI: the avxvnni kernel's vpdpbusd ymm where the CPU has AVX-VNNI, else
// vpmaddwd), a probe this CPU runs; none for the scalar reference.
TEST(KernelConfig, EachLevelsInt8PeakIsTheProbeOfItsGemmS8) {
  for (Isa level : cpu_isas()) {
    const Isa gemm = variant_for(level, &IsaTables::gemm_s8).isa;
    const PeakProbe* probe = isa_peak_probe(level, PeakKind::kInt8);
    if (gemm == Isa::kRef) {
      EXPECT_EQ(probe, nullptr) << isa_name(level);
      continue;
    }
    ASSERT_NE(probe, nullptr) << isa_name(level);
    EXPECT_EQ(probe->isa, gemm) << isa_name(level) << ": " << probe->name;
    EXPECT_TRUE(cpu_supports(probe->isa)) << probe->name;
  }
}

// Every probe this CPU runs counts the MACs of its iterations, and a tile shape's loop probe
// (<instruction>_<rows>x<columns>_loop) those of its shape: rows x columns per k step, times the 4
// bytes of an int8 k-group (so a probe whose assembly dropped or repeated a row fails), and its
// measured rate is positive.
TEST(PeakProbes, EveryProbeCountsTheMacsOfItsLoop) {
  int loops = 0;
  for (int i = 0; i < kPeakProbeCount; ++i) {
    const PeakProbe& p = kPeakProbes[i];
    if (!cpu_supports(p.isa) || p.fn(1) == 0) continue;
    SCOPED_TRACE(p.name);
    const uint64_t one = p.fn(1);
    EXPECT_EQ(p.fn(3), 3 * one);
    const std::string name = p.name;
    const size_t x = name.rfind('x'), end = name.rfind("_loop");
    if (end != std::string::npos && end + 5 == name.size()) {
      const size_t start = name.rfind('_', x) + 1;
      const uint64_t rows = std::stoul(name.substr(start, x - start)), cols = std::stoul(name.substr(x + 1, end - x - 1));
      EXPECT_EQ(one, rows * cols * (p.kind == PeakKind::kInt8 ? 4u : 1u));
      ++loops;
    }
    EXPECT_GT(measure_peak_gmacs(p), 0.0);
  }
#if defined(__x86_64__)
  if (cpu_supports(Isa::kAvx512Vnni)) {
    EXPECT_GE(loops, 8) << "the vpdpbusd and vfmadd231ps tile-shape probes";
  }
#endif
}

#if defined(__x86_64__)
// AMX needs the OS's permission for the tile state as well as CPUID: where it is granted, auto runs
// the amx gemm_s8; where Linux refuses it, asking for amx is an error that says so, and auto falls
// back to the level below.
TEST(KernelConfig, AmxRunsWhereTheOsGrantsItAndSaysWhyNotElsewhere) {
  const CpuFeatures& f = cpu_features();
  EXPECT_FALSE(f.amx && f.amx_refused != nullptr);
  if (cpu_supports(Isa::kAmx)) {
    const KernelConfigChoice c = kernel_config("auto");
    ASSERT_TRUE(c.config.has_value()) << c.error;
    EXPECT_EQ(c.config->isa, Isa::kAmx);
    EXPECT_EQ(c.config->gemm_s8.isa, Isa::kAmx);
    EXPECT_EQ(kernel_config_for(Isa::kAmx).quant.isa, Isa::kAvx512);
    return;
  }
  const KernelConfigChoice c = kernel_config("amx");
  EXPECT_FALSE(c.config.has_value());
  if (f.amx_refused != nullptr) {
    EXPECT_NE(c.error.find(f.amx_refused), std::string::npos) << c.error;
  }
  const KernelConfigChoice best = kernel_config("auto");
  ASSERT_TRUE(best.config.has_value());
  EXPECT_NE(best.config->isa, Isa::kAmx);
}
#endif

TEST(KernelConfig, UnknownIsaIsAnErrorListingWhatThisCpuRuns) {
  const std::string runs = "this CPU runs " + isa_mask_names(cpu_isa_mask());
  for (const char* bad : {"bogus", "AVX2", "", "avx512vnni "}) {
    const KernelConfigChoice c = kernel_config(bad);
    EXPECT_FALSE(c.config.has_value()) << bad;
    EXPECT_EQ(c.error, "unknown ISA '" + std::string(bad) + "': " + runs);
  }
}

TEST(KernelConfig, IsaThisCpuLacksIsAnError) {
#if defined(__x86_64__)
  const char* foreign = "neondot";
#else
  const char* foreign = "avx2";
#endif
  const KernelConfigChoice c = kernel_config(foreign);
  EXPECT_FALSE(c.config.has_value());
  EXPECT_EQ(c.error, std::string("ISA '") + foreign + "' is not supported by this CPU: this CPU runs " +
                         isa_mask_names(cpu_isa_mask()));
  for (int i = 0; i < kIsaCount; ++i) {
    const Isa isa = static_cast<Isa>(i);
    EXPECT_EQ(kernel_config(isa_name(isa)).config.has_value(), cpu_supports(isa)) << isa_name(isa);
  }
}

TEST(KernelTuning, EveryUarchHasItsRowAndNameBothWays) {
  std::string names;
  for (int i = 0; i < kUarchCount; ++i) {
    const Uarch u = static_cast<Uarch>(i);
    EXPECT_EQ(kernel_tuning(u).uarch, u) << uarch_name(u);
    EXPECT_EQ(parse_uarch(uarch_name(u)), u) << uarch_name(u);
    names.append(names.empty() ? "" : ", ").append(uarch_name(u));
  }
  EXPECT_EQ(uarch_names(), names);
  for (const char* bad : {"", "Zen4", "zen4 ", "skylake", "?"}) EXPECT_FALSE(parse_uarch(bad).has_value()) << bad;
}

// Signatures of real parts (CPUID leaf 1 EAX).
TEST(KernelTuning, CpuidSignaturesNameTheirCores) {
  EXPECT_EQ(x86_uarch_from_cpuid("AuthenticAMD", 0x00A10F11, true), Uarch::kZen4);      // EPYC 9004 (Genoa)
  EXPECT_EQ(x86_uarch_from_cpuid("AuthenticAMD", 0x00A60F12, true), Uarch::kZen4);      // Ryzen 7000 (Raphael)
  EXPECT_EQ(x86_uarch_from_cpuid("AuthenticAMD", 0x00A00F11, false), Uarch::kGeneric);  // EPYC 7003 (Zen 3)
  EXPECT_EQ(x86_uarch_from_cpuid("AuthenticAMD", 0x00B00F21, true), Uarch::kZen5);      // EPYC 9005 (Turin)
  EXPECT_EQ(x86_uarch_from_cpuid("AuthenticAMD", 0x00830F10, false), Uarch::kGeneric);  // EPYC 7002 (Zen 2)
  EXPECT_EQ(x86_uarch_from_cpuid("GenuineIntel", 0x000806F8, true), Uarch::kGoldenCove);  // Sapphire Rapids
  EXPECT_EQ(x86_uarch_from_cpuid("GenuineIntel", 0x000C06F2, true), Uarch::kGoldenCove);  // Emerald Rapids
  EXPECT_EQ(x86_uarch_from_cpuid("GenuineIntel", 0x00090672, false), Uarch::kGoldenCove); // Alder Lake-S
  EXPECT_EQ(x86_uarch_from_cpuid("GenuineIntel", 0x000B06E0, false), Uarch::kGracemont);  // N100
  EXPECT_EQ(x86_uarch_from_cpuid("GenuineIntel", 0x00050657, true), Uarch::kGeneric);     // Cascade Lake
  EXPECT_EQ(x86_uarch_from_cpuid("GenuineIntel", 0x000A06A4, false), Uarch::kGoldenCove); // Meteor Lake
  EXPECT_EQ(x86_uarch_from_cpuid("HygonGenuine", 0x00A10F11, true), Uarch::kGeneric);
}

// A tuning changes only what it says: the Zen 4 row drops the avx512 float GEMM's B prefetch,
// every other row keeps it; at every level the rest of the choice is the same.
TEST(KernelTuning, ChoosesAmongOneIsasVariantsOnly) {
  for (Isa level : cpu_isas()) {
    const KernelConfig generic = kernel_config_for(level, Uarch::kGeneric);
    for (int i = 0; i < kUarchCount; ++i) {
      const Uarch u = static_cast<Uarch>(i);
      const KernelConfigChoice c = kernel_config(isa_name(level), uarch_name(u));
      ASSERT_TRUE(c.config.has_value()) << c.error;
      EXPECT_EQ(c.config->isa, level);
      EXPECT_EQ(&c.config->tuning, &kernel_tuning(u));
      EXPECT_EQ(&c.config->gemm_s8, &generic.gemm_s8) << uarch_name(u);
      EXPECT_EQ(&c.config->quant, &generic.quant) << uarch_name(u);
      EXPECT_EQ(c.config->gemm_f32.isa, generic.gemm_f32.isa) << uarch_name(u);
      const bool prefetch_variant = c.config->gemm_f32.isa == Isa::kAvx512;
      if (prefetch_variant) {
        EXPECT_EQ(c.config->gemm_f32.name, std::string(gemm_f32_table_avx512(u != Uarch::kZen4)->name)) << uarch_name(u);
      } else {
        EXPECT_EQ(&c.config->gemm_f32, &generic.gemm_f32) << uarch_name(u);
      }
    }
  }
}

TEST(KernelTuning, UnknownTuningIsAnErrorListingTheChoices) {
  const KernelConfigChoice c = kernel_config("auto", "zen9");
  EXPECT_FALSE(c.config.has_value());
  EXPECT_TRUE(c.tuning_error);
  EXPECT_EQ(c.error, "unknown tuning 'zen9': choose auto or one of " + uarch_names());
  const KernelConfigChoice isa = kernel_config("bogus", "zen4");
  EXPECT_FALSE(isa.tuning_error);
  EXPECT_EQ(isa.error.rfind("unknown ISA 'bogus'", 0), 0u) << isa.error;
}

// The kernel tests honour ACT_ISA (the variant an Engine at that level runs): it must be valid.
TEST(KernelConfig, ActIsaOfThisRunIsValid) {
  const char* forced = std::getenv("ACT_ISA");
  if (forced == nullptr || forced[0] == '\0') GTEST_SKIP() << "ACT_ISA is not set";
  const KernelConfigChoice c = kernel_config(forced);
  EXPECT_TRUE(c.config.has_value()) << "ACT_ISA: " << c.error;
}

}  // namespace
}  // namespace act::kernels
