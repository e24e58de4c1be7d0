#include "kernels/peak/peak_probe.h"

#include <time.h>

#include <algorithm>
#include <optional>

namespace act::kernels {

const PeakProbe kPeakProbes[] = {
    {"tdpbssd", Isa::kAmx, PeakKind::kInt8, peak_tdpbssd, true},
    {"vpdpbusd_zmm", Isa::kAvx512Vnni, PeakKind::kInt8, peak_vpdpbusd_zmm, true},
    {"vpdpbusd_zmm_6x64_loop", Isa::kAvx512Vnni, PeakKind::kInt8, peak_vpdpbusd_zmm_6x64_loop, false},
    {"vpdpbusd_zmm_8x48_loop", Isa::kAvx512Vnni, PeakKind::kInt8, peak_vpdpbusd_zmm_8x48_loop, false},
    {"vpdpbusd_zmm_12x32_loop", Isa::kAvx512Vnni, PeakKind::kInt8, peak_vpdpbusd_zmm_12x32_loop, false},
    {"vpdpbusd_zmm_14x32_loop", Isa::kAvx512Vnni, PeakKind::kInt8, peak_vpdpbusd_zmm_14x32_loop, false},
    {"vpdpbusd_ymm", Isa::kAvxVnni, PeakKind::kInt8, peak_vpdpbusd_ymm, true},
    {"vpdpbusd_ymm_6x16_loop", Isa::kAvxVnni, PeakKind::kInt8, peak_vpdpbusd_ymm_6x16_loop, false},
    {"vpmaddwd_ymm", Isa::kAvx2, PeakKind::kInt8, peak_vpmaddwd_ymm, true},
    {"vpmaddwd+vpaddd_ymm", Isa::kAvx2, PeakKind::kInt8, peak_vpmaddwd_vpaddd_ymm, false},
    {"sdot", Isa::kNeonDot, PeakKind::kInt8, peak_sdot, true},
    {"vfmadd231ps_zmm", Isa::kAvx512, PeakKind::kFp32, peak_vfmadd_f32_zmm, true},
    {"vfmadd231ps_zmm_6x64_loop", Isa::kAvx512, PeakKind::kFp32, peak_vfmadd_f32_zmm_6x64_loop, false},
    {"vfmadd231ps_zmm_8x48_loop", Isa::kAvx512, PeakKind::kFp32, peak_vfmadd_f32_zmm_8x48_loop, false},
    {"vfmadd231ps_zmm_12x32_loop", Isa::kAvx512, PeakKind::kFp32, peak_vfmadd_f32_zmm_12x32_loop, false},
    {"vfmadd231ps_zmm_14x32_loop", Isa::kAvx512, PeakKind::kFp32, peak_vfmadd_f32_zmm_14x32_loop, false},
    {"vfmadd231ps_ymm", Isa::kAvx2, PeakKind::kFp32, peak_vfmadd_f32_ymm, true},
    {"fmla_4s", Isa::kNeon, PeakKind::kFp32, peak_fmla_f32, true},
};
const int kPeakProbeCount = static_cast<int>(sizeof(kPeakProbes) / sizeof(kPeakProbes[0]));

const PeakProbe* isa_peak_probe(Isa isa, PeakKind kind) {
  for (std::optional<Isa> level = isa; level; level = isa_below(*level)) {
    if (*level != isa && !cpu_supports(*level)) continue;  // avx512 does not imply avxvnni
    for (const PeakProbe& p : kPeakProbes) {
      if (p.isa == *level && p.kind == kind && p.is_isa_peak) return &p;
    }
  }
  return nullptr;
}

double thread_cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double measure_peak_gmacs(const PeakProbe& p) {
  if (!cpu_supports(p.isa) || p.fn(1) == 0) return 0.0;
  auto run = [&](uint64_t iters) {
    const double t0 = thread_cpu_seconds();
    const uint64_t macs = p.fn(iters);
    const double s = std::max(thread_cpu_seconds() - t0, 1e-9);
    return static_cast<double>(macs) / s * 1e-9;
  };
  const double macs_per_iteration = static_cast<double>(p.fn(1));
  const double warm = run(1u << 14);  // GMAC/s of a short run, to size the timed runs
  const auto iters_for = [&](double seconds) {
    return static_cast<uint64_t>(seconds * warm * 1e9 / macs_per_iteration) + 1;
  };
  run(iters_for(0.02));
  double best = 0.0;
  for (int rep = 0; rep < 10; ++rep) best = std::max(best, run(iters_for(0.002)));
  return best;
}

}  // namespace act::kernels
