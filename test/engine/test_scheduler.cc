// ChunkScheduler: which chunk row each control tick executes (queue and temporal ensembling), used
// asynchronously (rows aligned to the observation's tick) and synchronously (Policy).
#include "actengine/scheduler.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "support/act_test_util.h"
#include "support/test_paths.h"

namespace act {
namespace {

ModelInfo info(bool ensembling, int chunk, int steps, double coeff = 0.0, int action_dim = 1) {
  ModelInfo i;
  i.action_dim = action_dim;
  i.chunk_size = chunk;
  i.n_action_steps = steps;
  i.temporal_ensembling = ensembling;
  i.temporal_ensemble_coeff = coeff;
  return i;
}

ChunkScheduler make(const ModelInfo& model) {
  StatusOr<ChunkScheduler> s = ChunkScheduler::create(model);
  EXPECT_TRUE(s.ok()) << s.status().to_string();
  return std::move(s).value();
}

// A chunk whose row r holds base + r.
std::vector<float> ramp(float base, int rows) {
  std::vector<float> c(static_cast<size_t>(rows));
  for (int r = 0; r < rows; ++r) c[static_cast<size_t>(r)] = base + static_cast<float>(r);
  return c;
}

TEST(ChunkScheduler, QueueSkipsTheRowsThatWentByDuringInference) {
  ChunkScheduler s = make(info(false, 10, 6));
  float a = 0;
  EXPECT_EQ(s.action_at(0, {&a, 1}).code(), StatusCode::kNotFound);
  EXPECT_TRUE(s.wants_inference(0, 0));
  ASSERT_TRUE(s.add(ramp(100, 10), /*observation_tick=*/3).ok());
  ASSERT_TRUE(s.action_at(5, {&a, 1}).ok());
  EXPECT_EQ(a, 102);  // row 5 - 3
  ASSERT_TRUE(s.action_at(8, {&a, 1}).ok());
  EXPECT_EQ(a, 105);  // the last of n_action_steps = 6 rows
  EXPECT_EQ(s.action_at(9, {&a, 1}).code(), StatusCode::kNotFound);  // ran out: row 6 is beyond n_action_steps
  // Next inference: when the rows left are no more than the lead (latency + margin).
  EXPECT_FALSE(s.wants_inference(4, 4));  // 5 rows left
  EXPECT_TRUE(s.wants_inference(5, 4));   // 4 rows left
  // A newer chunk replaces the old one at once.
  ASSERT_TRUE(s.add(ramp(200, 10), 7).ok());
  ASSERT_TRUE(s.action_at(8, {&a, 1}).ok());
  EXPECT_EQ(a, 201);
  EXPECT_EQ(s.action_at(6, {&a, 1}).code(), StatusCode::kNotFound);  // before the newest observation
}

TEST(ChunkScheduler, SynchronousQueueRefillsWhenEmpty) {
  // Lead 0: infer exactly when this tick has no row left (LeRobot's queue).
  ChunkScheduler s = make(info(false, 5, 3));
  float a = 0;
  std::vector<int64_t> inferred_at;
  std::vector<float> actions;
  for (int64_t tick = 0; tick < 7; ++tick) {
    if (s.wants_inference(tick, 0)) {
      inferred_at.push_back(tick);
      ASSERT_TRUE(s.add(ramp(10.0f * static_cast<float>(tick), 5), tick).ok());
    }
    ASSERT_TRUE(s.action_at(tick, {&a, 1}).ok()) << tick;
    actions.push_back(a);
  }
  EXPECT_EQ(inferred_at, (std::vector<int64_t>{0, 3, 6}));
  EXPECT_EQ(actions, (std::vector<float>{0, 1, 2, 30, 31, 32, 60}));
}

TEST(ChunkScheduler, EnsemblingWeightsTheOldestFirst) {
  const double coeff = 0.1;
  ChunkScheduler s = make(info(true, 5, 1, coeff));
  EXPECT_TRUE(s.wants_inference(0, 100));  // always: ensembling infers as often as it can
  ASSERT_TRUE(s.add(ramp(0, 5), 0).ok());
  ASSERT_TRUE(s.add(ramp(10, 5), 2).ok());
  ASSERT_TRUE(s.add(ramp(20, 5), 3).ok());
  EXPECT_TRUE(s.wants_inference(3, 100));
  float a = 0;
  ASSERT_TRUE(s.action_at(4, {&a, 1}).ok());
  // Rows: chunk 0 row 4 = 4 (weight 1), chunk 1 row 2 = 12 (e^-0.1), chunk 2 row 1 = 21 (e^-0.2).
  const double w1 = std::exp(-coeff), w2 = std::exp(-2 * coeff);
  EXPECT_NEAR(a, (4 + 12 * w1 + 21 * w2) / (1 + w1 + w2), 1e-5);
  ASSERT_TRUE(s.action_at(5, {&a, 1}).ok());  // chunk 0 no longer covers tick 5
  EXPECT_NEAR(a, (13 + 22 * w1) / (1 + w1), 1e-5);
  // A chunk whose rows are all in the past of a new observation is dropped.
  ASSERT_TRUE(s.add(ramp(30, 5), 8).ok());
  ASSERT_TRUE(s.action_at(8, {&a, 1}).ok());
  EXPECT_NEAR(a, 30, 1e-5);
  EXPECT_EQ(s.action_at(13, {&a, 1}).code(), StatusCode::kNotFound);
}

// LeRobot's ACTTemporalEnsembler.update, written as LeRobot does it (a running ensemble per pending
// step, updated online), with its float32 weights: the reference for the synchronous use.
class OnlineEnsembler {
 public:
  OnlineEnsembler(size_t chunk_size, size_t action_dim, float coeff) : chunk_size_(chunk_size), action_dim_(action_dim) {
    float running = 0;
    for (size_t i = 0; i < chunk_size; ++i) {
      weights_.push_back(std::exp(-coeff * static_cast<float>(i)));
      running += weights_.back();
      cumsum_.push_back(running);
    }
  }
  std::vector<float> update(const std::vector<float>& chunk) {
    if (counts_.empty()) {
      ensembled_ = chunk;
      counts_.assign(chunk_size_, 1);
    } else {
      for (size_t slot = 0; slot < counts_.size(); ++slot) {
        const size_t c = counts_[slot];
        for (size_t i = 0; i < action_dim_; ++i) {
          float& e = ensembled_[slot * action_dim_ + i];
          e = (e * cumsum_[c - 1] + chunk[slot * action_dim_ + i] * weights_[std::min(c, chunk_size_ - 1)]) /
              cumsum_[std::min(c, chunk_size_ - 1)];
        }
        counts_[slot] = std::min(c + 1, chunk_size_);
      }
      ensembled_.insert(ensembled_.end(), chunk.end() - static_cast<ptrdiff_t>(action_dim_), chunk.end());
      counts_.push_back(1);
    }
    std::vector<float> action(ensembled_.begin(), ensembled_.begin() + static_cast<ptrdiff_t>(action_dim_));
    ensembled_.erase(ensembled_.begin(), ensembled_.begin() + static_cast<ptrdiff_t>(action_dim_));
    counts_.erase(counts_.begin());
    return action;
  }

