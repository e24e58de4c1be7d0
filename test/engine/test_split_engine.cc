// The split engine (EngineOptions::external_backbone): given the backbone's output, it runs the rest
// of the network exactly as the whole engine does, on FP32 and INT8 blobs, and says where each part runs.
#include <gtest/gtest.h>

#include "actengine/convert.h"
#include "actengine/engine.h"
#include "support/act_test_util.h"
#include "support/test_paths.h"

namespace act {
namespace {

// The whole engine's chunk, and each camera's projected features read back from it, channel-first
// (the split engine's input layout) from the engine's [h * w, D] tokens.
struct WholeRun {
  std::vector<float> chunk;
  std::vector<std::vector<float>> features_chw;
};

WholeRun run_whole(const std::string& blob, const Observation& obs) {
  auto engine = Engine::open(blob, {.threads = 2, .keep_intermediates = true});
  EXPECT_TRUE(engine.ok()) << engine.status().to_string();
  const ModelInfo& info = (*engine)->model_info();
  WholeRun run;
  run.chunk.resize(info.chunk_values());
  EXPECT_TRUE((*engine)->infer(obs, run.chunk).ok());
  for (size_t c = 0; c < info.cameras.size(); ++c) {
    StatusOr<std::vector<float>> tokens = (*engine)->intermediate("cam" + std::to_string(c) + ".img_feat_proj");
    EXPECT_TRUE(tokens.ok()) << tokens.status().to_string();
    const size_t d = static_cast<size_t>(info.dim_model);
    const size_t pixels = static_cast<size_t>(info.cameras[c].feature_height) * info.cameras[c].feature_width;
    EXPECT_EQ(tokens->size(), pixels * d);
    std::vector<float> chw(tokens->size());
    for (size_t i = 0; i < pixels; ++i) {
      for (size_t ch = 0; ch < d; ++ch) chw[ch * pixels + i] = (*tokens)[i * d + ch];
    }
    run.features_chw.push_back(std::move(chw));
  }
  return run;
}

void expect_split_reproduces_whole(const std::string& blob) {
  const int H = 96, W = 128;
  std::vector<uint8_t> image(static_cast<size_t>(H) * W * 3);
  for (size_t i = 0; i < image.size(); ++i) image[i] = static_cast<uint8_t>((i * 37 + i / 311) % 256);
  const std::vector<float> state = {0.25f, -0.5f};
  Observation obs;
  obs.images = {ImageView::rgb_u8(image.data(), H, W)};
  obs.state = state;
  const WholeRun whole = run_whole(blob, obs);

  auto split = Engine::open(blob, {.threads = 2, .profile = true, .external_backbone = true});
  ASSERT_TRUE(split.ok()) << split.status().to_string();
  const ModelInfo& info = (*split)->model_info();
  EXPECT_EQ(info.placement, "backbone: external (features given by the caller), transformer: actengine (cpu)");
  // act-tiny: ResNet-18 downsamples 96x128 by 32; dim_model 64.
  ASSERT_EQ(info.cameras.size(), 1u);
  EXPECT_EQ(info.cameras[0].feature_height, 3);
  EXPECT_EQ(info.cameras[0].feature_width, 4);
  EXPECT_EQ(info.dim_model, 64);
  Observation features = obs;
  features.images = {ImageView::backbone_features(whole.features_chw[0].data(), 3, 4)};
  std::vector<float> chunk(info.chunk_values());
  ASSERT_TRUE((*split)->infer(features, chunk).ok());
  EXPECT_EQ(chunk, whole.chunk);  // the same ops on the same values: bit for bit
  EXPECT_EQ((*split)->last_timings().backbone_ms, 0.0);
}

TEST(SplitEngine, Fp32RunsTheRestExactlyAsTheWholeEngine) {
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  const std::string blob = test::convert_checkpoint(test::fixture_dir("act-tiny"), test::scratch_dir());
  expect_split_reproduces_whole(blob);
  auto whole = Engine::open(blob, {.threads = 1});
  ASSERT_TRUE(whole.ok());
  EXPECT_EQ((*whole)->model_info().placement, "backbone: actengine (cpu), transformer: actengine (cpu)");
}

TEST(SplitEngine, Int8StaticBlobRunsTheRestExactlyAsTheWholeEngine) {
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  auto model = import_checkpoint(test::fixture_dir("act-tiny"));
  ASSERT_TRUE(model.ok()) << model.status().to_string();
  const Int8Options options = test::quick_int8_options();
  StatusOr<CalibrationSet> frames = (*model)->synthetic_calibration_set(calibration_frames_wanted(options), 1);
  ASSERT_TRUE(frames.ok()) << frames.status().to_string();
  const std::string blob = test::scratch_dir() + "/int8.actb";
  ASSERT_TRUE((*model)->write_int8(blob, *frames, options).ok());
  expect_split_reproduces_whole(blob);
}

}  // namespace
}  // namespace act
