#include "apps/drive/inference.h"

#include <pthread.h>
#include <sched.h>

#include <cstring>

#include "actengine/status.h"
#include "actengine/vision.h"

namespace act::drive {
namespace {

class EngineModel : public ChunkModel {
 public:
  explicit EngineModel(std::unique_ptr<Engine> engine) : engine_(std::move(engine)) {}
  const ModelInfo& info() const override { return engine_->model_info(); }
  Status infer(const Observation& observation, std::span<float> chunk) override {
    return engine_->infer(observation, chunk);
  }

 private:
  std::unique_ptr<Engine> engine_;
};

}  // namespace

std::unique_ptr<ChunkModel> open_engine_model(const std::string& path, int threads) {
  auto engine = Engine::open(path, {.threads = threads});
  if (!engine.ok()) throw Error(engine.status());
  return std::make_unique<EngineModel>(std::move(engine.value()));
}

void apply_thread_placement(const ThreadPlacement& placement, const std::string& thread_name, std::ostream& log) {
  if (!placement.cpus.empty()) {
    cpu_set_t set;
    CPU_ZERO(&set);
    for (int cpu : placement.cpus) CPU_SET(cpu, &set);
    const int err = pthread_setaffinity_np(pthread_self(), sizeof set, &set);
    if (err != 0) {
      log << "act_drive: warning: cannot pin the " << thread_name << " thread to its CPUs (" << std::strerror(err)
          << "); it runs on any CPU\n";
    }
  }
  if (placement.fifo_priority > 0) {
    sched_param param{};
    param.sched_priority = placement.fifo_priority;
    const int err = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
    if (err != 0) {
      log << "act_drive: warning: SCHED_FIFO priority " << placement.fifo_priority << " for the " << thread_name
          << " thread refused (" << std::strerror(err)
          << "; needs root or CAP_SYS_NICE / an rtprio limit); using the default scheduler\n";
    }
  }
}

// ---- InferenceWorker ----

InferenceWorker::InferenceWorker(ModelFactory factory, const FrameSource& frames, InferenceWorkerOptions options,
                                 std::ostream& log)
    : frames_(frames), options_(std::move(options)), log_(log) {
  thread_ = std::thread([this, f = std::move(factory)]() mutable { run(std::move(f)); });
  std::unique_lock lock(mutex_);
  wake_.wait(lock, [this] { return started_; });
  if (start_error_) {
    lock.unlock();
    thread_.join();
    std::rethrow_exception(start_error_);
  }
}

InferenceWorker::~InferenceWorker() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

bool InferenceWorker::busy() const {
  std::lock_guard lock(mutex_);
  return busy_;
}

void InferenceWorker::request(std::vector<float> state) {
  {
    std::lock_guard lock(mutex_);
    busy_ = true;
    pending_state_ = std::move(state);
  }
  wake_.notify_all();
}

std::optional<InferenceResult> InferenceWorker::take_result() {
  std::lock_guard lock(mutex_);
  if (!result_) return std::nullopt;
  std::optional<InferenceResult> out = std::move(result_);
  result_.reset();
  busy_ = false;
  return out;
}

void InferenceWorker::wait_for_result() {
  std::unique_lock lock(mutex_);
  wake_.wait(lock, [this] { return !busy_ || result_.has_value(); });
}

void InferenceWorker::run(ModelFactory factory) {
  std::unique_ptr<ChunkModel> model;
  try {
    apply_thread_placement(options_.placement, "inference", log_);
    model = factory();
    info_ = model->info();
  } catch (...) {
    std::lock_guard lock(mutex_);
    start_error_ = std::current_exception();
    started_ = true;
    wake_.notify_all();
    return;
  }
  {
    std::lock_guard lock(mutex_);
    started_ = true;
  }
  wake_.notify_all();
  for (;;) {
    std::vector<float> state;
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [this] { return stop_ || pending_state_.has_value(); });
      if (stop_) return;
      state = std::move(*pending_state_);
      pending_state_.reset();
    }
    InferenceResult result;
    try {
      result = infer_once(*model, std::move(state));
    } catch (const std::exception& e) {  // a frame the preprocessing cannot take, out of memory...
      result.error = std::string("inference failed: ") + e.what();
    }
    {
      std::lock_guard lock(mutex_);
      result_ = std::move(result);
    }
    wake_.notify_all();  // wait_for_result
  }
}

InferenceResult InferenceWorker::infer_once(ChunkModel& model, std::vector<float> state) {
  InferenceResult result;
  const std::shared_ptr<const Frame> frame = frames_.latest();
  const auto start = Clock::now();
  if (!frame || frame_age(*frame, start) > options_.max_frame_age) {
    result.stale_frame = true;
    result.frame_age_ms = frame ? ms_between(frame->captured, start) : 0;
    return result;
  }
  result.frame_captured = frame->captured;
  result.frame_index = frame->index;
  result.frame_age_ms = ms_between(frame->captured, start);

  const CameraInfo& camera = info_.cameras.front();
  const Status converted = frame_to_model_rgb(frame->bgr, camera.height, camera.width, result.model_input);
  if (!converted.ok()) throw Error(converted);
  const auto preprocessed = Clock::now();
  result.preprocess_ms = ms_between(start, preprocessed);

  result.state = std::move(state);
  Observation observation;
  observation.images = {ImageView::rgb_u8(result.model_input.data(), camera.height, camera.width)};
  observation.state = result.state;
  result.chunk.resize(info_.chunk_values());
  const Status status = model.infer(observation, result.chunk);
  result.infer_ms = ms_between(preprocessed, Clock::now());
  if (!options_.keep_model_inputs) result.model_input = {};
  if (!status.ok()) result.error = "inference failed: " + status.to_string();
  return result;
}

}  // namespace act::drive
