// ChunkScheduler: the n_action_steps queue and LeRobot's temporal ensembling over tick-tagged chunks.
#include "actengine/scheduler.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <string>

#include "weights/blob/model_config.h"

namespace act {

StatusOr<ChunkScheduler> ChunkScheduler::create(const ModelInfo& info) {
  const auto invalid = [](const std::string& what) { return Status(StatusCode::kInvalidArgument, "chunk scheduler: " + what); };
  if (info.action_dim < 1) return invalid("action_dim " + std::to_string(info.action_dim) + " must be >= 1");
  if (info.chunk_size < 1) return invalid("chunk_size " + std::to_string(info.chunk_size) + " must be >= 1");
  if (!info.temporal_ensembling && (info.n_action_steps < 1 || info.n_action_steps > info.chunk_size)) {
    return invalid("n_action_steps " + std::to_string(info.n_action_steps) + " must be in [1, chunk_size " +
                   std::to_string(info.chunk_size) + "]");
  }
  if (info.temporal_ensembling) {
    const std::string problem = ModelConfig::ensemble_coeff_problem(info.temporal_ensemble_coeff, info.chunk_size);
    if (!problem.empty()) return invalid(problem);
  }
  return ChunkScheduler(info);
}

std::string ChunkScheduler::deployment_problem(const ModelInfo& info) {
  const std::optional<double> coeff = info.temporal_ensembling ? std::optional<double>(info.temporal_ensemble_coeff) : std::nullopt;
  return ModelConfig::deployment_problem(info.n_action_steps, coeff, info.chunk_size);
}

ChunkScheduler::ChunkScheduler(const ModelInfo& info)
    : action_dim_(static_cast<size_t>(info.action_dim)),
      chunk_size_(static_cast<size_t>(info.chunk_size)),
      n_action_steps_(static_cast<size_t>(info.n_action_steps)),
      ensembling_(info.temporal_ensembling) {
  if (ensembling_) {
    // LeRobot: w = exp(-coeff * arange(chunk_size)) and its cumulative sum, in float32.
    const float coeff = static_cast<float>(info.temporal_ensemble_coeff);
    weights_.resize(chunk_size_);
    weight_cumsum_.resize(chunk_size_);
    float running = 0.0f;
    for (size_t i = 0; i < chunk_size_; ++i) {
      weights_[i] = std::exp(-coeff * static_cast<float>(i));
      running += weights_[i];
      weight_cumsum_[i] = running;
    }
  }
}

Status ChunkScheduler::add(std::span<const float> chunk, int64_t observation_tick) {
  if (chunk.size() != chunk_size_ * action_dim_) {
    return Status(StatusCode::kInvalidArgument, "chunk holds " + std::to_string(chunk.size()) + " values, expected " +
                                                    std::to_string(chunk_size_) + " x " + std::to_string(action_dim_));
  }
  for (size_t i = 0; i < chunk.size(); ++i) {
    if (!std::isfinite(chunk[i])) {
      return Status(StatusCode::kInvalidArgument, "non-finite action (" + std::to_string(chunk[i]) + " at step " +
                                                      std::to_string(i / action_dim_) + ", value " +
                                                      std::to_string(i % action_dim_) + ")");
    }
  }
  if (!chunks_.empty() && observation_tick < chunks_.back().observation_tick) {
    return Status(StatusCode::kInvalidArgument, "chunk observed at tick " + std::to_string(observation_tick) +
                                                    " is older than the previous one (tick " +
                                                    std::to_string(chunks_.back().observation_tick) + ")");
  }
  // Chunks that can no longer count give their memory to the new one (no allocation once warm).
  std::vector<float> storage;
  const auto retire_front = [&] {
    storage = std::move(chunks_.front().actions);
    chunks_.pop_front();
  };
  if (!ensembling_) {
    while (!chunks_.empty()) retire_front();  // the queue only ever executes the newest chunk
  }
  const int64_t rows = static_cast<int64_t>(chunk_size_);
  while (!chunks_.empty() && chunks_.front().observation_tick + rows <= observation_tick) retire_front();
  storage.assign(chunk.begin(), chunk.end());
  chunks_.push_back({std::move(storage), observation_tick});
  return Status();
}

const float* ChunkScheduler::row_for(const Chunk& chunk, int64_t tick) const {
  if (tick < chunk.observation_tick) return nullptr;
  const size_t row = static_cast<size_t>(tick - chunk.observation_tick);
  const size_t horizon = ensembling_ ? chunk_size_ : n_action_steps_;
  return row < horizon ? chunk.actions.data() + row * action_dim_ : nullptr;
}

Status ChunkScheduler::action_at(int64_t tick, std::span<float> action) const {
  if (action.size() != action_dim_) {
    return Status(StatusCode::kInvalidArgument, "action buffer holds " + std::to_string(action.size()) +
                                                    " values, the model has " + std::to_string(action_dim_));
  }
  size_t count = 0;  // chunks folded in so far, oldest first
  for (const Chunk& chunk : chunks_) {
    const float* row = row_for(chunk, tick);
    if (row == nullptr) continue;
    if (count == 0) {
      std::copy_n(row, action_dim_, action.begin());
    } else {
      // LeRobot's ACTTemporalEnsembler.update for one slot, its count clamped to chunk_size as there.
      const size_t c = std::min(count, chunk_size_);
      const float w_prev = weight_cumsum_[c - 1];
      const float w_new = weights_[std::min(c, chunk_size_ - 1)];
      const float w_total = weight_cumsum_[std::min(c, chunk_size_ - 1)];
      for (size_t i = 0; i < action_dim_; ++i) action[i] = (action[i] * w_prev + row[i] * w_new) / w_total;
    }
    ++count;
  }
  if (count == 0) return Status(StatusCode::kNotFound, "no chunk covers tick " + std::to_string(tick));
  // The last check before an action leaves the scheduler: never hand out a non-finite number.
  for (size_t i = 0; i < action_dim_; ++i) {
    if (!std::isfinite(action[i])) {
      return Status(StatusCode::kInternal, "the action for tick " + std::to_string(tick) + " is not finite (value " +
                                               std::to_string(i) + ")");
    }
  }
  return Status();
}

bool ChunkScheduler::wants_inference(int64_t tick, int lead_ticks) const {
  if (ensembling_ || chunks_.empty()) return true;
  const int64_t rows_left = chunks_.back().observation_tick + static_cast<int64_t>(n_action_steps_) - tick;
  return rows_left <= lead_ticks;
}

}  // namespace act
