#include "kernels/common/isa.h"

#include <cstdlib>

#if defined(ACT_HAVE_CPUINFO)
#include <cpuinfo.h>
#endif
#if defined(__linux__) && defined(__aarch64__)
#include <asm/hwcap.h>
#include <sys/auxv.h>
#endif

namespace act::kernels {

namespace {

constexpr const char* kIsaNames[kIsaCount] = {"ref", "avx2", "avx512vnni", "neondot"};

// Best first: the order choose_isa() prefers when there is no override.
constexpr Isa kPreference[] = {Isa::kAvx512Vnni, Isa::kAvx2, Isa::kNeonDot, Isa::kRef};

CpuFeatures detect() {
  CpuFeatures f;
  bool from_cpuinfo = false;
#if defined(ACT_HAVE_CPUINFO)
  // cpuinfo_initialize() may fail, e.g. under qemu-user where /proc/cpuinfo describes the host;
  // then the fallbacks below still answer.
  if (cpuinfo_initialize()) {
    from_cpuinfo = true;
    f.source = "cpuinfo";
#if defined(__x86_64__)
    f.avx2 = cpuinfo_has_x86_avx2();
    f.fma = cpuinfo_has_x86_fma3();
    f.avx512f = cpuinfo_has_x86_avx512f();
    f.avx512bw = cpuinfo_has_x86_avx512bw();
    f.avx512vl = cpuinfo_has_x86_avx512vl();
    f.avx512vnni = cpuinfo_has_x86_avx512vnni();
#elif defined(__aarch64__)
    f.neon = cpuinfo_has_arm_neon();
    f.dotprod = cpuinfo_has_arm_neon_dot();
#endif
  }
#endif
#if defined(__x86_64__)
  if (!from_cpuinfo) {
    // GCC's cpu indicator checks CPUID and the OS's XSAVE state (XCR0), like cpuinfo.
    __builtin_cpu_init();
    f.source = "cpuid";
    f.avx2 = __builtin_cpu_supports("avx2");
    f.fma = __builtin_cpu_supports("fma");
    f.avx512f = __builtin_cpu_supports("avx512f");
    f.avx512bw = __builtin_cpu_supports("avx512bw");
    f.avx512vl = __builtin_cpu_supports("avx512vl");
    f.avx512vnni = __builtin_cpu_supports("avx512vnni");
  }
#elif defined(__aarch64__)
  f.neon = true;  // Advanced SIMD is mandatory in AArch64.
#if defined(__linux__)
  // The kernel's hwcaps are the ground truth (and what qemu-user -cpu max reports).
  if ((getauxval(AT_HWCAP) & HWCAP_ASIMDDP) != 0 && !f.dotprod) {
    f.dotprod = true;
    f.source = from_cpuinfo ? "cpuinfo+auxv" : "auxv";
  } else if (!from_cpuinfo) {
    f.source = "auxv";
  }
#endif
#endif
  (void)from_cpuinfo;
  return f;
}

}  // namespace

const char* isa_name(Isa isa) {
  const auto i = static_cast<unsigned>(isa);
  return i < kIsaCount ? kIsaNames[i] : "?";
}

std::optional<Isa> parse_isa(std::string_view name) {
  for (int i = 0; i < kIsaCount; ++i) {
    if (name == kIsaNames[i]) return static_cast<Isa>(i);
  }
  return std::nullopt;
}

std::string isa_mask_names(IsaMask mask) {
  std::string out;
  for (int i = 0; i < kIsaCount; ++i) {
    if ((mask & isa_bit(static_cast<Isa>(i))) == 0) continue;
    if (!out.empty()) out += ", ";
    out += kIsaNames[i];
  }
  return out.empty() ? "none" : out;
}

const CpuFeatures& cpu_features() {
  static const CpuFeatures features = detect();  // thread-safe, once per process
  return features;
}

bool cpu_supports(Isa isa) {
  const CpuFeatures& f = cpu_features();
  switch (isa) {
    case Isa::kRef: return true;
    case Isa::kAvx2: return f.avx2 && f.fma;
    case Isa::kAvx512Vnni: return f.avx512f && f.avx512bw && f.avx512vl && f.avx512vnni;
    case Isa::kNeonDot: return f.neon && f.dotprod;
  }
  return false;
}

IsaMask cpu_isa_mask() {
  IsaMask mask = 0;
  for (int i = 0; i < kIsaCount; ++i) {
    if (cpu_supports(static_cast<Isa>(i))) mask |= isa_bit(static_cast<Isa>(i));
  }
  return mask;
}

IsaChoice choose_isa(const char* override_value, IsaMask built, IsaMask detected) {
  IsaChoice choice;
  if (override_value != nullptr && override_value[0] != '\0') {
    const std::string value(override_value);
    const std::optional<Isa> isa = parse_isa(value);
    if (!isa) {
      choice.error = "ACT_ISA=" + value + ": unknown ISA (expected one of ref, avx2, avx512vnni, neondot)";
    } else if ((built & isa_bit(*isa)) == 0) {
      choice.error = "ACT_ISA=" + value + ": this build has no " + value +
                     " kernels (built for this target: " + isa_mask_names(built) + ")";
    } else if ((detected & isa_bit(*isa)) == 0) {
      choice.error = "ACT_ISA=" + value + ": this CPU does not support " + value +
                     " (supported: " + isa_mask_names(built & detected) + ")";
    } else {
      choice.isa = *isa;
    }
    return choice;
  }
  for (Isa isa : kPreference) {
    if ((built & detected & isa_bit(isa)) != 0) {
      choice.isa = isa;
      return choice;
    }
  }
  choice.error = "no kernel variant is both built and supported (built: " + isa_mask_names(built) + ")";
  return choice;
}

IsaChoice choose_isa_from_env(IsaMask built) {
  return choose_isa(std::getenv("ACT_ISA"), built, cpu_isa_mask());
}

}  // namespace act::kernels
