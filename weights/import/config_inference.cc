#include "weights/import/config_inference.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "actengine/status.h"
#include "weights/blob/file_util.h"

namespace act {

namespace {

using OrderedJson = nlohmann::ordered_json;

// Prefixes training wrappers put in front of a policy's keys: DistributedDataParallel, torch.compile,
// a LightningModule holding the policy as `self.policy`.
constexpr const char* kWrapperPrefixes[] = {"module.", "_orig_mod.", "policy."};
// LeRobot's ACTPolicy keys: "model.<ACT module>" and, in the legacy layout, the normalisation buffers.
constexpr const char* kNormBufferPrefixes[] = {"normalize_inputs.", "normalize_targets.", "unnormalize_outputs."};
constexpr const char* kActModules[] = {"backbone.", "encoder.", "decoder.", "action_head.", "encoder_latent_input_proj.",
                                       "decoder_pos_embed.", "encoder_img_feat_input_proj.", "vae_encoder."};

bool starts_with(const std::string& s, const std::string& prefix) { return s.rfind(prefix, 0) == 0; }

bool is_norm_buffer(const std::string& name) {
  for (const char* p : kNormBufferPrefixes) {
    if (starts_with(name, p)) return true;
  }
  return false;
}

// Brings the keys to LeRobot's ACTPolicy names; returns what it did, for the notes.
void normalise_keys(PyTorchCheckpoint& ckpt, std::vector<std::string>& notes) {
  std::vector<std::string> names = ckpt.state_dict.names();
  std::string stripped;
  for (bool again = true; again && !names.empty();) {
    again = false;
    for (const char* p : kWrapperPrefixes) {
      if (std::all_of(names.begin(), names.end(), [&](const std::string& n) { return starts_with(n, p); })) {
        for (auto& n : names) n = n.substr(std::string(p).size());
        stripped += p;
        again = true;
      }
    }
  }
  const bool has_model = std::any_of(names.begin(), names.end(), [](const std::string& n) { return starts_with(n, "model."); });
  const bool bare_act = !has_model && std::any_of(names.begin(), names.end(), [](const std::string& n) {
    return std::any_of(std::begin(kActModules), std::end(kActModules), [&](const char* m) { return starts_with(n, m); });
  });
  if (stripped.empty() && !bare_act) return;
  auto rename = [&](const std::string& old) {
    std::string n = old.substr(stripped.size());
    return bare_act && !is_norm_buffer(n) ? "model." + n : n;
  };
  ckpt.state_dict.rename(rename);
  for (auto& n : ckpt.saved_order) n = rename(n);
  if (!stripped.empty()) notes.push_back("removed the wrapper prefix \"" + stripped + "\" from every key");
  if (bare_act) notes.push_back("keys have no \"model.\" prefix (a saved policy.model): added it");
}

// Numbers of a (nested) JSON array, flattened; false if anything else is inside.
bool flatten_numbers(const OrderedJson& j, std::vector<float>& out) {
  if (j.is_number()) {
    out.push_back(j.get<float>());
    return true;
  }
  if (!j.is_array()) return false;
  for (const auto& x : j) {
    if (!flatten_numbers(x, out)) return false;
  }
  return true;
}

class Planner {
 public:
  Planner(const ConfigSources& src, PyTorchConversion& plan) : src_(src), plan_(plan), sd_(plan.checkpoint.state_dict) {}

  void run() {
    infer_from_weights();
    if (!src_.config_path.empty()) {
      merge_config_file();
    } else {
      build_config();
    }
  }

