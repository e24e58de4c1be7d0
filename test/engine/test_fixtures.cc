// The FP32 engine against LeRobot's own numbers: every intermediate, the action chunks, and the
// select_action sequences stored in the shared fixtures.
#include <gtest/gtest.h>

#include <filesystem>

#include "actengine/engine.h"
#include "support/act_test_util.h"
#include "support/test_paths.h"
#include "weights/blob/actb.h"
#include "weights/import/safetensors.h"

namespace act {
namespace {

constexpr double kTol = 1e-4;

class FixtureTest : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    dir_ = test::fixture_dir(GetParam());
    ACT_REQUIRE_PATH(dir_);
    scratch_ = test::scratch_dir();
    blob_ = test::convert_checkpoint(dir_, scratch_);
    ref_.emplace(SafetensorsFile::open(dir_ + "/reference.safetensors"));
  }
  const SafetensorsTensor& ref(const std::string& name) { return ref_->get(name); }

  std::string dir_, scratch_, blob_;
  std::optional<SafetensorsFile> ref_;
};

// Observation i of the reference file, images as float CHW (or uint8 HWC).
struct RefObservation {
  std::vector<float> image_f32;
  std::vector<uint8_t> image_u8;
  std::vector<float> state;
};

RefObservation load_obs(const SafetensorsFile& f, size_t i, int h, int w) {
  RefObservation o;
  const size_t per = 3 * static_cast<size_t>(h) * w;
  const auto images = f.get("input.observation.images.front").to_f32();
  o.image_f32.assign(images.begin() + static_cast<ptrdiff_t>(i * per), images.begin() + static_cast<ptrdiff_t>((i + 1) * per));
  const auto& u8 = f.get("input.observation.images.front.u8_nhwc");
  o.image_u8.assign(u8.data + i * per, u8.data + (i + 1) * per);
  const auto state = f.get("input.observation.state").to_f32();
  const size_t s = state.size() / static_cast<size_t>(f.get("input.observation.state").shape[0]);
  o.state.assign(state.begin() + static_cast<ptrdiff_t>(i * s), state.begin() + static_cast<ptrdiff_t>((i + 1) * s));
  return o;
}

TEST_P(FixtureTest, EveryIntermediateMatchesLeRobot) {
  auto engine = Engine::open(blob_, {.threads = 2, .keep_intermediates = true});
  ASSERT_TRUE(engine.ok()) << engine.status().to_string();
  const ModelInfo& info = (*engine)->model_info();
  const auto& cam = info.cameras.at(0);
  const RefObservation o = load_obs(*ref_, 0, cam.height, cam.width);
  Observation obs;
  obs.images = {ImageView::rgb_f32_chw(o.image_f32.data(), cam.height, cam.width)};
  obs.state = o.state;
  std::vector<float> actions(info.chunk_values());
  ASSERT_TRUE((*engine)->infer_normalized(obs, actions).ok());

  // Engine value `name` against `expected` (the reference, in the engine's layout).
  auto expect_close = [&](const std::string& what, const std::string& name, const float* expected, size_t n) {
    const StatusOr<std::vector<float>> value = (*engine)->intermediate(name);
    ASSERT_TRUE(value.ok()) << value.status().to_string();
    ASSERT_EQ(value->size(), n) << name;
    EXPECT_TRUE(test::all_close(what, value->data(), expected, n, kTol));
  };
  // Normalised image: ours is HWC.
  {
    const auto& r = ref("sample0.model_input.observation.images.front");
    const auto hwc = test::nchw_to_hwc(r.to_f32().data(), 3, cam.height, cam.width);
    expect_close("normalised image", "cam0.image", hwc.data(), hwc.size());
  }
  {
    const auto r = ref("sample0.model_input.observation.state").to_f32();
    expect_close("normalised state", "state", r.data(), r.size());
  }
  for (const std::string stage : {"stem", "maxpool", "layer1", "layer2", "layer3", "layer4"}) {
    const auto& r = ref("sample0.cam0.backbone." + stage);
    const auto hwc = test::nchw_to_hwc(r.to_f32().data(), static_cast<int>(r.shape[1]), static_cast<int>(r.shape[2]),
                                       static_cast<int>(r.shape[3]));
    expect_close("backbone." + stage, "cam0.backbone." + stage, hwc.data(), hwc.size());
  }
  {
    const auto& r = ref("sample0.cam0.img_feat_proj");  // (1, D, h, w) -> tokens [h*w, D]
    const auto tokens = test::nchw_to_hwc(r.to_f32().data(), static_cast<int>(r.shape[1]), static_cast<int>(r.shape[2]),
                                          static_cast<int>(r.shape[3]));
    expect_close("img_feat_proj", "cam0.img_feat_proj", tokens.data(), tokens.size());
  }
  {
    // Positional embeddings are folded into bias tables; the blob keeps them for this check.
    const ActbFile blob = ActbFile::open(blob_);
    const auto r = ref("sample0.encoder_in_pos_embed").to_f32();
    EXPECT_TRUE(test::all_close("encoder positions", blob.get("encoder.pos").f32(), r.data(), r.size(), kTol));
  }
  for (const std::string name : {"encoder_in_tokens", "encoder_layer0_out", "encoder_layer1_out", "decoder_layer0_out",
                                 "decoder_out", "actions_normalized"}) {
    const std::string ref_name = name == "actions_normalized" ? "sample0.actions_normalized" : "sample0." + name;
    const auto r = ref(ref_name).to_f32();
    expect_close(name, name, r.data(), r.size());
  }
  // Post-norm: the encoder output is the last layer's output.
  const auto enc = ref("sample0.encoder_out").to_f32();
  expect_close("encoder_out", "encoder_layer1_out", enc.data(), enc.size());
}

