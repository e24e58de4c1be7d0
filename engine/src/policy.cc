// Policy: LeRobot's select_action over an Engine (spec §6), a synchronous use of ChunkScheduler.
#include "actengine/scheduler.h"
#include "engine/src/engine_impl.h"

namespace act {

class Policy::State {
 public:
  State(Engine& engine, const Engine::Impl& impl, ChunkScheduler scheduler)
      : engine_(engine),
        impl_(impl),
        scheduler_(std::move(scheduler)),
        chunk_(engine.model_info().chunk_values()),
        normalized_action_(static_cast<size_t>(engine.model_info().action_dim)) {}

  // Each step is one tick: infer from this step's observation when the scheduler asks for it (queue
  // empty, or every step when ensembling), add the chunk at this tick, take this tick's action.
  // Ensembling happens on normalised actions, then the action is un-normalised (LeRobot's order).
  Status select(const Observation& obs, std::span<float> action) {
    if (action.size() != normalized_action_.size()) {
      return Status(StatusCode::kInvalidArgument, "action buffer holds " + std::to_string(action.size()) +
                                                      " values, the model has " + std::to_string(normalized_action_.size()));
    }
    if (scheduler_.wants_inference(tick_, /*lead_ticks=*/0)) {
      Status s = engine_.infer_normalized(obs, chunk_);
      if (s.ok()) s = scheduler_.add(chunk_, tick_);
      if (!s.ok()) return s;
    }
    Status s = scheduler_.action_at(tick_, normalized_action_);
    if (!s.ok()) return s;
    impl_.unnormalize(normalized_action_, action, 1);
    ++tick_;
    return Status();
  }

  void reset() {
    scheduler_.clear();
    tick_ = 0;
  }

  bool will_infer_next() const { return scheduler_.wants_inference(tick_, 0); }

 private:
  Engine& engine_;
  const Engine::Impl& impl_;
  ChunkScheduler scheduler_;
  std::vector<float> chunk_;              // the last normalised chunk
  std::vector<float> normalized_action_;  // this step's action before un-normalising
  int64_t tick_ = 0;                      // steps since the last reset
};

Policy::Policy(Engine& engine)
    : state_(std::make_unique<State>(engine, *engine.impl_, ChunkScheduler(engine.model_info()))) {}
Policy::~Policy() = default;
Policy::Policy(Policy&&) noexcept = default;
Policy& Policy::operator=(Policy&&) noexcept = default;

Status Policy::select_action(const Observation& observation, std::span<float> action) {
  return state_->select(observation, action);
}
void Policy::reset() { state_->reset(); }
bool Policy::will_infer_next() const { return state_->will_infer_next(); }

}  // namespace act
