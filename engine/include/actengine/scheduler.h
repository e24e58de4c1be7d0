// actengine public API: the chunk scheduler, which turns action chunks into one action per control
// tick (LeRobot's n_action_steps queue or temporal ensembling).
//
// Each chunk is tagged with the tick its observation was captured at; chunk row i belongs to tick
// (observation tick + i). Used synchronously (Policy: infer, add at this tick, take this tick's
// action) it is LeRobot's select_action. Used asynchronously (a robot keeps acting while the next
// chunk is inferred, as act_drive does), the rows that went by during the inference are skipped:
//
//   auto scheduler = act::ChunkScheduler::create(engine->model_info());
//   every tick:
//     if (chunk_ready) scheduler->add(chunk, tick_the_frame_was_captured_at);
//     if (scheduler->action_at(tick, action).ok()) drive(action); else hold_safe_action();
//     if (!inferring && scheduler->wants_inference(tick, latency_ticks + margin)) start_inference();
//
// Ensembling follows LeRobot's ACTTemporalEnsembler: every chunk that covers a tick counts, weighted
// exp(-coeff * i) with i = 0 for the oldest, folded in with LeRobot's online float32 update (the
// same operations in the same order as LeRobot's, so Policy reproduces its numbers).
//
// Units: the scheduler averages whatever it is given. Policy gives it normalised chunks
// (Engine::infer_normalized) and un-normalises the action it picks, as LeRobot does; that is what
// test/engine/test_fixtures.cc checks against LeRobot's select_action sequences. act_drive gives it
// raw chunks (Engine::infer): un-normalising is affine per dimension and the weights sum to 1, so
// averaging raw actions equals averaging normalised ones up to float rounding (~1e-6 relative).
//
// Not thread-safe: one thread at a time, like Engine. No call throws.
#pragma once

#include <cstdint>
#include <deque>
#include <span>
#include <string>
#include <vector>

#include "actengine/engine.h"
#include "actengine/status.h"

namespace act {

class ChunkScheduler {
 public:
  /// A scheduler for a model's chunks: action_dim, chunk_size, n_action_steps and temporal
  /// ensembling as in `info` (an Engine's model_info()). kInvalidArgument when the sizes make no
  /// sense (action_dim or chunk_size < 1, or a queue with n_action_steps outside [1, chunk_size]).
  static StatusOr<ChunkScheduler> create(const ModelInfo& info);

  /// Why `info`'s deployment choices (n_action_steps, temporal ensembling and its coefficient) do
  /// not fit its chunk_size under LeRobot's ACTConfig rules (1 <= n_action_steps <= chunk_size,
  /// ensembling needs n_action_steps == 1, a coefficient whose weights stay finite), or "" when they do.
  static std::string deployment_problem(const ModelInfo& info);

  /// Adds a chunk (chunk_size x action_dim, row-major) predicted from an observation captured at
  /// `observation_tick`. Queue: it replaces the previous chunk. Ensembling: it joins the chunks that
  /// still cover a tick from `observation_tick` on. kInvalidArgument for a wrong size, a non-finite
  /// value, or an observation older than the previous chunk's (chunks must come oldest first).
  Status add(std::span<const float> chunk, int64_t observation_tick);

  /// Writes the action for `tick` into `action` (action_dim values). kNotFound when no chunk covers
  /// the tick: none yet, none since clear(), or the queue ran out before the next chunk came.
  Status action_at(int64_t tick, std::span<float> action) const;

  /// True when the next inference should start at `tick`. Queue: when the newest chunk has no more
  /// than `lead_ticks` rows left from `tick` on, where lead_ticks is the expected inference latency
  /// in ticks plus any safety margin (0 when inference is synchronous: infer when the queue is
  /// empty). Ensembling: always, as LeRobot infers at every step.
  bool wants_inference(int64_t tick, int lead_ticks) const;

  /// Forgets every chunk (a new episode, or a fault).
  void clear() { chunks_.clear(); }

 private:
  friend class Policy;  // builds one from its Engine's ModelInfo, which the blob's config checks validated
  explicit ChunkScheduler(const ModelInfo& info);

  struct Chunk {
    std::vector<float> actions;
    int64_t observation_tick;
  };
  /// The row of `chunk` that belongs to `tick`, or nullptr when the chunk does not cover it.
  const float* row_for(const Chunk& chunk, int64_t tick) const;

  size_t action_dim_, chunk_size_, n_action_steps_;
  bool ensembling_;
  std::vector<float> weights_;         // LeRobot's exp(-coeff * i), float32
  std::vector<float> weight_cumsum_;   // and its running sum
  std::deque<Chunk> chunks_;           // oldest first
};

}  // namespace act
