// The public API: bad observations and blobs are clear errors; results do not depend on threads,
// memory planning or which Engine runs them; Engines run side by side and can change threads.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <set>
#include <thread>

#include <nlohmann/json.hpp>

#include "actengine/engine.h"
#include "kernels/common/isa.h"
#include "support/act_test_util.h"
#include "support/file_test_util.h"
#include "support/test_paths.h"
#include "weights/blob/actb.h"
#include "weights/blob/blob_names.h"
#include "weights/import/lerobot_import.h"
#include "weights/quantize/quantize_model.h"

namespace fs = std::filesystem;

namespace act {
namespace {

// A blob's tensor, copied out so that a test can change it and write another blob.
struct TensorCopy {
  std::string name;
  DType dtype;
  std::vector<int64_t> shape;
  std::vector<uint8_t> bytes;
  QuantParams quant;
};

// Writes `path`: the blob at `source` with `edit` applied to its config and tensors (the checksum
// is recomputed, so only the semantic checks can catch the change).
void rewrite_blob(const std::string& source, const std::string& path,
                  const std::function<void(nlohmann::json& config, std::vector<TensorCopy>& tensors)>& edit) {
  const ActbFile original = ActbFile::open(source);
  nlohmann::json config = original.config();
  std::vector<TensorCopy> tensors;
  for (const ActbTensor& t : original.tensors()) {
    tensors.push_back({t.name, t.dtype, t.shape, std::vector<uint8_t>(t.data, t.data + t.nbytes), t.quant});
  }
  edit(config, tensors);
  ActbWriter writer;
  writer.set_config(config);
  for (const TensorCopy& t : tensors) writer.add_tensor(t.name, t.dtype, t.shape, t.bytes.data(), t.bytes.size(), t.quant);
  writer.write(path);
}

TensorCopy& tensor_named(std::vector<TensorCopy>& tensors, const std::string& name) {
  const auto it = std::find_if(tensors.begin(), tensors.end(), [&](const TensorCopy& t) { return t.name == name; });
  if (it == tensors.end()) throw std::runtime_error("no tensor " + name);
  return *it;
}

class EngineApiTest : public ::testing::Test {
 protected:
  // act-tiny's blob is converted once per test program, into a folder of the suite's own (a test's
  // scratch folder goes when the test ends): each conversion took 0.5 s under ASan and 5-6 s under
  // TSan. No test changes it: those that need another blob copy or rewrite it into their scratch.
  static void TearDownTestSuite() {
    if (!suite_dir_.empty()) fs::remove_all(suite_dir_);
    suite_dir_.clear();
    suite_blob_.clear();
  }
  void SetUp() override {
    const std::string fixture = test::fixture_dir("act-tiny");
    ACT_REQUIRE_PATH(fixture);
    scratch_ = test::scratch_dir();
    if (suite_blob_.empty()) {
      // Beside the tests' scratch folders, one per process (sharded test programs run side by side).
      suite_dir_ = (fs::path(scratch_).parent_path() / ("EngineApiTest.suite." + std::to_string(::getpid()))).string();
      fs::remove_all(suite_dir_);
      fs::create_directories(suite_dir_);
      suite_blob_ = test::convert_checkpoint(fixture, suite_dir_);
    }
    blob_ = suite_blob_;
    auto e = Engine::open(blob_, {.threads = 2});
    ASSERT_TRUE(e.ok()) << e.status().to_string();
    engine_ = std::move(e.value());
    const auto& cam = engine_->model_info().cameras[0];
    image_.resize(static_cast<size_t>(cam.height) * cam.width * 3);
    for (size_t i = 0; i < image_.size(); ++i) image_[i] = static_cast<uint8_t>((i * 37) % 251);
    state_ = {0.3f, -1.2f};
  }
  Observation observation() {
    const auto& cam = engine_->model_info().cameras[0];
    Observation obs;
    obs.images = {ImageView::rgb_u8(image_.data(), cam.height, cam.width)};
    obs.state = state_;
    return obs;
  }
  std::vector<float> chunk() { return std::vector<float>(engine_->model_info().chunk_values()); }
  void expect_invalid(const Observation& obs, const std::string& needle) {
    auto out = chunk();
    const Status s = engine_->infer(obs, out);
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << s.to_string();
    EXPECT_NE(s.message().find(needle), std::string::npos) << s.message() << " (expected: " << needle << ")";
  }

