#include "kernels/common/isa.h"

#if defined(ACT_HAVE_CPUINFO)
#include <cpuinfo.h>
#endif
#if defined(__linux__) && defined(__aarch64__)
#include <asm/hwcap.h>
#include <sys/auxv.h>
#endif
#if defined(__x86_64__)
#include <cpuid.h>
#endif
#if defined(__linux__) && defined(__x86_64__)
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>
#endif

namespace act::kernels {

namespace {

constexpr const char* kIsaNames[kIsaCount] = {"ref", "avx2", "avx512", "avx512vnni", "neon", "neondot", "avxvnni", "amx"};
constexpr const char* kUarchNames[kUarchCount] = {"generic", "zen4", "zen5", "goldencove", "gracemont", "cortex-a76"};

// The name of `value` in `names`, and back: the Isa and Uarch spellings.
template <class Enum, int N>
const char* enum_name(const char* const (&names)[N], Enum value) {
  const auto i = static_cast<unsigned>(value);
  return i < N ? names[i] : "?";
}
template <class Enum, int N>
std::optional<Enum> parse_enum(const char* const (&names)[N], std::string_view name) {
  for (int i = 0; i < N; ++i) {
    if (name == names[i]) return static_cast<Enum>(i);
  }
  return std::nullopt;
}

}  // namespace

Uarch x86_uarch_from_cpuid(std::string_view vendor, uint32_t leaf1_eax, bool avx512f) {
  const unsigned base_family = (leaf1_eax >> 8) & 0xF;
  const unsigned family = base_family + (base_family == 0xF ? (leaf1_eax >> 20) & 0xFF : 0);
  const unsigned model =
      ((leaf1_eax >> 4) & 0xF) | (base_family == 0x6 || base_family == 0xF ? ((leaf1_eax >> 16) & 0xF) << 4 : 0);
  if (vendor == "AuthenticAMD") {
    if (family == 0x19 && avx512f) return Uarch::kZen4;
    if (family == 0x1A) return Uarch::kZen5;
  } else if (vendor == "GenuineIntel" && family == 0x6) {
    switch (model) {
      case 0x8F: case 0xCF: case 0xAD: case 0xAE:             // Sapphire, Emerald, Granite Rapids
      case 0x97: case 0x9A: case 0xB7: case 0xBA: case 0xBF:  // Alder Lake, Raptor Lake
      case 0xAA: case 0xAC:                                   // Meteor Lake
        return Uarch::kGoldenCove;
      case 0xBE:  // Alder Lake-N
        return Uarch::kGracemont;
      default: break;
    }
  }
  return Uarch::kGeneric;
}

namespace {

#if defined(__x86_64__)
Uarch x86_uarch(bool avx512f) {
  unsigned eax = 0, ebx = 0, ecx = 0, edx = 0;
  if (__get_cpuid(0, &eax, &ebx, &ecx, &edx) == 0) return Uarch::kGeneric;
  char vendor[12];
  for (int i = 0; i < 4; ++i) {
    vendor[i] = static_cast<char>(ebx >> (8 * i));
    vendor[4 + i] = static_cast<char>(edx >> (8 * i));
    vendor[8 + i] = static_cast<char>(ecx >> (8 * i));
  }
  if (__get_cpuid(1, &eax, &ebx, &ecx, &edx) == 0) return Uarch::kGeneric;
  return x86_uarch_from_cpuid(std::string_view(vendor, sizeof(vendor)), eax, avx512f);
}
#endif

// Best first: the highest level of either chain that the CPU supports wins.
constexpr Isa kPreference[] = {Isa::kAmx,    Isa::kAvx512Vnni, Isa::kAvx512, Isa::kAvxVnni,
                               Isa::kAvx2,   Isa::kNeonDot,    Isa::kNeon,   Isa::kRef};

#if defined(__x86_64__) && defined(__linux__)
// Linux keeps AMX's 8 KiB tile state off until a process asks for it (arch/x86/include/uapi/asm/prctl.h).
constexpr int kArchReqXcompPerm = 0x1023;
constexpr int kXfeatureXtiledata = 18;

// Asks once per process for the tile data state; nullptr when granted, else why not.
const char* request_amx_permission() {
  if (syscall(SYS_arch_prctl, kArchReqXcompPerm, kXfeatureXtiledata) == 0) return nullptr;
  return errno == EPERM ? "the OS refused AMX tile state (arch_prctl ARCH_REQ_XCOMP_PERM: EPERM)"
                        : "the OS does not offer AMX tile state (arch_prctl ARCH_REQ_XCOMP_PERM failed)";
}
#endif

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
    if (const cpuinfo_core* core = cpuinfo_get_core(0); core != nullptr && core->uarch == cpuinfo_uarch_cortex_a76) {
      f.uarch = Uarch::kCortexA76;
    }
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
  // Debian 12's cpuinfo knows neither AVX-VNNI nor AMX nor Zen 4: GCC's indicator (CPUID and XCR0)
  // and CPUID itself do.
  __builtin_cpu_init();
  f.uarch = x86_uarch(f.avx512f);
  f.avxvnni = __builtin_cpu_supports("avxvnni");
  if (__builtin_cpu_supports("amx-tile") && __builtin_cpu_supports("amx-int8")) {
#if defined(__linux__)
    f.amx_refused = request_amx_permission();
#else
    f.amx_refused = "AMX tile state is only requested on Linux";
#endif
    f.amx = f.amx_refused == nullptr;
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

const char* isa_name(Isa isa) { return enum_name(kIsaNames, isa); }
std::optional<Isa> parse_isa(std::string_view name) { return parse_enum<Isa>(kIsaNames, name); }
const char* uarch_name(Uarch uarch) { return enum_name(kUarchNames, uarch); }
std::optional<Uarch> parse_uarch(std::string_view name) { return parse_enum<Uarch>(kUarchNames, name); }

std::string uarch_names() {
  std::string out;
  for (const char* name : kUarchNames) out.append(out.empty() ? "" : ", ").append(name);
  return out;
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

std::optional<Isa> isa_below(Isa isa) {
  switch (isa) {
    case Isa::kRef: return std::nullopt;
    case Isa::kAvx2: return Isa::kRef;
    case Isa::kAvxVnni: return Isa::kAvx2;
    case Isa::kAvx512: return Isa::kAvxVnni;
    case Isa::kAvx512Vnni: return Isa::kAvx512;
    case Isa::kAmx: return Isa::kAvx512Vnni;
    case Isa::kNeon: return Isa::kRef;
    case Isa::kNeonDot: return Isa::kNeon;
  }
  return std::nullopt;
}

bool cpu_supports(Isa isa) {
  const CpuFeatures& f = cpu_features();
  const bool avx2 = f.avx2 && f.fma;
  const bool avx512 = avx2 && f.avx512f && f.avx512bw && f.avx512vl;
  switch (isa) {
    case Isa::kRef: return true;
    case Isa::kAvx2: return avx2;
    case Isa::kAvxVnni: return avx2 && f.avxvnni;
    case Isa::kAvx512: return avx512;
    case Isa::kAvx512Vnni: return avx512 && f.avx512vnni;
    case Isa::kAmx: return avx512 && f.avx512vnni && f.amx;
    case Isa::kNeon: return f.neon;
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

std::vector<Isa> cpu_isas() {
  std::vector<Isa> out;
  for (int i = 0; i < kIsaCount; ++i) {
    if (cpu_supports(static_cast<Isa>(i))) out.push_back(static_cast<Isa>(i));
  }
  return out;
}

Isa best_cpu_isa() {
  for (Isa isa : kPreference) {
    if (cpu_supports(isa)) return isa;
  }
  return Isa::kRef;
}

}  // namespace act::kernels
