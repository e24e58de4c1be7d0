// The kernels' tuning per core microarchitecture: what differs between cores that run the same ISA
// level. One row per Uarch; KernelConfig takes the row of the detected core (or of EngineOptions::
// uarch / ACT_UARCH) and chooses its variants with it.
//
// A field is here only when a measurement on that core chose it. The evidence is act_kernel_bench's
// bare-loop probes (peak/vpdpbusd_zmm_<tile>_loop: which tile shape streams fastest from L1) and its
// GEMM and conv rows run both ways (kernels/README.md has the tables). Today every x86 core measured
// (Zen 4, Zen 5) streams the 6x64 int8 and float tiles at the speed of the best other shape, so the
// tiles are the ISA's; the float GEMM's B prefetch is the one choice that differs.
#pragma once

#include "kernels/common/isa.h"

namespace act::kernels {

struct KernelTuning {
  Uarch uarch;
  /// The avx512 float GEMM prefetches the next B panel in software. On cores with two 512-bit FMA
  /// ports (Intel's) that gains 10-20 % on the large layers; Zen 4's one port runs the L2-resident
  /// layers 1-3 % slower with it.
  bool gemm_f32_b_prefetch = true;
};

/// The row of `uarch` (every Uarch has one).
const KernelTuning& kernel_tuning(Uarch uarch);

}  // namespace act::kernels