  static inline std::string suite_dir_, suite_blob_;
  std::string scratch_, blob_;
  std::unique_ptr<Engine> engine_;
  std::vector<uint8_t> image_;
  std::vector<float> state_;
};

TEST_F(EngineApiTest, ModelInfoDescribesTheModel) {
  const ModelInfo& info = engine_->model_info();
  ASSERT_EQ(info.cameras.size(), 1u);
  EXPECT_EQ(info.cameras[0].key, "observation.images.front");
  EXPECT_EQ(info.cameras[0].height, 96);
  EXPECT_EQ(info.cameras[0].width, 128);
  EXPECT_EQ(info.state_dim, 2);
  EXPECT_EQ(info.action_dim, 2);
  EXPECT_EQ(info.chunk_size, 10);
  EXPECT_EQ(info.precision, "fp32");
  EXPECT_EQ(engine_->threads(), 2);
}

TEST_F(EngineApiTest, BadObservationsAreNamed) {
  const auto& cam = engine_->model_info().cameras[0];
  {
    Observation obs = observation();
    obs.images[0].width = cam.width - 1;
    expect_invalid(obs, "the model expects 96x128");
  }
  {
    Observation obs = observation();
    obs.images.clear();
    expect_invalid(obs, "0 images");
  }
  {
    Observation obs = observation();
    obs.images[0].data = nullptr;
    expect_invalid(obs, "no data");
  }
  {
    Observation obs = observation();
    const std::vector<float> short_state = {1.0f};
    obs.state = short_state;
    expect_invalid(obs, "state has 1 values");
  }
  {
    Observation obs = observation();
    const std::vector<float> nan_state = {1.0f, NAN};
    obs.state = nan_state;
    expect_invalid(obs, "state[1] is not finite");
  }
  {
    Observation obs = observation();
    const std::vector<float> env = {1.0f};
    obs.env_state = env;
    expect_invalid(obs, "no environment state");
  }
  {
    std::vector<float> chw(3 * static_cast<size_t>(cam.height) * cam.width, 0.5f);
    chw[17] = INFINITY;
    Observation obs = observation();
    obs.images = {ImageView::rgb_f32_chw(chw.data(), cam.height, cam.width)};
    expect_invalid(obs, "NaN or Inf");
  }
  {
    // A 0-255 float image, and one far outside any range: refused, not turned into NaN actions.
    for (const float value : {255.0f, 1e30f, -0.5f}) {
      std::vector<float> chw(3 * static_cast<size_t>(cam.height) * cam.width, 0.5f);
      chw[chw.size() / 2] = value;
      Observation obs = observation();
      obs.images = {ImageView::rgb_f32_chw(chw.data(), cam.height, cam.width)};
      expect_invalid(obs, "float images hold [0, 1]");
    }
    std::vector<float> scaled(3 * static_cast<size_t>(cam.height) * cam.width, 200.0f);
    Observation obs = observation();
    obs.images = {ImageView::rgb_f32_chw(scaled.data(), cam.height, cam.width)};
    expect_invalid(obs, "a 0-255 image?");
  }
  {
    // A finite but absurd state once gave NaN actions with an OK status.
    Observation obs = observation();
    const std::vector<float> huge_state = {1.0f, 3e38f};
    obs.state = huge_state;
    expect_invalid(obs, "state[1] = 3e+38");
  }
  {
    std::vector<float> too_small(3);
    EXPECT_EQ(engine_->infer(observation(), too_small).code(), StatusCode::kInvalidArgument);
  }
}

TEST_F(EngineApiTest, NonFiniteOutputIsAnErrorNotAnAnswer) {
  // A damaged blob whose every number passes Engine::open's checks (the action head's weights at
  // 1e6, an action standard deviation of 3e38: finite, and statistics may be large) still
  // overflows the actions: infer must say so instead of returning OK with infinities (act_eval
  // once wrote -inf and exited 0).
  const std::string path = scratch_ + "/damaged.actb";
  rewrite_blob(blob_, path, [](nlohmann::json&, std::vector<TensorCopy>& tensors) {
    for (const auto& [name, value] : {std::pair{blob_names::kHeadWeight, 1e6f}, std::pair{blob_names::kUnnormScale, 3e38f}}) {
      TensorCopy& t = tensor_named(tensors, name);
      const std::vector<float> values(t.bytes.size() / sizeof(float), value);
      std::memcpy(t.bytes.data(), values.data(), t.bytes.size());
    }
  });
  auto engine = Engine::open(path, {.threads = 1});
  ASSERT_TRUE(engine.ok()) << engine.status().to_string();
  auto out = chunk();
  const Status s = (*engine)->infer(observation(), out);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << s.to_string();
  EXPECT_NE(s.message().find("is not finite"), std::string::npos) << s.message();
}

TEST_F(EngineApiTest, RowStrideIsHonoured) {
  const auto& cam = engine_->model_info().cameras[0];
  const size_t row = static_cast<size_t>(cam.width) * 3, stride = row + 13;
  std::vector<uint8_t> padded(stride * cam.height, 255);
  for (int y = 0; y < cam.height; ++y) std::copy_n(image_.data() + y * row, row, padded.data() + y * stride);
  Observation obs = observation();
  auto expected = chunk(), got = chunk();
  ASSERT_TRUE(engine_->infer(obs, expected).ok());
  obs.images = {ImageView::rgb_u8(padded.data(), cam.height, cam.width, stride)};
  ASSERT_TRUE(engine_->infer(obs, got).ok());
  EXPECT_EQ(expected, got);
}

TEST_F(EngineApiTest, SameResultForAnyThreadCountAndMemoryPlan) {
  auto reference = chunk();
  ASSERT_TRUE(engine_->infer(observation(), reference).ok());
  for (int threads : {1, 3}) {
    for (bool keep_all : {false, true}) {
      auto engine = Engine::open(blob_, {.threads = threads, .keep_intermediates = keep_all});
      ASSERT_TRUE(engine.ok()) << engine.status().to_string();
      auto raw = chunk();
      ASSERT_TRUE((*engine)->infer(observation(), raw).ok());
      // Tiles are split the same way whatever the thread count, so results are bit-identical.
      EXPECT_EQ(raw, reference) << threads << " threads, keep_all " << keep_all;
    }
  }
  // Repeated runs reuse the planned buffers and give the same answer.
  auto again = chunk();
  ASSERT_TRUE(engine_->infer(observation(), again).ok());
  EXPECT_EQ(again, reference);
}

TEST_F(EngineApiTest, TwoEnginesRunSideBySide) {
  auto reference = chunk();
  ASSERT_TRUE(engine_->infer(observation(), reference).ok());
  auto other = Engine::open(blob_, {.threads = 1});
  ASSERT_TRUE(other.ok());
  std::vector<std::vector<float>> results(2, chunk());
  std::vector<Status> statuses(2);
  Engine* engines[2] = {engine_.get(), other->get()};
  std::vector<std::thread> threads;
  for (int t = 0; t < 2; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < 5 && statuses[t].ok(); ++i) statuses[t] = engines[t]->infer(observation(), results[t]);
    });
  }
  for (auto& th : threads) th.join();
  for (int t = 0; t < 2; ++t) {
    EXPECT_TRUE(statuses[t].ok()) << statuses[t].to_string();
    EXPECT_EQ(results[t], reference);
  }
}

TEST_F(EngineApiTest, OneEngineHandedFromThreadToThread) {
  // One Engine, never used by two threads at once but by several in turn (as act_drive hands it
  // from its loader thread to its control loop): same answers, and nothing for TSan to report.
  auto reference = chunk();
  ASSERT_TRUE(engine_->infer(observation(), reference).ok());
  for (int turn = 0; turn < 3; ++turn) {
    auto result = chunk();
    Status status;
    std::thread([&] { status = engine_->infer(observation(), result); }).join();
    EXPECT_TRUE(status.ok()) << status.to_string();
    EXPECT_EQ(result, reference) << "turn " << turn;
  }
}

