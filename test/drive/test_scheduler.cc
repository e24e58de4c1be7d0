// ChunkScheduler: which chunk row each control tick executes (queue and temporal ensembling).
#include <gtest/gtest.h>

#include <cmath>

#include "apps/drive/inference.h"
#include "support/act_test_util.h"
#include "support/test_paths.h"

namespace act::drive {
namespace {

ModelInfo info(bool ensembling, int chunk, int steps, double coeff = 0.0) {
  ModelInfo i;
  i.action_dim = 1;
  i.chunk_size = chunk;
  i.n_action_steps = steps;
  i.temporal_ensembling = ensembling;
  i.temporal_ensemble_coeff = coeff;
  return i;
}

// A chunk whose row r holds base + r.
std::vector<float> ramp(float base, int rows) {
  std::vector<float> c(static_cast<size_t>(rows));
  for (int r = 0; r < rows; ++r) c[static_cast<size_t>(r)] = base + static_cast<float>(r);
  return c;
}

TEST(ChunkScheduler, QueueSkipsTheRowsThatWentByDuringInference) {
  ChunkScheduler s(info(false, 10, 6));
  float a = 0;
  EXPECT_FALSE(s.action_at(0, {&a, 1}));
  EXPECT_TRUE(s.wants_inference(0, 0));
  s.add(ramp(100, 10), /*observation_tick=*/3);
  ASSERT_TRUE(s.action_at(5, {&a, 1}));
  EXPECT_EQ(a, 102);  // row 5 - 3
  ASSERT_TRUE(s.action_at(8, {&a, 1}));
  EXPECT_EQ(a, 105);  // the last of n_action_steps = 6 rows
  EXPECT_FALSE(s.action_at(9, {&a, 1}));  // ran out: row 6 is beyond n_action_steps
  // Next inference: when the rows left are no more than the latency + 2 ticks of margin.
  EXPECT_FALSE(s.wants_inference(4, 2));  // 5 rows left
  EXPECT_TRUE(s.wants_inference(5, 2));   // 4 rows left
  // A newer chunk replaces the old one at once.
  s.add(ramp(200, 10), 7);
  ASSERT_TRUE(s.action_at(8, {&a, 1}));
  EXPECT_EQ(a, 201);
  s.clear();
  EXPECT_FALSE(s.action_at(8, {&a, 1}));
}

TEST(ChunkScheduler, EnsemblingWeightsTheOldestFirst) {
  const double coeff = 0.1;
  ChunkScheduler s(info(true, 5, 1, coeff));
  EXPECT_TRUE(s.wants_inference(0, 100));  // always: ensembling infers as often as it can
  s.add(ramp(0, 5), 0);
  s.add(ramp(10, 5), 2);
  s.add(ramp(20, 5), 3);
  float a = 0;
  ASSERT_TRUE(s.action_at(4, {&a, 1}));
  // Rows: chunk 0 row 4 = 4 (weight 1), chunk 1 row 2 = 12 (e^-0.1), chunk 2 row 1 = 21 (e^-0.2).
  const double w1 = std::exp(-coeff), w2 = std::exp(-2 * coeff);
  EXPECT_NEAR(a, (4 + 12 * w1 + 21 * w2) / (1 + w1 + w2), 1e-5);
  ASSERT_TRUE(s.action_at(5, {&a, 1}));  // chunk 0 no longer covers tick 5
  EXPECT_NEAR(a, (13 + 22 * w1) / (1 + w1), 1e-5);
  // A chunk whose rows are all in the past of a new observation is dropped.
  s.add(ramp(30, 5), 8);
  ASSERT_TRUE(s.action_at(8, {&a, 1}));
  EXPECT_NEAR(a, 30, 1e-5);
  EXPECT_FALSE(s.action_at(13, {&a, 1}));
}

}  // namespace
}  // namespace act::drive

// With no inference latency (each chunk's observation tick is the tick it arrives in), the scheduler
// must pick exactly what the engine's Policy (LeRobot's select_action, checked against LeRobot in
// test/engine) returns, for both the n_action_steps queue and temporal ensembling.
namespace act::drive {
namespace {

class SchedulerVsPolicy : public ::testing::TestWithParam<bool> {};

TEST_P(SchedulerVsPolicy, ZeroLatencyMatchesPolicySelectAction) {
  const std::string fixture = act::test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(fixture);
  const bool ensembling = GetParam();
  const std::string scratch = act::test::scratch_dir();
  const std::string checkpoint = scratch + "/ckpt";
  act::test::patch_checkpoint(fixture, checkpoint,
                              ensembling ? R"({"temporal_ensemble_coeff": 0.01, "n_action_steps": 1})"
                                         : R"({"n_action_steps": 4})");
  const std::string blob = act::test::convert_checkpoint(checkpoint, scratch);
  auto policy_engine = Engine::open(blob, {.threads = 1});
  auto chunk_engine = Engine::open(blob, {.threads = 1});
  ASSERT_TRUE(policy_engine.ok() && chunk_engine.ok());
  const ModelInfo& model = (*chunk_engine)->model_info();
  ASSERT_EQ(model.temporal_ensembling, ensembling);
  Policy policy(**policy_engine);
  ChunkScheduler scheduler(model);

  const auto& camera = model.cameras.front();
  std::vector<uint8_t> image(static_cast<size_t>(camera.height) * camera.width * 3);
  std::vector<float> state(static_cast<size_t>(model.state_dim));
  std::vector<float> chunk(model.chunk_values()), expected(static_cast<size_t>(model.action_dim)),
      ours(static_cast<size_t>(model.action_dim));
  for (int64_t tick = 0; tick < 14; ++tick) {
    // A different observation every tick.
    for (size_t i = 0; i < image.size(); ++i) image[i] = static_cast<uint8_t>((i * 7 + static_cast<size_t>(tick) * 31) % 251);
    for (size_t i = 0; i < state.size(); ++i) state[i] = 0.1f * static_cast<float>(tick) - 0.3f * static_cast<float>(i);
    Observation obs;
    obs.images = {ImageView::rgb_u8(image.data(), camera.height, camera.width)};
    obs.state = state;
    if (scheduler.wants_inference(tick, /*latency_ticks=*/-2)) {  // -2 cancels the margin: LeRobot's timing
      ASSERT_TRUE((*chunk_engine)->infer(obs, chunk).ok());
      scheduler.add(chunk, tick);
    }
    ASSERT_TRUE(policy.select_action(obs, expected).ok());
    ASSERT_TRUE(scheduler.action_at(tick, ours));
    EXPECT_TRUE(act::test::all_close("tick " + std::to_string(tick), ours.data(), expected.data(), ours.size(), 1e-5));
  }
}

INSTANTIATE_TEST_SUITE_P(Modes, SchedulerVsPolicy, ::testing::Values(false, true),
                         [](const auto& p) { return p.param ? "TemporalEnsembling" : "Queue"; });

}  // namespace
}  // namespace act::drive
