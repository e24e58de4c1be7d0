// Engine internals, shared by engine.cc and policy.cc, and used by tests to read intermediates.
#pragma once

#include <chrono>
#include <memory>
#include <new>
#include <span>
#include <string>

#include "actengine/engine.h"
#include "actengine/status.h"
#include "graph/act_network.h"
#include "graph/thread_pool.h"
#include "kernels/config/kernel_config.h"
#include "weights/blob/actb.h"
#include "weights/blob/blob_tensors.h"
#include "weights/blob/model_config.h"

namespace act {

/// What a model config says a model takes and gives (ModelInfo's shape fields, its precision and
/// summary); an Engine adds the kernels it runs.
ModelInfo model_info_of(const ModelConfig& config);

class Engine::Impl {
 public:
  /// Opens the blob and plans the network (EngineOptions::keep_intermediates gives every graph value
  /// its own memory, so it can be read after a run). Throws act::Error.
  /// `packed_weights_from`: another Engine's float weights to share (graph::ActNetwork's
  /// packed_weights_from, whose contract the caller keeps).
  Impl(const std::string& blob_path, const EngineOptions& options, const Impl* packed_weights_from = nullptr);

  const ModelInfo& info() const { return info_; }
  const ModelConfig& config() const { return config_; }
  int threads() const { return pool_.threads(); }
  graph::ActNetwork& network() { return *network_; }

  /// Validates and normalises the observation into the network's inputs, runs it, and copies the
  /// normalised chunk out. Throws act::Error(kInvalidArgument) on a bad observation.
  void run(const Observation& observation, std::span<float> actions_normalized);
  /// x = (y + shift) * scale + offset per action dimension, for `rows` rows.
  void unnormalize(std::span<const float> normalized, std::span<float> raw, size_t rows) const;
  /// A value of the last run as floats (see Engine::intermediate). Throws act::Error.
  std::vector<float> intermediate(const std::string& name);
  /// Stage times of the last run (zeros unless profiling).
  InferenceTimings& timings() { return timings_; }
  bool profiling() const { return profile_; }
  /// Per-op sums since open or reset_op_profile (empty unless profiling).
  std::vector<OpProfile> op_profile() const;
  void reset_op_profile();
  /// The last run as Chrome trace JSON. Throws act::Error(kFailedPrecondition) without profiling
  /// or before the first run.
  std::string chrome_trace() const;

 private:
  struct InputNorm {
    NormMode mode = NormMode::kIdentity;
    const float* sub = nullptr;
    const float* div = nullptr;
    float apply(float x, size_t i) const;
    float invert(float z, size_t i) const;  ///< the raw value that normalises to z
  };
  /// The statistics of input feature `key` (`size` values), read at open.
  InputNorm input_norm(const std::string& key, size_t size);
  void load_image(size_t camera, const ImageView& image);
  /// load_image()'s two formats, after its checks; `what` names the image in messages.
  void load_rgb_u8(size_t camera, const ImageView& image, const std::string& what);
  void load_float_chw(size_t camera, const ImageView& image, const std::string& what);
  /// An int8 stem's input codes from normalised floats.
  void quantize_camera_codes(size_t camera, size_t n, const float* x, int8_t* y) const;
  /// Profiling: turns last_run_ into the stage timings and adds it to the op sums.
  void record_profile(std::chrono::steady_clock::time_point preprocess_start,
                      std::chrono::steady_clock::time_point preprocess_end);
  /// Split engine: the camera's backbone output, channel-first, as the network's [h * w, D] tokens.
  void load_features(size_t camera, const ImageView& features);
  void load_vector(const char* what, std::span<const float> values, size_t expected, const InputNorm& norm, float* dst);

  ActbFile blob_;
  BlobTensors blob_tensors_;  // records what open() reads of blob_
  ModelConfig config_;
  ModelInfo info_;
  ThreadPool pool_;
  kernels::KernelConfig kernels_;  // before network_, which packs for it and runs with it
  std::unique_ptr<graph::ActNetwork> network_;
  std::vector<InputNorm> camera_norm_;
  std::vector<float> float_image_;  // a float image normalised before it is quantized for an int8 stem
  InputNorm state_norm_, env_norm_;
  const float* unnorm_shift_ = nullptr;
  const float* unnorm_scale_ = nullptr;
  const float* unnorm_offset_ = nullptr;
  bool profile_ = false;
  graph::RunProfile last_run_;             // profiling: when each op of the last run ran, per thread
  std::vector<double> op_total_seconds_;   // profiling: each op's time summed over the runs
  int64_t profiled_runs_ = 0;
  bool keep_intermediates_ = false;
  bool external_backbone_ = false;
  bool has_run_ = false;
  InferenceTimings timings_;
};

/// Runs `fn`, turning act::Error and std exceptions into a Status (the API never throws).
template <typename Fn>
Status guarded(Fn&& fn) {
  try {
    fn();
    return Status();
  } catch (const Error& e) {
    return e.status();
  } catch (const std::bad_alloc&) {
    return Status(StatusCode::kInternal, "out of memory");
  } catch (const std::exception& e) {
    return Status(StatusCode::kInternal, e.what());
  }
}

}  // namespace act
