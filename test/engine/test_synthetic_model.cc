// The built-in synthetic models: deterministic, well-scaled, and runnable.
#include <gtest/gtest.h>

#include <cmath>

#include "actengine/engine.h"
#include "actengine/status.h"
#include "support/test_paths.h"
#include "weights/import/synthetic_model.h"

namespace act {
namespace {

TEST(SyntheticModel, ConfigsAndErrors) {
  EXPECT_EQ(lerobot_model_config(synthetic_config("default"), "x").cameras[0].height, 480);
  const ModelConfig rover = lerobot_model_config(synthetic_config("rover"), "x");
  EXPECT_EQ(rover.cameras[0].height, 360);
  EXPECT_EQ(rover.cameras[0].width, 640);
  EXPECT_EQ(rover.action_dim, 2);
  const ModelConfig custom = lerobot_model_config(synthetic_config("240x320"), "x");
  EXPECT_EQ(custom.cameras[0].height, 240);  // HxW: height first
  EXPECT_EQ(custom.cameras[0].width, 320);
  for (const char* bad : {"huge", "10x10", "320x", "99999x480"}) {
    try {
      synthetic_config(bad);
      ADD_FAILURE() << bad << " accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), StatusCode::kInvalidArgument);
      EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
    }
  }
}

TEST(SyntheticModel, DeterministicForASeed) {
  const ImportedModel a = make_synthetic_model("64x64", 7), b = make_synthetic_model("64x64", 7);
  const ImportedModel c = make_synthetic_model("64x64", 8);
  ASSERT_EQ(a.tensors.size(), b.tensors.size());
  for (size_t i = 0; i < a.tensors.size(); ++i) EXPECT_EQ(a.tensors[i].values, b.tensors[i].values) << a.tensors[i].name;
  EXPECT_NE(a.find("head.weight")->values, c.find("head.weight")->values);
  EXPECT_DOUBLE_EQ(a.config.macs().total(), lerobot_model_config(synthetic_config("64x64"), "x").macs().total());
}

TEST(SyntheticModel, ActivationsStayWellScaled) {
  const std::string dir = test::scratch_dir();
  write_fp32_blob(make_synthetic_model("rover"), dir + "/rover.actb");
  auto engine = Engine::open(dir + "/rover.actb", {.threads = 2, .keep_intermediates = true});
  ASSERT_TRUE(engine.ok()) << engine.status().to_string();
  const auto& cam = (*engine)->model_info().cameras[0];
  std::vector<uint8_t> image(static_cast<size_t>(cam.height) * cam.width * 3);
  for (size_t i = 0; i < image.size(); ++i) image[i] = static_cast<uint8_t>((i / 3 % cam.width + i / (3 * cam.width)) % 256);
  const std::vector<float> state = {0.1f, -0.2f};
  Observation obs;
  obs.images = {ImageView::rgb_u8(image.data(), cam.height, cam.width)};
  obs.state = state;
  std::vector<float> actions((*engine)->model_info().chunk_values());
  ASSERT_TRUE((*engine)->infer_normalized(obs, actions).ok());
  for (const char* name : {"cam0.backbone.layer1", "cam0.backbone.layer4", "encoder_layer3_out", "actions_normalized"}) {
    const StatusOr<std::vector<float>> values = (*engine)->intermediate(name);
    ASSERT_TRUE(values.ok()) << values.status().to_string();
    ASSERT_FALSE(values->empty()) << name;
    double sq = 0;
    for (float v : values.value()) {
      ASSERT_TRUE(std::isfinite(v)) << name;
      sq += static_cast<double>(v) * v;
    }
    const double rms = std::sqrt(sq / static_cast<double>(values->size()));
    EXPECT_GT(rms, 0.05) << name;
    EXPECT_LT(rms, 20.0) << name;
  }
}

}  // namespace
}  // namespace act
