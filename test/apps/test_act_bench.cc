// act_bench: its JSON holds every number, and the numbers are consistent with each other and with
// the model (never asserted against wall-clock limits).
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>
#include <set>

#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "actengine/convert.h"
#include "apps/bench_support.h"
#include "apps/op_profile_report.h"
#include "apps/pi5_estimate.h"
#include "graph/thread_pool.h"
#include "support/command.h"
#include "support/test_paths.h"
#include "weights/import/lerobot_import.h"
#include "weights/import/synthetic_model.h"

namespace act {
namespace {

using test::q;
using test::run_command;

void expect_consistent_summary(const nlohmann::json& s, size_t runs, const std::string& what) {
  EXPECT_EQ(s.at("count").get<size_t>(), runs) << what;
  const double min = s.at("min"), p50 = s.at("p50"), p90 = s.at("p90"), p95 = s.at("p95"), p99 = s.at("p99"), max = s.at("max");
  EXPECT_LE(min, p50) << what;
  EXPECT_LE(p50, p90) << what;
  EXPECT_LE(p90, p95) << what;
  EXPECT_LE(p95, p99) << what;
  EXPECT_LE(p99, max) << what;
  EXPECT_LE(min, s.at("mean").get<double>()) << what;
  EXPECT_LE(s.at("mean").get<double>(), max) << what;
  EXPECT_GE(s.at("std").get<double>(), 0.0) << what;
}

TEST(ActBench, BuiltInModelJsonIsCompleteAndConsistent) {
  const std::string dir = test::scratch_dir();
  const auto r = run_command(std::string(ACT_BENCH_BIN) + " --config 64x96 -n 4 -w 1 -t 1 --json " + q(dir + "/b.json") +
                             " --csv " + q(dir + "/b.csv"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("p99"), std::string::npos);
  std::ifstream in(dir + "/b.json");
  const nlohmann::json j = nlohmann::json::parse(in);

  // The MAC count is the model's.
  const double expected_gmac = lerobot_model_config(synthetic_config("64x96"), "test").macs().total() / 1e9;
  EXPECT_NEAR(j["model"]["gmac"]["total"].get<double>(), expected_gmac, 1e-9 * expected_gmac);
  double parts = 0;
  for (const char* p : {"backbone", "projections", "encoder", "decoder", "head"}) parts += j["model"]["gmac"][p].get<double>();
  EXPECT_NEAR(parts, expected_gmac, 1e-9 * expected_gmac);
  EXPECT_EQ(j["model"]["config"]["cameras"][0]["width"], 96);
  EXPECT_EQ(j["model"]["config"]["cameras"][0]["height"], 64);
  EXPECT_GT(j["model"]["weight_bytes"].get<double>(), 1e6);
  EXPECT_EQ(j["engine"]["threads"], 1);

  const size_t runs = j["runs"]["timed"];
  EXPECT_EQ(runs, 4u);
  const auto& lat = j["latency_ms"];
  for (const char* stage : {"preprocess", "backbone", "encoder", "decoder", "other", "total"}) {
    expect_consistent_summary(lat.at(stage), runs, stage);
  }
  // Stage times add up to the total (each run's "other" is what the named stages leave).
  double sum = 0;
  for (const char* stage : {"preprocess", "backbone", "encoder", "decoder", "other"}) sum += lat[stage]["mean"].get<double>();
  EXPECT_NEAR(sum, lat["total"]["mean"].get<double>(), 1e-6 * lat["total"]["mean"].get<double>());
  const double mean_s = lat["total"]["mean"].get<double>() / 1e3;
  EXPECT_NEAR(j["throughput_per_s"].get<double>(), 1.0 / mean_s, 1e-9 / mean_s);
  EXPECT_NEAR(j["achieved_gmac_per_s"].get<double>(), expected_gmac / mean_s, 1e-6 * expected_gmac / mean_s);
  EXPECT_GT(j["peak_rss_bytes"].get<double>(), 0.0);
  // The engine's memory in huge pages: whole 2 MB pages, part of the resident set.
  const auto huge = j["huge_page_bytes"].get<uint64_t>();
  EXPECT_EQ(huge % (uint64_t{2} << 20), 0u) << huge;
  EXPECT_LE(static_cast<double>(huge), j["peak_rss_bytes"].get<double>());
  EXPECT_NE(r.output.find("in huge pages"), std::string::npos) << r.output;
  // % of peak is the achieved rate over the peak of the engine's threads (the probe on each at once),
  // the higher of the probe's readings before and after the timed runs.
  if (j["peak"]["gmac_per_s"].get<double>() > 0) {
    const double before = j["peak"]["gmac_per_s_before_runs"], after = j["peak"]["gmac_per_s_after_runs"];
    EXPECT_GT(before, 0.0);
    EXPECT_GT(after, 0.0);
    EXPECT_EQ(j["peak"]["gmac_per_s"].get<double>(), std::max(before, after));
    EXPECT_EQ(j["peak"]["threads"], 1);
    EXPECT_DOUBLE_EQ(j["peak"]["gmac_per_s_per_core"].get<double>(), j["peak"]["gmac_per_s"].get<double>());
    EXPECT_NE(r.output.find("the probe read"), std::string::npos) << r.output;
    const double want = 100.0 * j["achieved_gmac_per_s"].get<double>() / j["peak"]["gmac_per_s"].get<double>();
    EXPECT_NEAR(j["peak"]["percent_of_peak"].get<double>(), want, 1e-6 * want);
    // ... and at the median run: the GMAC over the total's p50.
    const double want_p50 = 100.0 * expected_gmac / (lat["total"]["p50"].get<double>() / 1e3) /
                            j["peak"]["gmac_per_s"].get<double>();
    EXPECT_NEAR(j["peak"]["percent_of_peak_p50"].get<double>(), want_p50, 1e-6 * want_p50);
    EXPECT_EQ(j["peak"]["kind"], "fp32");
    // Per stage the same at its median run, over the MACs it runs: the camera projections with the
    // backbone, the action head with the decoder; the stages' MACs are the model's.
    const auto& gmac = j["model"]["gmac"];
    const std::pair<const char*, double> stage_gmac[] = {
        {"backbone", gmac["backbone"].get<double>() + gmac["projections"].get<double>()},
        {"encoder", gmac["encoder"].get<double>()},
        {"decoder", gmac["decoder"].get<double>() + gmac["head"].get<double>()},
        {"total", expected_gmac}};
    double stage_sum = 0;
    for (const auto& [stage, want_gmac] : stage_gmac) {
      EXPECT_NEAR(lat[stage]["gmac"].get<double>(), want_gmac, 1e-9 * want_gmac) << stage;
      if (std::string(stage) != "total") stage_sum += lat[stage]["gmac"].get<double>();
      const double want_pct = 100.0 * want_gmac / (lat[stage]["p50"].get<double>() / 1e3) /
                              j["peak"]["gmac_per_s"].get<double>();
      EXPECT_NEAR(lat[stage]["percent_of_peak_p50"].get<double>(), want_pct, 1e-6 * want_pct) << stage;
    }
    EXPECT_NEAR(stage_sum, expected_gmac, 1e-9 * expected_gmac) << "every MAC in one stage";
    EXPECT_NEAR(lat["total"]["percent_of_peak_p50"].get<double>(), want_p50, 1e-6 * want_p50);
    for (const char* stage : {"preprocess", "other"}) EXPECT_FALSE(lat[stage].contains("percent_of_peak_p50")) << stage;
    EXPECT_NE(r.output.find("peak@p50"), std::string::npos) << r.output;
  }
  EXPECT_FALSE(j["machine"]["cpu_model"].get<std::string>().empty());
  EXPECT_GE(j["machine"]["online_cores"].get<int>(), 1);
  EXPECT_GE(j["init"]["first_inference_ms"].get<double>(), 0.0);

  // CSV: a header and one row per timed run, whose totals match the JSON's extremes.
  std::ifstream csv(dir + "/b.csv");
  std::string line;
  std::getline(csv, line);
  EXPECT_EQ(line, "run,preprocess_ms,backbone_ms,encoder_ms,decoder_ms,other_ms,total_ms");
  size_t rows = 0;
  double max_total = 0;
  while (std::getline(csv, line)) {
    ++rows;
    max_total = std::max(max_total, std::stod(line.substr(line.rfind(',') + 1)));
  }
  EXPECT_EQ(rows, runs);
  EXPECT_NEAR(max_total, lat["total"]["max"].get<double>(), 1e-3);
}

TEST(ActBench, BuiltInInt8AndCompare) {
  const std::string dir = test::scratch_dir();
  const auto r = run_command(std::string(ACT_BENCH_BIN) + " --config 64x96 --precision int8 --compare -n 3 -w 0 -t 1 --json " +
                             q(dir + "/c.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("the speed of fp32"), std::string::npos) << r.output;
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(dir + "/c.json"));
  EXPECT_EQ(j["model"]["precision"], "int8 static");
  EXPECT_NE(j["engine"]["kernels"].get<std::string>().find("gemm_s8"), std::string::npos);
  const auto& c = j["compare"];
  EXPECT_EQ(c["other_precision"], "fp32");
  expect_consistent_summary(c["other_latency_ms"], 3, "fp32 total");
  const double ratio = c["other_latency_ms"]["mean"].get<double>() / j["latency_ms"]["total"]["mean"].get<double>();
  EXPECT_NEAR(c["speed_ratio"].get<double>(), ratio, 1e-9 * ratio);
  // INT8 and FP32 of the same model agree closely, but not exactly (else nothing was quantized).
  EXPECT_GT(c["action_max_abs"].get<double>(), 0.0);
  EXPECT_LE(c["action_mse"].get<double>(), 1e-3);
  EXPECT_LE(c["action_max_abs"].get<double>(), 0.1);
}

// --save-model writes the blob the built-in run benchmarks: the saved FP32 blob's actions are the
// in-process model's exactly, and the saved INT8 blob against it differs from FP32 exactly as the
// built-in --compare run's INT8 does (same inputs, same quantization).
TEST(ActBench, SaveModelWritesTheBuiltInBlob) {
  const std::string dir = test::scratch_dir();
  const std::string bench = std::string(ACT_BENCH_BIN) + " --config 64x96 -t 1 ";
  for (const char* precision : {"fp32", "int8"}) {
    const auto r = run_command(bench + "--precision " + precision + " --save-model " + q(dir + "/" + precision + ".actb"));
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_NE(r.output.find("wrote " + dir + "/" + precision + ".actb"), std::string::npos) << r.output;
  }
  auto model = import_synthetic_model("64x96", 1);
  ASSERT_TRUE(model.ok()) << model.status().to_string();
  ASSERT_TRUE((*model)->write_fp32(dir + "/ref.actb").ok());
  const auto compare = [&](const std::string& blob, const std::string& other, const std::string& json) {
    const auto r = run_command(std::string(ACT_BENCH_BIN) + " -m " + q(dir + "/" + blob) + " --compare --compare-with " +
                               q(dir + "/" + other) + " -n 2 -w 0 -t 1 --json " + q(dir + "/" + json));
    EXPECT_EQ(r.exit_code, 0) << r.output;
    return nlohmann::json::parse(std::ifstream(dir + "/" + json))["compare"];
  };
  const nlohmann::json same = compare("fp32.actb", "ref.actb", "same.json");
  EXPECT_EQ(same["action_max_abs"].get<double>(), 0.0);
  const nlohmann::json saved = compare("int8.actb", "fp32.actb", "saved.json");
  const auto r = run_command(bench + "--precision int8 --compare -n 2 -w 0 --json " + q(dir + "/builtin.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json builtin = nlohmann::json::parse(std::ifstream(dir + "/builtin.json"))["compare"];
  EXPECT_GT(saved["action_max_abs"].get<double>(), 0.0);
  EXPECT_EQ(saved["action_max_abs"].get<double>(), builtin["action_max_abs"].get<double>());
  EXPECT_EQ(saved["action_mse"].get<double>(), builtin["action_mse"].get<double>());
  // It times nothing, so the timing outputs are refused.
  const auto refused = run_command(bench + "--save-model " + q(dir + "/x.actb") + " --json " + q(dir + "/x.json"));
  EXPECT_NE(refused.exit_code, 0);
  EXPECT_NE(refused.output.find("--save-model writes the built-in model and times nothing: drop --json"), std::string::npos)
      << refused.output;
}

// --op_profiling: a row per op whose shares add up, kinds that cover every op, the same in the
// JSON; --trace: a Chrome trace with a lane per thread. (--enable_op_profiling is TFLite's name.)
TEST(ActBench, OpProfileAndTrace) {
  const std::string dir = test::scratch_dir();
  const auto r = run_command(std::string(ACT_BENCH_BIN) + " --config 64x96 --precision int8 -n 2 -w 0 -t 2 " +
                             "--enable_op_profiling --json " + q(dir + "/p.json") + " --trace " + q(dir + "/t.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* section : {"op profile", "top 10 ops by median time", "by kind", "gemm_s8"}) {
    EXPECT_NE(r.output.find(section), std::string::npos) << section << "\n" << r.output;
  }
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(dir + "/p.json"));
  // Two threads' peak: the probe on two threads at once (on as many cores as there are).
  const int probe_threads = std::min(2, ThreadPool::hardware_threads());
  EXPECT_EQ(j["peak"]["threads"], probe_threads);
  EXPECT_NEAR(j["peak"]["gmac_per_s_per_core"].get<double>() * probe_threads, j["peak"]["gmac_per_s"].get<double>(),
              1e-9 * j["peak"]["gmac_per_s"].get<double>());
  const auto& profile = j.at("op_profile");
  double percent = 0, ms = 0;
  for (const auto& op : profile.at("ops")) {
    EXPECT_EQ(op.at("runs"), 2);
    // The median of two runs is their mean: the per-run times add up to the engine's sums.
    EXPECT_NEAR(op.at("p50_ms").get<double>(), op.at("mean_ms").get<double>(), 1e-9 + 1e-9 * op.at("mean_ms").get<double>());
    percent += op.at("percent").get<double>();
    ms += op.at("mean_ms").get<double>();
  }
  EXPECT_NEAR(percent, 100.0, 1e-6);
  EXPECT_NEAR(ms, profile.at("total_ms").get<double>(), 1e-9 * ms);
  EXPECT_LE(ms, j["latency_ms"]["total"]["mean"].get<double>()) << "the ops run inside the inference";
  int kind_ops = 0;
  for (const auto& kind : profile.at("kinds")) kind_ops += kind.at("ops").get<int>();
  EXPECT_EQ(kind_ops, static_cast<int>(profile.at("ops").size()));
  const nlohmann::json trace = nlohmann::json::parse(std::ifstream(dir + "/t.json"));
  std::set<int> lanes;
  for (const auto& ev : trace.at("traceEvents")) lanes.insert(ev.at("tid").get<int>());
  EXPECT_EQ(lanes, (std::set<int>{0, 1}));
}

// FP32 as a user runs it: the ResNet blocks' 3x3 stride-1 convs profile as Winograd, the stem and
// the strided convs stay direct, and the output says why the shares can pass 100 %.
TEST(ActBench, Fp32RunsTheBlocks3x3ConvsAsWinograd) {
  const std::string dir = test::scratch_dir();
  const auto r = run_command(std::string(ACT_BENCH_BIN) + " --config 64x96 --precision fp32 -n 1 -w 0 -t 1 " +
                             "--enable_op_profiling --json " + q(dir + "/p.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("run as Winograd F(2x2,3x3)"), std::string::npos) << r.output;
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(dir + "/p.json"));
  int winograd = 0, direct = 0;
  for (const auto& op : j.at("op_profile").at("ops")) {
    const std::string kind = op.at("kind");
    if (kind == "conv2d_f32_winograd") ++winograd;
    if (kind.rfind("conv2d_f32", 0) == 0 && kind != "conv2d_f32_winograd") ++direct;
  }
  EXPECT_EQ(winograd, 13) << "resnet18's 3x3 stride-1 convs";
  EXPECT_EQ(direct, 7) << "the stem, three strided 3x3 and three 1x1 downsamples";
}

// The table's arithmetic on a profile made by hand.
TEST(OpProfileTable, MeansSharesRatesAndKinds) {
  const std::vector<OpProfile> profile = {{"a", "conv", "k1", "backbone", 1e6, 2, 4.0},
                                          {"b", "conv", "k1", "backbone", 3e6, 2, 2.0},
                                          {"c", "norm", "k2", "encoder", 0.0, 2, 2.0}};
  const OpProfileTable t = OpProfileTable::make(profile, 10.0);
  EXPECT_DOUBLE_EQ(t.total_ms, 4.0);
  ASSERT_EQ(t.ops.size(), 3u);
  EXPECT_DOUBLE_EQ(t.ops[0].mean_ms, 2.0);
  EXPECT_DOUBLE_EQ(t.ops[0].percent, 50.0);
  EXPECT_DOUBLE_EQ(t.ops[0].gmacs_per_s, 0.5);  // 1e6 MAC in 2 ms
  EXPECT_DOUBLE_EQ(t.ops[0].percent_of_peak, 5.0);
  EXPECT_DOUBLE_EQ(t.ops[1].gmacs_per_s, 3.0);
  EXPECT_DOUBLE_EQ(t.ops[2].gmacs_per_s, 0.0);
  ASSERT_EQ(t.kinds.size(), 2u);
  EXPECT_EQ(t.kinds[0].kind, "conv");
  EXPECT_EQ(t.kinds[0].ops, 2);
  EXPECT_DOUBLE_EQ(t.kinds[0].mean_ms, 3.0);
  EXPECT_DOUBLE_EQ(t.kinds[0].percent, 75.0);
  EXPECT_DOUBLE_EQ(t.kinds[0].gmacs_per_s, 4e6 / 3e6);
  const auto top = t.top(2);
  ASSERT_EQ(top.size(), 2u);
  EXPECT_EQ(top[0].name, "a");
  EXPECT_EQ(top[1].name, "b");
  EXPECT_DOUBLE_EQ(OpProfileTable::make(profile, 0.0).ops[0].percent_of_peak, 0.0) << "no peak, no % of peak";

  // With per-run times: medians, the rates at the median, the top by median.
  const OpProfileTable m = OpProfileTable::make(profile, 10.0, {{1.0, 5.0, 3.0}, {0.5, 1.5}, {}});
  EXPECT_DOUBLE_EQ(m.ops[0].p50_ms, 3.0);
  EXPECT_DOUBLE_EQ(m.ops[1].p50_ms, 1.0);
  EXPECT_DOUBLE_EQ(m.ops[2].p50_ms, 1.0) << "no runs given: the mean";
  EXPECT_DOUBLE_EQ(m.ops[0].mean_ms, 2.0) << "the mean stays the engine's";
  EXPECT_DOUBLE_EQ(m.ops[0].gmacs_per_s, 1e6 / 3e6);
  EXPECT_DOUBLE_EQ(m.kinds[0].p50_ms, 4.0);
}

// --target pi5: the Pi 5 estimate alone, nothing timed, INT8 for a built-in model; positive, never
// slower on more cores, smaller for the rover's smaller image, labelled an estimate, and the JSON a
// record of the numbers table (scripts/perf_table.py).
// The estimate's arithmetic: each kind's MACs at its unit's projected rate (attention plus its
// softmax per score), ops without MACs left to the overhead factor, cores by the parallel efficiency.
TEST(Pi5Estimate, MacsPerKindAtTheProjectedRates) {
  const std::vector<OpProfile> ops = {{"a", "conv2d_s8_s8", "k", "backbone", 2e9, 0, 0},
                                      {"b", "conv2d_s8_s8", "k", "backbone", 1e9, 0, 0},
                                      {"c", "linear_f32", "k", "decoder", 1e8, 0, 0},
                                      {"d", "attention_s8", "k", "encoder", 2.0 * 64 * 1e6, 0, 0},
                                      {"e", "layernorm_f32", "k", "encoder", 0, 0, 0},
                                      {"f", "conv2d_f32_winograd", "k", "backbone", 9e8, 0, 0}};
  const Pi5Rates& r = pi5_rates();
  const Pi5Estimate e = Pi5Estimate::of(ops, 64);
  ASSERT_EQ(e.kinds.size(), 4u);  // the layer norm has no MACs
  EXPECT_EQ(e.kinds[0].kind, "conv2d_s8_s8");
  EXPECT_EQ(e.kinds[0].unit, "sdot");
  const double hz = r.clock_ghz * 1e9;
  EXPECT_NEAR(e.kinds[0].ms_one_core, 3e9 / (r.sdot_macs_per_cycle * r.sdot_efficiency) / hz * 1e3, 1e-9);
  for (const Pi5KindCost& k : e.kinds) {
    if (k.kind == "linear_f32") {
      EXPECT_EQ(k.unit, "fmla");
      EXPECT_NEAR(k.ms_one_core, 1e8 / (r.fmla_macs_per_cycle * r.fmla_efficiency) / hz * 1e3, 1e-9);
    }
    if (k.kind == "conv2d_f32_winograd") {  // 16 of the direct conv's 36 multiply-adds
      EXPECT_EQ(k.unit, "fmla");
      EXPECT_NEAR(k.ms_one_core, 9e8 * 16 / 36 / (r.fmla_macs_per_cycle * r.fmla_efficiency) / hz * 1e3, 1e-9);
    }
    if (k.kind == "attention_s8") {  // 1e6 scores of 2 x 64 MACs, each with its softmax
      EXPECT_GT(k.ms_one_core, 2.0 * 64 * 1e6 / (r.sdot_macs_per_cycle * r.sdot_efficiency) / hz * 1e3);
    }
  }
  ASSERT_EQ(e.latency_ms.size(), 4u);
  EXPECT_NEAR(e.latency_ms[0], e.kernel_ms_one_core * r.other_ops_factor, 1e-9);
  for (size_t c = 1; c < 4; ++c) EXPECT_LT(e.latency_ms[c], e.latency_ms[c - 1]);
  EXPECT_GT(e.latency_ms[3], e.latency_ms[0] / 4);  // never better than linear
  EXPECT_NE(Pi5Estimate::method().find("llvm-mca -mcpu=cortex-a76"), std::string::npos);
}

TEST(ActBench, TargetPi5EstimatesTheDefaultAndRoverModels) {
  const std::string dir = test::scratch_dir();
  std::map<std::string, double> four_cores;
  for (const std::string config : {"default", "rover"}) {
    const std::string json_path = dir + "/" + config + ".json";
    const auto r = run_command(std::string(ACT_BENCH_BIN) + " --config " + config + " --target pi5 -t 2 --json " + q(json_path));
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_NE(r.output.find("int8 static on a Raspberry Pi 5 (4x Cortex-A76, 2.4 GHz), ESTIMATED: 1 core "), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("estimate, not a measurement"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("llvm-mca -mcpu=cortex-a76"), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find("timed runs"), std::string::npos) << r.output;
    std::ifstream in(json_path);
    const nlohmann::json j = nlohmann::json::parse(in);
    EXPECT_TRUE(j.at("estimate").get<bool>());
    EXPECT_EQ(j.at("model").at("precision"), "int8 static");
    const nlohmann::json& e = j.at("pi5_estimate");
    EXPECT_TRUE(e.at("estimate").get<bool>());
    double previous = 0;
    for (const std::string cores : {"1", "2", "3", "4"}) {
      const double ms = e.at("latency_ms_by_cores").at(cores);
      EXPECT_GT(ms, 0) << config << " " << cores;
      if (previous > 0) {
        EXPECT_LT(ms, previous) << config << ": " << cores << " cores slower than fewer";
      }
      previous = ms;
    }
    EXPECT_DOUBLE_EQ(j.at("latency_ms").at("total").at("p50").get<double>(), previous);
    EXPECT_EQ(j.at("engine").at("threads"), 4);
    double kinds_ms = 0;
    for (const auto& kind : e.at("kinds")) kinds_ms += kind.at("ms_one_core").get<double>();
    EXPECT_NEAR(kinds_ms, e.at("kernel_ms_one_core").get<double>(), 1e-9 * kinds_ms);
    four_cores[config] = previous;
  }
  EXPECT_LT(four_cores["rover"], four_cores["default"]);
  // Beside the measured numbers on any machine, in the text and the JSON.
  const auto measured = run_command(std::string(ACT_BENCH_BIN) + " --config 64x96 -n 1 -w 0 -t 1 --json " + q(dir + "/here.json"));
  ASSERT_EQ(measured.exit_code, 0) << measured.output;
  EXPECT_NE(measured.output.find("pi5 estimate fp32 on a Raspberry Pi 5"), std::string::npos) << measured.output;
  std::ifstream in(dir + "/here.json");
  EXPECT_GT(nlohmann::json::parse(in).at("pi5_estimate").at("latency_ms_by_cores").at("4").get<double>(), 0);
  // Timed options do not go with it.
  const auto refused = run_command(std::string(ACT_BENCH_BIN) + " --target pi5 --compare");
  EXPECT_EQ(refused.exit_code, 1);
  EXPECT_NE(refused.output.find("--compare needs timed runs; --target pi5 times nothing"), std::string::npos) << refused.output;
}

TEST(ActBench, CompareWithABlobNeedsTheOtherPrecision) {
  const std::string fixture = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(fixture);
  const std::string dir = test::scratch_dir();
  write_fp32_blob(import_lerobot_checkpoint(fixture), dir + "/tiny.actb");
  auto r = run_command(std::string(ACT_BENCH_BIN) + " -m " + q(dir + "/tiny.actb") + " --compare -n 1");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("--compare-with"), std::string::npos) << r.output;
  r = run_command(std::string(ACT_BENCH_BIN) + " -m " + q(dir + "/tiny.actb") + " --precision int8 -n 1");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("built-in"), std::string::npos) << r.output;
}

TEST(ActBench, BlobWithRealObservations) {
  const std::string fixture = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(fixture);
  const std::string dir = test::scratch_dir();
  write_fp32_blob(import_lerobot_checkpoint(fixture), dir + "/tiny.actb");
  const auto r = run_command(std::string(ACT_BENCH_BIN) + " -m " + q(dir + "/tiny.actb") + " --input " +
                             q(fixture + "/reference.safetensors") + " -n 3 --json " + q(dir + "/b.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream in(dir + "/b.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j["model"]["source"], "blob");
  EXPECT_NEAR(j["model"]["gmac"]["total"].get<double>(), 0.446056832, 1e-9);
}

// --config is HxW, height first, as every other tool; a size higher than wide was act_bench's old
// WxH order for a landscape camera, so it is refused with the fix unless --portrait says it is meant.
TEST(ActBench, ConfigIsHeightByWidthAndRefusesTheTransposedForm) {
  const std::string dir = test::scratch_dir();
  auto r = run_command(std::string(ACT_BENCH_BIN) + " --config 160x120 -n 1");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("--config 160x120 is HxW (height first"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("For a camera 160 wide and 120 high give --config 120x160; for a portrait camera add --portrait"),
            std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("stage (ms)"), std::string::npos) << "benchmarked:\n" << r.output;
  r = run_command(std::string(ACT_BENCH_BIN) + " --config 96x64 --portrait -n 1 -w 0 -t 1 --json " + q(dir + "/p.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream in(dir + "/p.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j["model"]["config"]["cameras"][0]["height"], 96);
  EXPECT_EQ(j["model"]["config"]["cameras"][0]["width"], 64);
  r = run_command(std::string(ACT_BENCH_BIN) + " --help");
  EXPECT_NE(r.output.find("120x160 = 120 high, 160 wide"), std::string::npos) << r.output;
  r = run_command(std::string(ACT_BENCH_BIN) + " --config rover --portrait -n 1");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("--portrait goes with --config HxW"), std::string::npos) << r.output;
}

// ACT_UARCH as a user sets it: the kernels line and the JSON name the tuning; an unknown one is an
// error naming the variable and the choices, before anything is timed.
TEST(ActBench, ActUarchChoosesTheTuningAndRefusesUnknownNames) {
  const std::string dir = test::scratch_dir();
  const std::string bench = std::string(ACT_BENCH_BIN) + " --config 64x96 -n 1 -w 0 -t 1";
  auto r = run_command("ACT_UARCH=gracemont " + bench + " --json " + q(dir + "/g.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find(", tuned for gracemont: gemm_s8 "), std::string::npos) << r.output;
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(dir + "/g.json"));
  EXPECT_NE(j["engine"]["kernels"].get<std::string>().find(", tuned for gracemont: "), std::string::npos);
  r = run_command("ACT_UARCH=zen9 " + bench);
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("ACT_UARCH: unknown tuning 'zen9': choose auto or one of generic, zen4"), std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("stage (ms)"), std::string::npos) << "benchmarked first:\n" << r.output;
}

TEST(ActBench, BadArgumentsAreClearErrors) {
  const std::string dir = test::scratch_dir();
  auto r = run_command(std::string(ACT_BENCH_BIN) + " --config 12345");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("12345"), std::string::npos) << r.output;
  r = run_command(std::string(ACT_BENCH_BIN) + " -m " + q(dir + "/none.actb"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("none.actb"), std::string::npos) << r.output;
  // An output that cannot be written fails before the benchmark, not silently after it.
  for (const char* flag : {"--json", "--csv", "--trace"}) {
    r = run_command(std::string(ACT_BENCH_BIN) + " --num_runs 1 " + flag + " " + q(dir + "/missing/out"));
    EXPECT_EQ(r.exit_code, 1) << flag << "\n" << r.output;
    EXPECT_NE(r.output.find(dir + "/missing/out"), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find("stage (ms)"), std::string::npos) << "benchmarked first:\n" << r.output;
  }
  r = run_command(std::string(ACT_BENCH_BIN) + " --num_runs 0");
  EXPECT_NE(r.exit_code, 0);
  r = run_command(std::string(ACT_BENCH_BIN) + " --help");
  EXPECT_EQ(r.exit_code, 0);
  for (const char* flag : {"--warmup_runs", "--num_runs", "--max_secs", "--threads", "--num_threads", "--graph", "--json",
                           "--csv", "--config"}) {
    EXPECT_NE(r.output.find(flag), std::string::npos) << flag;
  }
}

TEST(ActBench, TfliteNamesAndTooManyThreads) {
  const std::string dir = test::scratch_dir();
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  ASSERT_EQ(run_command(std::string(ACT_CONVERT_BIN) + " " + q(test::fixture_dir("act-tiny")) + " -q -o " + q(dir + "/tiny.actb")).exit_code, 0);
  // benchmark_model's names: --graph, --num_threads, --num_runs, --warmup_runs.
  auto r = run_command(std::string(ACT_BENCH_BIN) + " --graph " + q(dir + "/tiny.actb") +
                       " --num_threads 1 --num_runs 2 --warmup_runs 0 --json " + q(dir + "/b.json"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream in(dir + "/b.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j["model"]["source"], "blob");
  EXPECT_EQ(j["engine"]["threads"], 1);
  EXPECT_EQ(j["runs"]["timed"], 2);
  EXPECT_EQ(j["runs"]["warmup"], 0);
  EXPECT_EQ(r.output.find("more than the"), std::string::npos) << r.output;
  // More threads than online cores: a warning saying how many there are.
  const long cores = ::sysconf(_SC_NPROCESSORS_ONLN);
  r = run_command(std::string(ACT_BENCH_BIN) + " --graph " + q(dir + "/tiny.actb") + " --num_threads " +
                  std::to_string(cores + 1) + " --num_runs 1");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("warning: --threads " + std::to_string(cores + 1) + " is more than the " + std::to_string(cores) +
                          " online cores"), std::string::npos) << r.output;
}

TEST(DetectEmulation, QemuUsersTracesAndNativeRuns) {
  // What qemu-aarch64 7.2 on an x86-64 host shows an ARM program (this machine, measured).
  const std::string host_maps =
      "5500000000-5500001000 r-xp 00000000 fe:00 10954828                       /usr/bin/act_bench\n"
      "562c9a3e6000-562c9a69e000 r-xp 00099000 fe:00 10977375                   /usr/bin/qemu-aarch64\n";
  const std::string x86_cpuinfo = "processor\t: 0\nvendor_id\t: AuthenticAMD\nmodel name\t: AMD EPYC\nflags\t\t: fpu avx2\n";
  const std::string arm_cpuinfo = "processor\t: 0\nBogoMIPS\t: 108.00\nFeatures\t: fp asimd asimddp\nCPU implementer\t: 0x41\n";
  EXPECT_EQ(detect_emulation(host_maps, "", "act_bench"), "qemu-user: /usr/bin/qemu-aarch64 is mapped into this process");
  EXPECT_EQ(detect_emulation("", "", "qemu-aarch64"), "qemu-user: this process is qemu-aarch64");
#if defined(__x86_64__)
  EXPECT_NE(detect_emulation("", arm_cpuinfo, "act_bench").find("another architecture"), std::string::npos);
  EXPECT_EQ(detect_emulation("", x86_cpuinfo, "act_bench"), "");
#elif defined(__aarch64__)
  EXPECT_NE(detect_emulation("", x86_cpuinfo, "act_bench").find("another architecture"), std::string::npos);
  EXPECT_EQ(detect_emulation("", arm_cpuinfo, "act_bench"), "");
#endif
  // A library whose folder merely has qemu in its name is no emulator.
  EXPECT_EQ(detect_emulation("7f00-7f01 r-xp 0 fe:00 1 /opt/qemu-tools/lib/libz.so.1\n", "", "act_bench"), "");
}

TEST(LatencySummary, PercentilesInterpolateAndOrder) {
  const LatencySummary s = summarize({5, 1, 4, 2, 3});
  EXPECT_EQ(s.count, 5u);
  EXPECT_DOUBLE_EQ(s.min, 1);
  EXPECT_DOUBLE_EQ(s.max, 5);
  EXPECT_DOUBLE_EQ(s.p50, 3);
  EXPECT_DOUBLE_EQ(s.p90, 4.6);
  EXPECT_DOUBLE_EQ(s.mean, 3);
  EXPECT_NEAR(s.stddev, std::sqrt(2.5), 1e-12);
  const LatencySummary one = summarize({7});
  EXPECT_DOUBLE_EQ(one.p99, 7);
  EXPECT_DOUBLE_EQ(one.stddev, 0);
  EXPECT_EQ(summarize({}).count, 0u);
}

TEST(LatencyHistogram, MatchesTheExactSummaryInConstantMemory) {
  // act_drive once kept every latency sample (about 2 MB an hour at 30 Hz): the histogram must give
  // the same summary without them. Log-normal latencies around 20 ms, with a few 1-second outliers.
  std::mt19937 rng(7);
  std::lognormal_distribution<double> latency(std::log(20.0), 0.4);
  std::vector<double> samples;
  LatencyHistogram histogram;
  for (int i = 0; i < 100000; ++i) {
    const double v = i % 5000 == 0 ? 1000.0 : latency(rng);
    samples.push_back(v);
    histogram.add(v);
  }
  const LatencySummary exact = summarize(samples), approx = histogram.summary();
  EXPECT_EQ(approx.count, exact.count);
  EXPECT_DOUBLE_EQ(approx.min, exact.min);
  EXPECT_DOUBLE_EQ(approx.max, exact.max);
  EXPECT_NEAR(approx.mean, exact.mean, 1e-9 * exact.mean);
  EXPECT_NEAR(approx.stddev, exact.stddev, 1e-6 * exact.stddev);
  for (const auto& [a, e] : {std::pair{approx.p50, exact.p50}, std::pair{approx.p90, exact.p90},
                             std::pair{approx.p95, exact.p95}, std::pair{approx.p99, exact.p99}}) {
    EXPECT_NEAR(a, e, 0.01 * e);
  }
  EXPECT_LE(approx.p50, approx.p90);
  EXPECT_LE(approx.p99, approx.max);
  histogram.clear();
  EXPECT_EQ(histogram.summary().count, 0u);
  histogram.add(0.0);  // below the first bin edge: still counted, percentiles clamped to [min, max]
  histogram.add(0.0);
  histogram.add(5e7);  // above the last one
  EXPECT_EQ(histogram.summary().count, 3u);
  EXPECT_DOUBLE_EQ(histogram.summary().p99, 5e7);
  EXPECT_DOUBLE_EQ(histogram.summary().p50, 0.0);
}

}  // namespace
}  // namespace act
