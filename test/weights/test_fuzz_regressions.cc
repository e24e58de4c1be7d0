// Inputs found by the fuzz targets (test/fuzz) and their neighbours: each must be a clear error
// naming the field, never undefined behaviour (the ASan + UBSan stage runs these too).
#include <gtest/gtest.h>

#include <fstream>
#include <optional>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "actengine/status.h"
#include "support/file_test_util.h"
#include "support/test_paths.h"
#include "weights/import/lerobot_import.h"
#include "weights/blob/model_config.h"
#include "weights/blob/quant_config.h"

namespace act {
namespace {

nlohmann::ordered_json read_regression_json(const std::string& name) {
  std::ifstream in(std::string(ACT_FUZZ_REGRESSIONS_DIR) + "/" + name);
  EXPECT_TRUE(in) << name;
  return nlohmann::ordered_json::parse(in);
}

// A macro (not a function) so that a failure points at the line of the case.
#define EXPECT_ERROR(parse, expected_code, needle)                                                \
  do {                                                                                            \
    const std::optional<Error> e_ = test::error_thrown_by([&] { parse; });                                     \
    ASSERT_TRUE(e_.has_value()) << "no error thrown";                                             \
    EXPECT_EQ(e_->code(), expected_code) << e_->what();                                           \
    EXPECT_NE(std::string(e_->what()).find(needle), std::string::npos) << "message: " << e_->what(); \
  } while (0)

// The act-tiny fixture's architecture as a blob states it: every input feature in input_norm.
ModelConfig act_tiny_blob_config() {
  std::ifstream config_file(test::fixture_dir("act-tiny") + "/config.json");
  ModelConfig config = lerobot_model_config(nlohmann::ordered_json::parse(config_file), "config.json");
  for (const std::string& key : config.input_keys()) config.input_norm.emplace_back(key, NormMode::kIdentity);
  return config;
}

TEST(FuzzRegressions, LeRobotConfigFeatureShapeThatIsNotAnInteger) {
  // Seen by UBSan in fuzz_lerobot_config (on a hand-made input; the fuzzer had not reached it yet):
  // "shape": [1e300] was converted to int64, which is undefined behaviour.
  const auto config = read_regression_json("config_float_feature_shape.json");
  EXPECT_ERROR(lerobot_model_config(config, "config.json"), StatusCode::kDataLoss,
               "feature \"observation.state\" needs a string \"type\" and an integer \"shape\"");
  // Its neighbours: a dimension beyond int (once silently wrapped: 2^32 + 2 became 2), a negative one.
  for (const char* shape : {"[4294967298]", "[-2]", "\"2\""}) {
    auto patched = config;
    patched["input_features"]["observation.state"]["shape"] = nlohmann::ordered_json::parse(shape);
    EXPECT_ERROR(lerobot_model_config(patched, "config.json"), StatusCode::kDataLoss, "observation.state");
  }
}

TEST(FuzzRegressions, BlobModelConfigIntegersAreRangeChecked) {
  const std::string fixture = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(fixture);
  const nlohmann::json good = act_tiny_blob_config().to_json();
  ASSERT_NO_THROW(ModelConfig::from_json(good));
  for (const char* value : {"1e300", "4294967298", "2.5", "\"64\""}) {
    nlohmann::json bad = good;
    bad["dim_model"] = nlohmann::json::parse(value);
    EXPECT_ERROR(ModelConfig::from_json(bad), StatusCode::kDataLoss, "dim_model");
  }
  nlohmann::json bad_camera = good;
  bad_camera["cameras"][0]["height"] = 1e300;
  EXPECT_ERROR(ModelConfig::from_json(bad_camera), StatusCode::kDataLoss, "height");
  nlohmann::json bad_blocks = good;
  bad_blocks["backbone_blocks"] = {2, 2, 1e300, 2};
  EXPECT_ERROR(ModelConfig::from_json(bad_blocks), StatusCode::kDataLoss, "backbone_blocks");
}

// The blob's precision is parsed once, into ModelConfig: fp32 or int8, anything else is an error.
TEST(FuzzRegressions, BlobModelConfigPrecisionIsValidated) {
  const std::string fixture = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(fixture);
  ModelConfig config = act_tiny_blob_config();
  EXPECT_EQ(config.precision, Precision::kFp32) << "an imported checkpoint is float";
  config.precision = Precision::kInt8;
  const nlohmann::json int8 = config.to_json();
  EXPECT_EQ(int8["precision"], "int8");
  EXPECT_EQ(ModelConfig::from_json(int8).precision, Precision::kInt8);
  nlohmann::json fp16 = int8;
  fp16["precision"] = "fp16";
  EXPECT_ERROR(ModelConfig::from_json(fp16), StatusCode::kUnimplemented, "precision 'fp16' is not supported");
  nlohmann::json missing = int8;
  missing.erase("precision");
  EXPECT_ERROR(ModelConfig::from_json(missing), StatusCode::kDataLoss, "precision");
}

TEST(FuzzRegressions, BlobQuantizationParametersAreRangeChecked) {
  const auto quant = [](const std::string& activation) {
    return nlohmann::json::parse(R"({"mode": "static", "activations": {"conv1": )" + activation +
                                 R"(}, "float_layers": []})");
  };
  ASSERT_NO_THROW(QuantConfig::from_json(quant("[0.5, 3]")));
  for (const char* bad : {"[1e300, 3]", "[0.5, 1e300]", "[0.5, 2.5]", "[0.5, 4294967298]", "[-0.5, 0]"}) {
    EXPECT_ERROR(QuantConfig::from_json(quant(bad)), StatusCode::kDataLoss, "\"conv1\"");
  }
}

TEST(FuzzRegressions, ProcessorStepFieldsAreChecked) {
  const auto pipeline = [](const std::string& step) {
    return nlohmann::ordered_json::parse(R"({"steps": [{"registry_name": 7}, )" + step + "]}");
  };
  const std::string step = R"({"registry_name": "normalizer_processor", "state_file": "stats.safetensors")";
  const ProcessorStep parsed = parse_processor_step(
      pipeline(step + R"(, "config": {"eps": 1e-8, "norm_map": {"STATE": "MEAN_STD"}}})"), "normalizer_processor", "p.json");
  EXPECT_EQ(parsed.state_file, "stats.safetensors");
  EXPECT_FLOAT_EQ(*parsed.eps, 1e-8f);
  EXPECT_EQ(parsed.norm_map->at("STATE"), "MEAN_STD");

  EXPECT_ERROR(parse_processor_step(pipeline(step + R"(, "config": {"eps": 1e300}})"), "normalizer_processor", "p.json"),
               StatusCode::kDataLoss, "p.json: eps must be a finite non-negative number");
  EXPECT_ERROR(parse_processor_step(pipeline(step + R"(, "config": {"norm_map": {"STATE": 1}}})"), "normalizer_processor",
                                    "p.json"),
               StatusCode::kDataLoss, "norm_map values must be strings");
  EXPECT_ERROR(parse_processor_step(pipeline(R"({"registry_name": "normalizer_processor", "state_file": "../x"})"),
                                    "normalizer_processor", "p.json"),
               StatusCode::kDataLoss, "state_file must be a file name");
  EXPECT_ERROR(parse_processor_step(pipeline(step + "}"), "unnormalizer_processor", "p.json"), StatusCode::kNotFound,
               "no \"unnormalizer_processor\" step");
  EXPECT_ERROR(parse_processor_step(nlohmann::ordered_json::parse("[1]"), "normalizer_processor", "p.json"),
               StatusCode::kDataLoss, "expected {\"steps\"");
}

}  // namespace
}  // namespace act