 private:
  size_t chunk_size_, action_dim_;
  std::vector<float> weights_, cumsum_, ensembled_;
  std::vector<size_t> counts_;
};

TEST(ChunkScheduler, SynchronousEnsemblingIsLeRobotsOnlineUpdateBitForBit) {
  constexpr int kChunk = 6, kDim = 3;
  const float coeff = 0.3f;
  ChunkScheduler s = make(info(true, kChunk, 1, coeff, kDim));
  OnlineEnsembler reference(kChunk, kDim, coeff);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> value(-2.0f, 2.0f);
  std::vector<float> chunk(kChunk * kDim), action(kDim);
  for (int64_t tick = 0; tick < 3 * kChunk; ++tick) {
    for (float& v : chunk) v = value(rng);
    ASSERT_TRUE(s.add(chunk, tick).ok());
    ASSERT_TRUE(s.action_at(tick, action).ok());
    EXPECT_EQ(action, reference.update(chunk)) << "tick " << tick;
  }
}

TEST(ChunkScheduler, ClearForgetsEveryChunk) {
  for (bool ensembling : {false, true}) {
    ChunkScheduler s = make(info(ensembling, 4, ensembling ? 1 : 4, 0.01));
    ASSERT_TRUE(s.add(ramp(0, 4), 5).ok());
    ASSERT_TRUE(s.add(ramp(10, 4), 6).ok());
    if (!ensembling) {
      EXPECT_FALSE(s.wants_inference(6, 0));  // 4 rows left
    }
    s.clear();
    float a = 0;
    EXPECT_EQ(s.action_at(6, {&a, 1}).code(), StatusCode::kNotFound) << ensembling;
    EXPECT_TRUE(s.wants_inference(6, 0));
    // After clear() (a new episode), the ticks may start again from zero.
    ASSERT_TRUE(s.add(ramp(20, 4), 0).ok());
    ASSERT_TRUE(s.action_at(1, {&a, 1}).ok());
    EXPECT_EQ(a, 21);
  }
}

TEST(ChunkScheduler, RejectsBadInput) {
  EXPECT_EQ(ChunkScheduler::create(info(false, 0, 1)).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ChunkScheduler::create(info(false, 4, 1, 0.0, 0)).status().code(), StatusCode::kInvalidArgument);
  for (int steps : {0, 5}) {
    const Status s = ChunkScheduler::create(info(false, 4, steps)).status();
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
    EXPECT_NE(s.message().find("n_action_steps"), std::string::npos) << s.message();
  }
  // An ensemble coefficient whose weights overflow float32 (it once gave NaN from the second step on).
  for (const double coeff : {-100.0, -1.0, 1.0 / 0.0}) {
    const Status overflow = ChunkScheduler::create(info(true, 100, 1, coeff)).status();
    EXPECT_EQ(overflow.code(), StatusCode::kInvalidArgument) << coeff;
    EXPECT_NE(overflow.message().find("temporal_ensemble_coeff"), std::string::npos) << overflow.message();
  }
  EXPECT_TRUE(ChunkScheduler::create(info(true, 100, 1, -0.8)).ok());  // 0.8 * 99 = 79.2 still fits
  ChunkScheduler s = make(info(true, 4, 1, 0.01, 2));
  EXPECT_EQ(s.add(std::vector<float>(7), 0).code(), StatusCode::kInvalidArgument);
  std::vector<float> chunk(8, 1.0f);
  chunk[5] = NAN;
  const Status nan = s.add(chunk, 0);
  EXPECT_EQ(nan.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(nan.message().find("non-finite action (nan at step 2, value 1)"), std::string::npos) << nan.message();
  chunk[5] = 1.0f;
  ASSERT_TRUE(s.add(chunk, 3).ok());
  const Status older = s.add(chunk, 2);
  EXPECT_EQ(older.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(older.message().find("older"), std::string::npos) << older.message();
  std::vector<float> action(2), short_action(1);
  ASSERT_TRUE(s.action_at(3, action).ok());
  EXPECT_EQ(action, (std::vector<float>{1, 1}));  // the refused chunks left nothing behind
  EXPECT_EQ(s.action_at(3, short_action).code(), StatusCode::kInvalidArgument);
}

// With no inference latency (each chunk's observation tick is the tick it arrives in), the scheduler
// must pick exactly what the engine's Policy (LeRobot's select_action, checked against LeRobot in
// test_fixtures.cc) returns, for both the n_action_steps queue and temporal ensembling, though it
// averages raw actions where Policy averages normalised ones.
class SchedulerVsPolicy : public ::testing::TestWithParam<bool> {};

TEST_P(SchedulerVsPolicy, ZeroLatencyOnRawChunksMatchesPolicySelectAction) {
  const std::string fixture = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(fixture);
  const bool ensembling = GetParam();
  const std::string scratch = test::scratch_dir();
  const std::string checkpoint = scratch + "/ckpt";
  test::patch_checkpoint(fixture, checkpoint,
                         ensembling ? R"({"temporal_ensemble_coeff": 0.01, "n_action_steps": 1})" : R"({"n_action_steps": 4})");
  const std::string blob = test::convert_checkpoint(checkpoint, scratch);
  auto policy_engine = Engine::open(blob, {.threads = 1});
  auto chunk_engine = Engine::open(blob, {.threads = 1});
  ASSERT_TRUE(policy_engine.ok() && chunk_engine.ok());
  const ModelInfo& model = (*chunk_engine)->model_info();
  ASSERT_EQ(model.temporal_ensembling, ensembling);
  Policy policy(**policy_engine);
  ChunkScheduler scheduler = make(model);

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
    EXPECT_EQ(scheduler.wants_inference(tick, 0), policy.will_infer_next()) << "tick " << tick;
    if (scheduler.wants_inference(tick, /*lead_ticks=*/0)) {
      ASSERT_TRUE((*chunk_engine)->infer(obs, chunk).ok());
      ASSERT_TRUE(scheduler.add(chunk, tick).ok());
    }
    ASSERT_TRUE(policy.select_action(obs, expected).ok());
    ASSERT_TRUE(scheduler.action_at(tick, ours).ok());
    EXPECT_TRUE(test::all_close("tick " + std::to_string(tick), ours.data(), expected.data(), ours.size(), 1e-5));
  }
}

INSTANTIATE_TEST_SUITE_P(Modes, SchedulerVsPolicy, ::testing::Values(false, true),
                         [](const auto& p) { return p.param ? "TemporalEnsembling" : "Queue"; });

}  // namespace
}  // namespace act
