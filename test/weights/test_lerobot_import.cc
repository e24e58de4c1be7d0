// LeRobot checkpoint import: what it folds, and every way a checkpoint can be wrong.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "support/act_test_util.h"
#include "support/test_paths.h"
#include "weights/error.h"
#include "weights/lerobot_import.h"
#include "weights/safetensors.h"

namespace fs = std::filesystem;

namespace act {
namespace {

// Runs the import and returns the error it raised (kOk if none).
Error import_error(const std::string& dir) {
  try {
    import_lerobot_checkpoint(dir);
  } catch (const Error& e) {
    return e;
  }
  return Error(StatusCode::kOk, "");
}

class ImportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    tiny_ = test::fixture_dir("act-tiny");
    legacy_ = test::fixture_dir("act-tiny-legacy");
    ACT_REQUIRE_PATH(tiny_);
    ACT_REQUIRE_PATH(legacy_);
    scratch_ = test::scratch_dir();
  }
  // A copy of act-tiny (or the legacy fixture) with config fields replaced.
  std::string patched(const std::string& patch, bool legacy = false) {
    const std::string dst = scratch_ + "/ckpt" + std::to_string(counter_++);
    test::patch_checkpoint(legacy ? legacy_ : tiny_, dst, patch);
    return dst;
  }
  void expect_error(const std::string& dir, StatusCode code, const std::string& needle) {
    const Error e = import_error(dir);
    EXPECT_EQ(e.code(), code) << e.what();
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << "message: " << e.what() << "\nexpected: " << needle;
  }
  std::string tiny_, legacy_, scratch_;
  int counter_ = 0;
};

TEST_F(ImportTest, ReadsTheFixtureConfig) {
  const ImportedModel m = import_lerobot_checkpoint(tiny_);
  EXPECT_EQ(m.layout, "current");
  EXPECT_EQ(m.config.dim_model, 64);
  EXPECT_EQ(m.config.n_heads, 4);
  EXPECT_EQ(m.config.dim_feedforward, 128);
  EXPECT_EQ(m.config.n_encoder_layers, 2);
  EXPECT_EQ(m.config.chunk_size, 10);
  ASSERT_EQ(m.config.cameras.size(), 1u);
  EXPECT_EQ(m.config.cameras[0].height, 96);
  EXPECT_EQ(m.config.cameras[0].width, 128);
  EXPECT_EQ(m.config.n_tokens(), 14);
  EXPECT_EQ(m.checkpoint_tensors, 210u);
  EXPECT_GT(m.training_only_tensors, 0u);  // the VAE encoder is dropped
  for (const auto& t : m.tensors) EXPECT_EQ(t.name.find("vae"), std::string::npos) << t.name;
  // The spec's MAC count for the tiny fixtures.
  EXPECT_DOUBLE_EQ(m.config.macs().total(), 446056832.0);
  EXPECT_DOUBLE_EQ(m.config.macs().backbone, 444137472.0);
  EXPECT_EQ(import_lerobot_checkpoint(legacy_).layout, "legacy");
}

TEST_F(ImportTest, MacCountOfTheDefaultConfigMatchesTheSpec) {
  ModelConfig c;
  c.backbone_blocks = {2, 2, 2, 2};
  c.cameras = {{"observation.images.front", 480, 640}};
  c.state_dim = 6;
  c.action_dim = 6;
  EXPECT_DOUBLE_EQ(c.macs().total(), 17465498624.0);
  EXPECT_DOUBLE_EQ(c.macs().backbone, 11103436800.0);
  c.cameras = {{"observation.images.front", 360, 640}};
  c.state_dim = c.action_dim = 2;
  EXPECT_DOUBLE_EQ(c.macs().total(), 13632091136.0);
  c.backbone_blocks = {3, 4, 6, 3};
  c.cameras = {{"observation.images.front", 480, 640}};
  // resnet34 stage coefficients from the spec: 9408, 221184, 1114112, 6815744, 13107200.
  EXPECT_DOUBLE_EQ(c.macs().backbone, 9408.0 * 240 * 320 + 221184.0 * 120 * 160 + 1114112.0 * 60 * 80 +
                                          6815744.0 * 30 * 40 + 13107200.0 * 15 * 20);
}

