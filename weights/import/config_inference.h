// A LeRobot ACT config for a bare state dict (a PyTorch .pth): what the weights themselves say
// (dimensions, layer counts, chunk size, backbone depth, cameras from statistics names), and the rest
// (image size, n_action_steps, normalisation statistics, hyperparameters that leave no trace in the
// tensor shapes) from a config.json, a statistics file or flags. Every value records where it came
// from, for `act_convert --explain`; whatever is neither in the weights nor given is reported as
// missing, never guessed.
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "weights/import/lerobot_import.h"
#include "weights/import/pytorch_checkpoint.h"
#include "weights/import/safetensors.h"

namespace act {

/// What the user gave beside the weights.
struct ConfigSources {
  std::string config_path;               ///< LeRobot config.json ("" = none)
  std::vector<std::string> stats_paths;  ///< "<feature>.<stat>" safetensors (processor state files) or meta/stats.json
  std::optional<std::pair<int, int>> image_size;  ///< height, width of every camera
  std::optional<int> n_action_steps;
  std::optional<std::optional<double>> temporal_ensemble_coeff;  ///< set: replaces the config's (empty: null)
  std::optional<int> n_heads;
  std::optional<std::string> activation;  ///< relu / gelu / glu
  std::vector<std::string> cameras;       ///< camera feature keys, in token order
  bool lerobot_defaults = false;  ///< take LeRobot's ACTConfig defaults for what leaves no trace in the weights
  bool no_normalization = false;  ///< the model was trained on raw values: no statistics
  std::string state_dict_key;     ///< entry of a wrapping dict holding the state dict
};

/// One config value and where it came from.
struct ConfigFact {
  std::string field;   ///< LeRobot config.json field, e.g. "dim_model", "input_features.observation.state"
  std::string value;   ///< as JSON
  std::string source;  ///< e.g. "model.action_head.weight [2, 64]", "--image-size", "config.json"
};

struct PyTorchConversion {
  PyTorchCheckpoint checkpoint;         ///< the state dict, keys normalised to LeRobot's ("model." ...)
  nlohmann::ordered_json config;        ///< the equivalent LeRobot config.json
  std::vector<ConfigFact> facts;        ///< every config value with its source, in config order
  std::vector<std::string> missing;     ///< what cannot be known, each with the flag that gives it
  std::vector<std::string> notes;       ///< e.g. key prefixes added or removed
  std::optional<OwnedTensorSet> stats;  ///< statistics from --stats (nullopt: in the state dict, or none)
  std::string statistics_source;        ///< for --explain
};

/// Reads the checkpoint and works out its config. Throws act::Error for unreadable files and for
/// contradictions (a config.json that does not match the weights); does not throw for missing facts
/// (see `missing`), so --explain can list them all.
PyTorchConversion plan_pytorch_conversion(const std::string& pth_path, const ConfigSources& sources);

/// Imports a planned conversion. Throws act::Error(kInvalidArgument) listing `missing` if any.
ImportedModel import_pytorch_conversion(const PyTorchConversion& plan);

/// Statistics files -> one set of "<feature>.<stat>" float tensors. Throws naming the file.
OwnedTensorSet read_statistics_files(const std::vector<std::string>& paths);

}  // namespace act
