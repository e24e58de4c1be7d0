// actengine public API: make an .actb blob from a trained LeRobot ACT policy (libactengine_convert).
//
//   auto model = act::import_checkpoint("outputs/train/act_so100/checkpoints/last/pretrained_model");
//   if (!model.ok()) { std::cerr << model.status().to_string(); ... }
//   auto bytes = (*model)->write_fp32("model.actb");   // StatusOr<uint64_t>
//
//   act::CalibrationSet calibration;             // frames at the model's input size, e.g. from
//   calibration.frames = ...;                    // actengine/vision.h's frame_to_model_rgb
//   auto report = (*model)->write_int8("model_int8.actb", calibration, {.mode = act::Int8Mode::kStatic});
//   std::cout << report->to_text();              // held-out error against the FP32 model, per-layer SQNR
//
// Blobs are written atomically: until a call succeeds nothing appears at the path, and an interrupted
// or killed conversion leaves no file behind (intermediate blobs live in unnamed files).
// No call throws; failures come back as act::Status with a message naming the problem.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "actengine/engine.h"
#include "actengine/status.h"

namespace act {

// ------------------------------------------------------------------------------------------ import

/// What a PyTorch .pth state dict does not say, given beside it (act_convert's .pth options). A
/// LeRobot checkpoint folder needs none of this: its config.json and statistics are in the folder.
struct PthOptions {
  std::string config_path;               ///< LeRobot config.json of the trained policy ("" = none)
  std::vector<std::string> stats_paths;  ///< meta/stats.json or policy_*_normalizer_processor.safetensors
  std::optional<std::pair<int, int>> image_size;  ///< height, width of every camera in training
  std::optional<int> n_heads;
  std::optional<std::string> activation;  ///< "relu", "gelu" or "glu"
  std::vector<std::string> cameras;       ///< camera feature keys, in token order
  bool lerobot_defaults = false;  ///< take LeRobot's ACTConfig defaults for what leaves no trace in the weights
  bool no_normalization = false;  ///< the model was trained on raw inputs and actions (no statistics)
  std::string state_dict_key;     ///< entry of a wrapping dict that holds the state dict
};

/// How the robot executes the chunks, a deployment choice LeRobot keeps in config.json: given, it
/// replaces the checkpoint's (a .pth needs n_action_steps from here or its --config). Checked as
/// LeRobot's ACTConfig does: 1 <= n_action_steps <= chunk_size, ensembling needs n_action_steps 1, the
/// coefficient a finite number small enough for exp(-coeff * i) over the chunk.
struct DeploymentOptions {
  std::optional<int> n_action_steps;  ///< actions executed per predicted chunk
  /// Set: replaces temporal_ensemble_coeff. A number turns ensembling on; an empty value (LeRobot's
  /// null) turns it off.
  std::optional<std::optional<double>> temporal_ensemble_coeff;
};

/// One config value of a .pth conversion and where it came from.
struct ConfigValueSource {
  std::string field;   ///< LeRobot config.json field, e.g. "dim_model"
  std::string value;   ///< as JSON
  std::string source;  ///< e.g. "model.action_head.weight [2, 64]", "--image-size", "config.json"
};

/// What was read from a .pth and how its config was worked out (act_convert --explain).
struct PthExplanation {
  std::string origin;                   ///< the file (and the archive member) the state dict came from
  std::string format;                   ///< torch.save format: "zip" or "legacy"
  std::string location;                 ///< where in the saved object the state dict was found
  size_t tensors = 0;                   ///< in the state dict
  std::vector<std::string> other_entries;  ///< saved beside the state dict, not used
  std::vector<std::string> notes;          ///< e.g. key prefixes added or removed
  std::string statistics_source;           ///< "" when none was found
  std::vector<ConfigValueSource> config;   ///< every config value with its source, in config order
  std::vector<std::string> missing;        ///< what cannot be known, each with the option that gives it
};

class ImportedCheckpoint;

/// A .pth read and its config worked out, not yet imported: explain() it, then import_checkpoint().
class PthPlan {
 public:
  /// Reads the state dict. Fails on an unreadable file or a contradiction (a config.json that does
  /// not match the weights); facts that cannot be known are listed in explanation().missing instead.
  static StatusOr<std::unique_ptr<PthPlan>> read(const std::string& pth_path, const PthOptions& options = {},
                                                 const DeploymentOptions& deployment = {});
  ~PthPlan();
  PthPlan(const PthPlan&) = delete;
  PthPlan& operator=(const PthPlan&) = delete;

