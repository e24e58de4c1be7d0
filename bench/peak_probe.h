// Register-only throughput probes of the INT8 multiply-accumulate instructions: tight loops of
// independent instructions with no memory traffic, giving this core's measured peak to compare
// the GEMM kernels against. Each returns the int8 MACs performed (0 when not built for this target).
// `iterations` must be at least 1.
#pragma once

#include <cstdint>

namespace act::bench {

/// 16 independent vpdpbusd zmm chains per iteration (64 MACs each). AVX-512 VNNI.
uint64_t peak_vpdpbusd_zmm(uint64_t iterations);
/// 12 independent vpmaddwd ymm chains per iteration (16 int16 MACs each). AVX2.
uint64_t peak_vpmaddwd_ymm(uint64_t iterations);
/// 8 vpmaddwd + vpaddd accumulate pairs per iteration: the AVX2 kernel's actual idiom.
uint64_t peak_vpmaddwd_vpaddd_ymm(uint64_t iterations);
/// 16 independent sdot (by element) chains per iteration (16 MACs each). AArch64 dotprod.
uint64_t peak_sdot(uint64_t iterations);

}  // namespace act::bench
