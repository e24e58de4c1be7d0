// LeRobot ACT checkpoint folder -> the folded FP32 inference weights of the .actb blob.
//
// Reads config.json, model.safetensors and (current layout) the pre/post-processor files, checks
// every tensor the config implies (name, shape, dtype) and refuses anything it would otherwise have to
// ignore. At import it folds BatchNorm into the convs, drops the training-only VAE weights, and
// precomputes the observation-independent parts of the network (see fold notes in the .cc).
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "weights/blob/actb.h"
#include "weights/blob/model_config.h"
#include "weights/import/safetensors.h"

namespace act {

struct NamedTensor {
  std::string name;
  std::vector<int64_t> shape;
  std::vector<float> values;
};

struct ImportedModel {
  ModelConfig config;
  std::vector<NamedTensor> tensors;  ///< blob tensors (names in weights/blob/blob_names.h)
  std::string layout;                ///< "current" (processor files) or "legacy" (buffers in the weights)
  size_t checkpoint_tensors = 0;     ///< tensors in model.safetensors
  uint64_t checkpoint_values = 0;
  size_t training_only_tensors = 0;  ///< dropped (VAE encoder, training targets)
  uint64_t training_only_values = 0;
  std::vector<std::string> notes;    ///< things a user should know (e.g. features without statistics)

  uint64_t blob_values() const;
  const NamedTensor* find(const std::string& name) const;
};

/// Imports a LeRobot ACT checkpoint folder (either layout). Throws act::Error naming the file and the
/// problem: kNotFound (missing file / tensor), kDataLoss (malformed), kInvalidArgument (shape mismatch,
/// inconsistent config), kUnimplemented (a valid LeRobot setting this engine does not run).
ImportedModel import_lerobot_checkpoint(const std::string& checkpoint_dir);

/// The architecture a LeRobot config.json describes (validated; normalisation not yet resolved,
/// that needs the statistics). Throws act::Error like the import.
ModelConfig lerobot_model_config(const nlohmann::ordered_json& config, const std::string& where);

/// Imports a LeRobot ACT model held in memory: the content of its config.json and a legacy-layout
/// state dict (normalisation buffers included). The built-in synthetic models take this path.
ImportedModel import_lerobot_state_dict(const nlohmann::ordered_json& config, const TensorSet& state_dict);

/// Imports a state dict without normalisation buffers (a current LeRobot policy's state_dict(), e.g.
/// from a .pth) with the statistics kept outside it: `stats` holds "<feature>.<stat>" tensors as in
/// LeRobot's processor state files (and meta/stats.json), applied as the current layout applies them
/// (eps 1e-8). Unlike a checkpoint folder, a normalised feature without statistics is an error
/// (kNotFound): the statistics were given explicitly, so a gap is a mistake, not a LeRobot default.
ImportedModel import_lerobot_state_dict(const nlohmann::ordered_json& config, const TensorSet& state_dict,
                                        const TensorSet& stats);

/// The normalisation step `registry_name` ("normalizer_processor" / "unnormalizer_processor") of a
/// current-layout processor pipeline file (policy_preprocessor.json / policy_postprocessor.json).
struct ProcessorStep {
  std::optional<float> eps;
  std::optional<std::map<std::string, std::string>> norm_map;  ///< feature type -> mode name, as written
  std::string state_file;  ///< a plain file name in the checkpoint folder
};
/// Parses that step out of the pipeline's JSON. Throws act::Error naming `where`: kDataLoss
/// (malformed), kNotFound (no such step).
ProcessorStep parse_processor_step(const nlohmann::ordered_json& pipeline, const std::string& registry_name,
                                   const std::string& where);

/// The imported model as an FP32 .actb blob, ready to write. The writer refers to the model's tensors
/// (no copy): write it while `model` lives, unchanged.
ActbWriter fp32_blob(const ImportedModel& model);
/// Writes fp32_blob(model) (atomically). Returns the file size in bytes.
size_t write_fp32_blob(const ImportedModel& model, const std::string& path);

}  // namespace act
