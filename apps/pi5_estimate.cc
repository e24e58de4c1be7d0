#include "apps/pi5_estimate.h"

#include <algorithm>
#include <cstdio>

namespace act {

// Every number of the estimate, derived here (kernels/README.md has the per-loop table):
//
//   aarch64-linux-gnu-g++ -std=c++20 -O3 -DNDEBUG -ffp-contract=off -march=armv8.2-a+dotprod -I.
//       -c kernels/gemm_s8/gemm_s8_neondot.cc -o gemm_s8_neondot.o     (and kernels/fp32/gemm_f32_neon.cc)
//   aarch64-linux-gnu-objdump -d --no-show-raw-insn -C gemm_s8_neondot.o > gemm_s8_neondot.s
//   python3 bench/tools/count_loop_insns.py gemm_s8_neondot.s --mca cortex-a76 --llvm-mca llvm-mca-14
//
// (GCC 12, LLVM 14's llvm-mca, 200 iterations of each innermost loop, its own branch dropped,
// operands in L1.) gemm_s8's 4x16c4 k loop: 1024 MACs (64 sdot) in 39.1 cycles, 82 % of the A76's
// 32 MACs per cycle (SDOT on both 128-bit pipes). gemm_f32's 8x12 k step: 96 MACs (24 fmla) in 24.1
// cycles, 50 % of 8 MACs per cycle: LLVM 14 schedules -mcpu=cortex-a76 with its Cortex-A57 model,
// one FMLA pipe, so this is the lower bound (LLVM 19's neoverse-n1 model, the A76's server twin,
// gives 94 % and 85 %). Attention adds its softmax per score: 3.2 cycles (int8 codes) or 15 (float,
// the exp's latency) from the same projection of softmax_rows_s8 / softmax_rows_f32, against the
// 2 x head_dim MACs of its two matmuls per score. The ops without MACs (layer norms, quantize,
// pooling, adds) and the tiles' starts and epilogues: the ops with MACs take 90 % of an inference
// on x86 on one thread (act_bench --op_profiling). Cores: two threads ran 1.95x one on x86, taken
// as 95 % of a core per core added. DRAM stalls are left out.
const Pi5Rates& pi5_rates() {
  static const Pi5Rates rates{2.4, 32.0, 0.82, 8.0, 0.50, 1.0 / 0.9, 0.95};
  return rates;
}

namespace {

constexpr double kSoftmaxCyclesPerScoreS8 = 3.2, kSoftmaxCyclesPerScoreF32 = 15.0;
constexpr int kMaxCores = 4;  // the Pi 5's

bool is_int8_kind(const std::string& kind) { return kind.find("s8") != std::string::npos; }
// Winograd F(2x2, 3x3) convs do 16 of the direct conv's 36 multiply-adds per 2x2 output tile.
constexpr double kWinogradMacShare = 16.0 / 36.0;

}  // namespace

bool is_winograd_kind(const std::string& kind) { return kind.ends_with("_winograd"); }

std::string Pi5Estimate::method() {
  const Pi5Rates& r = pi5_rates();
  char text[512];
  std::snprintf(text, sizeof text,
                "estimate, not a measurement: the model's MACs per op kind at the NEON kernels' rates projected by "
                "llvm-mca -mcpu=cortex-a76 on their inner loops (sdot %.0f %% of %.0f MACs/cycle, fmla %.0f %% of %.0f, "
                "attention's softmax added, Winograd convs at 16/36 of their MACs, transforms left out), %.1f GHz, +%.0f %% "
                "for the ops without MACs, %.0f %% per added core; DRAM stalls left out",
                r.sdot_efficiency * 100, r.sdot_macs_per_cycle, r.fmla_efficiency * 100, r.fmla_macs_per_cycle, r.clock_ghz,
                (r.other_ops_factor - 1) * 100, r.parallel_efficiency * 100);
  return text;
}

Pi5Estimate Pi5Estimate::of(std::span<const OpProfile> ops, int head_dim) {
  const Pi5Rates& r = pi5_rates();
  Pi5Estimate e;
  for (const OpProfile& op : ops) {
    if (op.macs <= 0) continue;
    auto it = std::find_if(e.kinds.begin(), e.kinds.end(), [&](const Pi5KindCost& k) { return k.kind == op.kind; });
    if (it == e.kinds.end()) it = e.kinds.insert(e.kinds.end(), {op.kind, is_int8_kind(op.kind) ? "sdot" : "fmla", 0, 0});
    it->macs += op.macs;
  }
  for (Pi5KindCost& k : e.kinds) {
    const bool int8 = k.unit == "sdot";
    const double macs_per_cycle = int8 ? r.sdot_macs_per_cycle * r.sdot_efficiency : r.fmla_macs_per_cycle * r.fmla_efficiency;
    double cycles = k.macs * (is_winograd_kind(k.kind) ? kWinogradMacShare : 1.0) / macs_per_cycle;
    if (k.kind.rfind("attention", 0) == 0 && head_dim > 0) {
      const double scores = k.macs / (2.0 * head_dim);
      cycles += scores * (int8 ? kSoftmaxCyclesPerScoreS8 : kSoftmaxCyclesPerScoreF32);
    }
    k.ms_one_core = cycles / (r.clock_ghz * 1e9) * 1e3;
    e.kernel_ms_one_core += k.ms_one_core;
  }
  std::sort(e.kinds.begin(), e.kinds.end(), [](const Pi5KindCost& a, const Pi5KindCost& b) { return a.ms_one_core > b.ms_one_core; });
  for (int cores = 1; cores <= kMaxCores; ++cores) {
    const double speedup = 1.0 + (cores - 1) * r.parallel_efficiency;
    e.latency_ms.push_back(e.kernel_ms_one_core * r.other_ops_factor / speedup);
  }
  return e;
}

nlohmann::ordered_json Pi5Estimate::to_json() const {
  nlohmann::ordered_json j;
  j["estimate"] = true;
  j["target"] = "Raspberry Pi 5, 4x Cortex-A76";
  j["method"] = method();
  nlohmann::ordered_json latency;
  for (size_t c = 0; c < latency_ms.size(); ++c) latency[std::to_string(c + 1)] = latency_ms[c];
  j["latency_ms_by_cores"] = latency;
  j["kernel_ms_one_core"] = kernel_ms_one_core;
  j["kinds"] = nlohmann::ordered_json::array();
  for (const Pi5KindCost& k : kinds) {
    j["kinds"].push_back({{"kind", k.kind}, {"unit", k.unit}, {"gmac", k.macs / 1e9}, {"ms_one_core", k.ms_one_core}});
  }
  const Pi5Rates& r = pi5_rates();
  j["rates"] = {{"clock_ghz", r.clock_ghz},
                {"sdot_macs_per_cycle", r.sdot_macs_per_cycle},
                {"sdot_efficiency", r.sdot_efficiency},
                {"fmla_macs_per_cycle", r.fmla_macs_per_cycle},
                {"fmla_efficiency", r.fmla_efficiency},
                {"other_ops_factor", r.other_ops_factor},
                {"parallel_efficiency", r.parallel_efficiency}};
  return j;
}

}  // namespace act