TEST_P(FixtureTest, ActionChunksMatchLeRobotForEverySampleAndImageFormat) {
  auto engine = Engine::open(blob_, {.threads = 2});
  ASSERT_TRUE(engine.ok()) << engine.status().to_string();
  const ModelInfo& info = (*engine)->model_info();
  const auto& cam = info.cameras.at(0);
  const auto expected = ref("output.action").to_f32();
  const auto expected_norm = ref("output.action_normalized").to_f32();
  const size_t per = info.chunk_values();
  const size_t n = static_cast<size_t>(ref("output.action").shape[0]);
  for (size_t i = 0; i < n; ++i) {
    const RefObservation o = load_obs(*ref_, i, cam.height, cam.width);
    for (bool u8 : {false, true}) {
      Observation obs;
      obs.images = {u8 ? ImageView::rgb_u8(o.image_u8.data(), cam.height, cam.width)
                       : ImageView::rgb_f32_chw(o.image_f32.data(), cam.height, cam.width)};
      obs.state = o.state;
      std::vector<float> raw(per), norm(per);
      ASSERT_TRUE((*engine)->infer(obs, raw).ok());
      ASSERT_TRUE((*engine)->infer_normalized(obs, norm).ok());
      const std::string what = "sample " + std::to_string(i) + (u8 ? " (u8 image)" : " (float image)");
      EXPECT_TRUE(test::all_close(what + " raw actions", raw.data(), expected.data() + i * per, per, kTol));
      EXPECT_TRUE(test::all_close(what + " normalised actions", norm.data(), expected_norm.data() + i * per, per, kTol));
    }
  }
}

TEST_P(FixtureTest, SelectActionQueueMatchesLeRobot) {
  auto engine = Engine::open(blob_, {.threads = 1});
  ASSERT_TRUE(engine.ok()) << engine.status().to_string();
  const ModelInfo& info = (*engine)->model_info();
  const auto& cam = info.cameras.at(0);
  const RefObservation o = load_obs(*ref_, 0, cam.height, cam.width);
  Observation obs;
  obs.images = {ImageView::rgb_u8(o.image_u8.data(), cam.height, cam.width)};
  obs.state = o.state;
  const auto expected = ref("select_action.queue_sample0").to_f32();
  const size_t a = static_cast<size_t>(info.action_dim);
  ASSERT_EQ(expected.size(), static_cast<size_t>(info.n_action_steps) * a);
  Policy policy(**engine);
  for (int round = 0; round < 2; ++round) {  // a second round after reset() replays the same queue
    for (int step = 0; step < info.n_action_steps; ++step) {
      EXPECT_EQ(policy.will_infer_next(), step == 0);
      std::vector<float> action(a);
      ASSERT_TRUE(policy.select_action(obs, action).ok());
      EXPECT_TRUE(test::all_close("step " + std::to_string(step), action.data(), expected.data() + step * a, a, kTol));
    }
    policy.reset();
  }
}

TEST_P(FixtureTest, TemporalEnsemblingMatchesLeRobot) {
  // The fixture's sequence was made with temporal_ensemble_coeff 0.01 and n_action_steps 1, same weights.
  const std::string patched = scratch_ + "/ensemble_ckpt";
  test::patch_checkpoint(dir_, patched, R"({"temporal_ensemble_coeff": 0.01, "n_action_steps": 1})");
  const std::string blob = test::convert_checkpoint(patched, scratch_, "ensemble");
  auto engine = Engine::open(blob, {.threads = 2});
  ASSERT_TRUE(engine.ok()) << engine.status().to_string();
  const ModelInfo& info = (*engine)->model_info();
  ASSERT_TRUE(info.temporal_ensembling);
  const auto& cam = info.cameras.at(0);
  const auto expected = ref("temporal_ensemble.actions").to_f32();
  const size_t a = static_cast<size_t>(info.action_dim);
  Policy policy(**engine);
  for (int round = 0; round < 2; ++round) {
    for (size_t i = 0; i < expected.size() / a; ++i) {
      const RefObservation o = load_obs(*ref_, i, cam.height, cam.width);
      Observation obs;
      obs.images = {ImageView::rgb_f32_chw(o.image_f32.data(), cam.height, cam.width)};
      obs.state = o.state;
      std::vector<float> action(a);
      ASSERT_TRUE(policy.select_action(obs, action).ok());
      EXPECT_TRUE(test::all_close("ensembled step " + std::to_string(i), action.data(), expected.data() + i * a, a, kTol));
    }
    policy.reset();
  }
}

INSTANTIATE_TEST_SUITE_P(Fixtures, FixtureTest, ::testing::Values("act-tiny", "act-tiny-legacy"),
                         [](const auto& p) { return p.param == "act-tiny" ? "Current" : "Legacy"; });

}  // namespace
}  // namespace act
