// The public conversion API (actengine/convert.h) over the importers, the weight quantizer and the
// INT8 converter: every act::Error becomes the Status of the same code.
#include <algorithm>
#include <filesystem>

#include "engine/src/convert/calibration_frames.h"
#include "engine/src/convert/convert_impl.h"
#include "engine/src/convert/int8_converter.h"
#include "engine/src/engine_impl.h"
#include "weights/blob/file_kind.h"
#include "weights/blob/file_util.h"
#include "weights/import/synthetic_model.h"

namespace act {

namespace {

ConfigSources config_sources(const PthOptions& o, const DeploymentOptions& deployment) {
  ConfigSources s;
  s.config_path = o.config_path;
  s.stats_paths = o.stats_paths;
  s.image_size = o.image_size;
  s.n_action_steps = deployment.n_action_steps;
  s.temporal_ensemble_coeff = deployment.temporal_ensemble_coeff;
  s.n_heads = o.n_heads;
  s.activation = o.activation;
  s.cameras = o.cameras;
  s.lerobot_defaults = o.lerobot_defaults;
  s.no_normalization = o.no_normalization;
  s.state_dict_key = o.state_dict_key;
  return s;
}

bool any_pth_option(const PthOptions& o) {
  return !o.config_path.empty() || !o.stats_paths.empty() || o.image_size || o.n_heads || o.activation ||
         !o.cameras.empty() || o.lerobot_defaults || o.no_normalization || !o.state_dict_key.empty();
}

// The folder's config.json with the deployment choices replaced, checked again as a whole.
void apply_deployment(ModelConfig& config, const DeploymentOptions& deployment, const std::string& config_path) {
  if (deployment.n_action_steps) config.n_action_steps = *deployment.n_action_steps;
  if (deployment.temporal_ensemble_coeff) config.temporal_ensemble_coeff = *deployment.temporal_ensemble_coeff;
  if (const std::string problem = ModelConfig::deployment_problem(config.n_action_steps, config.temporal_ensemble_coeff,
                                                                 config.chunk_size);
      !problem.empty()) {
    fail(StatusCode::kInvalidArgument,
         "deployment settings (" + config_path + " with the overrides given): " + problem);
  }
}

PthExplanation explain(const PyTorchConversion& plan) {
  PthExplanation e;
  const PyTorchCheckpoint& c = plan.checkpoint;
  e.origin = c.state_dict.origin();
  e.format = c.format;
  e.location = c.location;
  e.tensors = c.state_dict.names().size();
  e.other_entries = c.other_entries;
  e.notes = plan.notes;
  e.statistics_source = plan.statistics_source;
  for (const ConfigFact& f : plan.facts) e.config.push_back({f.field, f.value, f.source});
  e.missing = plan.missing;
  return e;
}

ImportSummary import_summary(const ImportedModel& model, std::string source) {
  ImportSummary s;
  s.source = std::move(source);
  s.model = model_info_of(model.config);
  s.encoder_tokens = model.config.n_tokens();
  s.checkpoint_values = model.checkpoint_values;
  s.checkpoint_tensors = model.checkpoint_tensors;
  s.training_only_values = model.training_only_values;
  s.training_only_tensors = model.training_only_tensors;
  s.blob_values = model.blob_values();
  const ModelConfig::Macs macs = model.config.macs();
  s.macs = macs.total();
  s.backbone_macs = macs.backbone;
  s.encoder_macs = macs.encoder;
  s.decoder_macs = macs.decoder;
  s.notes = model.notes;
  return s;
}

std::string pth_source(const PyTorchConversion& plan) {
  return "PyTorch " + plan.checkpoint.format + " .pth, " + plan.checkpoint.location + ", statistics from " +
         plan.statistics_source;
}

}  // namespace

const char* int8_mode_name(Int8Mode mode) {
  switch (mode) {
    case Int8Mode::kDynamic: return "dynamic";
    case Int8Mode::kStatic: return "static";
    case Int8Mode::kMixed: return "mixed";
  }
  return "?";
}

const char* calibration_method_name(CalibrationMethod method) {
  switch (method) {
    case CalibrationMethod::kMinMax: return "minmax";
    case CalibrationMethod::kPercentile: return "percentile";
    case CalibrationMethod::kMse: return "mse";
  }
  return "?";
}

StatusOr<CalibrationMethod> parse_calibration_method(std::string_view name) {
  for (CalibrationMethod m : {CalibrationMethod::kMinMax, CalibrationMethod::kPercentile, CalibrationMethod::kMse}) {
    if (name == calibration_method_name(m)) return m;
  }
  return Status(StatusCode::kInvalidArgument,
                "unknown calibration method \"" + std::string(name) + "\" (minmax, percentile, mse)");
}

size_t calibration_frames_wanted(const Int8Options& options) {
  return options.calib_samples + options.holdout.value_or(std::clamp<size_t>(options.calib_samples / 4, 1, 16));
}

PthPlan::PthPlan(std::unique_ptr<Impl> impl) : impl_(std::move(impl)), explanation_(explain(impl_->plan)) {}
PthPlan::~PthPlan() = default;

StatusOr<std::unique_ptr<PthPlan>> PthPlan::read(const std::string& pth_path, const PthOptions& options,
                                                 const DeploymentOptions& deployment) {
  std::unique_ptr<PthPlan> plan;
  const Status s = guarded([&] {
    auto impl = std::make_unique<Impl>();
    impl->plan = plan_pytorch_conversion(pth_path, config_sources(options, deployment));
    plan.reset(new PthPlan(std::move(impl)));
  });
  if (!s.ok()) return s;
  return plan;
}

ImportedCheckpoint::ImportedCheckpoint(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ImportedCheckpoint::~ImportedCheckpoint() = default;

StatusOr<CheckpointLocation> locate_checkpoint(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path given(path);
  if (!fs::exists(given, ec)) return Status(StatusCode::kNotFound, "no such file or folder: " + path);
  const auto has_config = [&](const fs::path& dir) { return fs::is_regular_file(dir / "config.json", ec); };
  if (fs::is_directory(given, ec)) {
    if (has_config(given)) return CheckpointLocation{path, true, ""};
    // LeRobot's training output: outputs/train/<run>/checkpoints/<step or last>/pretrained_model/.
    if (has_config(given / "pretrained_model")) {
      const std::string inner = (given / "pretrained_model").string();
      return CheckpointLocation{inner, true, "the policy of this training checkpoint is in " + inner};
    }
    if (const FileKind kind = file_kind(path); kind == FileKind::kRecording || kind == FileKind::kLeRobotDataset) {
      return Status(StatusCode::kInvalidArgument, wrong_kind_message(path, kind, "a checkpoint"));
    }
    return Status(StatusCode::kNotFound, path + " is a folder but not a LeRobot checkpoint: it has no config.json "
                  "(nor pretrained_model/config.json)");
  }
  // A checkpoint's own weights file given directly: the folder around it is the checkpoint.
  if (given.filename() == "model.safetensors" && given.has_parent_path() && has_config(given.parent_path())) {
    const std::string folder = given.parent_path().string();
    return CheckpointLocation{folder, true, path + " is a LeRobot checkpoint's weights: converting its folder " + folder};
  }
  // Anything else but a PyTorch file says what it is (an unknown kind may still be a pickle: the reader
  // decides); a damaged blob is still known by its name.
  const FileKind kind = given.extension() == ".actb" ? FileKind::kActb : file_kind(path);
  if (kind != FileKind::kPyTorchZip && kind != FileKind::kPyTorchLegacy && kind != FileKind::kOther) {
    return Status(StatusCode::kInvalidArgument,
                  wrong_kind_message(path, kind, "a checkpoint (a LeRobot checkpoint folder or a PyTorch .pth file)"));
  }
  return CheckpointLocation{path, false, ""};
}

StatusOr<std::unique_ptr<ImportedCheckpoint>> import_checkpoint(const std::string& given, const PthOptions& pth,
                                                                const DeploymentOptions& deployment) {
  const StatusOr<CheckpointLocation> location = locate_checkpoint(given);
  if (!location.ok()) return location.status();
  const std::string& path = location->path;
  if (location->lerobot_folder && any_pth_option(pth)) {
    return Status(StatusCode::kInvalidArgument, "the .pth options do not apply to a LeRobot checkpoint folder (" + path +
                  "): its config.json and statistics are in the folder");
  }
  if (!location->lerobot_folder) {
    StatusOr<std::unique_ptr<PthPlan>> plan = PthPlan::read(path, pth, deployment);
    if (!plan.ok()) return plan.status();
    return import_checkpoint(**plan);
  }
  std::unique_ptr<ImportedCheckpoint> out;
  const Status s = guarded([&] {
    const std::string config_path = path + "/config.json";
    if (deployment.n_action_steps || deployment.temporal_ensemble_coeff) {
      // Checked against config.json before the weights are read, so that a bad override fails at once.
      ModelConfig described = lerobot_model_config(detail::read_json_file(config_path), config_path);
      apply_deployment(described, deployment, config_path);
    }
    auto impl = std::make_unique<ImportedCheckpoint::Impl>();
    impl->model = import_lerobot_checkpoint(path);
    apply_deployment(impl->model.config, deployment, config_path);
    out.reset(new ImportedCheckpoint(std::move(impl)));
    out->summary_ = import_summary(out->impl_->model, out->impl_->model.layout + " LeRobot layout");
  });
  if (!s.ok()) return s;
  return out;
}

StatusOr<std::unique_ptr<ImportedCheckpoint>> import_checkpoint(const PthPlan& plan) {
  std::unique_ptr<ImportedCheckpoint> out;
  const Status s = guarded([&] {
    auto impl = std::make_unique<ImportedCheckpoint::Impl>();
    impl->model = import_pytorch_conversion(plan.impl_->plan);
    out.reset(new ImportedCheckpoint(std::move(impl)));
    out->summary_ = import_summary(out->impl_->model, pth_source(plan.impl_->plan));
  });
  if (!s.ok()) return s;
  return out;
}

StatusOr<std::unique_ptr<ImportedCheckpoint>> import_synthetic_model(const std::string& preset, uint32_t seed) {
  std::unique_ptr<ImportedCheckpoint> out;
  const Status s = guarded([&] {
    auto impl = std::make_unique<ImportedCheckpoint::Impl>();
    impl->model = make_synthetic_model(preset, seed);
    out.reset(new ImportedCheckpoint(std::move(impl)));
    out->summary_ = import_summary(out->impl_->model, "built-in \"" + preset + "\" model (synthetic weights)");
  });
  if (!s.ok()) return s;
  return out;
}

Status ImportedCheckpoint::set_action_names(std::vector<std::string> names) {
  const std::string problem = ModelConfig::action_names_problem(names, impl_->model.config.action_dim);
  if (!problem.empty()) return Status(StatusCode::kInvalidArgument, problem);
  impl_->model.config.action_names = names;
  summary_.model.action_names = std::move(names);
  return Status::ok_status();
}

StatusOr<uint64_t> ImportedCheckpoint::write_fp32(const std::string& path) const {
  uint64_t bytes = 0;
  const Status s = guarded([&] { bytes = write_fp32_blob(impl_->model, path); });
  if (!s.ok()) return s;
  return bytes;
}

StatusOr<Int8Report> ImportedCheckpoint::write_int8(const std::string& path, const CalibrationSet& calibration,
                                                    const Int8Options& options) const {
  Int8Report report;
  const Status s = guarded([&] { report = convert_to_int8(impl_->model, path, calibration, options); });
  if (!s.ok()) return s;
  return report;
}

StatusOr<CalibrationSet> ImportedCheckpoint::synthetic_calibration_set(size_t count, uint64_t seed) const {
  CalibrationSet set;
  const Status s = guarded([&] {
    StateSampler states(impl_->model, seed);
    set = synthetic_calibration_frames(states, count, seed);
  });
  if (!s.ok()) return s;
  return set;
}

}  // namespace act