TEST_F(ImportTest, ConfigRoundTripsThroughJson) {
  const ImportedModel m = import_lerobot_checkpoint(tiny_);
  const ModelConfig back = ModelConfig::from_json(m.config.to_json());
  EXPECT_EQ(back.to_json(), m.config.to_json());
}

TEST_F(ImportTest, MissingFolderOrConfig) {
  expect_error(scratch_ + "/does-not-exist", StatusCode::kNotFound, "does-not-exist");
  fs::create_directories(scratch_ + "/empty");
  expect_error(scratch_ + "/empty", StatusCode::kNotFound, "config.json");
}

TEST_F(ImportTest, RefusesUnsupportedOrInconsistentConfigs) {
  expect_error(patched(R"({"type": "diffusion"})"), StatusCode::kInvalidArgument, "not \"act\"");
  expect_error(patched(R"({"vision_backbone": "efficientnet_b0"})"), StatusCode::kUnimplemented, "efficientnet_b0");
  expect_error(patched(R"({"feedforward_activation": "swish"})"), StatusCode::kUnimplemented, "swish");
  expect_error(patched(R"({"n_heads": 5})"), StatusCode::kInvalidArgument, "n_heads");
  expect_error(patched(R"({"n_action_steps": 11})"), StatusCode::kInvalidArgument, "n_action_steps");
  expect_error(patched(R"({"temporal_ensemble_coeff": 0.01})"), StatusCode::kInvalidArgument, "n_action_steps == 1");
  expect_error(patched(R"({"replace_final_stride_with_dilation": 1})"), StatusCode::kUnimplemented, "Bottleneck");
  expect_error(patched(R"({"n_obs_steps": 2})"), StatusCode::kUnimplemented, "n_obs_steps");
  expect_error(patched(R"({"dim_model": "big"})"), StatusCode::kDataLoss, "dim_model");
  expect_error(patched(R"({"normalization_mapping": {"VISUAL": "SOMETHING"}})"), StatusCode::kUnimplemented, "SOMETHING");
  expect_error(patched(R"({"input_features": {"observation.images.front": {"type": "VISUAL", "shape": [1, 96, 128]}}})"),
               StatusCode::kInvalidArgument, "[3, H, W]");
  expect_error(patched(R"({"output_features": {}})"), StatusCode::kInvalidArgument, "action");
}

TEST_F(ImportTest, OldStyleConfigIsNamed) {
  const std::string dir = scratch_ + "/old";
  fs::create_directories(dir);
  std::ofstream(dir + "/config.json") << R"({"type": "act", "input_shapes": {"observation.state": [2]}})";
  expect_error(dir, StatusCode::kUnimplemented, "input_shapes");
}

TEST_F(ImportTest, MalformedConfigJson) {
  const std::string dir = scratch_ + "/badjson";
  fs::create_directories(dir);
  std::ofstream(dir + "/config.json") << "{\"type\": \"act\", ";
  expect_error(dir, StatusCode::kDataLoss, "not valid JSON");
}

TEST_F(ImportTest, WeightsThatDoNotMatchTheConfig) {
  // More layers than the weights have: the first missing tensor is named.
  expect_error(patched(R"({"n_encoder_layers": 3})"), StatusCode::kNotFound, "model.encoder.layers.2.");
  // Fewer layers than the weights have: the leftovers are reported, never ignored.
  expect_error(patched(R"({"n_encoder_layers": 1})"), StatusCode::kInvalidArgument, "model.encoder.layers.1.");
  // Another FFN width: the shape mismatch is named.
  expect_error(patched(R"({"dim_feedforward": 256})"), StatusCode::kInvalidArgument, "linear1.weight");
  // LeRobot's glu cannot run: its linear2 expects the full FFN width.
  expect_error(patched(R"({"feedforward_activation": "glu"})"), StatusCode::kInvalidArgument, "linear2.weight");
  // resnet34 needs more blocks than resnet18 weights have.
  expect_error(patched(R"({"vision_backbone": "resnet34"})"), StatusCode::kNotFound, "layer1.2");
  // Pre-norm needs the encoder's final norm.
  expect_error(patched(R"({"pre_norm": true})"), StatusCode::kNotFound, "model.encoder.norm.weight");
}

