// The peak of T of the engine's threads: a peak probe (kernels/peak/peak_probe.h) run on T threads
// at once, their readings summed. One core's reading times T overstates it wherever cores share a
// clock budget (all-core turbo), an SMT core, or a host's uneven vCPUs (this workplace's 2-vCPU EPYC
// guests read 425 and 447 GMAC/s on their two vCPUs alone: which one the single probe landed on
// moved two-thread percentages by 2-5 %).
#pragma once

#include "kernels/peak/peak_probe.h"

namespace act::graph {

/// The threads a peak of `threads` is read on: at least one, at most one per online core.
int peak_probe_threads(int threads);

/// Sustained GMAC/s of `threads` threads running `probe` at once (each read as measure_peak_gmacs
/// reads one, by its own CPU time), summed, on peak_probe_threads(threads): more threads than
/// online cores count as the cores, a core's peak is not shared out further. 0 when the probe is
/// not built or the CPU lacks it.
double measure_peak_gmacs_together(const kernels::PeakProbe& probe, int threads);

}  // namespace act::graph