 private:
  // ---- facts from the weights
  const SafetensorsTensor* tensor(const std::string& name) const { return sd_.find(name); }
  const SafetensorsTensor& required(const std::string& name) const {
    const SafetensorsTensor* t = sd_.find(name);
    if (!t) fail(StatusCode::kInvalidArgument, sd_.origin() + ": no \"" + name + "\": this is not the state dict of a LeRobot ACT policy");
    return *t;
  }
  std::string described(const SafetensorsTensor& t) const { return t.name + " " + shape_string(t.shape); }
  int dim(const SafetensorsTensor& t, size_t i, size_t rank) const {
    if (t.shape.size() != rank) fail(StatusCode::kInvalidArgument, sd_.origin() + ": " + described(t) + " should have " + std::to_string(rank) + " dimensions");
    return static_cast<int>(t.shape[i]);
  }
  // How many "<prefix><i>." indices exist; they must be 0..n-1.
  int count_indices(const std::string& prefix) const {
    std::set<int> seen;
    for (const auto& name : sd_.names()) {
      if (!starts_with(name, prefix)) continue;
      const size_t dot = name.find('.', prefix.size());
      const std::string idx = name.substr(prefix.size(), dot - prefix.size());
      if (idx.empty() || idx.size() > 4 || idx.find_first_not_of("0123456789") != std::string::npos) continue;
      seen.insert(std::stoi(idx));
    }
    if (!seen.empty() && (*seen.begin() != 0 || *seen.rbegin() != static_cast<int>(seen.size()) - 1)) {
      fail(StatusCode::kInvalidArgument, sd_.origin() + ": the indices of " + prefix + "<i> are not 0.." + std::to_string(seen.size() - 1));
    }
    return static_cast<int>(seen.size());
  }
  void infer(const std::string& field, OrderedJson value, const std::string& source) { inferred_[field] = {std::move(value), source}; }

  void infer_from_weights() {
    const auto& latent = required("model.encoder_latent_input_proj.weight");
    const int D = dim(latent, 0, 2);
    infer("dim_model", D, described(latent));
    infer("latent_dim", dim(latent, 1, 2), described(latent));
    const auto& head = required("model.action_head.weight");
    action_dim_ = dim(head, 0, 2);
    infer("output_features.action", action_dim_, described(head));
    if (const auto* s = tensor("model.encoder_robot_state_input_proj.weight")) {
      state_dim_ = dim(*s, 1, 2);
      infer("input_features.observation.state", state_dim_, described(*s));
    }
    if (const auto* e = tensor("model.encoder_env_state_input_proj.weight")) {
      env_dim_ = dim(*e, 1, 2);
      infer("input_features.observation.environment_state", env_dim_, described(*e));
    }
    const auto& pos = required("model.decoder_pos_embed.weight");
    infer("chunk_size", dim(pos, 0, 2), described(pos));
    infer("n_encoder_layers", count_indices("model.encoder.layers."), "the model.encoder.layers.<i> keys");
    infer("n_decoder_layers", count_indices("model.decoder.layers."), "the model.decoder.layers.<i> keys");
    const auto& l1 = required("model.encoder.layers.0.linear1.weight");
    const int F = dim(l1, 0, 2);
    infer("dim_feedforward", F, described(l1));
    const auto& l2 = required("model.encoder.layers.0.linear2.weight");
    if (dim(l2, 1, 2) * 2 == F) infer("feedforward_activation", "glu", described(l2) + " (half of dim_feedforward: GLU)");
    infer("pre_norm", sd_.contains("model.encoder.norm.weight"),
          sd_.contains("model.encoder.norm.weight") ? "model.encoder.norm.weight exists" : "no model.encoder.norm.weight");
    std::vector<int> blocks;
    for (int s = 1; s <= 4; ++s) blocks.push_back(count_indices("model.backbone.layer" + std::to_string(s) + "."));
    const bool bottleneck = sd_.contains("model.backbone.layer1.0.conv3.weight");
    const auto& resnets = resnet_architectures();
    const auto bb = std::find_if(resnets.begin(), resnets.end(),
                                 [&](const ResNetArchitecture& a) { return a.blocks == blocks && a.bottleneck == bottleneck; });
    std::string counts;
    for (int b : blocks) counts += (counts.empty() ? "" : "+") + std::to_string(b);
    if (bb == resnets.end()) {
      fail(StatusCode::kUnimplemented, sd_.origin() + ": the backbone has " + counts + " blocks per stage" +
           (bottleneck ? " (bottleneck)" : "") + ", which is no torchvision ResNet this engine runs");
    }
    infer("vision_backbone", bb->name, "model.backbone.layer<s>.<block> keys: " + counts + " blocks" + (bottleneck ? ", conv3 (bottleneck)" : ""));
    has_buffers_ = std::any_of(plan_.checkpoint.saved_order.begin(), plan_.checkpoint.saved_order.end(), is_norm_buffer);
  }

  // ---- the rest
  void fact(const std::string& field, const OrderedJson& value, const std::string& source) {
    plan_.facts.push_back({field, value.dump(), source});
  }
  void missing(const std::string& what) { plan_.missing.push_back(what); }