TEST_F(ImportTest, MissingOrCorruptFiles) {
  {
    const std::string dir = patched("{}");
    fs::remove(dir + "/policy_preprocessor_step_3_normalizer_processor.safetensors");
    expect_error(dir, StatusCode::kNotFound, "normalizer_processor.safetensors");
  }
  {
    const std::string dir = patched("{}");
    fs::remove(dir + "/policy_postprocessor.json");
    expect_error(dir, StatusCode::kNotFound, "policy_postprocessor.json");
  }
  {
    const std::string dir = patched("{}");
    fs::remove(dir + "/model.safetensors");
    expect_error(dir, StatusCode::kNotFound, "model.safetensors");
  }
  {
    // A truncated weights file.
    const std::string dir = patched("{}");
    fs::remove(dir + "/model.safetensors");
    fs::copy_file(tiny_ + "/model.safetensors", dir + "/model.safetensors");
    fs::resize_file(dir + "/model.safetensors", fs::file_size(dir + "/model.safetensors") / 2);
    expect_error(dir, StatusCode::kDataLoss, "model.safetensors");
  }
}

TEST_F(ImportTest, LegacyCheckpointWithoutItsNormalisationBuffers) {
  // Legacy layout with MIN_MAX images: those buffers are not in the file.
  expect_error(patched(R"({"normalization_mapping": {"VISUAL": "MIN_MAX", "STATE": "MEAN_STD", "ACTION": "MEAN_STD"}})", true),
               StatusCode::kNotFound, "observation.images.front");
}

TEST_F(ImportTest, CurrentLayoutFeatureWithoutStatisticsIsPassedThroughAndSaid) {
  // The processor files hold statistics for every dataset feature, so point the state at a key with none.
  const std::string dir = patched(R"({"input_features": {
      "observation.state": {"type": "STATE", "shape": [2]},
      "observation.images.front": {"type": "VISUAL", "shape": [3, 96, 128]},
      "observation.environment_state": {"type": "ENV", "shape": [2]}},
      "normalization_mapping": {"VISUAL": "MEAN_STD", "STATE": "MEAN_STD", "ACTION": "MEAN_STD", "ENV": "MEAN_STD"}})");
  // The env projection weights are missing, which is what must be reported first.
  expect_error(dir, StatusCode::kNotFound, "encoder_env_state_input_proj");
}

TEST_F(ImportTest, FoldsTheConstantDecoderBlock) {
  const ImportedModel m = import_lerobot_checkpoint(tiny_);
  const NamedTensor* y = m.find("decoder.layers.0.const_y");
  const NamedTensor* q = m.find("decoder.layers.0.cross_q");
  ASSERT_NE(y, nullptr);
  ASSERT_NE(q, nullptr);
  EXPECT_EQ(y->shape, (std::vector<int64_t>{64}));
  EXPECT_EQ(q->shape, (std::vector<int64_t>{10, 64}));
  // Post-norm: const_y is a LayerNorm output, so (with its gamma/beta undone) it has zero mean.
  const NamedTensor* g = m.find("decoder.layers.0.norm1.weight");
  const NamedTensor* b = m.find("decoder.layers.0.norm1.bias");
  double mean = 0;
  for (size_t i = 0; i < 64; ++i) mean += (y->values[i] - b->values[i]) / g->values[i];
  EXPECT_NEAR(mean / 64, 0.0, 1e-5);
}

}  // namespace
}  // namespace act
