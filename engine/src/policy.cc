// Policy: LeRobot's select_action over an Engine (spec §6).
#include <cmath>

#include "engine/src/engine_impl.h"

namespace act {

class Policy::State {
 public:
  explicit State(Engine& engine) : engine_(engine) {
    const ModelInfo& info = engine.model_info();
    action_dim_ = static_cast<size_t>(info.action_dim);
    chunk_size_ = static_cast<size_t>(info.chunk_size);
    chunk_.resize(info.chunk_values());
    if (info.temporal_ensembling) {
      // LeRobot: w = exp(-coeff * arange(T)) and its cumulative sum, in float32.
      const float coeff = static_cast<float>(info.temporal_ensemble_coeff);
      weights_.resize(chunk_size_);
      cumsum_.resize(chunk_size_);
      float running = 0.0f;
      for (size_t i = 0; i < chunk_size_; ++i) {
        weights_[i] = std::exp(-coeff * static_cast<float>(i));
        running += weights_[i];
        cumsum_[i] = running;
      }
    }
  }

  Status select(const Observation& obs, std::span<float> action) {
    if (action.size() != action_dim_) {
      return Status(StatusCode::kInvalidArgument, "action buffer holds " + std::to_string(action.size()) +
                                                      " values, the model has " + std::to_string(action_dim_));
    }
    return engine_.model_info().temporal_ensembling ? select_ensembled(obs, action) : select_queued(obs, action);
  }

  void reset() {
    queue_next_ = queue_end_ = 0;
    ensembled_.clear();
    counts_.clear();
  }

  bool will_infer_next() const { return engine_.model_info().temporal_ensembling || queue_next_ == queue_end_; }

 private:
  Status select_queued(const Observation& obs, std::span<float> action) {
    // The queue is the first n_action_steps rows of the last chunk; queue_next_ is its front.
    if (queue_next_ == queue_end_) {
      Status s = engine_.infer_normalized(obs, chunk_);
      if (!s.ok()) return s;
      queue_next_ = 0;
      queue_end_ = static_cast<size_t>(engine_.model_info().n_action_steps);
    }
    engine_.impl().unnormalize(std::span<const float>(chunk_.data() + queue_next_ * action_dim_, action_dim_), action, 1);
    ++queue_next_;
    return Status();
  }

  // LeRobot's ACTTemporalEnsembler.update, on normalised actions; the popped action is then
  // un-normalised (current layout behaviour).
  Status select_ensembled(const Observation& obs, std::span<float> action) {
    Status s = engine_.infer_normalized(obs, chunk_);
    if (!s.ok()) return s;
    if (counts_.empty()) {
      ensembled_ = chunk_;
      counts_.assign(chunk_size_, 1);
    } else {
      const size_t pending = counts_.size();  // chunk_size - 1
      for (size_t slot = 0; slot < pending; ++slot) {
        const size_t c = counts_[slot];
        const float w_prev = cumsum_[c - 1];
        const float w_new = weights_[std::min(c, chunk_size_ - 1)];
        const float w_total = cumsum_[std::min(c, chunk_size_ - 1)];
        for (size_t i = 0; i < action_dim_; ++i) {
          float& e = ensembled_[slot * action_dim_ + i];
          e = (e * w_prev + chunk_[slot * action_dim_ + i] * w_new) / w_total;
        }
        counts_[slot] = std::min(c + 1, chunk_size_);
      }
      ensembled_.insert(ensembled_.end(), chunk_.end() - static_cast<ptrdiff_t>(action_dim_), chunk_.end());
      counts_.push_back(1);
    }
    engine_.impl().unnormalize(std::span<const float>(ensembled_.data(), action_dim_), action, 1);
    ensembled_.erase(ensembled_.begin(), ensembled_.begin() + static_cast<ptrdiff_t>(action_dim_));
    counts_.erase(counts_.begin());
    return Status();
  }

  Engine& engine_;
  size_t action_dim_ = 0;
  size_t chunk_size_ = 0;
  std::vector<float> chunk_;  // the last normalised chunk
  size_t queue_next_ = 0, queue_end_ = 0;
  std::vector<float> weights_, cumsum_;
  std::vector<float> ensembled_;  // pending slots x action_dim
  std::vector<size_t> counts_;
};

Policy::Policy(Engine& engine) : state_(std::make_unique<State>(engine)) {}
Policy::~Policy() = default;
Policy::Policy(Policy&&) noexcept = default;
Policy& Policy::operator=(Policy&&) noexcept = default;

Status Policy::select_action(const Observation& observation, std::span<float> action) {
  return state_->select(observation, action);
}
void Policy::reset() { state_->reset(); }
bool Policy::will_infer_next() const { return state_->will_infer_next(); }

}  // namespace act
