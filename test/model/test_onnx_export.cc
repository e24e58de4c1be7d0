// The ONNX export in ONNX Runtime (npm's onnxruntime-node, run by test/onnx/run_onnx.js, installed by
// scripts/install_node_deps.sh): on the fixtures and the generated checkpoints, the exported policy
// reproduces the engine's FP32 chunk, and the exported backbone's features fed to the split engine
// (EngineOptions::external_backbone) reproduce it too; an INT8 blob's QDQ export runs with an error
// against FP32 no worse than twice the engine's; bad exports fail and write nothing.
// Release stage only (scripts/run_tests.sh: the "Onnx" tests load Node and full-size models).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "actengine/convert.h"
#include "actengine/engine.h"
#include "actengine/onnx_export.h"
#include "actengine/calibration_files.h"
#include "engine/src/convert/observation_file.h"
#include "support/act_test_util.h"
#include "support/command.h"
#include "support/test_paths.h"

namespace fs = std::filesystem;

namespace act {
namespace {

constexpr double kOnnxRuntimeTol = 1e-4;

struct Model {
  const char* name;
  bool fixture;  // in the shared fixtures (else a generated checkpoint)
  // The QDQ export's action MSE against FP32 (and the split engine's fed by the QDQ backbone) as a
  // multiple of the engine's INT8 error, at most.
  double qdq_error_ratio = 2.0;
};

// ONNX Runtime runs each int8 residual block as QLinearConv + QLinearAdd, which rounds the sum
// before the residual to int8 once more (the engine adds the residual to the exact sum); over the
// random resnet34's 16 blocks that ends near 4x the engine's error (MSE 1.3e-3 against 3.5e-4).
const Model kModels[] = {{"act-tiny", true},
                         {"act-tiny-legacy", true},
                         {"multicam-prenorm-gelu", false},
                         {"minmax-legacy-env", false},
                         {"quantiles-identity", false},
                         {"default-360x640-legacy", false},
                         {"default-480x640", false},
                         {"resnet34-novae", false, 5.0},
                         {"resnet50-dilation", false}};

std::string checkpoint_dir(const Model& m) {
  return m.fixture ? test::fixture_dir(m.name) : test::generated_checkpoint_dir(m.name);
}

void write_floats(const std::string& path, const float* data, size_t n, bool append = false) {
  std::ofstream out(path, append ? std::ios::binary | std::ios::app : std::ios::binary);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(n * sizeof(float)));
  ASSERT_TRUE(out.good()) << path;
}

std::vector<float> read_floats(const std::string& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  EXPECT_TRUE(in.good()) << path;
  std::vector<float> values(static_cast<size_t>(in.tellg()) / sizeof(float));
  in.seekg(0);
  in.read(reinterpret_cast<char*>(values.data()), static_cast<std::streamsize>(values.size() * sizeof(float)));
  return values;
}

struct OrtInput {
  std::string name, file;
  std::vector<int64_t> shape;
};

// Runs the model in ONNX Runtime on `samples` inputs (each input file holds that many, one after
// another); its outputs land in `out_dir` as <name>.bin, the samples' one after another.
::testing::AssertionResult run_ort(const std::string& model, const std::string& out_dir, const std::vector<OrtInput>& inputs,
                                   size_t samples = 1) {
  std::string cmd = "node " + test::q(ACT_ONNX_RUNNER) + " " + test::q(model) + " " + test::q(out_dir) + " --samples " +
                    std::to_string(samples);
  for (const auto& in : inputs) {
    std::string dims;
    for (int64_t d : in.shape) {
      if (!dims.empty()) dims += 'x';
      dims += std::to_string(d);
    }
    std::string arg = in.name;
    arg.append("=").append(in.file).append(":").append(dims);
    cmd.append(" ").append(test::q(arg));
  }
  const test::CommandResult r = test::run_command(cmd);
  if (r.exit_code != 0) return ::testing::AssertionFailure() << cmd << "\n" << r.output;
  return ::testing::AssertionSuccess();
}

class OnnxExportTest : public ::testing::TestWithParam<Model> {
 protected:
  void SetUp() override {
    ACT_REQUIRE_PATH(std::string(ACT_ONNX_DIR) + "/node_modules/onnxruntime-node/package.json");
    dir_ = checkpoint_dir(GetParam());
    ACT_REQUIRE_PATH(dir_ + "/reference.safetensors");
    ASSERT_EQ(test::run_command("node --version").exit_code, 0) << "node is not installed (scripts/install_deps.sh)";
    scratch_ = test::scratch_dir();
    blob_ = test::convert_checkpoint(dir_, scratch_);
    auto engine = Engine::open(blob_, {.threads = 2});
    ASSERT_TRUE(engine.ok()) << engine.status().to_string();
    engine_ = std::move(engine).value();
    batch_ = std::make_unique<ObservationBatch>(
        ObservationBatch::read(dir_ + "/reference.safetensors", engine_->model_info(), ImageSource::kFloat));
    observation_ = batch_->at(0);
    expected_.resize(engine_->model_info().chunk_values());
    ASSERT_TRUE(engine_->infer(observation_, expected_).ok());
  }