TEST_F(EngineApiTest, EnginesOpenAndRunConcurrently) {
  // Opening touches process-wide state (CPU detection, kernel dispatch): several at once must be safe.
  auto reference = chunk();
  ASSERT_TRUE(engine_->infer(observation(), reference).ok());
  constexpr int kEngines = 3;
  std::vector<std::vector<float>> results(kEngines, chunk());
  std::vector<Status> statuses(kEngines);
  std::vector<std::thread> threads;
  for (int t = 0; t < kEngines; ++t) {
    threads.emplace_back([&, t] {
      auto e = Engine::open(blob_, {.threads = 1 + t % 2});
      statuses[t] = e.ok() ? (*e)->infer(observation(), results[t]) : e.status();
    });
  }
  for (auto& th : threads) th.join();
  for (int t = 0; t < kEngines; ++t) {
    EXPECT_TRUE(statuses[t].ok()) << statuses[t].to_string();
    EXPECT_EQ(results[t], reference) << "engine " << t;
  }
}

// Sets ACT_ISA for one scope (nullptr: unset), restoring the previous value.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const char* value) : name_(name) {
    const char* old = std::getenv(name);
    had_ = old != nullptr;
    if (had_) old_ = old;
    if (value != nullptr) {
      setenv(name, value, 1);
    } else {
      unsetenv(name);
    }
  }
  ~ScopedEnv() {
    if (had_) {
      setenv(name_, old_.c_str(), 1);
    } else {
      unsetenv(name_);
    }
  }

 private:
  const char* name_;
  bool had_ = false;
  std::string old_;
};

// "x86-64 runs ref, avx2, ...": the list every ISA error ends with.
std::string isas_this_cpu_runs() { return "this CPU runs " + kernels::isa_mask_names(kernels::cpu_isa_mask()); }

