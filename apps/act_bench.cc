// act_bench: end-to-end latency of an ACT model, the numbers a TFLite or ONNX Runtime user reads at a
// glance. Without --model it builds LeRobot's default ACT in-process (deterministic synthetic weights),
// so a new user sees numbers with nothing to download.
#include <CLI/CLI.hpp>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <optional>
#include <random>
#include <sstream>

#include "actengine/convert.h"
#include "actengine/engine.h"
#include "actengine/status.h"
#include "apps/bench_support.h"
#include "apps/diff_stats.h"
#include "engine/src/convert/observation_file.h"
#include "apps/op_profile_report.h"
#include "apps/pi5_estimate.h"
#include "apps/progress.h"
#include "apps/version.h"
#include "bench/probes/bench_probes.h"
#include "weights/blob/file_util.h"

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
  bool op_profiling = false;
  std::string trace_path;
  uint32_t seed = 1;
  bool portrait = false;
  std::string target = "here";  // here: measure (the Pi 5 estimate beside); pi5: only the estimate
  std::string save_model;        // write the built-in model's blob here and time nothing
};

// --config HxW is height first, as every other tool's sizes (act_drive --camera-size, the model's
// cameras); act_bench once took WxH. A size higher than wide is what the old order wrote for a
// landscape camera, so it needs --portrait to say it is meant.
void check_builtin_config(const Options& opt) {
  const size_t x = opt.config.find('x');
  const auto digits = [](const std::string& part) {
    return !part.empty() && part.size() <= 5 && part.find_first_not_of("0123456789") == std::string::npos;
  };
  if (x == std::string::npos || !digits(opt.config.substr(0, x)) || !digits(opt.config.substr(x + 1))) {
    if (opt.portrait) act::fail(act::StatusCode::kInvalidArgument, "--portrait goes with --config HxW");
    return;  // a preset name, or something the import refuses with its own message
  }
  const int height = std::stoi(opt.config.substr(0, x)), width = std::stoi(opt.config.substr(x + 1));
  if (height <= width || opt.portrait) return;
  act::fail(act::StatusCode::kInvalidArgument,
            "--config " + opt.config + " is HxW (height first, as act_drive --camera-size and act_convert): a portrait camera " +
                std::to_string(height) + " high and " + std::to_string(width) + " wide. For a camera " + std::to_string(height) +
                " wide and " + std::to_string(width) + " high give --config " + std::to_string(width) + "x" +
                std::to_string(height) + "; for a portrait camera add --portrait");
}

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

// The built-in model written as the FP32 and INT8 static blobs that are asked for. INT8 is calibrated
// on a few synthetic frames: enough for speed; act_convert with real frames is what gives accuracy.
struct BuiltinBlobs {
  TempBlob fp32{"fp32"}, int8{"int8"};
  bool has_int8 = false;
  std::string int8_note;
};

