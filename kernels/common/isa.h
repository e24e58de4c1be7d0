// Instruction-set levels of the kernels and CPU feature detection (done once per process: the
// hardware does not change). Each kernel family compiles a variant for some of these levels (per-ISA
// files, see kernels/README.md); kernels/config/kernel_config.h chooses among them.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace act::kernels {

/// Instruction-set levels, one chain per architecture, ordered as the hardware adds them:
///   x86-64   ref < avx2 (AVX2 + FMA) < avxvnni (+ AVX-VNNI: VEX vpdpbusd on ymm, Intel's small
///            cores) < avx512 (AVX-512 F/BW/VL) < avx512vnni (+ VNNI) < amx (+ AMX-TILE/INT8)
///   AArch64  ref < neon (Advanced SIMD) < neondot (+ the ARMv8.2 dot product)
/// A level needs every feature of the levels below it with one exception: avxvnni is not implied
/// by avx512 (Zen 4 and Ice Lake have AVX-512 VNNI but no AVX-VNNI), so a CPU can run a level and
/// not one below it. A kernel variant is named by the level it needs; a family's variant for a
/// level is its best variant at or below it that the CPU runs (kernels/config/kernel_config.h).
/// kRef is the portable scalar reference. The values are stable (masks, covered paths).
enum class Isa : uint8_t {
  kRef = 0,
  kAvx2 = 1,
  kAvx512 = 2,
  kAvx512Vnni = 3,
  kNeon = 4,
  kNeonDot = 5,
  kAvxVnni = 6,
  kAmx = 7,
};
inline constexpr int kIsaCount = 8;

/// A set of Isa values: bit i stands for Isa(i).
using IsaMask = uint32_t;
constexpr IsaMask isa_bit(Isa isa) { return IsaMask{1} << static_cast<unsigned>(isa); }

/// "ref", "avx2", "avxvnni", "avx512", "avx512vnni", "amx", "neon" or "neondot" (the spelling EngineOptions::isa,
/// ACT_ISA and kernel names use).
const char* isa_name(Isa isa);
/// The inverse of isa_name; nullopt for anything else (case-sensitive).
std::optional<Isa> parse_isa(std::string_view name);
/// Comma-separated names of the set, in Isa order, e.g. "ref, avx2".
std::string isa_mask_names(IsaMask mask);
/// The level directly below `isa` in its chain (amx -> avx512vnni -> avx512 -> avxvnni -> avx2 ->
/// ref, neondot -> neon -> ref); nullopt for kRef.
std::optional<Isa> isa_below(Isa isa);

/// The core microarchitectures whose kernels are tuned apart (kernels/config/kernel_tuning.h), from
/// the CPUID signature (x86-64) or the MIDR (AArch64) of the first core; kGeneric for every other.
///   zen4        AMD family 19h with AVX-512 (Zen 3, the same family, has none)
///   zen5        AMD family 1Ah
///   goldencove  Intel's big cores from Golden Cove on: Sapphire/Emerald/Granite Rapids, the
///               P-cores of Alder/Raptor/Meteor Lake
///   gracemont   Intel's E-cores alone: Alder Lake-N (N100, N150, N200, N305)
///   cortex-a76  the Raspberry Pi 5's core
/// The values are stable (names, JSON).
enum class Uarch : uint8_t { kGeneric = 0, kZen4 = 1, kZen5 = 2, kGoldenCove = 3, kGracemont = 4, kCortexA76 = 5 };
inline constexpr int kUarchCount = 6;
/// "generic", "zen4", "zen5", "goldencove", "gracemont" or "cortex-a76" (the spelling
/// EngineOptions::uarch and ACT_UARCH use).
const char* uarch_name(Uarch uarch);
/// The inverse of uarch_name; nullopt for anything else (case-sensitive).
std::optional<Uarch> parse_uarch(std::string_view name);
/// Every name, comma-separated, in Uarch order.
std::string uarch_names();
/// The x86-64 core of a CPUID vendor string ("GenuineIntel", "AuthenticAMD") and leaf 1's EAX
/// (family and model with their extended fields, as the SDM and AMD's APM define them).
Uarch x86_uarch_from_cpuid(std::string_view vendor, uint32_t leaf1_eax, bool avx512f);

/// What this CPU (and its OS) supports, detected once per process.
struct CpuFeatures {
  bool avx2 = false, fma = false;                                       // x86-64
  bool avx512f = false, avx512bw = false, avx512vl = false, avx512vnni = false;
  bool avxvnni = false;
  /// AMX-TILE and AMX-INT8 in CPUID, and Linux granted this process the tile data state
  /// (arch_prctl(ARCH_REQ_XCOMP_PERM), asked once at detection). amx_refused says why not when
  /// the CPU has AMX but the OS refused it (then the kernels fall back to the levels below).
  bool amx = false;
  const char* amx_refused = nullptr;
  bool neon = false, dotprod = false;                                   // AArch64
  /// The microarchitecture (see Uarch). Only the kernels' tuning depends on it.
  Uarch uarch = Uarch::kGeneric;
  /// How the features were found: "cpuinfo", "cpuinfo+auxv", "auxv", "cpuid" or "none".
  const char* source = "none";
};
const CpuFeatures& cpu_features();

/// True when the CPU can run `isa`: avx2 needs AVX2 + FMA; avxvnni that and AVX-VNNI; avx512 AVX2,
/// FMA and AVX-512 F/BW/VL; avx512vnni also AVX-512 VNNI; amx also AMX-TILE/INT8 with the OS's
/// permission; neon needs Advanced SIMD; neondot also the dot-product extension. kRef is always
/// supported.
bool cpu_supports(Isa isa);
/// The set of ISAs cpu_supports() accepts.
IsaMask cpu_isa_mask();
/// The same as a list, in Isa order (what tests and benchmarks walk to reach every variant).
std::vector<Isa> cpu_isas();
/// The highest level this CPU runs (its chain's best supported ISA).
Isa best_cpu_isa();

}  // namespace act::kernels
