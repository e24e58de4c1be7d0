// The inference side of act_drive: a model interface (the engine, or a test double) and a worker
// thread that turns the newest camera frame into an action chunk while the control loop keeps acting
// (the loop picks each tick's action out of the chunks with act::ChunkScheduler).
#pragma once

#include <condition_variable>
#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <ostream>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "actengine/engine.h"
#include "apps/drive/camera.h"

namespace act::drive {

/// What act_drive needs from a model: its shapes and one chunk per observation.
class ChunkModel {
 public:
  virtual ~ChunkModel() = default;
  virtual const ModelInfo& info() const = 0;
  /// Writes chunk_size x action_dim raw actions.
  virtual Status infer(const Observation& observation, std::span<float> chunk) = 0;
};

/// The real model: an act::Engine on an .actb file. Throws act::Error when it cannot be opened.
std::unique_ptr<ChunkModel> open_engine_model(const std::string& path, int threads);

/// Real-time scheduling for one thread (Linux): SCHED_FIFO priority and CPU pinning.
struct ThreadPlacement {
  int fifo_priority = 0;   ///< 1..99, 0 = leave the default scheduler
  std::vector<int> cpus;   ///< empty = any CPU
};
/// Applies `placement` to the calling thread; threads it creates later inherit it. Writes a warning
/// naming `thread_name` and falls back to the default when the OS refuses (no permission).
void apply_thread_placement(const ThreadPlacement& placement, const std::string& thread_name, std::ostream& log);

struct InferenceResult {
  std::string error;              ///< empty on success
  bool stale_frame = false;       ///< no frame younger than max_frame_age: nothing was inferred
  std::vector<float> chunk;       ///< chunk_size x action_dim raw actions (ChunkScheduler::add refuses NaN)
  Clock::time_point frame_captured{};
  uint64_t frame_index = 0;
  double frame_age_ms = 0;        ///< age of the frame when the worker took it
  double preprocess_ms = 0;
  double infer_ms = 0;
  std::vector<uint8_t> model_input;  ///< the RGB image the model saw (kept when recording)
  std::vector<float> state;          ///< the state it saw
};

struct InferenceWorkerOptions {
  std::chrono::milliseconds max_frame_age{200};
  ThreadPlacement placement;
  bool keep_model_inputs = false;  ///< return each observation's image (for --record)
};

/// One thread that owns the model. The control loop posts a request (with the state to use) and
/// later picks up the result; a frame older than max_frame_age is never used.
class InferenceWorker {
 public:
  using ModelFactory = std::function<std::unique_ptr<ChunkModel>()>;
  /// Starts the thread, which applies the placement and then builds the model (so the engine's own
  /// threads inherit the placement). Blocks until the model is ready; rethrows the factory's error.
  InferenceWorker(ModelFactory factory, const FrameSource& frames, InferenceWorkerOptions options, std::ostream& log);
  ~InferenceWorker();
  InferenceWorker(const InferenceWorker&) = delete;
  InferenceWorker& operator=(const InferenceWorker&) = delete;

  const ModelInfo& info() const { return info_; }
  /// True from request() until the result has been taken.
  bool busy() const;
  /// Asks for a chunk from the newest frame. Requires !busy().
  void request(std::vector<float> state);
  /// The finished result, if there is one (never blocks).
  std::optional<InferenceResult> take_result();
  /// Blocks until the requested result is ready (an offline replay's lockstep; the real-time loop
  /// never calls it).
  void wait_for_result();

 private:
  void run(ModelFactory factory);
  InferenceResult infer_once(ChunkModel& model, std::vector<float> state);

  const FrameSource& frames_;
  InferenceWorkerOptions options_;
  std::ostream& log_;
  ModelInfo info_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  bool started_ = false;                  // guarded by mutex_
  std::exception_ptr start_error_;        // guarded by mutex_
  bool stop_ = false;                     // guarded by mutex_
  bool busy_ = false;                     // guarded by mutex_
  std::optional<std::vector<float>> pending_state_;  // guarded by mutex_
  std::optional<InferenceResult> result_;            // guarded by mutex_
  std::thread thread_;
};

}  // namespace act::drive
