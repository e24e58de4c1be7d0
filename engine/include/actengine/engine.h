// actengine public API: run a converted LeRobot ACT policy (.actb blob).
//
//   auto engine = act::Engine::open("model.actb", {.threads = 4});
//   if (!engine.ok()) { std::cerr << engine.status().to_string(); ... }
//   act::Observation obs;
//   obs.images = {act::ImageView::rgb_u8(frame.data, 480, 640)};
//   obs.state = state;                       // raw units, model_info().state_dim values
//   std::vector<float> chunk(engine->model_info().chunk_values());
//   act::Status s = (*engine)->infer(obs, chunk);   // [chunk_size x action_dim], raw units
//
// Thread safety: an Engine owns its buffers and its thread pool; one Engine must not be used from
// two threads at once (infer() is not reentrant). Different Engines share nothing and may run side
// by side in any threads. A Policy is bound to one Engine and has the same rule.
// No call throws; failures come back as act::Status with a message naming the problem.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "actengine/status.h"

namespace act {

/// The most threads an Engine runs on (and what every --threads / threads= accepts): a larger count
/// is refused with an error naming this limit instead of starting that many OS threads.
inline constexpr int kMaxThreads = 256;

struct EngineOptions {
  /// Worker threads for one inference, 0..kMaxThreads; 0 = one per online core (at most kMaxThreads).
  /// A thread the OS refuses makes Engine::open fail with a Status saying so (never a hang).
  int threads = 0;
  /// Verify the blob's checksum at open (reads the whole file once).
  bool verify_checksum = true;
  /// The model an Engine runs never changes: by default open() reads the blob into memory of its
  /// own, so copying a new model over the file (cp, scp), or truncating it, while the Engine runs
  /// changes nothing. true shares the file's pages instead (no copy, less memory when several
  /// processes run one blob); then the file must not change while the Engine is open: a rewrite
  /// changes the weights under it, a truncation kills the process with SIGBUS.
  bool share_blob_pages = false;
  /// Time every stage and op of every inference (Engine::last_timings, op_profile, chrome_trace);
  /// costs two clock reads per op and thread. Off, the profiler costs nothing.
  bool profile = false;
  /// Give every network value its own memory so Engine::intermediate() can read it after an
  /// inference (to compare with LeRobot layer by layer); costs memory, never changes results.
  bool keep_intermediates = false;
  /// The instruction set the kernels use: "auto" (the best this CPU runs; the ACT_ISA environment
  /// variable, when set, overrides it) or one of ref, avx2, avxvnni, avx512, avx512vnni, amx (x86-64), neon,
  /// neondot (AArch64). An unknown ISA, or one this CPU cannot run, fails Engine::open with a
  /// message listing the ISAs this CPU runs.
  std::string isa = "auto";
  /// The core the kernels are tuned for: "auto" (this CPU's; the ACT_UARCH environment variable,
  /// when set, overrides it) or one of generic, zen4, zen5, goldencove, gracemont, cortex-a76
  /// (kernels/config/kernel_tuning.h). Any of them runs on any CPU; an unknown name fails
  /// Engine::open with a message listing them.
  std::string uarch = "auto";
  /// The split engine: the cameras' backbones (ResNet + input projection) run elsewhere, e.g. the ONNX
  /// export's `--onnx-part backbone` on an accelerator, and every image of an Observation is their
  /// output, ImageView::backbone_features. The blob is the same; its backbone weights go unused.
  bool external_backbone = false;
};

/// Wall time of one inference by stage, in milliseconds. "other" is what belongs to no stage: the
/// state tokens, copying the chunk out, un-normalising.
struct InferenceTimings {
  double preprocess_ms = 0;  ///< validating and normalising the observation
  double backbone_ms = 0;    ///< ResNet and the image projections, all cameras (0 when external)
  double encoder_ms = 0;
  double decoder_ms = 0;     ///< decoder and action head
  double other_ms = 0;
  double total_ms = 0;
};

/// One op of the network as the profiler saw it (EngineOptions::profile): its wall time summed
/// over every inference since open() or Engine::reset_op_profile().
struct OpProfile {
  std::string name;    ///< the value it computes, e.g. "cam0.backbone.layer1.0.conv1.s8"
  std::string kind;    ///< e.g. "conv2d_s8_s8", "attention_f32"
  std::string kernel;  ///< the kernel variant it calls, e.g. "gemm_s8_s8out_6x64c4_avx512vnni"
  std::string stage;   ///< "backbone", "encoder", "decoder" or "other"
  double macs = 0;     ///< multiply-accumulates of one run (0 for ops that do no dot products)
  int64_t runs = 0;
  double total_ms = 0;
};

struct CameraInfo {
  std::string key;  ///< feature key, e.g. "observation.images.front"
  int height = 0;
  int width = 0;
  int feature_height = 0;  ///< of the backbone's output feature map (ImageView::backbone_features)
  int feature_width = 0;
};

/// What a loaded model expects and produces; everything is derived from the blob's config.
struct ModelInfo {
  std::vector<CameraInfo> cameras;  ///< in token order (the config's input_features order)
  int state_dim = 0;                ///< robot state values per observation (0 = no state input)
  int env_state_dim = 0;            ///< environment state values (0 = none)
  std::string env_state_key;        ///< its feature key, e.g. "observation.environment_state"
  int action_dim = 0;
  /// The action dimensions' names stored in the blob (act_convert --action-names), one per action
  /// value; empty for a blob without them (then tools say action.0, action.1, ...).
  std::vector<std::string> action_names;
  int dim_model = 0;  ///< the transformer's width: channels of the backbone's output features
  int chunk_size = 0;
  int n_action_steps = 0;
  /// The raw actions that the network's normalised -1 and +1 stand for, per action dimension
  /// (MEAN_STD: mean -/+ std; MIN_MAX: min and max; no normalisation: -1 and +1): the scale of the
  /// model's actions, e.g. to tell pulse widths in microseconds from values around 0.
  std::vector<float> action_low, action_high;
  /// The same for the robot state (state_dim values each): the raw states that normalised -1 and +1
  /// stand for. Their middle is the training mean (MEAN_STD) or mid-range (MIN_MAX), e.g. a sensible
  /// state before the robot has acted.
  std::vector<float> state_low, state_high;
  bool temporal_ensembling = false;
  double temporal_ensemble_coeff = 0.0;
  std::string precision;  ///< "fp32", "int8 static", "int8 dynamic" or "int8 mixed"
  std::string isa;        ///< the instruction set the kernels were chosen for, e.g. "avx512vnni"
  std::string kernels;    ///< the kernel variants in use, e.g. "avx512vnni, tuned for zen4: gemm_s8 6x64c4 avx512vnni, ..."
  std::string summary;    ///< one line: backbone, dims, layers, cameras
  /// Where each part runs: "backbone: actengine (cpu), transformer: actengine (cpu)", or with
  /// EngineOptions::external_backbone "backbone: external (features given by the caller), ...".
  std::string placement;
  size_t chunk_values() const { return static_cast<size_t>(chunk_size) * action_dim; }
};

/// One camera image, viewed (not copied). Either uint8 RGB, height x width x 3, rows `row_stride`
/// bytes apart (0 = packed); or float32 RGB channel-first 3 x height x width with values in [0, 1];
/// or, for an Engine opened with EngineOptions::external_backbone, the camera's backbone output:
/// float32 channel-first dim_model x feature_height x feature_width (the ONNX backbone's
/// "<camera key>.features" [1, dim_model, h, w], CameraInfo::feature_height/width).
struct ImageView {
  enum class Format { kRgbU8Hwc, kRgbF32Chw, kBackboneFeaturesF32Chw };
  Format format = Format::kRgbU8Hwc;
  const void* data = nullptr;
  int height = 0;
  int width = 0;
  size_t row_stride = 0;