  // The observation's images (NCHW float, [0, 1]) and states as ONNX Runtime inputs; with `append`,
  // after those already in the files (run_ort's samples).
  std::vector<OrtInput> inputs(bool states, bool append = false) {
    const ModelInfo& info = engine_->model_info();
    std::vector<OrtInput> list;
    for (size_t c = 0; c < info.cameras.size(); ++c) {
      const CameraInfo& cam = info.cameras[c];
      const std::string file = scratch_ + "/image" + std::to_string(c) + ".bin";
      write_floats(file, static_cast<const float*>(observation_.images[c].data), 3 * static_cast<size_t>(cam.height) * cam.width,
                   append);
      list.push_back({cam.key, file, {1, 3, cam.height, cam.width}});
    }
    if (states && info.state_dim > 0) {
      write_floats(scratch_ + "/state.bin", observation_.state.data(), observation_.state.size(), append);
      list.push_back({"observation.state", scratch_ + "/state.bin", {1, info.state_dim}});
    }
    if (states && info.env_state_dim > 0) {
      write_floats(scratch_ + "/env.bin", observation_.env_state.data(), observation_.env_state.size(), append);
      list.push_back({info.env_state_key, scratch_ + "/env.bin", {1, info.env_state_dim}});
    }
    return list;
  }

