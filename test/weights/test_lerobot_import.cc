// LeRobot checkpoint import: what it folds, and every way a checkpoint can be wrong.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <cstring>
#include <fstream>
#include <optional>

#include <nlohmann/json.hpp>

#include "actengine/status.h"
#include "support/act_test_util.h"
#include "support/file_test_util.h"
#include "support/test_paths.h"
#include "weights/import/lerobot_import.h"
#include "weights/import/safetensors.h"

namespace fs = std::filesystem;

namespace act {
namespace {

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
    const std::optional<Error> e = test::error_thrown_by([&] { import_lerobot_checkpoint(dir); });
    ASSERT_TRUE(e.has_value()) << "the import of " << dir << " succeeded; expected: " << needle;
    EXPECT_EQ(e->code(), code) << e->what();
    EXPECT_NE(std::string(e->what()).find(needle), std::string::npos) << "message: " << e->what() << "\nexpected: " << needle;
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
  expect_error(patched(R"({"temporal_ensemble_coeff": -100, "n_action_steps": 1})"), StatusCode::kInvalidArgument,
               "ensemble weights exp(-coeff * i) overflow float32");
  expect_error(patched(R"({"replace_final_stride_with_dilation": 1})"), StatusCode::kUnimplemented, "Bottleneck");
  expect_error(patched(R"({"n_obs_steps": 2})"), StatusCode::kUnimplemented, "n_obs_steps");
  expect_error(patched(R"({"dim_model": "big"})"), StatusCode::kDataLoss, "dim_model");
  expect_error(patched(R"({"normalization_mapping": {"VISUAL": "SOMETHING"}})"), StatusCode::kUnimplemented, "SOMETHING");
  expect_error(patched(R"({"input_features": {"observation.images.front": {"type": "VISUAL", "shape": [1, 96, 128]}}})"),
               StatusCode::kInvalidArgument, "[3, H, W]");
  expect_error(patched(R"({"output_features": {}})"), StatusCode::kInvalidArgument, "action");
}

TEST_F(ImportTest, AnAbsurdlyLargeWeightIsRefused) {
  // A finite 3e38 in a weight once converted without a word and made every action infinite.
  const std::string dir = patched("{}");
  const std::string weights = dir + "/model.safetensors";
  std::vector<std::vector<uint8_t>> copies;
  std::vector<SafetensorsWriteTensor> out;
  std::string damaged;
  {
    const SafetensorsFile in = SafetensorsFile::open(weights);
    copies.reserve(in.names().size());
    for (const std::string& name : in.names()) {
      const SafetensorsTensor& t = in.get(name);
      copies.emplace_back(t.data, t.data + t.nbytes);
      if (damaged.empty() && t.dtype == DType::kF32 && name.find("backbone.conv1.weight") != std::string::npos) {
        const float huge = 3e38f;
        std::memcpy(copies.back().data(), &huge, sizeof huge);
        damaged = name;
      }
      out.push_back({name, t.dtype, t.shape, copies.back().data(), t.nbytes});
    }
  }
  ASSERT_FALSE(damaged.empty());
  write_safetensors(weights, out);
  expect_error(dir, StatusCode::kInvalidArgument, "\"" + damaged + "\" holds 3e+38");
}

TEST_F(ImportTest, DuplicateKeysInTheConfigAreRefused) {
  // A key given twice in config.json used to take its last value silently.
  const std::string dir = patched("{}");
  const std::vector<uint8_t> bytes = test::read_file(dir + "/config.json");
  std::string text(bytes.begin(), bytes.end());
  const size_t brace = text.find('{');
  text.insert(brace + 1, "\n  \"chunk_size\": 7,");
  std::ofstream(dir + "/config.json", std::ios::trunc) << text;
  expect_error(dir, StatusCode::kDataLoss, "duplicate key 'chunk_size'");
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

TEST_F(ImportTest, StateDictWithAnExtraOrAMissingKey) {
  // The legacy fixture's weights as a state dict in memory (as a .pth gives them), one key added or
  // dropped: the extra key is named as unaccounted for, the missing one as not found.
  std::ifstream config_file(legacy_ + "/config.json");
  const auto config = nlohmann::ordered_json::parse(config_file);
  const SafetensorsFile weights = SafetensorsFile::open(legacy_ + "/model.safetensors");
  const auto state_dict = [&](const std::string& skip, bool add_extra) {
    OwnedTensorSet set("state dict");
    for (const auto& name : weights.names()) {
      if (name == skip) continue;
      const SafetensorsTensor& t = weights.get(name);
      set.add(name, t.dtype, t.shape, std::vector<uint8_t>(t.data, t.data + t.nbytes));
    }
    if (add_extra) set.add_f32("model.extra_head.weight", {2}, {1.0f, 2.0f});
    return set;
  };
  ASSERT_NO_THROW(import_lerobot_state_dict(config, state_dict("", false)));
  const auto error_of = [&](const OwnedTensorSet& set) {
    return test::error_thrown_by([&] { import_lerobot_state_dict(config, set); });
  };
  const std::optional<Error> extra = error_of(state_dict("", true));
  ASSERT_TRUE(extra.has_value());
  EXPECT_EQ(extra->code(), StatusCode::kInvalidArgument) << extra->what();
  EXPECT_NE(std::string(extra->what()).find("tensors the config does not account for: \"model.extra_head.weight\""),
            std::string::npos) << extra->what();
  const std::optional<Error> missing = error_of(state_dict("model.action_head.weight", false));
  ASSERT_TRUE(missing.has_value());
  EXPECT_EQ(missing->code(), StatusCode::kNotFound) << missing->what();
  EXPECT_NE(std::string(missing->what()).find("model.action_head.weight"), std::string::npos) << missing->what();
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

TEST_F(ImportTest, EnvStateInTheConfigButNotInTheWeights) {
  const std::string dir = patched(R"({"input_features": {
      "observation.state": {"type": "STATE", "shape": [2]},
      "observation.images.front": {"type": "VISUAL", "shape": [3, 96, 128]},
      "observation.environment_state": {"type": "ENV", "shape": [2]}}})");
  expect_error(dir, StatusCode::kNotFound, "encoder_env_state_input_proj");
}

TEST_F(ImportTest, CurrentLayoutFeatureWithoutStatisticsIsPassedThroughAndSaid) {
  // LeRobot passes a feature whose statistics are absent through unchanged; so do we, and say so.
  const std::string dir = patched("{}");
  const std::string stats = "policy_preprocessor_step_3_normalizer_processor.safetensors";
  const SafetensorsFile original = SafetensorsFile::open(tiny_ + "/" + stats);
  std::vector<SafetensorsWriteTensor> kept;
  for (const auto& name : original.names()) {
    if (name.rfind("observation.state.", 0) == 0) continue;
    const auto& t = original.get(name);
    kept.push_back({name, t.dtype, t.shape, t.data, t.nbytes});
  }
  fs::remove(dir + "/" + stats);
  write_safetensors(dir + "/" + stats, kept);
  const ImportedModel m = import_lerobot_checkpoint(dir);
  EXPECT_EQ(m.config.input_norm_mode("observation.state"), NormMode::kIdentity);
  EXPECT_EQ(m.config.input_norm_mode("observation.images.front"), NormMode::kMeanStd);
  ASSERT_FALSE(m.notes.empty());
  EXPECT_NE(m.notes[0].find("observation.state"), std::string::npos) << m.notes[0];
}

TEST_F(ImportTest, LegacyFallsBackToTrainingTargetStatisticsForActions) {
  // A legacy model saved while normalize_targets and unnormalize_outputs shared memory keeps only
  // normalize_targets.buffer_action.* (spec §10.2); the import must use those.
  const std::string dir = patched("{}", /*legacy=*/true);
  const SafetensorsFile original = SafetensorsFile::open(legacy_ + "/model.safetensors");
  std::vector<SafetensorsWriteTensor> kept;
  for (const auto& name : original.names()) {
    if (name.rfind("unnormalize_outputs.", 0) == 0) continue;
    const auto& t = original.get(name);
    kept.push_back({name, t.dtype, t.shape, t.data, t.nbytes});
  }
  fs::remove(dir + "/model.safetensors");
  write_safetensors(dir + "/model.safetensors", kept);
  const ImportedModel with_fallback = import_lerobot_checkpoint(dir);
  const ImportedModel reference = import_lerobot_checkpoint(legacy_);
  for (const char* name : {"unnorm.action.scale", "unnorm.action.offset"}) {
    ASSERT_NE(with_fallback.find(name), nullptr);
    EXPECT_EQ(with_fallback.find(name)->values, reference.find(name)->values) << name;
  }
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

namespace act {
namespace {

// IEEE binary16 bits of a finite float, rounded to nearest even (subnormals included).
uint16_t f32_to_f16_bits(float value) {
  uint32_t x;
  std::memcpy(&x, &value, 4);
  const uint32_t sign = (x >> 16) & 0x8000u;
  const int exp = static_cast<int>((x >> 23) & 0xffu) - 127 + 15;
  uint32_t mant = x & 0x7fffffu;
  if (exp >= 31) return static_cast<uint16_t>(sign | 0x7c00u);  // overflow: infinity
  uint32_t half, rem, halfway;
  if (exp <= 0) {  // subnormal half: value / 2^-24
    if (exp < -10) return static_cast<uint16_t>(sign);
    mant |= 0x800000u;
    const int shift = 14 - exp;
    half = mant >> shift;
    rem = mant & ((1u << shift) - 1);
    halfway = 1u << (shift - 1);
  } else {
    half = (static_cast<uint32_t>(exp) << 10) | (mant >> 13);
    rem = mant & 0x1fffu;
    halfway = 0x1000u;
  }
  if (rem > halfway || (rem == halfway && (half & 1u))) ++half;  // a carry into the exponent is right
  return static_cast<uint16_t>(sign | half);
}

// Half-precision checkpoints: importing F16 / BF16 weights must give exactly what importing the same
// (rounded) values stored as F32 gives.
TEST(ImportHalfPrecision, F16AndBF16WeightsImportLikeTheirF32Values) {
  const std::string tiny = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(tiny);
  const std::string scratch = test::scratch_dir();
  const SafetensorsFile original = SafetensorsFile::open(tiny + "/model.safetensors");
  for (DType half : {DType::kF16, DType::kBF16}) {
    std::vector<std::vector<uint16_t>> half_data;
    std::vector<std::vector<float>> rounded_data;
    std::vector<SafetensorsWriteTensor> half_tensors, rounded_tensors;
    half_data.reserve(original.names().size());
    rounded_data.reserve(original.names().size());
    for (const auto& name : original.names()) {
      const auto& t = original.get(name);
      std::vector<float> v = t.to_f32();
      std::vector<uint16_t> bits(v.size());
      for (size_t i = 0; i < v.size(); ++i) {
        if (half == DType::kF16) {
          bits[i] = f32_to_f16_bits(v[i]);
        } else {
          uint32_t u;
          std::memcpy(&u, &v[i], 4);
          u += 0x7fffu + ((u >> 16) & 1u);  // round to nearest even (no NaNs in the weights)
          bits[i] = static_cast<uint16_t>(u >> 16);
        }
      }
      std::vector<float> rounded(v.size());
      convert_to_f32(half, bits.data(), bits.size(), rounded.data());
      half_data.push_back(std::move(bits));
      rounded_data.push_back(std::move(rounded));
      half_tensors.push_back({name, half, t.shape, half_data.back().data(), half_data.back().size() * 2});
      rounded_tensors.push_back({name, DType::kF32, t.shape, rounded_data.back().data(), rounded_data.back().size() * 4});
    }
    const std::string half_dir = scratch + "/" + dtype_name(half), f32_dir = scratch + "/" + dtype_name(half) + "_as_f32";
    for (const auto& [dir, tensors] : {std::pair{half_dir, &half_tensors}, std::pair{f32_dir, &rounded_tensors}}) {
      fs::create_directories(dir);
      for (const auto& entry : fs::directory_iterator(tiny)) {
        if (entry.path().filename() != "model.safetensors") fs::create_symlink(entry.path(), fs::path(dir) / entry.path().filename());
      }
      write_safetensors(dir + "/model.safetensors", *tensors);
    }
    const ImportedModel from_half = import_lerobot_checkpoint(half_dir);
    const ImportedModel from_f32 = import_lerobot_checkpoint(f32_dir);
    ASSERT_EQ(from_half.tensors.size(), from_f32.tensors.size());
    for (size_t i = 0; i < from_half.tensors.size(); ++i) {
      EXPECT_EQ(from_half.tensors[i].name, from_f32.tensors[i].name);
      EXPECT_EQ(from_half.tensors[i].values, from_f32.tensors[i].values) << dtype_name(half) << " " << from_half.tensors[i].name;
    }
    // The rounding really changed the weights (so the check above is not trivially true).
    EXPECT_NE(from_f32.find("head.weight")->values, import_lerobot_checkpoint(tiny).find("head.weight")->values);
  }
}

}  // namespace
}  // namespace act
