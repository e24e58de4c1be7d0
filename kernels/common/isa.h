// Instruction-set variants of the kernels, CPU feature detection (done once per process) and the
// ACT_ISA override. Each kernel family compiles some of these variants (per-ISA files, see
// kernels/gemm_s8/README.md); a variant can run when it is both built and detected.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace act::kernels {

/// Kernel variants, one per instruction set. kRef is the portable scalar reference.
enum class Isa : uint8_t { kRef = 0, kAvx2 = 1, kAvx512Vnni = 2, kNeonDot = 3 };
inline constexpr int kIsaCount = 4;

/// A set of Isa values: bit i stands for Isa(i).
using IsaMask = uint32_t;
constexpr IsaMask isa_bit(Isa isa) { return IsaMask{1} << static_cast<unsigned>(isa); }

/// "ref", "avx2", "avx512vnni" or "neondot" (the spelling ACT_ISA accepts and kernel names use).
const char* isa_name(Isa isa);
/// The inverse of isa_name; nullopt for anything else (case-sensitive).
std::optional<Isa> parse_isa(std::string_view name);
/// Comma-separated names of the set, in Isa order, e.g. "ref, avx2".
std::string isa_mask_names(IsaMask mask);

/// What this CPU (and its OS) supports, detected once per process.
struct CpuFeatures {
  bool avx2 = false, fma = false;                                       // x86-64
  bool avx512f = false, avx512bw = false, avx512vl = false, avx512vnni = false;
  bool neon = false, dotprod = false;                                   // AArch64
  /// How the features were found: "cpuinfo", "cpuinfo+auxv", "auxv", "cpuid" or "none".
  const char* source = "none";
};
const CpuFeatures& cpu_features();

/// True when the CPU can run `isa`: avx2 needs AVX2+FMA; avx512vnni needs AVX-512 F/BW/VL/VNNI;
/// neondot needs the ARMv8.2 dot-product extension. kRef is always supported.
bool cpu_supports(Isa isa);
/// The set of ISAs cpu_supports() accepts.
IsaMask cpu_isa_mask();

/// The result of choosing a variant: the ISA, or an error that says what is wrong.
struct IsaChoice {
  Isa isa = Isa::kRef;
  std::string error;  ///< empty when ok
  bool ok() const { return error.empty(); }
};

/// Chooses the ISA a kernel family runs with. `override_value` is the ACT_ISA value (nullptr or ""
/// when unset): it must name an ISA that the family built (`built`) and the CPU supports
/// (`detected`), otherwise the choice is an error (never a silent fallback). Without an override
/// the best ISA in built & detected wins (avx512vnni > avx2 > ref, neondot > ref).
IsaChoice choose_isa(const char* override_value, IsaMask built, IsaMask detected);

/// choose_isa() with the ACT_ISA environment variable (read at each call) and cpu_isa_mask().
IsaChoice choose_isa_from_env(IsaMask built);

}  // namespace act::kernels