void build_builtin(const Options& opt, bool want_fp32, bool want_int8, BuiltinBlobs& out) {
  auto imported = act::import_synthetic_model(opt.config, opt.seed);
  if (!imported.ok()) throw act::Error(imported.status());
  const act::ImportedCheckpoint& model = **imported;
  if (want_fp32) {
    const auto written = model.write_fp32(out.fp32.path);
    if (!written.ok()) throw act::Error(written.status());
  }
  if (!want_int8) return;
  auto frames = model.synthetic_calibration_set(5, opt.seed);
  if (!frames.ok()) throw act::Error(frames.status());
  act::Int8Options int8;
  int8.mode = act::Int8Mode::kStatic;
  int8.holdout = 1;
  int8.threads = opt.threads;
  int8.layer_report = false;
  std::fprintf(stderr, "act_bench: quantizing the built-in model to INT8 (static, calibrated on 4 synthetic frames) ...\n");
  // In a child process, so that the calibration's FP32 run and its buffers do not count in this
  // process's peak RSS. The child reports the held-out error through a pipe.
  int fds[2];
  if (::pipe(fds) != 0) act::fail(act::StatusCode::kIoError, "pipe() failed");
  const pid_t child = ::fork();
  if (child < 0) act::fail(act::StatusCode::kIoError, "fork() failed");
  if (child == 0) {
    ::close(fds[0]);
    int code = 0;
    const act::StatusOr<act::Int8Report> r = model.write_int8(out.int8.path, *frames, int8);
    if (r.ok()) {
      const std::string mse = std::to_string(r->action_error.mse);
      code = ::write(fds[1], mse.data(), mse.size()) == static_cast<ssize_t>(mse.size()) ? 0 : 1;
    } else {
      std::fprintf(stderr, "act_bench: error: INT8 conversion failed: %s\n", r.status().message().c_str());
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
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) act::fail(act::StatusCode::kInternal, "INT8 conversion of the built-in model failed");
  out.has_int8 = true;
  out.int8_note = "INT8 static, mse calibration on 4 synthetic frames (held-out action MSE " + mse + ")";
}

std::unique_ptr<act::Engine> open_engine(const std::string& path, int threads) {
  auto engine_or = act::Engine::open(path, {.threads = threads, .profile = true});
  if (!engine_or.ok()) throw act::Error(engine_or.status());
  return std::move(*engine_or);
}

// The model's MACs each timed stage runs: the cameras' feature projections with the backbone they
// follow, the action head with the decoder whose last op computes it; preprocess and other none.
double stage_macs(const std::string& stage, const act::bench::Macs& macs) {
  if (stage == "backbone") return macs.backbone + macs.projections;
  if (stage == "encoder") return macs.encoder;
  if (stage == "decoder") return macs.decoder + macs.head;
  if (stage == "total") return macs.total();
  return 0.0;
}

// Latency per stage, in the order of the report; the last is the whole inference.
const std::pair<const char*, double act::InferenceTimings::*> kStages[] = {
    {"preprocess", &act::InferenceTimings::preprocess_ms}, {"backbone", &act::InferenceTimings::backbone_ms},
    {"encoder", &act::InferenceTimings::encoder_ms},       {"decoder", &act::InferenceTimings::decoder_ms},
    {"other", &act::InferenceTimings::other_ms},           {"total", &act::InferenceTimings::total_ms}};

// What each run infers on: observations from a file (cycled through), or the synthetic one.
class Observations {
 public:
  Observations(const std::string& input_path, const act::ModelInfo& info) {
    if (!input_path.empty()) {
      batch_.emplace(act::ObservationBatch::read(input_path, info));
    } else {
      synthetic_ = make_input(info);
    }
  }
  act::Observation at(int i) const { return batch_ ? batch_->at(static_cast<size_t>(i) % batch_->size()) : synthetic_.obs; }

 private:
  std::optional<act::ObservationBatch> batch_;
  SyntheticInput synthetic_;
};

// The timed runs: each run's stage times and, with --compare, the other precision's interleaved
// runs and the action difference between the two (normalised units).
struct TimedRuns {
  double first_ms = 0;  ///< the first inference, before the warm-up
  double bench_ms = 0;  ///< wall time of the timed runs
  std::vector<act::InferenceTimings> runs, other_runs;
  std::vector<std::vector<double>> op_ms;  ///< --op_profiling: [op][run] milliseconds
  act::DiffStats action_diff;  ///< ours against the other precision's
};

// The peak of the engine's threads for its main kernels (int8 dot products, or float FMAs): the
// same register-only probe as act_kernel_bench, run on as many threads at once as the engine runs
// (graph/peak_together.h: one core's reading times T overstates T cores where they differ or share
// a clock budget), right before the timed runs and right after: the higher of the two is the peak. A
// shared host's speed moves within seconds (one probe read 369 GMAC/s and the next 434, minutes
// apart), and a probe that caught a slow moment would put the runs above their real share of the
// machine.
struct Peak {
  bool int8 = false;
  act::bench::KernelPeak probe;
  int threads = 1;  ///< the threads the probe runs on at once: the engine's, at most one per core
  double before_runs = 0, after_runs = 0;  ///< the probe's readings, GMAC/s of all `threads`

  double gmacs() const { return std::max(before_runs, after_runs); }
  double gmacs_per_core() const { return gmacs() / threads; }
  /// One reading of the probe now (0 without one).
  double read() const { return probe.read(threads); }
};

// The probe for the engine's precision and kernel level, not yet read.
Peak peak_probe_for(const act::ModelInfo& info, int engine_threads) {
  Peak peak;
  peak.threads = act::bench::peak_probe_threads(engine_threads);
  peak.int8 = info.precision.rfind("int8", 0) == 0;
  peak.probe = act::bench::KernelPeak(info.isa, peak.int8);
  return peak;
}

// --compare: the other precision's latency, and how far its actions are from ours.
struct Comparison {
  std::string other_precision;
  act::LatencySummary other_total;
  double speed_ratio = 0;
  act::DiffStats action_diff;
  nlohmann::ordered_json to_json() const {
    const auto number_or_null = [](double v) { return std::isfinite(v) ? nlohmann::ordered_json(v) : nlohmann::ordered_json(); };
    return {{"other_precision", other_precision}, {"other_latency_ms", other_total.to_json()},
            {"speed_ratio", speed_ratio}, {"action_mse", number_or_null(action_diff.mse())},
            {"action_max_abs", action_diff.max_abs}, {"action_non_finite", action_diff.non_finite}};
  }
};

// One benchmark, step by step: choose the model, open it, time it, summarise, report.
class Benchmark {
 public:
  explicit Benchmark(const Options& opt) : opt_(opt) {}

  int run() {
    open_outputs();
    choose_model();
    if (!opt_.save_model.empty()) return save_model();
    blob_.emplace(act::bench::BlobFacts::open(blob_path_));
    open_engines();
    estimate_pi5();
    if (opt_.target == "pi5") {  // nothing is timed: the model, its compute and the estimate
      macs_ = blob_->macs();
      gmac_ = macs_.total() / 1e9;
      print_model();
      print_pi5_estimate();
      if (json_file_) write_pi5_json();
      return 0;
    }
    time_runs(Observations(opt_.input_path, engine_->model_info()));
    summarize_runs();
    print_report();
    if (json_file_) write_json();
    if (csv_file_) write_csv();
    if (trace_file_) write_trace();
    return 0;
  }

 private:
  // The output files are created (unnamed until written) before the minutes of benchmarking, so a
  // folder that does not exist or cannot be written fails at once, not silently at the end.
  void open_outputs() {
    if (!opt_.json_path.empty()) json_file_.emplace(opt_.json_path);
    if (!opt_.csv_path.empty()) csv_file_.emplace(opt_.csv_path);
    if (!opt_.trace_path.empty()) trace_file_.emplace(opt_.trace_path);
  }

  // The model: a blob, or a built-in synthetic one written to a temporary blob.
  void choose_model() {
    if (opt_.compare && !opt_.model.empty() && opt_.compare_with.empty()) {
      act::fail(act::StatusCode::kInvalidArgument, "--compare with --model needs the other precision's blob: --compare-with OTHER.actb");
    }
    blob_path_ = model_label_ = opt_.model;
    other_path_ = opt_.compare_with;
    if (blob_path_.empty()) {
      const auto start = Clock::now();
      const bool int8 = opt_.precision == "int8";
      build_builtin(opt_, !int8 || opt_.compare, int8 || opt_.compare, builtin_);
      blob_path_ = int8 ? builtin_.int8.path : builtin_.fp32.path;
      if (opt_.compare) other_path_ = int8 ? builtin_.fp32.path : builtin_.int8.path;
      build_ms_ = ms_since(start);
      model_label_ = "built-in \"" + opt_.config + "\" (synthetic weights, seed " + std::to_string(opt_.seed) + ")";
    } else if (opt_.precision != "fp32") {
      act::fail(act::StatusCode::kInvalidArgument, "--precision chooses among the built-in models; a blob has its own precision");
    }
  }

  // --save-model: the built-in blob this run would benchmark, for act_convert --export-onnx and
  // other runtimes (bench/tools/compare_ort.sh); nothing is timed.
  int save_model() {
    std::error_code ec;
    fs::copy_file(blob_path_, opt_.save_model, fs::copy_options::overwrite_existing, ec);
    if (ec) act::fail(act::StatusCode::kIoError, "--save-model " + opt_.save_model + ": " + ec.message());
    std::printf("act_bench: wrote %s (%s, %s)\n", opt_.save_model.c_str(), model_label_.c_str(), opt_.precision.c_str());
    return 0;
  }

  // The engine and, with --compare, the same model in the other precision.
  void open_engines() {
    const auto load_start = Clock::now();
    engine_ = open_engine(blob_path_, opt_.threads);
    load_ms_ = ms_since(load_start);
    if (other_path_.empty()) return;
    other_ = open_engine(other_path_, opt_.threads);
    const act::ModelInfo& info = engine_->model_info();
    if (other_->model_info().chunk_values() != info.chunk_values() || other_->model_info().summary != info.summary) {
      act::fail(act::StatusCode::kInvalidArgument, "--compare-with " + other_path_ + " is not the same model (" +
                other_->model_info().summary + " vs " + info.summary + ")");
    }
  }

  // The first inference, the warm-up, then the timed runs (until num_runs or max_secs).
  void time_runs(const Observations& inputs) {
    std::vector<float> chunk(engine_->model_info().chunk_values()), other_chunk(chunk.size());
    auto infer = [&](act::Engine& e, int i, std::vector<float>& out) {
      const act::Status s = e.infer_normalized(inputs.at(i), out);
      if (!s.ok()) throw act::Error(s);
    };
    const auto first_start = Clock::now();
    infer(*engine_, 0, chunk);
    timed_.first_ms = ms_since(first_start);
    for (int i = 0; i < opt_.warmup_runs; ++i) {
      infer(*engine_, i, chunk);
      if (other_) infer(*other_, i, other_chunk);
    }
    engine_->reset_op_profile();  // the op profile averages the timed runs only
    peak_ = peak_probe_for(engine_->model_info(), engine_->threads());
    peak_.before_runs = peak_.read();

    act::ProgressLine progress(stderr, "act_bench", act::ProgressLine::stderr_is_terminal());
    const size_t runs = static_cast<size_t>(opt_.num_runs);
    progress.update("timed runs", 0, runs, "runs");
    const auto bench_start = Clock::now();
    for (int i = 0; i < opt_.num_runs; ++i) {
      infer(*engine_, i, chunk);
      timed_.runs.push_back(engine_->last_timings());
      if (opt_.op_profiling) record_op_times();
      if (other_) {  // interleaved run by run, so both see the same machine conditions
        infer(*other_, i, other_chunk);
        timed_.other_runs.push_back(other_->last_timings());
        for (size_t k = 0; k < chunk.size(); ++k) timed_.action_diff.add(chunk[k], other_chunk[k]);
      }
      progress.update("timed runs", timed_.runs.size(), runs, "runs");
      if (ms_since(bench_start) > opt_.max_secs * 1e3) {
        char stopped[64];
        std::snprintf(stopped, sizeof stopped, "stopped after --max_secs %g s", opt_.max_secs);
        progress.message(stopped);
        break;
      }
    }
    progress.finish();
    timed_.bench_ms = ms_since(bench_start);
  }

  // This run's time of each op: the growth of the engine's per-op sums since the last run (for the
  // op table's medians, which a descheduled run on a shared machine does not drag like a mean).
  void record_op_times() {
    const std::vector<act::OpProfile> profile = engine_->op_profile();
    timed_.op_ms.resize(profile.size());
    op_totals_.resize(profile.size(), 0.0);
    for (size_t op = 0; op < profile.size(); ++op) {
      timed_.op_ms[op].push_back(profile[op].total_ms - op_totals_[op]);
      op_totals_[op] = profile[op].total_ms;
    }
  }

  // Statistics per stage, the achieved rate against this CPU's peak, the comparison, the memory.
  void summarize_runs() {
    for (const auto& [name, member] : kStages) {
      std::vector<double> samples;
      for (const auto& r : timed_.runs) samples.push_back(r.*member);
      stages_.emplace_back(name, act::summarize(samples));
    }
    macs_ = blob_->macs();
    gmac_ = macs_.total() / 1e9;
    gmacs_per_s_ = gmac_ / (total().mean / 1e3);
    if (other_) {
      std::vector<double> samples;
      for (const auto& r : timed_.other_runs) samples.push_back(r.total_ms);
      Comparison c;
      c.other_precision = other_->model_info().precision;
      c.other_total = act::summarize(samples);
      c.speed_ratio = c.other_total.mean / total().mean;
      c.action_diff = timed_.action_diff;
      comparison_ = c;
    }
    machine_ = act::read_machine_info();
    // The achieved rate is compared with the peak of the engine's threads.
    peak_.after_runs = peak_.read();
    // Also at the median run: one slow run of a shared host moves the mean, not the median.
    const double peak_gmacs = peak_.gmacs();
    const auto percent_of_peak = [&](double gmac, double ms) { return 100.0 * gmac / (ms / 1e3) / peak_gmacs; };
    pct_peak_ = peak_gmacs > 0 ? 100.0 * gmacs_per_s_ / peak_gmacs : 0.0;
    pct_peak_p50_ = peak_gmacs > 0 ? percent_of_peak(gmac_, total().p50) : 0.0;
    // Each stage's rate at its median run against the same peak (the per-stage targets).
    for (const auto& [name, s] : stages_) {
      nlohmann::ordered_json& stage = stage_json_[name] = s.to_json();
      const double gmac = stage_macs(name, macs_) / 1e9;
      if (gmac <= 0) continue;
      stage["gmac"] = gmac;
      if (peak_gmacs > 0 && s.p50 > 0) stage["percent_of_peak_p50"] = percent_of_peak(gmac, s.p50);
    }
    rss_ = act::peak_rss_bytes();
    huge_page_bytes_ = act::bench::huge_page_bytes();
    if (opt_.op_profiling) {
      const std::vector<act::OpProfile> profile = engine_->op_profile();
      op_table_ = act::OpProfileTable::make(profile, peak_.gmacs(), timed_.op_ms);
    }
  }

  const act::LatencySummary& total() const { return stages_.back().second; }

  // The model's MACs in convs that run as Winograd (op kind conv2d_f32_winograd), in GMAC.
  double winograd_gmac() const {
    double macs = 0;
    for (const act::OpProfile& op : engine_->op_profile()) {
      if (act::is_winograd_kind(op.kind)) macs += op.macs;
    }
    return macs / 1e9;
  }

  // The Pi 5 estimate from the engine's ops (their kinds and MACs: nothing runs for it).
  void estimate_pi5() {
    const nlohmann::json config = blob_->config_json();
    const int heads = config.value("n_heads", 0);
    pi5_ = act::Pi5Estimate::of(engine_->op_profile(), heads > 0 ? config.value("dim_model", 0) / heads : 0);
  }

  void print_pi5_estimate() const {
    std::printf("%s %s on a Raspberry Pi 5 (4x Cortex-A76, %.1f GHz), ESTIMATED:", opt_.target == "pi5" ? "pi5         " : "\npi5 estimate",
                engine_->model_info().precision.c_str(), act::pi5_rates().clock_ghz);
    for (size_t c = 0; c < pi5_.latency_ms.size(); ++c) {
      std::printf("%s %zu core%s %.1f ms", c ? "," : "", c + 1, c ? "s" : "", pi5_.latency_ms[c]);
    }
    std::printf(" (%.1f inferences/s on 4)\n             %s\n", 1e3 / pi5_.latency_ms.back(), act::Pi5Estimate::method().c_str());
  }

  // --target pi5 --json: the estimate as a record scripts/perf_table.py puts in the numbers table.
  void write_pi5_json() {
    nlohmann::ordered_json j;
    j["actengine_version"] = act::version();
    j["model"] = model_json();
    j["engine"] = {{"threads", static_cast<int>(pi5_.latency_ms.size())}, {"kernels", "neondot (projected)"}};
    j["latency_ms"] = {{"total", {{"p50", pi5_.latency_ms.back()}}}};
    j["peak"] = {{"percent_of_peak_p50", nullptr}};
    j["machine_label"] = "Raspberry Pi 5, 4x Cortex-A76";
    j["estimate"] = true;
    j["note"] = "Projected by act_bench --target pi5 from the model's MACs per op kind and the NEON kernels' inner loops "
                "(llvm-mca -mcpu=cortex-a76), not measured: docs/arm.md.";
    j["pi5_estimate"] = pi5_.to_json();
    json_file_->write(j.dump(2) + "\n");
    json_file_->commit();
  }

  nlohmann::ordered_json model_json() const {
    return {{"source", opt_.model.empty() ? "built-in" : "blob"},
            {"name", model_label_},
            {"summary", blob_->summary()},
            {"config", blob_->config_json()},
            {"precision", engine_->model_info().precision},
            {"weight_bytes", blob_->file_size()},
            {"gmac", {{"total", gmac_},
                      {"backbone", macs_.backbone / 1e9},
                      {"projections", macs_.projections / 1e9},
                      {"encoder", macs_.encoder / 1e9},
                      {"decoder", macs_.decoder / 1e9},
                      {"head", macs_.head / 1e9}}}};
  }

  // The model, its compute and its engine.
  void print_model() const {
    const act::ModelInfo& info = engine_->model_info();
    std::printf("actengine act_bench %s\n", act::version());
    std::printf("model        %s\n             %s\n", model_label_.c_str(), blob_->summary().c_str());
    std::printf("compute      %.3f GMAC per inference (backbone %.3f, projections %.3f, encoder %.3f, decoder %.3f, head %.4f)\n",
                gmac_, macs_.backbone / 1e9, macs_.projections / 1e9, macs_.encoder / 1e9, macs_.decoder / 1e9, macs_.head / 1e9);
    std::printf("engine       %s, weights %.1f MB, %d threads\nkernels      %s\n", info.precision.c_str(),
                static_cast<double>(blob_->file_size()) / 1e6, engine_->threads(), info.kernels.c_str());
    if (!builtin_.int8_note.empty()) std::printf("int8         %s\n", builtin_.int8_note.c_str());
  }

  void print_report() const {
    print_model();
    std::printf("machine      %s\n", machine_.one_line().c_str());
    if (!machine_.emulation.empty()) {
      std::printf("EMULATED     every time below is the emulator's, not a CPU's (%s)\n", machine_.emulation.c_str());
    }
    if (build_ms_ > 0) std::printf("build        %.0f ms (synthetic weights, import, blob)\n", build_ms_);
    std::printf("init         load + plan %.1f ms, first inference %.1f ms\n", load_ms_, timed_.first_ms);
    std::printf("runs         %zu timed (after %d warm-up) in %.1f s\n\n", timed_.runs.size(), opt_.warmup_runs,
                timed_.bench_ms / 1e3);
    std::printf("%-11s %9s %9s %9s %9s %9s %9s %9s %9s %9s\n", "stage (ms)", "mean", "std", "min", "p50", "p90", "p95", "p99",
                "max", "peak@p50");
    for (const auto& [name, s] : stages_) {
      const nlohmann::ordered_json& stage = stage_json_.at(name);
      char peak[32] = "";
      if (stage.contains("percent_of_peak_p50")) {
        std::snprintf(peak, sizeof peak, "%.1f %%", stage["percent_of_peak_p50"].get<double>());
      }
      std::printf("%-11s %9.2f %9.2f %9.2f %9.2f %9.2f %9.2f %9.2f %9.2f %9s\n", name.c_str(), s.mean, s.stddev, s.min, s.p50,
                  s.p90, s.p95, s.p99, s.max, peak);
    }
    std::printf("\nthroughput   %.2f inferences/s, %.1f GMAC/s achieved\n", 1e3 / total().mean, gmacs_per_s_);
    if (peak_.probe.has_probe() && peak_.gmacs_per_core() > 0) {
      char on_threads[96];
      if (peak_.threads == 1) {
        std::snprintf(on_threads, sizeof on_threads, "on 1 thread (%s probe)", peak_.probe.probe_name());
      } else {
        std::snprintf(on_threads, sizeof on_threads, "on %d threads (%s probe on each at once, %.1f per core)", peak_.threads,
                      peak_.probe.probe_name(), peak_.gmacs_per_core());
      }
      std::printf("peak         %.1f %% of this CPU's %s peak at the mean run, %.1f %% at the median: %.1f GMAC/s %s%s\n",
                  pct_peak_, peak_.int8 ? "INT8" : "FP32", pct_peak_p50_, peak_.gmacs(), on_threads,
                  machine_.emulation.empty() ? "" : " (both emulated: says nothing of a real CPU)");
      std::printf("             the probe read %.1f GMAC/s before the timed runs and %.1f after: the higher is the peak\n",
                  peak_.before_runs, peak_.after_runs);
      if (const double winograd = winograd_gmac(); winograd > 0) {
        std::printf("             counting the direct convolutions' MACs: %.3f GMAC of 3x3 convs run as Winograd F(2x2,3x3),"
                    " with 2.25x fewer multiply-adds, so a share can pass 100 %%\n",
                    winograd);
      }
    } else {
      std::printf("peak         no probe for the %s kernels on this CPU\n", peak_.probe.isa_name());
    }
    std::printf("peak RSS     %.1f MB; %.1f MB of the engine's weights and values in huge pages\n",
                static_cast<double>(rss_) / 1e6, static_cast<double>(huge_page_bytes_) / 1e6);
    print_pi5_estimate();
    if (op_table_) op_table_->print(stdout, 10);
    if (comparison_) {
      const Comparison& c = *comparison_;
      std::printf("\ncompare      %s: mean %.2f ms, p50 %.2f ms (interleaved with the runs above)\n", c.other_precision.c_str(),
                  c.other_total.mean, c.other_total.p50);
      std::printf("             %s is %.2fx the speed of %s\n", engine_->model_info().precision.c_str(), c.speed_ratio, c.other_precision.c_str());
      const act::DiffStats& d = c.action_diff;
      if (d.non_finite > 0) {
        std::printf("             action difference: %zu of %zu values NaN or infinite in one of the two (no MSE)\n",
                    d.non_finite, d.count);
      } else {
        std::printf("             action difference (normalised units): MSE %.3g, RMS %.3g, max |diff| %.3g\n", d.mse(),
                    std::sqrt(d.mse()), d.max_abs);
      }
    }
  }

  void write_json() {
    const act::ModelInfo& info = engine_->model_info();
    nlohmann::ordered_json j;
    j["actengine_version"] = act::version();
    j["emulated"] = !machine_.emulation.empty();  // then every time is the emulator's (machine.emulation says why)
    j["model"] = model_json();
    j["engine"] = {{"threads", engine_->threads()}, {"kernels", info.kernels}};
    if (comparison_) j["compare"] = comparison_->to_json();
    j["machine"] = machine_.to_json();
    j["init"] = {{"build_ms", build_ms_}, {"load_ms", load_ms_}, {"first_inference_ms", timed_.first_ms}};
    j["runs"] = {{"warmup", opt_.warmup_runs}, {"timed", timed_.runs.size()}, {"seconds", timed_.bench_ms / 1e3}};
    j["latency_ms"] = stage_json_;
    j["throughput_per_s"] = 1e3 / total().mean;
    j["achieved_gmac_per_s"] = gmacs_per_s_;
    j["peak"] = {{"kind", peak_.int8 ? "int8" : "fp32"},
                 {"probe", peak_.probe.probe_name()},
                 {"threads", peak_.threads},
                 {"gmac_per_s", peak_.gmacs()},
                 {"gmac_per_s_per_core", peak_.gmacs_per_core()},
                 {"gmac_per_s_before_runs", peak_.before_runs},
                 {"gmac_per_s_after_runs", peak_.after_runs},
                 {"percent_of_peak", pct_peak_},
                 {"percent_of_peak_p50", pct_peak_p50_}};
    j["peak_rss_bytes"] = rss_;
    j["huge_page_bytes"] = huge_page_bytes_;
    if (op_table_) j["op_profile"] = op_table_->to_json();
    j["pi5_estimate"] = pi5_.to_json();
    json_file_->write(j.dump(2) + "\n");
    json_file_->commit();
  }

  void write_csv() {
    std::ostringstream csv;
    csv << std::fixed << std::setprecision(4);  // 0.1 us: the default 6 significant digits lose that on slow runs
    csv << "run,preprocess_ms,backbone_ms,encoder_ms,decoder_ms,other_ms,total_ms\n";
    for (size_t i = 0; i < timed_.runs.size(); ++i) {
      const auto& r = timed_.runs[i];
      csv << i << "," << r.preprocess_ms << "," << r.backbone_ms << "," << r.encoder_ms << "," << r.decoder_ms << ","
          << r.other_ms << "," << r.total_ms << "\n";
    }
    csv_file_->write(csv.str());
    csv_file_->commit();
  }

  // The last timed inference as a Chrome trace: one lane per thread.
  void write_trace() {
    act::StatusOr<std::string> trace = engine_->chrome_trace();
    if (!trace.ok()) throw act::Error(trace.status());
    trace_file_->write(*trace);
    trace_file_->commit();
    std::printf("trace        %s (open in ui.perfetto.dev or chrome://tracing)\n", opt_.trace_path.c_str());
  }

  const Options& opt_;
  std::optional<act::detail::AtomicFileWriter> json_file_, csv_file_, trace_file_;
  // The model.
  BuiltinBlobs builtin_;  // owns the built-in model's temporary blobs until the benchmark ends
  std::string blob_path_, model_label_, other_path_;
  double build_ms_ = 0;
  std::optional<act::bench::BlobFacts> blob_;
  // Its engines.
  std::unique_ptr<act::Engine> engine_, other_;
  double load_ms_ = 0;
  // The measurements and what they add up to.
  TimedRuns timed_;
  std::vector<std::pair<std::string, act::LatencySummary>> stages_;  // kStages order
  nlohmann::ordered_json stage_json_;
  act::bench::Macs macs_;
  double gmac_ = 0, gmacs_per_s_ = 0;
  std::optional<Comparison> comparison_;
  std::optional<act::OpProfileTable> op_table_;
  std::vector<double> op_totals_;  // --op_profiling: each op's summed time after the last run
  act::MachineInfo machine_;
  act::Pi5Estimate pi5_;
  Peak peak_;
  double pct_peak_ = 0, pct_peak_p50_ = 0;  // at the mean run, at the median run
  size_t rss_ = 0;
  size_t huge_page_bytes_ = 0;
};

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"act_bench: end-to-end latency of an ACT policy. Without --model it benchmarks a built-in synthetic "
               "copy of LeRobot's default ACT (resnet18, D 512, 4+1 layers, one 480x640 camera)."};
  // A repeated option takes its last value, so scripts can set defaults users override
  // (scripts/run_bench.sh passes --num_runs 20 before the user's arguments).
  app.option_defaults()->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
  Options opt;
  // TFLite benchmark_model's names are aliases: --graph, --num_threads (--num_runs, --warmup_runs are ours too).
  app.add_option("-m,--model,--graph", opt.model, "an .actb blob (from act_convert); default: a built-in model");
  app.add_option("--config", opt.config, "built-in model: default (480x640), rover (360x640, 2-dim state/action), or HxW: "
                 "height first, as every tool's sizes (120x160 = 120 high, 160 wide); a size higher than wide needs --portrait")
      ->capture_default_str();
  app.add_flag("--portrait", opt.portrait, "with --config HxW: the camera is higher than wide indeed");
  app.add_option("--precision", opt.precision, "built-in model precision: fp32 or int8")
      ->check(CLI::IsMember({"fp32", "int8"}))
      ->capture_default_str();
  app.add_option("-t,--threads,--num_threads", opt.threads, "threads (0 = all cores)")->check(CLI::Range(0, act::kMaxThreads))->capture_default_str();
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
  app.add_flag("--op_profiling,--enable_op_profiling", opt.op_profiling,
               "per-op profile of the timed runs: time, share, GMAC/s and % of peak per op, top ops, ops by kind "
               "(also in --json)");
  app.add_option("--trace", opt.trace_path, "write the last timed inference as a Chrome trace (ui.perfetto.dev), a lane per thread");
  app.add_option("--seed", opt.seed, "seed of the built-in model's weights")->capture_default_str();
  app.add_option("--target", opt.target, "here: time the model on this machine (a Raspberry Pi 5 estimate is printed "
                 "beside); pi5: only the Pi 5 estimate (nothing timed; a built-in model is then INT8 unless --precision "
                 "says otherwise)")->check(CLI::IsMember({"here", "pi5"}))->capture_default_str();
  app.add_option("--save-model", opt.save_model, "write the built-in model (--config, --precision, --seed) as an .actb "
                 "blob here and time nothing (for act_convert --export-onnx: the same model in ONNX Runtime)");
  app.set_version_flag("--version", act::version_line("act_bench"));
  CLI11_PARSE(app, argc, argv);
  if (!opt.save_model.empty()) {
    for (const char* other : {"--model", "--compare", "--compare-with", "--json", "--csv", "--trace", "--input", "--op_profiling"}) {
      if (app.count(other)) {
        std::cerr << "act_bench: error: --save-model writes the built-in model and times nothing: drop " << other << "\n";
        return 1;
      }
    }
    if (opt.target == "pi5") {
      std::cerr << "act_bench: error: --save-model and --target pi5: give one\n";
      return 1;
    }
  }
  if (opt.target == "pi5") {
    if (opt.model.empty() && !app.count("--precision")) opt.precision = "int8";  // what a Pi runs
    for (const char* timed : {"--compare", "--compare-with", "--csv", "--trace", "--input", "--op_profiling"}) {
      if (app.count(timed)) {
        std::cerr << "act_bench: error: " << timed << " needs timed runs; --target pi5 times nothing (it estimates the "
                     "Pi 5 from the model's MACs): drop --target pi5, or " << timed << "\n";
        return 1;
      }
    }
  }
  if (const long cores = ::sysconf(_SC_NPROCESSORS_ONLN); cores > 0 && opt.threads > cores) {
    std::cerr << "act_bench: warning: --threads " << opt.threads << " is more than the " << cores
              << " online cores: threads then take turns on a core and every parallel op waits for the last one "
                 "(slower, not faster); use --threads " << cores << " or fewer\n";
  }
  try {
    if (opt.model.empty()) check_builtin_config(opt);
    return Benchmark(opt).run();
  } catch (const std::exception& e) {
    std::cerr << "act_bench: error: " << e.what() << "\n";
    return 1;
  }
}