  static ImageView rgb_u8(const uint8_t* data, int height, int width, size_t row_stride = 0) {
    return {Format::kRgbU8Hwc, data, height, width, row_stride};
  }
  static ImageView rgb_f32_chw(const float* data, int height, int width) {
    return {Format::kRgbF32Chw, data, height, width, 0};
  }
  static ImageView backbone_features(const float* data, int feature_height, int feature_width) {
    return {Format::kBackboneFeaturesF32Chw, data, feature_height, feature_width, 0};
  }
};

/// One observation: an image per camera (in ModelInfo::cameras order) and the raw state vectors.
struct Observation {
  std::vector<ImageView> images;
  std::span<const float> state;
  std::span<const float> env_state;
};

class Engine {
 public:
  /// Opens an .actb blob (a private copy, or shared pages: EngineOptions::share_blob_pages), builds
  /// and plans the network, starts the thread pool.
  static StatusOr<std::unique_ptr<Engine>> open(const std::string& blob_path, const EngineOptions& options = {});
  ~Engine();
  Engine(const Engine&) = delete;
  Engine& operator=(const Engine&) = delete;

  const ModelInfo& model_info() const;
  int threads() const;

  /// Runs the network on one observation and writes the raw (un-normalised) action chunk,
  /// chunk_size x action_dim row-major, into `actions` (which must hold chunk_values() floats).
  /// Validates image count, sizes, state lengths and that every input value is finite.
  Status infer(const Observation& observation, std::span<float> actions);
  /// As infer(), but writes the normalised network output (before un-normalisation).
  Status infer_normalized(const Observation& observation, std::span<float> actions_normalized);
  /// Stage times of the last successful infer (all zero unless EngineOptions::profile is set).
  const InferenceTimings& last_timings() const;
  /// Every op in the order it runs, with its time summed over the inferences since open() or
  /// reset_op_profile() (empty unless EngineOptions::profile is set).
  std::vector<OpProfile> op_profile() const;
  /// Starts the op profile's sums afresh (e.g. after warm-up runs).
  void reset_op_profile();
  /// The last inference as a Chrome trace (JSON for chrome://tracing and ui.perfetto.dev): one
  /// lane per thread, a slice per op on each thread that worked on it. kFailedPrecondition without
  /// EngineOptions::profile or before the first inference.
  StatusOr<std::string> chrome_trace() const;