  // A value with no trace in the weights: flag, else LeRobot's default if allowed, else missing.
  template <typename T>
  void choose(OrderedJson& config, const std::string& field, const std::optional<T>& flag, const std::string& flag_name,
              const OrderedJson& lerobot_default, const std::string& why_unknown) {
    if (flag) {
      config[field] = *flag;
      fact(field, config[field], flag_name);
    } else if (src_.lerobot_defaults) {
      config[field] = lerobot_default;
      fact(field, config[field], "LeRobot's default (--assume-lerobot-defaults)");
    } else {
      missing(field + ": " + why_unknown + "; give " + flag_name + ", --config or --assume-lerobot-defaults");
    }
  }

  std::vector<std::string> camera_keys() {
    if (!src_.cameras.empty()) {
      camera_source_ = "--camera";
      return src_.cameras;
    }
    std::vector<std::string> keys;
    auto add = [&](const std::string& k) {
      if (std::find(keys.begin(), keys.end(), k) == keys.end()) keys.push_back(k);
    };
    if (has_buffers_) {
      // Legacy LeRobot registers one buffer per input feature, in input_features order; the key's
      // dots became underscores, and camera names follow "observation.images." (or are "observation.image").
      const std::string prefix = "normalize_inputs.buffer_";
      for (const auto& name : plan_.checkpoint.saved_order) {
        if (!starts_with(name, prefix)) continue;
        const std::string flat = name.substr(prefix.size(), name.rfind('.') - prefix.size());
        if (starts_with(flat, "observation_images_")) add("observation.images." + flat.substr(19));
        if (flat == "observation_image") add("observation.image");
      }
      camera_source_ = "the normalize_inputs.buffer_observation_image* buffers, in saved order";
    } else if (plan_.stats) {
      for (const auto& name : plan_.stats->names()) {
        const std::string feature = name.substr(0, name.rfind('.'));
        if (starts_with(feature, "observation.images.") || feature == "observation.image") add(feature);
      }
      camera_source_ = "the statistics in " + plan_.statistics_source;
      if (keys.size() > 1) {
        std::string list;
        for (const auto& k : keys) list += (list.empty() ? "" : ", ") + k;
        missing("camera order: the statistics name " + std::to_string(keys.size()) + " cameras (" + list +
                ") but not their token order; give it with --camera KEY, once per camera, in training order");
        return {};
      }
    }
    if (keys.empty()) missing("cameras: no statistics name any camera; give --camera observation.images.<name> (or --stats)");
    return keys;
  }

  // Which statistics a legacy buffer set holds for a feature -> its LeRobot mode.
  std::string buffer_mode(const std::string& buffer_prefix) const {
    if (sd_.contains(buffer_prefix + ".mean")) return "MEAN_STD";
    if (sd_.contains(buffer_prefix + ".min")) return "MIN_MAX";
    return "IDENTITY";
  }

  static std::string flat(const std::string& key) {
    std::string f = key;
    std::replace(f.begin(), f.end(), '.', '_');
    return f;
  }

