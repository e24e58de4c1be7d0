// act_bench --op_profiling: the engine's per-op profile (act::Engine::op_profile) as a table a
// TFLite benchmark_model user reads at a glance: one row per op in the order they run, the top ops
// by time, and the ops grouped by kind, each with its share of the time and its rate against this
// CPU's peak.
#pragma once

#include <cstdio>
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <vector>

#include "actengine/engine.h"

namespace act {

struct OpProfileRow {
  std::string name, kind, kernel, stage;
  int ops = 1;             ///< ops summed into this row (1, or the ops of one kind)
  int64_t runs = 0;
  double mean_ms = 0;      ///< per inference
  double p50_ms = 0;       ///< the median run (the mean when no per-run times were given)
  double percent = 0;      ///< of the summed op time
  double macs = 0;         ///< per inference
  double gmacs_per_s = 0;  ///< at the median run's time; 0 for ops without dot products
  double percent_of_peak = 0;
};

struct OpProfileTable {
  std::vector<OpProfileRow> ops;    ///< in the order they run
  std::vector<OpProfileRow> kinds;  ///< one row per kind, most time first
  double total_ms = 0;              ///< all ops, per inference

  /// `peak_gmacs_per_s`: this CPU's peak for the engine's threads (0 = unknown: no % of peak);
  /// `run_ms` ([op][run], optional): each op's time in each run, for the medians.
  static OpProfileTable make(std::span<const OpProfile> profile, double peak_gmacs_per_s,
                             const std::vector<std::vector<double>>& run_ms = {});
  /// Ops by median time, most first (at most `n`).
  std::vector<OpProfileRow> top(size_t n) const;
  void print(std::FILE* out, size_t top_n) const;
  nlohmann::ordered_json to_json() const;
};

}  // namespace act
