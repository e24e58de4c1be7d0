// act_bench's Raspberry Pi 5 estimate: a model's latency on the Pi 5's Cortex-A76 cores, projected
// from its MACs per op kind (act::Engine::op_profile) and the NEON kernels' statically projected
// throughput. An estimate, not a measurement: no A76 timed it (docs/arm.md).
#pragma once

#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "actengine/engine.h"

namespace act {

/// The per-op-kind rates the estimate uses: one place, derived as pi5_estimate.cc says.
struct Pi5Rates {
  double clock_ghz;                ///< the Pi 5's Cortex-A76 clock
  double sdot_macs_per_cycle;      ///< one core's SDOT peak (two 128-bit pipes)
  double sdot_efficiency;          ///< the gemm_s8 k loop's projected share of it
  double fmla_macs_per_cycle;      ///< one core's FMLA peak
  double fmla_efficiency;          ///< the gemm_f32 k loop's projected share of it
  double other_ops_factor;         ///< whole inference / time in the ops with MACs
  double parallel_efficiency;      ///< each core's share of the speed-up beyond the first
};
const Pi5Rates& pi5_rates();

/// An op kind (OpProfile::kind) whose convs run as Winograd F(2x2, 3x3): its MACs are the direct
/// conv's, 36 per output tile where Winograd does 16.
bool is_winograd_kind(const std::string& kind);

/// The ops of one kind and what they cost on one A76 core.
struct Pi5KindCost {
  std::string kind;      ///< OpProfile::kind, e.g. "conv2d_s8_s8"
  std::string unit;      ///< "sdot" or "fmla"
  double macs = 0;       ///< per inference
  double ms_one_core = 0;
};

struct Pi5Estimate {
  std::vector<Pi5KindCost> kinds;  ///< the kinds with MACs, most time first
  double kernel_ms_one_core = 0;   ///< the sum over the kinds
  std::vector<double> latency_ms;  ///< [cores - 1], 1..4 cores
  /// One line: how the numbers were made (printed and in the JSON).
  static std::string method();
  /// From the engine's op profile (its kinds and MACs; the times are not used) and the attention's
  /// head dimension (dim_model / n_heads: the MACs of one score).
  static Pi5Estimate of(std::span<const OpProfile> ops, int head_dim);
  nlohmann::ordered_json to_json() const;
};

}  // namespace act
