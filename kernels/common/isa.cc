#include "kernels/common/isa.h"

#if defined(ACT_HAVE_CPUINFO)
#include <cpuinfo.h>
#endif
#if defined(__linux__) && defined(__aarch64__)
#include <asm/hwcap.h>
#include <sys/auxv.h>
#endif
#if defined(__linux__) && defined(__x86_64__)
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>
#endif

namespace act::kernels {

namespace {

constexpr const char* kIsaNames[kIsaCount] = {"ref", "avx2", "avx512", "avx512vnni", "neon", "neondot", "avxvnni", "amx"};

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
    if (const cpuinfo_core* core = cpuinfo_get_core(0); core != nullptr && core->vendor == cpuinfo_vendor_amd) {
      const uint32_t signature = core->cpuid;  // CPUID leaf 1 EAX: family = base + extended when base is 0xF
      const uint32_t family = ((signature >> 8) & 0xF) + (((signature >> 8) & 0xF) == 0xF ? (signature >> 20) & 0xFF : 0);
      f.amd_zen4 = family == 0x19 && f.avx512f;
    }
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
  // Debian 12's cpuinfo knows neither AVX-VNNI nor AMX: GCC's indicator (CPUID and XCR0) does.
  __builtin_cpu_init();
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