  void build_config() {
    OrderedJson c = OrderedJson::object();
    c["type"] = "act";
    c["n_obs_steps"] = 1;
    if (!src_.stats_paths.empty()) load_stats();
    // Features, in LeRobot's usual order: state, environment, cameras.
    OrderedJson inputs = OrderedJson::object();
    if (state_dim_ > 0) inputs["observation.state"] = {{"type", "STATE"}, {"shape", {state_dim_}}};
    if (env_dim_ > 0) inputs["observation.environment_state"] = {{"type", "ENV"}, {"shape", {env_dim_}}};
    if (state_dim_ > 0) fact("input_features.observation.state", state_dim_, inferred_["input_features.observation.state"].second);
    if (env_dim_ > 0) fact("input_features.observation.environment_state", env_dim_, inferred_["input_features.observation.environment_state"].second);
    const std::vector<std::string> cameras = camera_keys();
    for (const auto& key : cameras) {
      fact("input_features." + key, "VISUAL", camera_source_);
      if (src_.image_size) {
        inputs[key] = {{"type", "VISUAL"}, {"shape", {3, src_.image_size->first, src_.image_size->second}}};
        fact("input_features." + key + ".shape", inputs[key]["shape"], "--image-size");
      }
    }
    if (!cameras.empty() && !src_.image_size) missing("image size: not in the weights; give --image-size HxW (the camera images' size in training) or --config");
    c["input_features"] = inputs;
    c["output_features"] = {{"action", {{"type", "ACTION"}, {"shape", {action_dim_}}}}};
    fact("output_features.action", action_dim_, inferred_["output_features.action"].second);

    take_inferred(c, "chunk_size");
    if (src_.n_action_steps) {
      c["n_action_steps"] = *src_.n_action_steps;
      fact("n_action_steps", c["n_action_steps"], "--n-action-steps");
    } else {
      missing("n_action_steps: how many actions of each chunk the robot executes is a deployment choice, not in the weights; give --n-action-steps N (N <= chunk_size) or --config");
    }
    normalization(c, cameras);
    take_inferred(c, "vision_backbone");
    if (src_.lerobot_defaults) {
      c["replace_final_stride_with_dilation"] = false;
      fact("replace_final_stride_with_dilation", false, "LeRobot's default (--assume-lerobot-defaults)");
    } else {
      missing("replace_final_stride_with_dilation: leaves no trace in the weights; give --config or --assume-lerobot-defaults");
    }
    take_inferred(c, "pre_norm");
    take_inferred(c, "dim_model");
    choose(c, "n_heads", src_.n_heads, "--n-heads", 8, "attention heads leave no trace in the weights");
    take_inferred(c, "dim_feedforward");
    if (inferred_.count("feedforward_activation")) {
      if (src_.activation && *src_.activation != "glu") {
        fail(StatusCode::kInvalidArgument, "--activation " + *src_.activation + " contradicts the weights: " + inferred_["feedforward_activation"].second);
      }
      take_inferred(c, "feedforward_activation");
    } else {
      if (src_.activation == "glu") {
        fail(StatusCode::kInvalidArgument, "--activation glu contradicts the weights (linear2 takes all of dim_feedforward)");
      }
      choose(c, "feedforward_activation", src_.activation, "--activation", "relu", "relu and gelu leave no trace in the weights");
    }
    take_inferred(c, "n_encoder_layers");
    take_inferred(c, "n_decoder_layers");
    take_inferred(c, "latent_dim");
    if (src_.temporal_ensemble_coeff && *src_.temporal_ensemble_coeff) {
      c["temporal_ensemble_coeff"] = **src_.temporal_ensemble_coeff;
      fact("temporal_ensemble_coeff", c["temporal_ensemble_coeff"], "--temporal-ensemble-coeff");
    } else {
      c["temporal_ensemble_coeff"] = nullptr;
      fact("temporal_ensemble_coeff", nullptr, "not given (no temporal ensembling; a deployment choice: --temporal-ensemble-coeff)");
    }
    plan_.config = std::move(c);
  }

  void take_inferred(OrderedJson& c, const std::string& field) {
    const auto& [value, source] = inferred_.at(field);
    c[field] = value;
    fact(field, value, source);
  }

  void load_stats() {
    plan_.stats.emplace(read_statistics_files(src_.stats_paths));
    plan_.statistics_source.clear();
    for (const auto& p : src_.stats_paths) plan_.statistics_source += (plan_.statistics_source.empty() ? "" : " + ") + p;
  }