  const PthExplanation& explanation() const { return explanation_; }

 private:
  class Impl;
  friend StatusOr<std::unique_ptr<ImportedCheckpoint>> import_checkpoint(const PthPlan&);
  explicit PthPlan(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
  PthExplanation explanation_;
};

/// What an import found, for reports. Counts are of values (floats) and of tensors.
struct ImportSummary {
  std::string source;  ///< "current LeRobot layout", or the .pth's format, location and statistics source
  ModelInfo model;     ///< as an Engine would report the FP32 blob (kernels left empty)
  int encoder_tokens = 0;
  uint64_t checkpoint_values = 0;
  size_t checkpoint_tensors = 0;
  uint64_t training_only_values = 0;  ///< dropped: the VAE encoder and training targets
  size_t training_only_tensors = 0;
  uint64_t blob_values = 0;           ///< after BatchNorm and constant folding
  double macs = 0;                    ///< multiply-accumulates per inference, all of them
  double backbone_macs = 0, encoder_macs = 0, decoder_macs = 0;  ///< the three big parts of `macs`
  std::vector<std::string> notes;     ///< what a user should know (e.g. features without statistics)
};

// ------------------------------------------------------------------------------------------- INT8

enum class Int8Mode {
  kDynamic,  ///< activations quantized at run time, no calibration
  kStatic,   ///< calibrated backbone, int8 from layer to layer
  kMixed,    ///< static, keeping in float the fewest layers that meet Int8Options::target_mse
};
/// "dynamic", "static", "mixed".
const char* int8_mode_name(Int8Mode mode);

enum class CalibrationMethod {
  kMinMax,      ///< the whole observed range
  kPercentile,  ///< the range without its tails (Int8Options::percentile)
  kMse,         ///< the range that minimizes the expected squared quantization error
};
/// "minmax", "percentile", "mse".
const char* calibration_method_name(CalibrationMethod method);
StatusOr<CalibrationMethod> parse_calibration_method(std::string_view name);

/// One observation for calibration and the accuracy report.
struct CalibrationFrame {
  /// Per camera (ModelInfo::cameras order): RGB uint8, height x width x 3 packed, at the model's
  /// input size (actengine/vision.h converts a camera frame exactly as calibration expects).
  std::vector<std::vector<uint8_t>> images;
  /// Raw (un-normalised) robot and environment states. Empty: sampled from the model's normalisation
  /// statistics (a note in the report says so).
  std::vector<float> state, env_state;
};

struct CalibrationSet {
  std::vector<CalibrationFrame> frames;
  std::vector<std::string> notes;  ///< about the frames, carried into the report
  std::string preprocessing;       ///< how the images were made, for the report
};

/// The int8 codes the transformer's linears read (static and mixed modes): per token (each row's
/// scale and zero point from its own range at run time) or per tensor (calibrated, fixed). Per
/// tensor is tried where it buys speed: an FFN's hidden activation, which its hidden layer then
/// requantizes into inside its GEMM instead of a float pass (elsewhere it would save only finding
/// each row's range, and a calibrated range there, attention's output, say, clips more on frames
/// unlike the calibration frames).
enum class LinearInputCodes { kAuto, kPerToken, kPerTensor };
/// kAuto's budget: per-tensor codes may raise the held-out MSE by this fraction at most, and its
/// max |err| (one value of a few frames' chunks, a noisier figure) by kPerTensorCodesMaxErrorBudget.
inline constexpr double kPerTensorCodesErrorBudget = 0.10;
inline constexpr double kPerTensorCodesMaxErrorBudget = 0.25;

enum class AttentionPrecision { kAuto, kInt8, kFp32 };
/// kAuto's budget: int8 attention may raise the held-out error by this fraction at most.
inline constexpr double kInt8AttentionErrorBudget = 0.25;

/// How far a conversion is, for a progress display: `done` of `total` `unit`s of `task` (e.g. 3 of 64
/// "frames" of "calibrating (mse)"; done 0 when a task starts), or, with total 0, a one-off
/// message in `task` (e.g. "all layers int8: held-out MSE 0.0021 (target 0.001)").
struct ConversionProgress {
  std::string task;
  size_t done = 0, total = 0;
  const char* unit = "";
};

struct Int8Options {
  Int8Mode mode = Int8Mode::kStatic;
  CalibrationMethod method = CalibrationMethod::kMse;
  double percentile = 99.99;  ///< for CalibrationMethod::kPercentile, in [50, 100]
  /// Frames used for calibration, at most; the held-out frames come on top (calibration_frames_wanted).
  size_t calib_samples = 64;
  std::optional<size_t> holdout;     ///< frames kept out for the report (default: a fifth, 1..16)
  std::optional<double> target_mse;  ///< kMixed: the held-out MSE to meet, normalised units
  std::optional<double> max_mse;     ///< fail, writing nothing, above this held-out MSE (normalised)
  int threads = 0;                   ///< for calibration and evaluation; 0 = one per online core
  uint64_t seed = 1;                 ///< for sampled states and synthetic frames
  bool layer_report = true;          ///< per-layer SQNR (one more pass over up to 4 held-out frames)
  /// Attention's matmuls (Q K^T, P V): kAuto puts them on the int8 GEMM when that raises the
  /// held-out MSE and max |err| by at most kInt8AttentionErrorBudget (and, mixed, still meets the
  /// target); kInt8 and kFp32 force the choice.
  AttentionPrecision attention = AttentionPrecision::kAuto;
  /// The linears' input codes: kAuto makes per tensor the FFN hidden activations whose calibrated
  /// codes lose least (estimated SQNR against per token), as many as keep the held-out MSE and
  /// max |err| within kPerTensorCodesErrorBudget and kPerTensorCodesMaxErrorBudget of all per
  /// token (and, mixed, the target);
  /// kPerToken and kPerTensor force the choice (per tensor: every FFN's). Dynamic mode has no
  /// calibration: always per token, and anything but kAuto is refused (kInvalidArgument).
  LinearInputCodes linear_inputs = LinearInputCodes::kAuto;
  /// Layers kept in float, by their weight tensors' names (LayerSqnr::layer, Int8Report::float_layers,
  /// e.g. "backbone.conv1.weight"); kMixed chooses more on top when the target needs them.
  std::vector<std::string> keep_float;
  /// Called as the conversion goes (the library never prints); none if empty.
  std::function<void(const ConversionProgress&)> progress;
};

/// How many frames a CalibrationSet should hold for these options: calib_samples plus the held-out ones.
size_t calibration_frames_wanted(const Int8Options& options);

/// The INT8 model's actions against the FP32 model's, over the held-out frames. Normalised units
/// are the network's outputs; physical ones the robot's (after un-normalisation).
struct ActionError {
  double mse = 0, max_abs = 0;
  double mse_physical = 0, max_abs_physical = 0;
  std::vector<double> per_dim_mse, per_dim_max_abs;  ///< per action dimension
  std::vector<double> per_dim_mse_physical, per_dim_max_abs_physical;
};

struct LayerSqnr {
  /// The layer's name, as float_layers and Int8Options::keep_float name it: its weight tensor
  /// (e.g. "backbone.layer1.0.conv1.weight"); the max pool, which has none, by its output value.
  std::string layer;
  std::string value;  ///< the layer's output value (per camera: "cam0.backbone.layer1.0.conv1")
  std::string op;     ///< its op type, e.g. "conv2d_s8_s8"
  bool kept_float = false;  ///< a layer kept in float (float_layers): its output's SQNR is the noise of the layers before it
  double sqnr_db = 0;  ///< of the output against the FP32 one (200 when they are equal)
};

/// A calibrated activation: the int8 parameters chosen for a value and the range its float values
/// took on the calibration frames (static and mixed modes).
struct ActivationRange {
  std::string value;  ///< e.g. "cam0.backbone.layer1.0.conv1"
  float scale = 1;
  int32_t zero_point = 0;
  double observed_min = 0, observed_max = 0;  ///< over the calibration frames
  /// What the int8 values can stand for: scale * (-128 - zero_point) .. scale * (127 - zero_point).
  double quantized_min() const { return static_cast<double>(scale) * (-128 - zero_point); }
  double quantized_max() const { return static_cast<double>(scale) * (127 - zero_point); }
};

/// One matrix the transformer's int8 linears read, and the codes the converter chose for it.
struct LinearInputChoice {
  std::string value;   ///< e.g. "encoder_layer0.norm1"
  std::string reader;  ///< the weight of the (first) linear that reads it
  /// The FFN (0, 1, ... in graph order) whose hidden activation it is, when that FFN's hidden layer
  /// can requantize in its GEMM (ReLU or no activation): the inputs tried per tensor. -1: always
  /// per token.
  int ffn = -1;
  bool per_tensor = false;  ///< calibrated per-tensor codes; else per token at run time
  float scale = 1;          ///< the calibrated parameters (what per tensor uses)
  int32_t zero_point = 0;
  /// Quantization SQNR of each kind of codes over the calibration frames (estimated: the rounding
  /// noise of each row's step for per token, the histogram's expected error for per tensor).
  double sqnr_per_tensor_db = 0, sqnr_per_token_db = 0;
};

struct LayerSensitivity {
  std::string layer;           ///< weight name
  double mse_alone_int8 = 0;   ///< held-out MSE with only this layer in int8
};

struct Int8Report {
  Int8Mode mode = Int8Mode::kStatic;
  std::string calibration;  ///< the calibration method's name; "" for dynamic
  size_t calibration_frames = 0;
  size_t holdout_frames = 0;
  std::string preprocessing;
  std::vector<std::string> notes;
  uint64_t fp32_bytes = 0, int8_bytes = 0;
  std::vector<std::string> float_layers;  ///< weights kept in float (mixed)
  bool int8_attention = false;            ///< attention's matmuls on the int8 GEMM
  /// Held-out error with float and with int8 attention (the latter only when it was tried).
  std::optional<ActionError> fp32_attention_error, int8_attention_error;
  /// Static and mixed: every linear input in graph order with its codes, and the held-out error with
  /// all of them per token and with the choice (the latter only when one was tried).
  std::vector<LinearInputChoice> linear_inputs;
  std::optional<ActionError> per_token_inputs_error, chosen_inputs_error;
  ActionError action_error;
  int action_keys = 0;                    ///< action dimensions
  std::vector<LayerSensitivity> sensitivity;  ///< mixed, when the search ran: most sensitive first
  std::vector<LayerSqnr> layers;              ///< empty unless Int8Options::layer_report
  std::vector<ActivationRange> activations;   ///< calibrated activations in graph order (empty for dynamic)
  double seconds = 0;                         ///< the conversion's wall time

