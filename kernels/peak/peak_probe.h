// Register-only throughput probes of the multiply-accumulate instructions the kernels are built on:
// tight loops of independent instructions with no memory traffic, giving this core's measured peak
// to compare kernels (act_kernel_bench) and whole inferences (act_bench) against. Each raw probe
// returns the MACs performed (0 when not built for this target); `iterations` >= 1.
#pragma once

#include <cstdint>

#include "kernels/common/isa.h"

namespace act::kernels {

/// 16 independent vpdpbusd zmm chains per iteration (64 int8 MACs each). AVX-512 VNNI.
uint64_t peak_vpdpbusd_zmm(uint64_t iterations);
/// The 6x64c4 kernel's inner loop with its operands in L1 (4 weight loads, 6 broadcasts, 24
/// vpdpbusd per k-group): the ceiling of its instruction mix, below which the data's arrival lies.
uint64_t peak_vpdpbusd_zmm_6x64_loop(uint64_t iterations);
/// Other tile shapes' inner loops, the same way: 8x48c4 (3 weight loads, 8 broadcasts, 24 vpdpbusd
/// per k-group), 12x32c4 (2, 12, 24) and 14x32c4 (2, 14, 28). Which shape streams fastest on a
/// core is the evidence for its tuning (kernels/config/kernel_tuning.h).
uint64_t peak_vpdpbusd_zmm_8x48_loop(uint64_t iterations);
uint64_t peak_vpdpbusd_zmm_12x32_loop(uint64_t iterations);
uint64_t peak_vpdpbusd_zmm_14x32_loop(uint64_t iterations);
/// 4 independent tdpbssd tile chains per iteration (16 x 16 x 64 int8 MACs each), the operands in
/// tiles. AMX-INT8 (with the OS's permission for the tile state).
uint64_t peak_tdpbssd(uint64_t iterations);
/// 14 independent VEX vpdpbusd ymm chains per iteration (32 int8 MACs each). AVX-VNNI.
uint64_t peak_vpdpbusd_ymm(uint64_t iterations);
/// The 6x16c4 AVX-VNNI kernel's inner loop with its operands in L1 (2 weight loads, 6 broadcasts,
/// 12 vpdpbusd per k-group).
uint64_t peak_vpdpbusd_ymm_6x16_loop(uint64_t iterations);
/// 12 independent vpmaddwd ymm chains per iteration (16 int16 MACs each). AVX2.
uint64_t peak_vpmaddwd_ymm(uint64_t iterations);
/// 8 vpmaddwd + vpaddd accumulate pairs per iteration: the AVX2 kernel's actual idiom.
uint64_t peak_vpmaddwd_vpaddd_ymm(uint64_t iterations);
/// 16 independent sdot (by element) chains per iteration (16 MACs each). AArch64 dotprod.
uint64_t peak_sdot(uint64_t iterations);
/// 12 independent float FMA chains: vfmadd231ps ymm (8 MACs) / zmm (16 MACs).
uint64_t peak_vfmadd_f32_ymm(uint64_t iterations);
uint64_t peak_vfmadd_f32_zmm(uint64_t iterations);
/// The avx512 float GEMM's 6x64 tile's inner loop with its operands in L1 (4 B loads, 6 broadcasts,
/// 24 vfmadd231ps per k), and the other shapes of the vpdpbusd loop probes in float: 8x48, 12x32,
/// 14x32. AVX-512 F.
uint64_t peak_vfmadd_f32_zmm_6x64_loop(uint64_t iterations);
uint64_t peak_vfmadd_f32_zmm_8x48_loop(uint64_t iterations);
uint64_t peak_vfmadd_f32_zmm_12x32_loop(uint64_t iterations);
uint64_t peak_vfmadd_f32_zmm_14x32_loop(uint64_t iterations);
/// 16 independent fmla .4s chains (4 float MACs each). AArch64.
uint64_t peak_fmla_f32(uint64_t iterations);

enum class PeakKind { kInt8, kFp32 };

struct PeakProbe {
  const char* name;  ///< the instruction, e.g. "vpdpbusd_zmm"
  Isa isa;           ///< the kernel variant it bounds
  PeakKind kind;
  uint64_t (*fn)(uint64_t);
  bool is_isa_peak;  ///< the probe "% of peak" refers to for (isa, kind)
};

/// Every probe this library has, built for this target or not.
extern const PeakProbe kPeakProbes[];
extern const int kPeakProbeCount;

/// The probe "% of peak" refers to for kernels of `isa` and `kind`: the probe of the highest level
/// at or below `isa` that the CPU runs (the same rule that picks a family's variant for a level, so for an Engine's
/// level it bounds the GEMM that level runs); null when there is none (the scalar reference).
const PeakProbe* isa_peak_probe(Isa isa, PeakKind kind);

/// CPU time of the calling thread (seconds): unlike the wall clock, it does not count time the thread
/// spent descheduled, which on a shared machine would make a loaded core look slow.
double thread_cpu_seconds();

/// Sustained GMAC/s of a probe on this core, by thread CPU time (so that time descheduled on a
/// shared machine does not count): a ~20 ms warm-up (wide vectors lower the clock on many x86
/// cores), then the best of 10 runs of ~2 ms. 0 when the probe is not built or the CPU lacks it.
double measure_peak_gmacs(const PeakProbe& probe);

}  // namespace act::kernels