  /// The names of the network's values, in the order they are computed ("cam0.backbone.layer1",
  /// "encoder_layer0_out", "actions_normalized", ...).
  std::vector<std::string> intermediate_names() const;
  /// One value of the last inference as floats, in the engine's layout (image features are
  /// height x width x channels); int8 values dequantized. Needs EngineOptions::keep_intermediates.
  /// kNotFound for an unknown name; kFailedPrecondition without keep_intermediates or before the
  /// first inference; kUnimplemented for an int8 value quantized at run time (no scale is kept).
  StatusOr<std::vector<float>> intermediate(const std::string& name) const;

  class Impl;  ///< defined inside the library (engine/src); not part of the API

 private:
  friend class Policy;  // un-normalises the actions it picks
  explicit Engine(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// LeRobot's select_action: returns one action per control step, inferring synchronously. A thin
/// use of ChunkScheduler (actengine/scheduler.h), which also serves robots that keep acting while
/// the next chunk is inferred.
///  - n_action_steps queue (temporal ensembling off): runs the network when the queue is empty and
///    queues the first n_action_steps rows of the chunk;
///  - temporal ensembling (coeff set, n_action_steps == 1): runs every step and averages all
///    predictions of the current step with weights exp(-coeff * i), i = 0 the oldest, using LeRobot's
///    exact online update.
/// Ensembling happens on normalised actions, then the result is un-normalised (as LeRobot's current
/// layout does).
class Policy {
 public:
  explicit Policy(Engine& engine);
  ~Policy();
  Policy(Policy&&) noexcept;
  Policy& operator=(Policy&&) noexcept;

  /// Writes action_dim raw action values into `action`.
  Status select_action(const Observation& observation, std::span<float> action);
  /// Empties the queue / ensemble (call at the start of an episode).
  void reset();
  /// True when the next select_action() will run the network.
  bool will_infer_next() const;

 private:
  class State;
  std::unique_ptr<State> state_;
};

/// Library version, "0.1.0".
const char* version();

}  // namespace act