  std::string dir_, scratch_, blob_;
  std::unique_ptr<Engine> engine_;
  std::unique_ptr<ObservationBatch> batch_;
  Observation observation_;
  std::vector<float> expected_;  // the engine's FP32 raw chunk for sample 0
};

TEST_P(OnnxExportTest, FullModelInOnnxRuntimeMatchesTheEngine) {
  const std::string onnx = scratch_ + "/full.onnx";
  const auto summary = export_onnx(blob_, onnx);
  ASSERT_TRUE(summary.ok()) << summary.status().to_string();
  const ModelInfo& info = engine_->model_info();
  ASSERT_EQ(summary->outputs.size(), 1u);
  EXPECT_EQ(summary->outputs[0].name, "action");
  EXPECT_EQ(summary->outputs[0].shape, (std::vector<int64_t>{1, info.chunk_size, info.action_dim}));
  EXPECT_EQ(summary->inputs[0].name, info.cameras[0].key);
  ASSERT_TRUE(run_ort(onnx, scratch_ + "/ort_full", inputs(true)));
  const std::vector<float> got = read_floats(scratch_ + "/ort_full/action.bin");
  ASSERT_EQ(got.size(), expected_.size());
  EXPECT_TRUE(test::all_close(std::string(GetParam().name) + " ONNX Runtime vs engine", got.data(), expected_.data(),
                              got.size(), kOnnxRuntimeTol));
}

// --onnx-normalization out: normalised observations in (the engine's own, read back from its
// inputs), the network's normalised chunk out.
TEST_P(OnnxExportTest, NormalizationOutsideTakesAndGivesNormalizedValues) {
  const std::string onnx = scratch_ + "/out.onnx";
  const auto summary = export_onnx(blob_, onnx, {.normalization = OnnxNormalization::kOutside});
  ASSERT_TRUE(summary.ok()) << summary.status().to_string();
  auto engine = Engine::open(blob_, {.threads = 2, .keep_intermediates = true});
  ASSERT_TRUE(engine.ok()) << engine.status().to_string();
  const ModelInfo& info = (*engine)->model_info();
  std::vector<float> expected(info.chunk_values());
  ASSERT_TRUE((*engine)->infer_normalized(observation_, expected).ok());
  std::vector<OrtInput> list = inputs(true);
  for (OrtInput& in : list) {
    const bool image = in.shape.size() == 4;
    std::string value = in.name == "observation.state" ? "state" : "env_state";
    for (size_t c = 0; image && c < info.cameras.size(); ++c) {
      if (info.cameras[c].key == in.name) value = "cam" + std::to_string(c) + ".image";
    }
    StatusOr<std::vector<float>> normalized = (*engine)->intermediate(value);
    ASSERT_TRUE(normalized.ok()) << normalized.status().to_string();
    std::vector<float> data = *normalized;
    if (image) {  // HWC -> CHW
      const size_t pixels = data.size() / 3;
      for (size_t i = 0; i < pixels; ++i) {
        for (size_t ch = 0; ch < 3; ++ch) data[ch * pixels + i] = (*normalized)[i * 3 + ch];
      }
    }
    write_floats(in.file, data.data(), data.size());
  }
  ASSERT_TRUE(run_ort(onnx, scratch_ + "/ort_out", list));
  const std::vector<float> got = read_floats(scratch_ + "/ort_out/action.bin");
  ASSERT_EQ(got.size(), expected.size());
  EXPECT_TRUE(test::all_close(std::string(GetParam().name) + " normalised ONNX Runtime vs engine", got.data(),
                              expected.data(), got.size(), kOnnxRuntimeTol));
}

TEST_P(OnnxExportTest, OnnxBackboneFeedsTheSplitEngine) {
  const std::string onnx = scratch_ + "/backbone.onnx";
  const auto summary = export_onnx(blob_, onnx, {.part = OnnxPart::kBackbone});
  ASSERT_TRUE(summary.ok()) << summary.status().to_string();
  const ModelInfo& info = engine_->model_info();
  ASSERT_EQ(summary->outputs.size(), info.cameras.size());
  ASSERT_TRUE(run_ort(onnx, scratch_ + "/ort_backbone", inputs(false)));

  auto split = Engine::open(blob_, {.threads = 2, .external_backbone = true});
  ASSERT_TRUE(split.ok()) << split.status().to_string();
  EXPECT_NE((*split)->model_info().placement.find("backbone: external"), std::string::npos);
  std::vector<std::vector<float>> features;
  Observation obs = observation_;
  for (size_t c = 0; c < info.cameras.size(); ++c) {
    const CameraInfo& cam = info.cameras[c];
    EXPECT_EQ(summary->outputs[c].shape, (std::vector<int64_t>{1, info.dim_model, cam.feature_height, cam.feature_width}));
    features.push_back(read_floats(scratch_ + "/ort_backbone/" + cam.key + ".features.bin"));
    ASSERT_EQ(features.back().size(), static_cast<size_t>(info.dim_model) * cam.feature_height * cam.feature_width);
    obs.images[c] = ImageView::backbone_features(features.back().data(), cam.feature_height, cam.feature_width);
  }
  std::vector<float> got(expected_.size());
  ASSERT_TRUE((*split)->infer(obs, got).ok());
  EXPECT_TRUE(test::all_close(std::string(GetParam().name) + " ONNX backbone + split engine vs engine", got.data(),
                              expected_.data(), got.size(), kOnnxRuntimeTol));
  // The split engine refuses a camera image, features of the wrong size or not finite; the whole
  // engine refuses features.
  EXPECT_EQ((*split)->infer(observation_, got).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(engine_->infer(obs, got).code(), StatusCode::kInvalidArgument);
  const CameraInfo& cam0 = info.cameras[0];
  Observation bad = obs;
  bad.images[0] = ImageView::backbone_features(features[0].data(), cam0.feature_height, cam0.feature_width - 1);
  const Status wrong_size = (*split)->infer(bad, got);
  EXPECT_NE(wrong_size.message().find("feature map is"), std::string::npos) << wrong_size.to_string();
  features[0][features[0].size() / 2] = std::nanf("");
  EXPECT_EQ((*split)->infer(obs, got).code(), StatusCode::kInvalidArgument);
}

// The chunk in the network's normalised units (ModelInfo's action_low/high are the raw -1 and +1).
std::vector<double> normalized(const ModelInfo& info, const std::vector<float>& raw) {
  std::vector<double> out(raw.size());
  const size_t a = static_cast<size_t>(info.action_dim);
  for (size_t i = 0; i < raw.size(); ++i) {
    const double lo = info.action_low[i % a], hi = info.action_high[i % a];
    out[i] = (raw[i] - (lo + hi) / 2) / ((hi - lo) / 2);
  }
  return out;
}

double mse(const std::vector<double>& x, const std::vector<double>& y) {
  double sum = 0;
  for (size_t i = 0; i < x.size(); ++i) sum += (x[i] - y[i]) * (x[i] - y[i]);
  return sum / static_cast<double>(x.size());
}

// An INT8 blob (static calibration) exported as QDQ runs in ONNX Runtime, with our scales, and its
// error against FP32 is no worse than twice the engine's INT8 error, over the reference's samples; so
// is the split engine's on that blob, fed by the QDQ backbone (an accelerator's int8 features).
TEST_P(OnnxExportTest, Int8QdqExportRunsInOnnxRuntimeNearFp32) {
  const Int8Options opt = test::quick_int8_options();
  auto model = import_checkpoint(dir_);
  ASSERT_TRUE(model.ok()) << model.status().to_string();
  const StatusOr<CalibrationSet> frames = load_calibration_frames(
      {dir_ + "/reference.safetensors", test::fixture_dir("act-tiny")}, (*model)->summary().model, calibration_frames_wanted(opt));
  ASSERT_TRUE(frames.ok()) << frames.status().to_string();
  const std::string int8_blob = scratch_ + "/int8.actb";
  const StatusOr<Int8Report> report = (*model)->write_int8(int8_blob, *frames, opt);
  ASSERT_TRUE(report.ok()) << report.status().to_string();
  const std::string onnx = scratch_ + "/qdq.onnx";
  const auto summary = export_onnx(int8_blob, onnx);
  ASSERT_TRUE(summary.ok()) << summary.status().to_string();
  EXPECT_EQ(summary->precision, "int8 static");
  const std::string backbone = scratch_ + "/qdq_backbone.onnx";
  ASSERT_TRUE(export_onnx(int8_blob, backbone, {.part = OnnxPart::kBackbone}).ok());

  auto int8_engine = Engine::open(int8_blob, {.threads = 2});
  ASSERT_TRUE(int8_engine.ok()) << int8_engine.status().to_string();
  auto split = Engine::open(int8_blob, {.threads = 2, .external_backbone = true});
  ASSERT_TRUE(split.ok()) << split.status().to_string();
  const ModelInfo& info = engine_->model_info();
  // Every sample through each ONNX model in one ONNX Runtime process (a process and a model load
  // per sample took most of this test's time).
  const size_t samples = batch_->size();
  std::vector<OrtInput> all_inputs, image_inputs;
  for (size_t i = 0; i < samples; ++i) {
    observation_ = batch_->at(i);
    all_inputs = inputs(true, i > 0);
  }
  for (const OrtInput& in : all_inputs) {
    if (in.shape.size() == 4) image_inputs.push_back(in);
  }
  const std::string out = scratch_ + "/ort_qdq";
  ASSERT_TRUE(run_ort(onnx, out, all_inputs, samples));
  const std::vector<float> all_actions = read_floats(out + "/action.bin");
  ASSERT_EQ(all_actions.size(), samples * info.chunk_values());
  ASSERT_TRUE(run_ort(backbone, out, image_inputs, samples));
  std::vector<std::vector<float>> all_features;
  std::vector<size_t> features_per_sample;
  for (const CameraInfo& cam : info.cameras) {
    all_features.push_back(read_floats(out + "/" + cam.key + ".features.bin"));
    features_per_sample.push_back(static_cast<size_t>(info.dim_model) * cam.feature_height * cam.feature_width);
    ASSERT_EQ(all_features.back().size(), samples * features_per_sample.back());
  }
  double ours = 0, ort = 0, split_error = 0;
  for (size_t i = 0; i < samples; ++i) {
    observation_ = batch_->at(i);
    std::vector<float> fp32(info.chunk_values()), int8(info.chunk_values());
    ASSERT_TRUE(engine_->infer(observation_, fp32).ok());
    ASSERT_TRUE((*int8_engine)->infer(observation_, int8).ok());
    const auto sample_actions = all_actions.begin() + static_cast<std::ptrdiff_t>(i * fp32.size());
    const std::vector<float> got(sample_actions, sample_actions + static_cast<std::ptrdiff_t>(fp32.size()));
    ours += mse(normalized(info, int8), normalized(info, fp32));
    ort += mse(normalized(info, got), normalized(info, fp32));

    Observation obs = observation_;
    for (size_t c = 0; c < info.cameras.size(); ++c) {
      const CameraInfo& cam = info.cameras[c];
      obs.images[c] = ImageView::backbone_features(all_features[c].data() + i * features_per_sample[c], cam.feature_height,
                                                   cam.feature_width);
    }
    std::vector<float> split_actions(info.chunk_values());
    ASSERT_TRUE((*split)->infer(obs, split_actions).ok());
    split_error += mse(normalized(info, split_actions), normalized(info, fp32));
  }
  const double n = static_cast<double>(batch_->size());
  ours /= n;
  ort /= n;
  split_error /= n;
  std::cout << GetParam().name << ": INT8 action MSE vs FP32 (normalised): engine " << ours << ", ONNX Runtime QDQ " << ort
            << ", QDQ backbone in ONNX Runtime + split engine " << split_error << "\n";
  EXPECT_GT(ort, 0.0) << "the QDQ model computes in float: are the weights quantized?";
  EXPECT_LE(ort, GetParam().qdq_error_ratio * ours + 1e-9);
  EXPECT_LE(split_error, GetParam().qdq_error_ratio * ours + 1e-9);
}

std::string model_name(const ::testing::TestParamInfo<Model>& info) {
  std::string name = info.param.name;
  for (char& ch : name) {
    if (ch == '-') ch = '_';
  }
  return name;
}

INSTANTIATE_TEST_SUITE_P(Onnx, OnnxExportTest, ::testing::ValuesIn(kModels), model_name);

// --------------------------------------------------------------------------------------- bad input

class OnnxExportErrors : public ::testing::Test {
 protected:
  void SetUp() override {
    ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
    scratch_ = test::scratch_dir();
    blob_ = test::convert_checkpoint(test::fixture_dir("act-tiny"), scratch_);
  }
  // Exports `blob` and expects `code` with `words` in the message, and nothing written.
  void expect_failure(const std::string& blob, const std::string& out, StatusCode code, const std::string& words) {
    const auto r = export_onnx(blob, out);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.status().code(), code) << r.status().to_string();
    EXPECT_NE(r.status().message().find(words), std::string::npos) << r.status().to_string();
    EXPECT_FALSE(fs::exists(out));
    for (const auto& e : fs::recursive_directory_iterator(scratch_)) EXPECT_NE(e.path().extension(), ".onnx") << e.path();
  }
  std::string scratch_, blob_;
};

TEST_F(OnnxExportErrors, MissingWrongKindAndUnwritableWriteNothing) {
  expect_failure(scratch_ + "/absent.actb", scratch_ + "/a.onnx", StatusCode::kNotFound, "absent.actb");
  // A checkpoint's weights are no blob.
  expect_failure(test::fixture_dir("act-tiny") + "/model.safetensors", scratch_ + "/b.onnx", StatusCode::kInvalidArgument,
                 "model.safetensors");
  expect_failure(blob_, scratch_ + "/no-such-folder/c.onnx", StatusCode::kIoError, "no-such-folder");
  EXPECT_FALSE(parse_onnx_part("encoder").ok());
  EXPECT_FALSE(parse_onnx_normalization("maybe").ok());
}

}  // namespace
}  // namespace act
