// ChunkScheduler: which chunk row each control tick executes (queue and temporal ensembling).
#include <gtest/gtest.h>

#include <cmath>

#include "apps/drive/inference.h"

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