TEST_F(EngineApiTest, BadIsaOverrideIsAnError) {
  ScopedEnv env("ACT_ISA", "sse9");
  auto e = Engine::open(blob_);
  EXPECT_EQ(e.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(e.status().message(), "ACT_ISA: unknown ISA 'sse9': " + isas_this_cpu_runs());
  // An explicit option is not overridden.
  auto ref = Engine::open(blob_, {.threads = 2, .isa = "ref"});
  ASSERT_TRUE(ref.ok()) << ref.status().to_string();
  EXPECT_EQ((*ref)->model_info().isa, "ref");
  ScopedEnv ref_env("ACT_ISA", "ref");
  auto from_env = Engine::open(blob_, {.threads = 2});
  ASSERT_TRUE(from_env.ok()) << from_env.status().to_string();
  EXPECT_EQ((*from_env)->model_info().isa, "ref");
}

TEST_F(EngineApiTest, BadIsaOptionIsAnError) {
  ScopedEnv env("ACT_ISA", nullptr);
  auto bogus = Engine::open(blob_, {.isa = "bogus"});
  EXPECT_EQ(bogus.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(bogus.status().message(), "EngineOptions::isa: unknown ISA 'bogus': " + isas_this_cpu_runs());
#if defined(__x86_64__)
  const std::string foreign = "neondot";
#else
  const std::string foreign = "avx2";
#endif
  auto lacking = Engine::open(blob_, {.isa = foreign});
  EXPECT_EQ(lacking.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(lacking.status().message(),
            "EngineOptions::isa: ISA '" + foreign + "' is not supported by this CPU: " + isas_this_cpu_runs());
}

// Every tuning runs on every CPU and says which it is; an unknown one is an error naming its source.
TEST_F(EngineApiTest, TuningOptionAndOverride) {
  ScopedEnv no_env("ACT_UARCH", nullptr);
  auto want = chunk();
  {
    auto e = Engine::open(blob_, {.threads = 2});
    ASSERT_TRUE(e.ok()) << e.status().to_string();
    ASSERT_TRUE((*e)->infer(observation(), want).ok());
    const std::string detected = kernels::uarch_name(kernels::cpu_features().uarch);
    EXPECT_NE((*e)->model_info().kernels.find(", tuned for " + detected + ": "), std::string::npos)
        << (*e)->model_info().kernels;
  }
  for (int i = 0; i < kernels::kUarchCount; ++i) {
    const std::string name = kernels::uarch_name(static_cast<kernels::Uarch>(i));
    auto e = Engine::open(blob_, {.threads = 2, .uarch = name});
    ASSERT_TRUE(e.ok()) << e.status().to_string();
    EXPECT_NE((*e)->model_info().kernels.find(", tuned for " + name + ": "), std::string::npos)
        << (*e)->model_info().kernels;
    auto got = chunk();
    ASSERT_TRUE((*e)->infer(observation(), got).ok());
    for (size_t j = 0; j < got.size(); ++j) EXPECT_NEAR(got[j], want[j], 1e-4 * (1 + std::fabs(want[j]))) << name << " " << j;
  }
  const std::string choices = "choose auto or one of " + kernels::uarch_names();
  auto bogus = Engine::open(blob_, {.uarch = "zen9"});
  EXPECT_EQ(bogus.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(bogus.status().message(), "EngineOptions::uarch: unknown tuning 'zen9': " + choices);
  ScopedEnv env("ACT_UARCH", "Zen4");
  auto from_env = Engine::open(blob_);
  EXPECT_EQ(from_env.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(from_env.status().message(), "ACT_UARCH: unknown tuning 'Zen4': " + choices);
  ScopedEnv good_env("ACT_UARCH", "gracemont");
  auto tuned = Engine::open(blob_, {.threads = 2});
  ASSERT_TRUE(tuned.ok()) << tuned.status().to_string();
  EXPECT_NE((*tuned)->model_info().kernels.find(", tuned for gracemont: "), std::string::npos);
}

// Every ISA this CPU runs gives an Engine of that level, describing its kernels, whose actions agree
// with the default Engine's (FP32: the GEMMs may sum in another order).
TEST_F(EngineApiTest, EveryIsaThisCpuRunsGivesTheSameActions) {
  ScopedEnv env("ACT_ISA", nullptr);  // the fixture's engine_ took ACT_ISA when the run sets it: open one without
  auto best = Engine::open(blob_, {.threads = 2});
  ASSERT_TRUE(best.ok()) << best.status().to_string();
  auto want = chunk();
  ASSERT_TRUE((*best)->infer(observation(), want).ok());
  EXPECT_EQ((*best)->model_info().isa, kernels::isa_name(kernels::best_cpu_isa()));
  for (kernels::Isa isa : kernels::cpu_isas()) {
    const std::string name = kernels::isa_name(isa);
    auto e = Engine::open(blob_, {.threads = 2, .isa = name});
    ASSERT_TRUE(e.ok()) << e.status().to_string();
    EXPECT_EQ((*e)->model_info().isa, name);
    EXPECT_EQ((*e)->model_info().kernels.rfind(name + ", tuned for ", 0), 0u) << (*e)->model_info().kernels;
    auto got = chunk();
    ASSERT_TRUE((*e)->infer(observation(), got).ok());
    for (size_t i = 0; i < got.size(); ++i) EXPECT_NEAR(got[i], want[i], 1e-4 * (1 + std::fabs(want[i]))) << name << " " << i;
  }
}

TEST_F(EngineApiTest, ProfilingReportsEveryStage) {
  auto chunk_out = chunk();
  ASSERT_TRUE(engine_->infer(observation(), chunk_out).ok());
  EXPECT_EQ(engine_->last_timings().total_ms, 0.0) << "profiling is off by default";
  auto profiled = Engine::open(blob_, {.threads = 2, .profile = true});
  ASSERT_TRUE(profiled.ok());
  ASSERT_TRUE((*profiled)->infer(observation(), chunk_out).ok());
  const InferenceTimings& t = (*profiled)->last_timings();
  for (double stage : {t.preprocess_ms, t.backbone_ms, t.encoder_ms, t.decoder_ms}) {
    EXPECT_GT(stage, 0.0);
    EXPECT_LT(stage, t.total_ms);
  }
  EXPECT_GE(t.other_ms, 0.0);
}

// The op profile: every op once, with its kind, kernel and stage; its sums reset; the stage times
// are the sums of their ops' times. The trace: one slice per op on the caller's lane, in order, and
// each worker slice inside its op's.
TEST_F(EngineApiTest, ProfilerTimesEveryOpAndTracesEveryThread) {
  auto chunk_out = chunk();
  EXPECT_TRUE(engine_->op_profile().empty()) << "profiling is off by default";
  EXPECT_EQ(engine_->chrome_trace().status().code(), StatusCode::kFailedPrecondition);

  auto profiled = Engine::open(blob_, {.threads = 2, .profile = true});
  ASSERT_TRUE(profiled.ok()) << profiled.status().to_string();
  Engine& e = **profiled;
  EXPECT_EQ(e.chrome_trace().status().code(), StatusCode::kFailedPrecondition) << "before the first inference";
  for (int run = 0; run < 3; ++run) ASSERT_TRUE(e.infer(observation(), chunk_out).ok());
  std::vector<OpProfile> ops = e.op_profile();
  ASSERT_GT(ops.size(), 20u);
  std::set<std::string> names;
  double macs = 0;
  for (const OpProfile& op : ops) {
    EXPECT_TRUE(names.insert(op.name).second) << "op named twice: " << op.name;
    EXPECT_EQ(op.runs, 3) << op.name;
    EXPECT_GE(op.total_ms, 0.0) << op.name;
    EXPECT_FALSE(op.kind.empty()) << op.name;
    EXPECT_FALSE(op.kernel.empty()) << op.name;
    if (op.kind.rfind("conv2d", 0) == 0) {
      EXPECT_GT(op.macs, 0.0) << op.name;
      EXPECT_EQ(op.stage, "backbone") << op.name;
    }
    macs += op.macs;
  }
  EXPECT_GT(macs, 0.0);

  e.reset_op_profile();
  for (const OpProfile& op : e.op_profile()) EXPECT_EQ(op.runs, 0) << op.name;
  ASSERT_TRUE(e.infer(observation(), chunk_out).ok());
  ops = e.op_profile();
  std::map<std::string, double> stage_ms;
  for (const OpProfile& op : ops) {
    EXPECT_EQ(op.runs, 1) << op.name;
    stage_ms[op.stage] += op.total_ms;
  }
  const InferenceTimings& t = e.last_timings();
  EXPECT_NEAR(stage_ms["backbone"], t.backbone_ms, 1e-9 * t.total_ms);
  EXPECT_NEAR(stage_ms["encoder"], t.encoder_ms, 1e-9 * t.total_ms);
  EXPECT_NEAR(stage_ms["decoder"], t.decoder_ms, 1e-9 * t.total_ms);

  // One inference of the tiny model takes a millisecond or two: on a loaded machine the worker may
  // not be scheduled in time to take a tile of any op, so trace further inferences until it does.
  std::map<int, std::vector<nlohmann::json>> lanes;
  std::set<int> named_lanes;
  for (int attempt = 0; attempt < 100 && lanes[1].empty(); ++attempt) {
    if (attempt > 0) {
      ASSERT_TRUE(e.infer(observation(), chunk_out).ok());
    }
    const auto trace = e.chrome_trace();
    ASSERT_TRUE(trace.ok()) << trace.status().to_string();
    lanes.clear();
    named_lanes.clear();
    const nlohmann::json j = nlohmann::json::parse(*trace);
    for (const auto& ev : j.at("traceEvents")) {
      if (ev.at("ph") == "X") lanes[ev.at("tid").get<int>()].push_back(ev);
      if (ev.at("ph") == "M") named_lanes.insert(ev.at("tid").get<int>());
    }
  }
  EXPECT_EQ(named_lanes, (std::set<int>{0, 1}));
  const std::vector<nlohmann::json>& caller = lanes[0];
  ASSERT_EQ(caller.size(), ops.size());
  std::map<std::string, std::pair<double, double>> op_span;
  for (size_t i = 0; i < caller.size(); ++i) {
    EXPECT_EQ(caller[i].at("name"), ops[i].name);
    const double start = caller[i].at("ts"), end = start + caller[i].at("dur").get<double>();
    if (i > 0) {
      EXPECT_GE(start, op_span[ops[i - 1].name].second - 1e-3) << "ops overlap on the caller's lane";
    }
    op_span[ops[i].name] = {start, end};
  }
  ASSERT_FALSE(lanes[1].empty()) << "the worker took no tile of any op";
  for (const auto& ev : lanes[1]) {
    const auto [op_start, op_end] = op_span.at(ev.at("name").get<std::string>());
    const double start = ev.at("ts"), end = start + ev.at("dur").get<double>();
    EXPECT_GE(start, op_start - 1e-3) << ev.dump();
    EXPECT_LE(end, op_end + 1e-3) << ev.dump();
  }
}

TEST_F(EngineApiTest, IntermediatesAreReadAfterARunWhenKept) {
  const std::vector<std::string> names = engine_->intermediate_names();
  for (const char* name : {"cam0.image", "state", "cam0.backbone.layer4", "encoder_layer0_out", "actions_normalized"}) {
    EXPECT_NE(std::find(names.begin(), names.end(), name), names.end()) << name;
  }
  const auto not_kept = engine_->intermediate("actions_normalized");
  EXPECT_EQ(not_kept.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(not_kept.status().message().find("keep_intermediates"), std::string::npos) << not_kept.status().message();

  auto kept = Engine::open(blob_, {.threads = 2, .keep_intermediates = true});
  ASSERT_TRUE(kept.ok()) << kept.status().to_string();
  EXPECT_EQ((*kept)->intermediate_names(), names);
  EXPECT_EQ((*kept)->intermediate("actions_normalized").status().code(), StatusCode::kFailedPrecondition)
      << "before the first inference";
  auto normalized = chunk();
  ASSERT_TRUE((*kept)->infer_normalized(observation(), normalized).ok());
  const auto actions = (*kept)->intermediate("actions_normalized");
  ASSERT_TRUE(actions.ok()) << actions.status().to_string();
  EXPECT_EQ(actions.value(), normalized);
  const auto state = (*kept)->intermediate("state");
  ASSERT_TRUE(state.ok()) << state.status().to_string();
  EXPECT_EQ(state->size(), state_.size());
  const auto unknown = (*kept)->intermediate("cam7.backbone");
  EXPECT_EQ(unknown.status().code(), StatusCode::kNotFound);
  EXPECT_NE(unknown.status().message().find("cam7.backbone"), std::string::npos) << unknown.status().message();
}

TEST_F(EngineApiTest, Int8IntermediatesAreDequantized) {
  // Static INT8 with each activation's scale taken from its own FP32 range on this observation.
  auto fp32 = Engine::open(blob_, {.threads = 2, .keep_intermediates = true});
  ASSERT_TRUE(fp32.ok()) << fp32.status().to_string();
  auto fp32_actions = chunk();
  ASSERT_TRUE((*fp32)->infer(observation(), fp32_actions).ok());
  QuantConfig quant;
  quant.mode = QuantMode::kStatic;
  quant.calibration = "max";
  for (const std::string& name : (*fp32)->intermediate_names()) {
    const auto values = (*fp32)->intermediate(name);
    ASSERT_TRUE(values.ok()) << values.status().to_string();
    float max_abs = 0;
    for (float v : values.value()) max_abs = std::max(max_abs, std::abs(v));
    quant.activations[name] = {std::max(max_abs, 1e-3f) / 127.0f, 0};
  }
  const ImportedModel model = import_lerobot_checkpoint(test::fixture_dir("act-tiny"));
  const std::string int8_blob = scratch_ + "/static.actb";
  write_int8_blob(model, quant, int8_blob);
  auto int8 = Engine::open(int8_blob, {.threads = 2, .keep_intermediates = true});
  ASSERT_TRUE(int8.ok()) << int8.status().to_string();
  auto int8_actions = chunk();
  ASSERT_TRUE((*int8)->infer(observation(), int8_actions).ok());

  // An int8 value comes back as scale * q: whole multiples of its scale, near the float value.
  const std::string name = "cam0.backbone.layer1";
  const auto dequantized = (*int8)->intermediate(name);
  ASSERT_TRUE(dequantized.ok()) << dequantized.status().to_string();
  const auto reference = (*fp32)->intermediate(name);
  ASSERT_TRUE(reference.ok());
  ASSERT_EQ(dequantized->size(), reference->size());
  const float scale = quant.activations.at(name).scale;
  double error = 0, magnitude = 0;
  size_t nonzero = 0;
  for (size_t i = 0; i < dequantized->size(); ++i) {
    const float steps = dequantized.value()[i] / scale;
    ASSERT_NEAR(steps, std::round(steps), 1e-3) << "value " << i << " is not a multiple of the scale";
    nonzero += steps != 0;
    error += std::abs(dequantized.value()[i] - reference.value()[i]);
    magnitude += std::abs(reference.value()[i]);
  }
  EXPECT_GT(nonzero, dequantized->size() / 10);
  EXPECT_LT(error, 0.2 * magnitude);

  // The int8 stem takes the pixels straight to int8 codes (no float image): the image comes back as
  // the normalised FP32 image quantized with its scale, and the same picture as float CHW in [0, 1]
  // (v / 255, what the uint8 path computes) gives bit-identical actions.
  const auto image_codes = (*int8)->intermediate("cam0.image");
  const auto image_float = (*fp32)->intermediate("cam0.image");
  ASSERT_TRUE(image_codes.ok() && image_float.ok());
  ASSERT_EQ(image_codes->size(), image_float->size());
  const float image_scale = quant.activations.at("cam0.image").scale;
  for (size_t i = 0; i < image_codes->size(); ++i) {
    ASSERT_FLOAT_EQ(image_codes.value()[i], image_scale * std::nearbyint(image_float.value()[i] / image_scale)) << "pixel value " << i;
  }
  const auto& cam = (*int8)->model_info().cameras.at(0);
  std::vector<float> chw(image_.size());
  const size_t plane = chw.size() / 3;
  for (size_t i = 0; i < plane; ++i) {
    for (size_t c = 0; c < 3; ++c) chw[c * plane + i] = static_cast<float>(image_[3 * i + c]) / 255.0f;
  }
  Observation as_float = observation();
  as_float.images = {ImageView::rgb_f32_chw(chw.data(), cam.height, cam.width)};
  auto int8_actions_from_float = chunk();
  ASSERT_TRUE((*int8)->infer(as_float, int8_actions_from_float).ok());
  EXPECT_EQ(int8_actions_from_float, int8_actions);

  // Every ISA's kernels give the int8 backbone the same bits, the image's codes stored signed
  // (AVX2, NEON) or unsigned (AVX-512 VNNI's stem reads them without row sums).
  const auto layer4 = (*int8)->intermediate("cam0.backbone.layer4");
  ASSERT_TRUE(layer4.ok()) << layer4.status().to_string();
  for (kernels::Isa isa : kernels::cpu_isas()) {
    auto at_isa = Engine::open(int8_blob, {.threads = 2, .keep_intermediates = true, .isa = kernels::isa_name(isa)});
    ASSERT_TRUE(at_isa.ok()) << at_isa.status().to_string();
    auto actions = chunk();
    ASSERT_TRUE((*at_isa)->infer(observation(), actions).ok());
    EXPECT_EQ((*at_isa)->intermediate("cam0.image").value(), image_codes.value()) << kernels::isa_name(isa);
    EXPECT_EQ((*at_isa)->intermediate("cam0.backbone.layer4").value(), layer4.value()) << kernels::isa_name(isa);
  }

  // Dynamic INT8 quantizes at run time and keeps no scale: such a value cannot be read as floats.
  const std::string dynamic_blob = scratch_ + "/dynamic.actb";
  write_int8_blob(model, QuantConfig{}, dynamic_blob);
  auto dynamic = Engine::open(dynamic_blob, {.threads = 2, .keep_intermediates = true});
  ASSERT_TRUE(dynamic.ok()) << dynamic.status().to_string();
  ASSERT_TRUE((*dynamic)->infer(observation(), int8_actions).ok());
  const std::vector<std::string> names = (*dynamic)->intermediate_names();
  const auto run_time = std::find_if(names.begin(), names.end(), [](const std::string& n) { return n.ends_with(".s8dyn"); });
  ASSERT_NE(run_time, names.end());
  EXPECT_EQ((*dynamic)->intermediate(*run_time).status().code(), StatusCode::kUnimplemented);
  EXPECT_TRUE((*dynamic)->intermediate("cam0.backbone.layer1").ok());
}

TEST_F(EngineApiTest, ActionRangeIsTheUnnormalisationOfMinusOneAndOne) {
  const ModelInfo& info = engine_->model_info();
  ASSERT_EQ(info.action_low.size(), static_cast<size_t>(info.action_dim));
  ASSERT_EQ(info.action_high.size(), static_cast<size_t>(info.action_dim));
  // act-tiny's actions are MEAN_STD: -1 and +1 stand for mean -/+ std, so the midpoint is the mean
  // and both ends are finite and ordered.
  for (int i = 0; i < info.action_dim; ++i) {
    EXPECT_TRUE(std::isfinite(info.action_low[i]) && std::isfinite(info.action_high[i]));
    EXPECT_LT(info.action_low[i], info.action_high[i]);
  }
}

TEST_F(EngineApiTest, TheRunningModelCannotChangeUnderIt) {
  // Copying another model over the open blob (cp and scp rewrite the same inode) once changed the
  // weights mid-run, and truncating it killed the process with SIGBUS: the Engine reads its own copy.
  const std::string legacy = test::fixture_dir("act-tiny-legacy");
  ACT_REQUIRE_PATH(legacy);
  const std::string path = scratch_ + "/running.actb";
  fs::copy_file(blob_, path);
  auto running = Engine::open(path, {.threads = 1});
  ASSERT_TRUE(running.ok()) << running.status().to_string();
  auto before = chunk();
  ASSERT_TRUE((*running)->infer(observation(), before).ok());

  const std::vector<uint8_t> other = test::read_file(test::convert_checkpoint(legacy, scratch_, "other"));
  test::write_file(path, other);  // in place: same inode, as cp does
  auto after_rewrite = chunk();
  ASSERT_TRUE((*running)->infer(observation(), after_rewrite).ok());
  EXPECT_EQ(after_rewrite, before);

  ASSERT_EQ(::truncate(path.c_str(), 100), 0);
  auto after_truncation = chunk();
  ASSERT_TRUE((*running)->infer(observation(), after_truncation).ok());
  EXPECT_EQ(after_truncation, before);
}

TEST_F(EngineApiTest, CorruptBlobsAreClearErrors) {
  {
    auto e = Engine::open(scratch_ + "/missing.actb");
    EXPECT_EQ(e.status().code(), StatusCode::kNotFound);
    EXPECT_NE(e.status().message().find("missing.actb"), std::string::npos);
  }
  const auto size = fs::file_size(blob_);
  for (uintmax_t cut : {uintmax_t{0}, uintmax_t{7}, uintmax_t{100}, size / 2, size - 1}) {
    const std::string path = scratch_ + "/cut" + std::to_string(cut) + ".actb";
    fs::copy_file(blob_, path);
    fs::resize_file(path, cut);
    auto e = Engine::open(path);
    EXPECT_FALSE(e.ok()) << "truncated to " << cut;
    EXPECT_EQ(e.status().code(), StatusCode::kDataLoss) << e.status().to_string();
    EXPECT_NE(e.status().message().find(path), std::string::npos) << e.status().message();
  }
  {
    const std::string path = scratch_ + "/flipped.actb";
    fs::copy_file(blob_, path);
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(size - 1000));
    f.put('\x5a');
    f.close();
    auto e = Engine::open(path);
    EXPECT_EQ(e.status().code(), StatusCode::kDataLoss);
    EXPECT_NE(e.status().message().find("checksum"), std::string::npos) << e.status().message();
  }
  auto negative = Engine::open(blob_, {.threads = -1});
  EXPECT_EQ(negative.status().code(), StatusCode::kInvalidArgument);
}

// A blob whose config says one thing and whose tensors another (checksum intact) once opened and
// ran: each such contradiction is now a kDataLoss error naming the blob and what disagrees.
class BlobSemanticsTest : public EngineApiTest {
 protected:
  void expect_refused(const std::string& source, const std::string& name,
                      const std::function<void(nlohmann::json&, std::vector<TensorCopy>&)>& edit,
                      const std::vector<std::string>& needles) {
    const std::string path = scratch_ + "/" + name + ".actb";
    rewrite_blob(source, path, edit);
    auto e = Engine::open(path, {.threads = 1});
    ASSERT_FALSE(e.ok()) << name << " opened";
    EXPECT_EQ(e.status().code(), StatusCode::kDataLoss) << name << ": " << e.status().to_string();
    std::vector<std::string> expected = needles;
    expected.push_back(path);
    for (const std::string& needle : expected) {
      EXPECT_NE(e.status().message().find(needle), std::string::npos) << name << ": " << e.status().message()
                                                                      << " (expected: " << needle << ")";
    }
  }
  // act-tiny in dynamic INT8, written once per test (5-7 s under qemu).
  std::string int8_blob() {
    const std::string path = scratch_ + "/dynamic.actb";
    if (!fs::exists(path)) {
      write_int8_blob(import_lerobot_checkpoint(test::fixture_dir("act-tiny")), QuantConfig{}, path);
    }
    return path;
  }
  static nlohmann::json* input_norm_entry(nlohmann::json& config, const std::string& key) {
    for (auto& e : config["input_norm"]) {
      if (e["key"] == key) return &e;
    }
    return nullptr;
  }
};

TEST_F(BlobSemanticsTest, RewrittenBlobStillOpens) {
  // The edits below are the only difference: an unchanged rewrite opens and gives the same actions.
  const std::string path = scratch_ + "/same.actb";
  rewrite_blob(blob_, path, [](nlohmann::json&, std::vector<TensorCopy>&) {});
  auto e = Engine::open(path, {.threads = 2});
  ASSERT_TRUE(e.ok()) << e.status().to_string();
  auto ours = chunk(), theirs = chunk();
  ASSERT_TRUE(engine_->infer(observation(), ours).ok());
  ASSERT_TRUE((*e)->infer(observation(), theirs).ok());
  EXPECT_EQ(ours, theirs);
  const std::string int8 = int8_blob();
  EXPECT_TRUE(Engine::open(int8).ok());
}

TEST_F(BlobSemanticsTest, Int8WeightsMustBeSymmetric) {
  const std::string weight = blob_names::enc(0, "linear1.weight");
  expect_refused(int8_blob(), "zero_point", [&](nlohmann::json&, std::vector<TensorCopy>& tensors) {
    tensor_named(tensors, weight).quant.zero_points[3] = 5;
  }, {weight, "zero point 5", "symmetric"});
  expect_refused(int8_blob(), "per_tensor", [&](nlohmann::json&, std::vector<TensorCopy>& tensors) {
    TensorCopy& t = tensor_named(tensors, weight);
    t.quant = {{0.01f}, {0}, 0};
  }, {weight, "one scale per output channel"});
  expect_refused(blob_, "int8_in_fp32", [&](nlohmann::json&, std::vector<TensorCopy>& tensors) {
    TensorCopy& t = tensor_named(tensors, weight);
    t.dtype = DType::kI8;
    t.bytes.assign(t.bytes.size() / sizeof(float), 1);  // valid int8 values: only the precision is wrong
    t.quant = {std::vector<float>(static_cast<size_t>(t.shape[0]), 0.01f), std::vector<int32_t>(static_cast<size_t>(t.shape[0]), 0), 0};
  }, {weight, "precision is not int8"});
  expect_refused(blob_, "quant_on_float", [&](nlohmann::json&, std::vector<TensorCopy>& tensors) {
    tensor_named(tensors, blob_names::kHeadBias).quant = {{0.5f}, {0}, 0};
  }, {blob_names::kHeadBias, "quantization parameters"});
}

// A tampered blob (checksum recomputed) with an absurd number opened, and the damage showed only as
// a non-finite output at the first inference: the numbers the kernels read are checked at open.
TEST_F(BlobSemanticsTest, StoredNumbersMustBePlausible) {
  const std::string weight = blob_names::enc(0, "linear1.weight");
  const auto set_f32 = [](TensorCopy& t, size_t index, float value) {
    std::memcpy(t.bytes.data() + index * sizeof(float), &value, sizeof value);
  };
  expect_refused(blob_, "huge_weight", [&](nlohmann::json&, std::vector<TensorCopy>& tensors) {
    set_f32(tensor_named(tensors, weight), 7, 1e30f);
  }, {weight, "holds 1e+30 at index 7", "the limit is 1e+08"});
  expect_refused(blob_, "nan_bias", [&](nlohmann::json&, std::vector<TensorCopy>& tensors) {
    set_f32(tensor_named(tensors, blob_names::kHeadBias), 1, std::nanf(""));
  }, {blob_names::kHeadBias, "at index 1", "finite"});
  const std::string divisor = blob_names::norm_div("observation.state");
  expect_refused(blob_, "zero_divisor", [&](nlohmann::json&, std::vector<TensorCopy>& tensors) {
    set_f32(tensor_named(tensors, divisor), 0, 0.0f);
  }, {divisor, "holds 0 at index 0", "divisor"});
  expect_refused(int8_blob(), "huge_scale", [&](nlohmann::json&, std::vector<TensorCopy>& tensors) {
    tensor_named(tensors, weight).quant.scales[3] = 1.8e19f;
  }, {weight, "int8 scale 1.8e+19 for channel 3"});
  expect_refused(int8_blob(), "subnormal_scale", [&](nlohmann::json&, std::vector<TensorCopy>& tensors) {
    tensor_named(tensors, weight).quant.scales[0] = 1e-40f;
  }, {weight, "for channel 0", "outside ["});
  expect_refused(int8_blob(), "int8_minus_128", [&](nlohmann::json&, std::vector<TensorCopy>& tensors) {
    tensor_named(tensors, weight).bytes[5] = 0x80;
  }, {weight, "holds -128 at index 5", "[-127, 127]"});
  // A static blob's activation scales: the inverse of each quantizes a whole activation.
  QuantConfig quant;
  quant.mode = QuantMode::kStatic;
  for (const std::string& name : engine_->intermediate_names()) quant.activations[name] = {0.01f, 0};
  const std::string static_blob = scratch_ + "/static.actb";
  write_int8_blob(import_lerobot_checkpoint(test::fixture_dir("act-tiny")), quant, static_blob);
  const std::string activation = quant.activations.begin()->first;
  expect_refused(static_blob, "huge_activation_scale", [&](nlohmann::json& config, std::vector<TensorCopy>&) {
    config["quantization"]["activations"][activation] = {1.8e19, 0};
  }, {"activation \"" + activation + "\"", "scale 1.8e+19 is outside"});
  expect_refused(static_blob, "activation_zero_point", [&](nlohmann::json& config, std::vector<TensorCopy>&) {
    config["quantization"]["activations"][activation] = {0.01, 300};
  }, {"activation \"" + activation + "\"", "zero point 300"});
}

TEST_F(BlobSemanticsTest, InputNormMustNameEveryInputFeature) {
  expect_refused(blob_, "norm_missing", [](nlohmann::json& config, std::vector<TensorCopy>&) {
    nlohmann::json kept = nlohmann::json::array();
    for (const auto& e : config["input_norm"]) {
      if (e["key"] != "observation.state") kept.push_back(e);
    }
    config["input_norm"] = kept;
  }, {"input_norm", "\"observation.state\""});
  expect_refused(blob_, "norm_extra", [](nlohmann::json& config, std::vector<TensorCopy>&) {
    config["input_norm"].push_back({{"key", "observation.images.back"}, {"mode", "IDENTITY"}});
  }, {"input_norm", "observation.images.back", "no input feature"});
  expect_refused(blob_, "norm_twice", [](nlohmann::json& config, std::vector<TensorCopy>&) {
    config["input_norm"].push_back({{"key", "observation.state"}, {"mode", "IDENTITY"}});
  }, {"input_norm", "observation.state", "twice"});
  expect_refused(blob_, "norm_empty", [](nlohmann::json& config, std::vector<TensorCopy>&) {
    config["input_norm"] = nlohmann::json::array();
  }, {"input_norm", "observation.images.front"});
  expect_refused(blob_, "norm_null", [](nlohmann::json& config, std::vector<TensorCopy>&) {
    config["input_norm"] = nullptr;
  }, {"input_norm", "array"});
  // IDENTITY for a feature whose statistics the blob holds: the statistics nobody reads are named.
  expect_refused(blob_, "norm_identity", [](nlohmann::json& config, std::vector<TensorCopy>&) {
    (*input_norm_entry(config, "observation.state"))["mode"] = "IDENTITY";
  }, {"does not use", blob_names::norm_sub("observation.state")});
}

TEST_F(BlobSemanticsTest, EveryTensorMustBeUsed) {
  expect_refused(blob_, "fewer_layers", [](nlohmann::json& config, std::vector<TensorCopy>&) {
    config["n_encoder_layers"] = 1;
  }, {"does not use", blob_names::enc(1, "")});
  expect_refused(blob_, "extra_tensor", [](nlohmann::json&, std::vector<TensorCopy>& tensors) {
    tensors.push_back({"encoder.layers.7.linear1.weight", DType::kF32, {2}, std::vector<uint8_t>(8), {}});
  }, {"does not use", "encoder.layers.7.linear1.weight"});
  expect_refused(blob_, "no_action_norm", [](nlohmann::json& config, std::vector<TensorCopy>&) {
    config["action_norm"] = "IDENTITY";
  }, {"does not use", blob_names::kUnnormScale});
  expect_refused(blob_, "float_as_f16", [](nlohmann::json&, std::vector<TensorCopy>& tensors) {
    TensorCopy& t = tensor_named(tensors, blob_names::kHeadBias);
    t.dtype = DType::kF16;
    t.bytes.resize(t.bytes.size() / 2);
  }, {blob_names::kHeadBias, "F16"});
}

TEST_F(BlobSemanticsTest, BackboneMustBeOneThisEngineRuns) {
  expect_refused(blob_, "unknown_backbone", [](nlohmann::json& config, std::vector<TensorCopy>&) {
    config["backbone"] = "resnet19";
  }, {"backbone", "\"resnet19\"", "resnet18, resnet34, resnet50, resnet101, resnet152"});
  expect_refused(blob_, "wrong_backbone", [](nlohmann::json& config, std::vector<TensorCopy>&) {
    config["backbone"] = "resnet34";
  }, {"backbone", "\"resnet34\"", "2+2+2+2"});
}

TEST_F(BlobSemanticsTest, QuantizationSectionMustMatchTheNetwork) {
  expect_refused(blob_, "quant_in_fp32", [](nlohmann::json& config, std::vector<TensorCopy>&) {
    config["quantization"] = QuantConfig{}.to_json();
  }, {"quantization section", "not int8"});
  expect_refused(int8_blob(), "dynamic_with_activations", [](nlohmann::json& config, std::vector<TensorCopy>&) {
    config["quantization"]["activations"]["cam0.image"] = {0.01, 0};
  }, {"dynamic", "cam0.image"});
  // Static: parameters for every value of the network, and one for a value it does not have.
  QuantConfig quant;
  quant.mode = QuantMode::kStatic;
  for (const std::string& name : engine_->intermediate_names()) quant.activations[name] = {0.01f, 0};
  const std::string static_blob = scratch_ + "/static.actb";
  write_int8_blob(import_lerobot_checkpoint(test::fixture_dir("act-tiny")), quant, static_blob);
  ASSERT_TRUE(Engine::open(static_blob).ok());
  expect_refused(static_blob, "activation_of_nothing", [](nlohmann::json& config, std::vector<TensorCopy>&) {
    config["quantization"]["activations"]["cam0.backbone.layer9"] = {0.01, 0};
  }, {"cam0.backbone.layer9", "no value of the network"});
  expect_refused(int8_blob(), "float_layer_int8", [](nlohmann::json& config, std::vector<TensorCopy>&) {
    config["quantization"]["float_layers"] = {blob_names::enc(0, "linear1.weight")};
  }, {"float_layers", blob_names::enc(0, "linear1.weight"), "int8"});
}

}  // namespace
}  // namespace act