  void normalization(OrderedJson& c, const std::vector<std::string>& cameras) {
    if (has_buffers_) {
      if (!src_.stats_paths.empty()) {
        fail(StatusCode::kInvalidArgument, sd_.origin() + ": the state dict carries its own normalisation statistics "
             "(normalize_inputs.* buffers); drop --stats");
      }
      if (src_.no_normalization) fail(StatusCode::kInvalidArgument, sd_.origin() + ": --no-normalization, but the state dict carries normalisation statistics");
      OrderedJson mapping = OrderedJson::object();
      std::string visual = cameras.empty() ? "IDENTITY" : buffer_mode("normalize_inputs.buffer_" + flat(cameras[0]));
      mapping["VISUAL"] = visual;
      mapping["STATE"] = buffer_mode("normalize_inputs.buffer_observation_state");
      if (env_dim_ > 0) mapping["ENV"] = buffer_mode("normalize_inputs.buffer_observation_environment_state");
      std::string action = buffer_mode("unnormalize_outputs.buffer_action");
      if (action == "IDENTITY") action = buffer_mode("normalize_targets.buffer_action");
      mapping["ACTION"] = action;
      c["normalization_mapping"] = mapping;
      fact("normalization_mapping", mapping, "which statistics the normalize_inputs / unnormalize_outputs buffers hold");
      plan_.statistics_source = "the state dict's normalisation buffers";
    } else if (src_.no_normalization) {
      c["normalization_mapping"] = OrderedJson::object();
      fact("normalization_mapping", c["normalization_mapping"], "--no-normalization (raw inputs and actions)");
      plan_.statistics_source = "none (--no-normalization)";
    } else if (plan_.stats) {
      OrderedJson mapping = {{"VISUAL", "MEAN_STD"}, {"STATE", "MEAN_STD"}, {"ACTION", "MEAN_STD"}};
      if (src_.lerobot_defaults) {
        c["normalization_mapping"] = mapping;
        fact("normalization_mapping", mapping, "LeRobot's default (--assume-lerobot-defaults); statistics from " + plan_.statistics_source);
      } else {
        missing("normalization_mapping: the statistics file holds every statistic, the weights do not say which the model was trained with; give --config or --assume-lerobot-defaults (MEAN_STD everywhere)");
      }
    } else {
      missing("normalisation statistics: this state dict has none (a current LeRobot policy keeps them in its processor files); "
              "give --stats (the dataset's meta/stats.json, or the checkpoint's policy_preprocessor_step_*_normalizer_processor.safetensors), "
              "or --no-normalization if the model was trained on raw values");
    }
  }

  // --config: LeRobot's config.json is the source; the weights must agree with it, flags override it.
  void merge_config_file() {
    OrderedJson c = detail::read_json_file(src_.config_path);
    if (!c.is_object()) fail(StatusCode::kDataLoss, src_.config_path + ": expected a JSON object");
    const std::string cfg = "config.json";
    for (const auto& [field, inferred] : inferred_) {
      const auto& [value, source] = inferred;
      OrderedJson given;
      if (starts_with(field, "input_features.") || starts_with(field, "output_features.")) {
        const size_t dot = field.find('.');
        const auto& features = c.value(field.substr(0, dot), OrderedJson::object());
        const std::string key = field.substr(dot + 1);
        given = features.contains(key) ? features[key].value("shape", OrderedJson::array()) : OrderedJson();
        if (given != OrderedJson::array({value})) {
          fail(StatusCode::kInvalidArgument, src_.config_path + ": " + field + " has shape " + given.dump() + ", but " + source +
               " says [" + value.dump() + "]");
        }
      } else {
        if (!c.contains(field)) continue;  // the import reports fields it needs
        given = c[field];
        if (given != value) {
          fail(StatusCode::kInvalidArgument, src_.config_path + ": " + field + " is " + given.dump() + ", but " + source + " says " + value.dump());
        }
      }
    }
    if (src_.n_action_steps) c["n_action_steps"] = *src_.n_action_steps;
    if (src_.temporal_ensemble_coeff) {
      c["temporal_ensemble_coeff"] = *src_.temporal_ensemble_coeff ? OrderedJson(**src_.temporal_ensemble_coeff) : OrderedJson();
    }
    if (src_.n_heads) c["n_heads"] = *src_.n_heads;
    if (src_.activation) c["feedforward_activation"] = *src_.activation;
    if (src_.image_size && c.contains("input_features") && c["input_features"].is_object()) {
      for (auto& [key, f] : c["input_features"].items()) {
        if (f.is_object() && f.value("type", "") == "VISUAL") f["shape"] = {3, src_.image_size->first, src_.image_size->second};
      }
    }
    if (!src_.cameras.empty()) fail(StatusCode::kInvalidArgument, "--camera and --config: the cameras come from config.json's input_features");
    for (const auto& [field, value] : c.items()) {
      std::string source = cfg;
      if (inferred_.count(field)) source = inferred_[field].second + " (agrees with " + cfg + ")";
      if (field == "temporal_ensemble_coeff" && src_.temporal_ensemble_coeff) source = "--temporal-ensemble-coeff";
      if ((field == "n_action_steps" && src_.n_action_steps) || (field == "n_heads" && src_.n_heads) ||
          (field == "feedforward_activation" && src_.activation)) {
        source = "--" + std::string(field == "n_action_steps" ? "n-action-steps" : field == "n_heads" ? "n-heads" : "activation");
      }
      if (field == "input_features" && src_.image_size) source = cfg + ", image size from --image-size";
      fact(field, value, source);
    }
    if (has_buffers_) {
      if (!src_.stats_paths.empty()) {
        fail(StatusCode::kInvalidArgument, sd_.origin() + ": the state dict carries its own normalisation statistics (normalize_inputs.* buffers); drop --stats");
      }
      plan_.statistics_source = "the state dict's normalisation buffers";
    } else if (src_.no_normalization) {
      c["normalization_mapping"] = OrderedJson::object();
      plan_.statistics_source = "none (--no-normalization)";
    } else if (!src_.stats_paths.empty()) {
      load_stats();
    } else {
      missing("normalisation statistics: this state dict has none; give --stats (the dataset's meta/stats.json, or the checkpoint's "
              "policy_preprocessor_step_*_normalizer_processor.safetensors), or --no-normalization if the model was trained on raw values");
    }
    plan_.config = std::move(c);
  }

