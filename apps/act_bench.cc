// act_bench: end-to-end latency of an ACT model, the numbers a TFLite or ONNX Runtime user reads at a
// glance. Without --model it builds LeRobot's default ACT in-process (deterministic synthetic weights),
// so a new user sees numbers with nothing to download.
#include <CLI/CLI.hpp>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <memory>
#include <optional>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <random>

#include "actengine/engine.h"
#include "apps/bench_support.h"
#include "apps/convert/int8_conversion.h"
#include "kernels/fp32/gemm_f32.h"
#include "kernels/gemm_s8/gemm_s8.h"
#include "kernels/peak/peak_probe.h"
#include "apps/observation_file.h"
#include "weights/blob/actb.h"
#include "apps/status_error.h"
#include "weights/blob/error.h"
#include "weights/blob/model_config.h"
#include "weights/import/synthetic_model.h"

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

struct Options {
  std::string model;
  std::string config = "default";
  std::string precision = "fp32";
  int threads = 0;
  int warmup_runs = 1;
  int num_runs = 50;
  double max_secs = 150.0;
  std::string json_path, csv_path, input_path;
  bool compare = false;
  std::string compare_with;
  uint32_t seed = 1;
};

double ms_since(Clock::time_point start) { return std::chrono::duration<double, std::milli>(Clock::now() - start).count(); }

// Synthetic observation: a smooth gradient with some texture (not constant, not pure noise), and a
// small state vector; deterministic. `obs` views the vectors (their buffers survive a move).
struct SyntheticInput {
  std::vector<std::vector<uint8_t>> images;
  std::vector<float> state, env;
  act::Observation obs;
};

SyntheticInput make_input(const act::ModelInfo& info) {
  SyntheticInput in;
  std::mt19937 rng(42);
  for (const auto& cam : info.cameras) {
    std::vector<uint8_t> img(static_cast<size_t>(cam.height) * cam.width * 3);
    for (int y = 0; y < cam.height; ++y) {
      for (int x = 0; x < cam.width; ++x) {
        for (int c = 0; c < 3; ++c) {
          const int v = (x * 255 / cam.width + y * 255 / cam.height * (c + 1)) / (c + 2) + static_cast<int>(rng() % 32);
          img[(static_cast<size_t>(y) * cam.width + x) * 3 + c] = static_cast<uint8_t>(std::min(v, 255));
        }
      }
    }
    in.images.push_back(std::move(img));
  }
  in.state.assign(static_cast<size_t>(info.state_dim), 0.1f);
  in.env.assign(static_cast<size_t>(info.env_state_dim), 0.1f);
  for (size_t c = 0; c < info.cameras.size(); ++c) {
    in.obs.images.push_back(act::ImageView::rgb_u8(in.images[c].data(), info.cameras[c].height, info.cameras[c].width));
  }
  in.obs.state = in.state;
  in.obs.env_state = in.env;
  return in;
}

// A temporary blob removed when the benchmark ends (the engine's mapping stays valid after unlink).
struct TempBlob {
  std::string path;
  explicit TempBlob(const std::string& tag)
      : path((fs::temp_directory_path() / ("act_bench_" + std::to_string(::getpid()) + "_" + tag + ".actb")).string()) {}
  ~TempBlob() {
    std::error_code ec;
    fs::remove(path, ec);
  }
};

// The built-in model written as FP32 and (when asked) INT8 static blobs. INT8 is calibrated on a few
// synthetic frames: enough for speed; act_convert with real frames is what gives accuracy.
struct BuiltinBlobs {
  TempBlob fp32{"fp32"}, int8{"int8"};
  bool has_int8 = false;
  std::string int8_note;
};