  /// Everything above as a JSON object (act_convert --report), two-space indented.
  std::string to_json() const;
  /// The human report act_convert prints.
  std::string to_text() const;
  /// Whether the held-out error is good (max |err| normalised: 0.05 or less "good", up to 0.2
  /// "check", above "poor"), with what to do next; in to_json() and to_text() too.
  std::string verdict() const;
  /// Puts first among the notes what the calibration used of the `given` frames its sources held
  /// (load_calibration_frames' count, actengine/calibration_files.h): "128 frames given, 64 used for
  /// calibration, 16 held out, 48 left out (--calib-samples 64 sets how many are used)".
  void note_frames_given(size_t given, size_t calib_samples);
};

// --------------------------------------------------------------------------------------- the model

/// A checkpoint imported in memory (BatchNorm folded, training-only weights dropped), ready to be
/// written as an FP32 or INT8 blob any number of times.
class ImportedCheckpoint {
 public:
  ~ImportedCheckpoint();
  ImportedCheckpoint(const ImportedCheckpoint&) = delete;
  ImportedCheckpoint& operator=(const ImportedCheckpoint&) = delete;

  const ImportSummary& summary() const { return summary_; }

  /// Names the action dimensions (e.g. {"steering", "throttle"}), one per action value: stored in
  /// the blobs written after this (ModelInfo::action_names), for reports and act_drive's
  /// recordings. kInvalidArgument for a wrong count, an empty or repeated name, or a comma, quote or
  /// line break in one.
  Status set_action_names(std::vector<std::string> names);
  /// Writes the FP32 blob. Returns its size in bytes.
  StatusOr<uint64_t> write_fp32(const std::string& path) const;
  /// Calibrates on `calibration` (kDynamic needs no frames: synthetic ones then measure accuracy),
  /// measures the held-out error against the FP32 model and writes the INT8 blob; with max_mse missed,
  /// fails with kFailedPrecondition and writes nothing (the message holds the report).
  StatusOr<Int8Report> write_int8(const std::string& path, const CalibrationSet& calibration,
                                  const Int8Options& options) const;
  /// `count` frames of smooth random images with states sampled from the model's normalisation
  /// statistics: enough to time an INT8 model, not to judge its accuracy (the set's note says so).
  StatusOr<CalibrationSet> synthetic_calibration_set(size_t count, uint64_t seed) const;