  const ConfigSources& src_;
  PyTorchConversion& plan_;
  const OwnedTensorSet& sd_;
  std::map<std::string, std::pair<OrderedJson, std::string>> inferred_;  // field -> value, source
  int action_dim_ = 0, state_dim_ = 0, env_dim_ = 0;
  bool has_buffers_ = false;
  std::string camera_source_;
};

}  // namespace

OwnedTensorSet read_statistics_files(const std::vector<std::string>& paths) {
  std::string origin;
  for (const auto& p : paths) origin += (origin.empty() ? "" : " + ") + p;
  OwnedTensorSet out(origin);
  auto add = [&](const std::string& path, const std::string& name, std::vector<float> values) {
    if (const SafetensorsTensor* existing = out.find(name)) {
      if (existing->to_f32() != values) fail(StatusCode::kInvalidArgument, path + ": \"" + name + "\" differs from an earlier statistics file");
      return;
    }
    const int64_t n = static_cast<int64_t>(values.size());
    out.add_f32(name, {n}, std::move(values));
  };
  for (const auto& path : paths) {
    if (std::filesystem::path(path).extension() == ".json") {
      // LeRobot's meta/stats.json: {"<feature>": {"<stat>": [nested numbers], ...}, ...}
      const OrderedJson j = detail::read_json_file(path);
      if (!j.is_object()) fail(StatusCode::kDataLoss, path + ": expected {\"<feature>\": {\"<stat>\": [...]}}");
      for (const auto& [feature, stats] : j.items()) {
        if (!stats.is_object()) continue;
        for (const auto& [stat, value] : stats.items()) {
          std::vector<float> values;
          if (flatten_numbers(value, values)) add(path, feature + "." + stat, std::move(values));
        }
      }
    } else {
      const SafetensorsFile file = SafetensorsFile::open(path);
      for (const auto& name : file.names()) {
        const auto& t = file.get(name);
        if (t.dtype == DType::kF32 || t.dtype == DType::kF16 || t.dtype == DType::kBF16) add(path, name, t.to_f32());
      }
    }
  }
  if (out.names().empty()) fail(StatusCode::kInvalidArgument, origin + ": no statistics found");
  return out;
}

PyTorchConversion plan_pytorch_conversion(const std::string& pth_path, const ConfigSources& sources) {
  PyTorchConversion plan;
  plan.checkpoint = read_pytorch_checkpoint(pth_path, sources.state_dict_key);
  normalise_keys(plan.checkpoint, plan.notes);
  Planner(sources, plan).run();
  return plan;
}

ImportedModel import_pytorch_conversion(const PyTorchConversion& plan) {
  if (!plan.missing.empty()) {
    std::string list;
    for (const auto& m : plan.missing) list += "\n  - " + m;
    fail(StatusCode::kInvalidArgument,
         plan.checkpoint.state_dict.origin() + ": cannot convert without knowing:" + list +
             "\n(act_convert --explain shows what was inferred from the weights and from where)");
  }
  ImportedModel model = plan.stats ? import_lerobot_state_dict(plan.config, plan.checkpoint.state_dict, *plan.stats)
                                   : import_lerobot_state_dict(plan.config, plan.checkpoint.state_dict);
  model.notes.insert(model.notes.begin(), plan.notes.begin(), plan.notes.end());
  return model;
}

}  // namespace act