void build_builtin(const Options& opt, bool want_int8, BuiltinBlobs& out) {
  const act::ImportedModel model = act::make_synthetic_model(opt.config, opt.seed);
  act::write_fp32_blob(model, out.fp32.path);
  if (!want_int8) return;
  const act::ActbFile fp32 = act::ActbFile::open(out.fp32.path);
  const act::CalibSet frames = act::synthetic_calibration_frames(model.config, fp32, 5, opt.seed);
  act::Int8Options int8;
  int8.mode = act::QuantMode::kStatic;
  int8.holdout = 1;
  int8.threads = opt.threads;
  int8.layer_report = false;
  int8.progress = false;
  std::fprintf(stderr, "act_bench: quantizing the built-in model to INT8 (static, calibrated on 4 synthetic frames) ...\n");
  // In a child process, so that the calibration's FP32 run and its buffers do not count in this
  // process's peak RSS. The child reports the held-out error through a pipe.
  int fds[2];
  if (::pipe(fds) != 0) act::fail(act::ErrorCode::kIoError, "pipe() failed");
  const pid_t child = ::fork();
  if (child < 0) act::fail(act::ErrorCode::kIoError, "fork() failed");
  if (child == 0) {
    ::close(fds[0]);
    int code = 0;
    try {
      const act::Int8Result r = act::convert_to_int8(model, out.int8.path, int8, &frames);
      const std::string mse = std::to_string(r.report["action_error"]["mse"].get<double>());
      code = ::write(fds[1], mse.data(), mse.size()) == static_cast<ssize_t>(mse.size()) ? 0 : 1;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "act_bench: error: INT8 conversion failed: %s\n", e.what());
      code = 1;
    }
    ::_exit(code);
  }
  ::close(fds[1]);
  std::string mse;
  char buf[64];
  for (ssize_t n; (n = ::read(fds[0], buf, sizeof buf)) > 0;) mse.append(buf, static_cast<size_t>(n));
  ::close(fds[0]);
  int status = 0;
  ::waitpid(child, &status, 0);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) act::fail(act::ErrorCode::kInternal, "INT8 conversion of the built-in model failed");
  out.has_int8 = true;
  out.int8_note = "INT8 static, mse calibration on 4 synthetic frames (held-out action MSE " + mse + ")";
}

std::unique_ptr<act::Engine> open_engine(const std::string& path, int threads) {
  auto engine_or = act::Engine::open(path, {.threads = threads, .profile = true});
  act::throw_if_failed(engine_or.status());
  return std::move(*engine_or);
}