 private:
  class Impl;
  friend StatusOr<std::unique_ptr<ImportedCheckpoint>> import_checkpoint(const std::string&, const PthOptions&,
                                                                         const DeploymentOptions&);
  friend StatusOr<std::unique_ptr<ImportedCheckpoint>> import_checkpoint(const PthPlan&);
  friend StatusOr<std::unique_ptr<ImportedCheckpoint>> import_synthetic_model(const std::string&, uint32_t);
  explicit ImportedCheckpoint(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
  ImportSummary summary_;
};

/// Where the checkpoint a user names really is. A LeRobot folder (config.json inside) is also found
/// one level down in LeRobot's training output (`checkpoints/last` -> `checkpoints/last/pretrained_model`)
/// and from its `model.safetensors`; any other file is taken for a PyTorch .pth/.pt.
struct CheckpointLocation {
  std::string path;             ///< the folder or file to import
  bool lerobot_folder = false;  ///< a LeRobot checkpoint folder (else a PyTorch file)
  std::string note;             ///< how `path` was found when it is not what was given, else empty
};
/// kNotFound for a path that does not exist or a folder holding no checkpoint; kInvalidArgument for an
/// .actb blob (already converted), naming what it is.
StatusOr<CheckpointLocation> locate_checkpoint(const std::string& path);

/// Imports a LeRobot ACT checkpoint folder (config.json + model.safetensors [+ processor files], current
/// or legacy layout), or a torch.save .pth/.pt file holding the policy's state dict with `pth` saying
/// what the weights do not (for a folder, `pth` must be left empty); `deployment` replaces the
/// deployment choices of either. Errors name the file and the problem: kNotFound, kDataLoss (malformed),
/// kInvalidArgument (inconsistent config, or for a .pth, facts that cannot be known), kUnimplemented.
StatusOr<std::unique_ptr<ImportedCheckpoint>> import_checkpoint(const std::string& path, const PthOptions& pth = {},
                                                                const DeploymentOptions& deployment = {});
/// Imports a planned .pth (fails with kInvalidArgument listing what is missing).
StatusOr<std::unique_ptr<ImportedCheckpoint>> import_checkpoint(const PthPlan& plan);
/// A model with random weights of a built-in shape ("default", "rover", ... as act_bench knows them),
/// for benchmarks and tests.
StatusOr<std::unique_ptr<ImportedCheckpoint>> import_synthetic_model(const std::string& preset, uint32_t seed);

}  // namespace act