int run(const Options& opt) {
  if (opt.compare && !opt.model.empty() && opt.compare_with.empty()) {
    act::fail(act::ErrorCode::kInvalidArgument, "--compare with --model needs the other precision's blob: --compare-with OTHER.actb");
  }
  // The model: a blob, or a built-in synthetic one written to a temporary blob.
  std::string blob_path = opt.model, model_label = opt.model, other_path = opt.compare_with;
  double build_ms = 0;
  BuiltinBlobs builtin;
  if (blob_path.empty()) {
    const auto start = Clock::now();
    const bool int8 = opt.precision == "int8";
    build_builtin(opt, int8 || opt.compare, builtin);
    blob_path = int8 ? builtin.int8.path : builtin.fp32.path;
    if (opt.compare) other_path = int8 ? builtin.fp32.path : builtin.int8.path;
    build_ms = ms_since(start);
    model_label = "built-in \"" + opt.config + "\" (synthetic weights, seed " + std::to_string(opt.seed) + ")";
  } else if (opt.precision != "fp32") {
    act::fail(act::ErrorCode::kInvalidArgument, "--precision chooses among the built-in models; a blob has its own precision");
  }
  const act::ActbFile blob_file = act::ActbFile::open(blob_path);
  const act::ModelConfig config = act::ModelConfig::from_json(blob_file.config());
  const size_t weight_bytes = blob_file.file_size();

  const auto load_start = Clock::now();
  std::unique_ptr<act::Engine> engine_ptr = open_engine(blob_path, opt.threads);
  const double load_ms = ms_since(load_start);
  act::Engine& engine = *engine_ptr;
  const act::ModelInfo& info = engine.model_info();
  std::unique_ptr<act::Engine> other;
  if (!other_path.empty()) {
    other = open_engine(other_path, opt.threads);
    if (other->model_info().chunk_values() != info.chunk_values() || other->model_info().summary != info.summary) {
      act::fail(act::ErrorCode::kInvalidArgument, "--compare-with " + other_path + " is not the same model (" +
                other->model_info().summary + " vs " + info.summary + ")");
    }
  }

  // Inputs: real observations, or a synthetic one.
  std::optional<act::ObservationBatch> batch;
  SyntheticInput synthetic;
  if (!opt.input_path.empty()) {
    batch.emplace(act::ObservationBatch::read(opt.input_path, info));
  } else {
    synthetic = make_input(info);
  }
  auto observation = [&](int i) {
    return batch ? batch->at(static_cast<size_t>(i) % batch->size()) : synthetic.obs;
  };

  std::vector<float> chunk(info.chunk_values()), other_chunk(info.chunk_values());
  auto infer = [&](act::Engine& e, int i, std::vector<float>& out) {
    const act::Status s = e.infer_normalized(observation(i), out);
    act::throw_if_failed(s);
  };
  const auto first_start = Clock::now();
  infer(engine, 0, chunk);
  const double first_ms = ms_since(first_start);
  for (int i = 0; i < opt.warmup_runs; ++i) {
    infer(engine, i, chunk);
    if (other) infer(*other, i, other_chunk);
  }

  const bool progress = ::isatty(STDERR_FILENO);
  std::vector<act::InferenceTimings> runs, other_runs;
  double err_sq = 0, err_max = 0;
  size_t err_count = 0;
  const auto bench_start = Clock::now();
  for (int i = 0; i < opt.num_runs; ++i) {
    infer(engine, i, chunk);
    runs.push_back(engine.last_timings());
    if (other) {  // interleaved run by run, so both see the same machine conditions
      infer(*other, i, other_chunk);
      other_runs.push_back(other->last_timings());
      for (size_t k = 0; k < chunk.size(); ++k) {
        const double d = static_cast<double>(chunk[k]) - other_chunk[k];
        err_sq += d * d;
        err_max = std::max(err_max, std::fabs(d));
      }
      err_count += chunk.size();
    }
    if (progress) std::fprintf(stderr, "\rrun %d/%d  %.1f ms   ", i + 1, opt.num_runs, runs.back().total_ms);
    if (ms_since(bench_start) > opt.max_secs * 1e3) break;
  }
  if (progress) std::fprintf(stderr, "\r%40s\r", "");
  const double bench_ms = ms_since(bench_start);

  // Statistics per stage.
  const std::pair<const char*, double act::InferenceTimings::*> stages[] = {
      {"preprocess", &act::InferenceTimings::preprocess_ms}, {"backbone", &act::InferenceTimings::backbone_ms},
      {"encoder", &act::InferenceTimings::encoder_ms},       {"decoder", &act::InferenceTimings::decoder_ms},
      {"other", &act::InferenceTimings::other_ms},           {"total", &act::InferenceTimings::total_ms}};
  nlohmann::ordered_json stage_json;
  std::vector<std::pair<std::string, act::LatencySummary>> summaries;
  for (const auto& [name, member] : stages) {
    std::vector<double> samples;
    for (const auto& r : runs) samples.push_back(r.*member);
    summaries.emplace_back(name, act::summarize(samples));
    stage_json[name] = summaries.back().second.to_json();
  }
  const act::LatencySummary& total = summaries.back().second;
  const auto macs = config.macs();
  const double gmac = macs.total() / 1e9;
  const double gmacs_per_s = gmac / (total.mean / 1e3);
  std::optional<act::LatencySummary> other_total;
  if (other) {
    std::vector<double> samples;
    for (const auto& r : other_runs) samples.push_back(r.total_ms);
    other_total = act::summarize(samples);
  }
  const act::MachineInfo machine = act::read_machine_info();
  // This core's peak for the engine's main kernels (int8 dot products, or float FMAs), measured now
  // by the same register-only probe as act_kernel_bench; the achieved rate is compared with it
  // times the threads.
  const bool int8 = info.precision.rfind("int8", 0) == 0;
  const act::kernels::Isa isa = act::kernels::parse_isa(info.isa).value_or(act::kernels::Isa::kRef);
  const act::kernels::PeakProbe* probe =
      act::kernels::isa_peak_probe(isa, int8 ? act::kernels::PeakKind::kInt8 : act::kernels::PeakKind::kFp32);
  const double peak_gmacs = probe ? act::kernels::measure_peak_gmacs(*probe) : 0.0;
  const double pct_peak = peak_gmacs > 0 ? 100.0 * gmacs_per_s / (peak_gmacs * engine.threads()) : 0.0;
  const size_t rss = act::peak_rss_bytes();

  // Report.
  std::printf("actengine act_bench %s\n", act::version());
  std::printf("model        %s\n             %s\n", model_label.c_str(), config.summary().c_str());
  std::printf("compute      %.3f GMAC per inference (backbone %.3f, projections %.3f, encoder %.3f, decoder %.3f, head %.4f)\n",
              gmac, macs.backbone / 1e9, macs.projections / 1e9, macs.encoder / 1e9, macs.decoder / 1e9, macs.head / 1e9);
  std::printf("engine       %s, weights %.1f MB, %d threads\nkernels      %s\n", info.precision.c_str(),
              static_cast<double>(weight_bytes) / 1e6, engine.threads(), info.kernels.c_str());
  if (!builtin.int8_note.empty()) std::printf("int8         %s\n", builtin.int8_note.c_str());
  std::printf("machine      %s\n", machine.one_line().c_str());
  if (build_ms > 0) std::printf("build        %.0f ms (synthetic weights, import, blob)\n", build_ms);
  std::printf("init         load + plan %.1f ms, first inference %.1f ms\n", load_ms, first_ms);
  std::printf("runs         %zu timed (after %d warm-up) in %.1f s\n\n", runs.size(), opt.warmup_runs, bench_ms / 1e3);
  std::printf("%-11s %9s %9s %9s %9s %9s %9s %9s %9s\n", "stage (ms)", "mean", "std", "min", "p50", "p90", "p95", "p99",
              "max");
  for (const auto& [name, s] : summaries) {
    std::printf("%-11s %9.2f %9.2f %9.2f %9.2f %9.2f %9.2f %9.2f %9.2f\n", name.c_str(), s.mean, s.stddev, s.min, s.p50, s.p90,
                s.p95, s.p99, s.max);
  }
  std::printf("\nthroughput   %.2f inferences/s, %.1f GMAC/s achieved\n", 1e3 / total.mean, gmacs_per_s);
  if (probe != nullptr && peak_gmacs > 0) {
    std::printf("peak         %.1f %% of this CPU's %s peak: %.1f GMAC/s per core (%s probe) x %d threads\n", pct_peak,
                int8 ? "INT8" : "FP32", peak_gmacs, probe->name, engine.threads());
  } else {
    std::printf("peak         no probe for the %s kernels on this CPU\n", act::kernels::isa_name(isa));
  }
  std::printf("peak RSS     %.1f MB\n", static_cast<double>(rss) / 1e6);
  nlohmann::ordered_json compare_json;
  if (other) {
    const act::ModelInfo& oi = other->model_info();
    const double ratio = other_total->mean / total.mean;
    const double rmse = std::sqrt(err_sq / static_cast<double>(std::max<size_t>(err_count, 1)));
    std::printf("\ncompare      %s: mean %.2f ms, p50 %.2f ms (interleaved with the runs above)\n", oi.precision.c_str(),
                other_total->mean, other_total->p50);
    std::printf("             %s is %.2fx the speed of %s\n", info.precision.c_str(), ratio, oi.precision.c_str());
    std::printf("             action difference (normalised units): MSE %.3g, RMS %.3g, max |diff| %.3g\n", rmse * rmse, rmse,
                err_max);
    compare_json = {{"other_precision", oi.precision}, {"other_latency_ms", other_total->to_json()},
                    {"speed_ratio", ratio}, {"action_mse", rmse * rmse}, {"action_max_abs", err_max}};
  }

  if (!opt.json_path.empty()) {
    nlohmann::ordered_json j;
    j["actengine_version"] = act::version();
    j["model"] = {{"source", opt.model.empty() ? "built-in" : "blob"},
                  {"name", model_label},
                  {"summary", config.summary()},
                  {"config", config.to_json()},
                  {"precision", info.precision},
                  {"weight_bytes", weight_bytes},
                  {"gmac", {{"total", gmac},
                            {"backbone", macs.backbone / 1e9},
                            {"projections", macs.projections / 1e9},
                            {"encoder", macs.encoder / 1e9},
                            {"decoder", macs.decoder / 1e9},
                            {"head", macs.head / 1e9}}}};
    j["engine"] = {{"threads", engine.threads()}, {"kernels", info.kernels}};
    if (other) j["compare"] = compare_json;
    j["machine"] = machine.to_json();
    j["init"] = {{"build_ms", build_ms}, {"load_ms", load_ms}, {"first_inference_ms", first_ms}};
    j["runs"] = {{"warmup", opt.warmup_runs}, {"timed", runs.size()}, {"seconds", bench_ms / 1e3}};
    j["latency_ms"] = stage_json;
    j["throughput_per_s"] = 1e3 / total.mean;
    j["achieved_gmac_per_s"] = gmacs_per_s;
    j["peak"] = {{"kind", int8 ? "int8" : "fp32"},
                 {"probe", probe ? probe->name : ""},
                 {"gmac_per_s_per_core", peak_gmacs},
                 {"percent_of_peak", pct_peak}};
    j["peak_rss_bytes"] = rss;
    std::ofstream(opt.json_path) << j.dump(2) << "\n";
  }
  if (!opt.csv_path.empty()) {
    std::ofstream csv(opt.csv_path);
    csv << std::fixed << std::setprecision(4);  // 0.1 us: the default 6 significant digits lose that on slow runs
    csv << "run,preprocess_ms,backbone_ms,encoder_ms,decoder_ms,other_ms,total_ms\n";
    for (size_t i = 0; i < runs.size(); ++i) {
      const auto& r = runs[i];
      csv << i << "," << r.preprocess_ms << "," << r.backbone_ms << "," << r.encoder_ms << "," << r.decoder_ms << ","
          << r.other_ms << "," << r.total_ms << "\n";
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"act_bench: end-to-end latency of an ACT policy. Without --model it benchmarks a built-in synthetic "
               "copy of LeRobot's default ACT (resnet18, D 512, 4+1 layers, one 480x640 camera)."};
  // A repeated option takes its last value, so scripts can set defaults users override
  // (scripts/run_bench.sh passes --num_runs 20 before the user's arguments).
  app.option_defaults()->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
  Options opt;
  app.add_option("-m,--model", opt.model, "an .actb blob (from act_convert); default: a built-in model");
  app.add_option("--config", opt.config, "built-in model: default, rover (360x640, 2-dim state/action), or WxH")
      ->capture_default_str();
  app.add_option("--precision", opt.precision, "built-in model precision: fp32 or int8")
      ->check(CLI::IsMember({"fp32", "int8"}))
      ->capture_default_str();
  app.add_option("-t,--threads", opt.threads, "threads (0 = all cores)")->check(CLI::NonNegativeNumber)->capture_default_str();
  app.add_option("-w,--warmup_runs", opt.warmup_runs, "untimed runs after the first inference")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("-n,--num_runs", opt.num_runs, "timed runs")->check(CLI::PositiveNumber)->capture_default_str();
  app.add_option("--max_secs", opt.max_secs, "stop timing after this many seconds")->check(CLI::PositiveNumber)->capture_default_str();
  app.add_option("--json", opt.json_path, "write every number (and machine info) as JSON");
  app.add_option("--csv", opt.csv_path, "write per-run stage times as CSV");
  app.add_option("--input", opt.input_path, "benchmark on observations from a safetensors file (act_eval's format)");
  app.add_flag("--compare", opt.compare,
               "FP32 and INT8 of the same model, interleaved run by run: speed ratio and action difference "
               "(built-in models; with --model also give --compare-with)");
  app.add_option("--compare-with", opt.compare_with, "with --model and --compare: the same model in the other precision");
  app.add_option("--seed", opt.seed, "seed of the built-in model's weights")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  try {
    return run(opt);
  } catch (const std::exception& e) {
    std::cerr << "act_bench: error: " << e.what() << "\n";
    return 1;
  }
}
