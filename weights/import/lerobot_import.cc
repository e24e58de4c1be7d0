#include "weights/import/lerobot_import.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>

#include "weights/blob/actb.h"
#include "weights/blob/blob_names.h"
#include "actengine/status.h"
#include "weights/blob/file_util.h"
#include "weights/import/safetensors.h"

namespace fs = std::filesystem;
using OrderedJson = nlohmann::ordered_json;

namespace act {

namespace bn = blob_names;

uint64_t ImportedModel::blob_values() const {
  uint64_t n = 0;
  for (const auto& t : tensors) n += t.values.size();
  return n;
}

const NamedTensor* ImportedModel::find(const std::string& name) const {
  for (const auto& t : tensors) {
    if (t.name == name) return &t;
  }
  return nullptr;
}

namespace {

constexpr double kBatchNormEps = 1e-5;
constexpr float kLegacyEps = 1e-8f;
// Larger than any weight (or BatchNorm statistic) a trained ACT network holds by many orders of magnitude.
constexpr float kMaxWeightMagnitude = 1e6f;

// ------------------------------------------------------------------------------------------ config

// Typed access to config.json fields with errors that name the field and the file.
class ConfigReader {
 public:
  ConfigReader(const OrderedJson& j, std::string file) : j_(j), file_(std::move(file)) {}

  const OrderedJson& at(const std::string& key) const {
    if (!j_.contains(key)) fail(StatusCode::kDataLoss, file_ + ": missing field \"" + key + "\"");
    return j_.at(key);
  }
  int get_int(const std::string& key) const {
    const auto& v = at(key);
    if (!v.is_number_integer()) fail(StatusCode::kDataLoss, file_ + ": field \"" + key + "\" must be an integer");
    const auto x = v.get<int64_t>();
    if (x < std::numeric_limits<int>::min() || x > std::numeric_limits<int>::max()) {
      fail(StatusCode::kInvalidArgument, file_ + ": field \"" + key + "\" out of range");
    }
    return static_cast<int>(x);
  }
  std::string get_string(const std::string& key) const {
    const auto& v = at(key);
    if (!v.is_string()) fail(StatusCode::kDataLoss, file_ + ": field \"" + key + "\" must be a string");
    return v.get<std::string>();
  }
  bool get_bool(const std::string& key) const {
    const auto& v = at(key);
    // replace_final_stride_with_dilation is declared int in LeRobot and may be written as 0/1.
    if (v.is_boolean()) return v.get<bool>();
    if (v.is_number_integer()) return v.get<int64_t>() != 0;
    fail(StatusCode::kDataLoss, file_ + ": field \"" + key + "\" must be a boolean");
  }
  const std::string& file() const { return file_; }

 private:
  const OrderedJson& j_;
  std::string file_;
};

// LeRobot's normalisation modes as they appear in normalization_mapping / norm_map.
enum class LeRobotMode { kIdentity, kMeanStd, kMinMax, kQuantiles, kQuantile10 };

LeRobotMode parse_mode(const std::string& s, const std::string& where) {
  if (s == "IDENTITY") return LeRobotMode::kIdentity;
  if (s == "MEAN_STD") return LeRobotMode::kMeanStd;
  if (s == "MIN_MAX") return LeRobotMode::kMinMax;
  if (s == "QUANTILES") return LeRobotMode::kQuantiles;
  if (s == "QUANTILE10") return LeRobotMode::kQuantile10;
  fail(StatusCode::kUnimplemented, where + ": unknown normalisation mode \"" + s + "\"");
}

struct Feature {
  std::string key;
  std::string type;
  std::vector<int64_t> shape;
  std::vector<std::string> names;  ///< "names", when the feature has a list of strings (a dataset's features do)
};

std::vector<Feature> read_features(const ConfigReader& cfg, const std::string& field) {
  std::vector<Feature> out;
  const auto& obj = cfg.at(field);
  if (!obj.is_object()) fail(StatusCode::kDataLoss, cfg.file() + ": \"" + field + "\" must be an object");
  for (const auto& [key, value] : obj.items()) {  // ordered_json keeps the file's key order
    const std::string& name = key;  // (clang 14 cannot capture a structured binding)
    const auto malformed = [&] {
      fail(StatusCode::kDataLoss, cfg.file() + ": feature \"" + name + "\" needs a string \"type\" and an integer \"shape\"");
    };
    if (!value.is_object() || !value.contains("type") || !value["type"].is_string() || !value.contains("shape") ||
        !value["shape"].is_array()) {
      malformed();
    }
    Feature feature{key, value["type"].get<std::string>(), {}, {}};
    if (value.contains("names") && value["names"].is_array()) {
      for (const auto& n : value["names"]) {
        if (n.is_string()) feature.names.push_back(n.get<std::string>());
      }
    }
    for (const auto& d : value["shape"]) {
      // Checked before converting: a float (1e300) converted to an integer is undefined behaviour, and
      // the dimensions are used as int.
      if (!d.is_number_integer() || d.get<int64_t>() < 0 || d.get<int64_t>() > std::numeric_limits<int>::max()) {
        malformed();
      }
      feature.shape.push_back(d.get<int64_t>());
    }
    out.push_back(std::move(feature));
  }
  return out;
}

struct ParsedConfig {
  ModelConfig model;
  std::map<std::string, LeRobotMode> mapping;  // feature type -> mode
  std::vector<Feature> inputs;
  int latent_dim = 32;
};

// Refuses configs that are not a current LeRobot ACT policy with one observation step.
void check_act_policy(const OrderedJson& j, const ConfigReader& cfg, const fs::path& path) {
  if (!j.is_object()) fail(StatusCode::kDataLoss, path.string() + ": expected a JSON object");
  if (j.contains("input_shapes") && !j.contains("input_features")) {
    fail(StatusCode::kUnimplemented, path.string() +
         ": this is a pre-2025 LeRobot config (input_shapes / input_normalization_modes); re-save it with a "
         "current LeRobot first");
  }
  if (cfg.get_string("type") != "act") {
    fail(StatusCode::kInvalidArgument, path.string() + ": policy type is \"" + cfg.get_string("type") + "\", not \"act\"");
  }
  if (j.contains("n_obs_steps") && cfg.get_int("n_obs_steps") != 1) {
    fail(StatusCode::kUnimplemented, path.string() + ": n_obs_steps must be 1 for ACT");
  }
}

Activation parse_activation(const std::string& act, const fs::path& path) {
  if (act == "relu") return Activation::kRelu;
  if (act == "gelu") return Activation::kGelu;
  if (act == "glu") return Activation::kGlu;
  fail(StatusCode::kUnimplemented, path.string() + ": feedforward_activation \"" + act + "\" is not supported (relu, gelu, glu)");
}

// The network's shape: backbone, transformer sizes, chunking.
void read_architecture(const OrderedJson& j, const ConfigReader& cfg, const fs::path& path, ModelConfig& m) {
  const std::string backbone = cfg.get_string("vision_backbone");
  const ResNetArchitecture* resnet = find_resnet(backbone);
  if (resnet == nullptr) {
    fail(StatusCode::kUnimplemented, path.string() + ": vision_backbone \"" + backbone + "\" is not supported (" +
         resnet_names() + ")");
  }
  m.backbone = backbone;
  m.backbone_blocks = resnet->blocks;
  m.bottleneck = resnet->bottleneck;
  m.dilate_layer4 = j.contains("replace_final_stride_with_dilation") && cfg.get_bool("replace_final_stride_with_dilation");
  m.pre_norm = cfg.get_bool("pre_norm");
  m.dim_model = cfg.get_int("dim_model");
  m.n_heads = cfg.get_int("n_heads");
  m.dim_feedforward = cfg.get_int("dim_feedforward");
  m.activation = parse_activation(cfg.get_string("feedforward_activation"), path);
  m.n_encoder_layers = cfg.get_int("n_encoder_layers");
  m.n_decoder_layers = cfg.get_int("n_decoder_layers");
  m.chunk_size = cfg.get_int("chunk_size");
  m.n_action_steps = cfg.get_int("n_action_steps");
  if (j.contains("temporal_ensemble_coeff") && !j.at("temporal_ensemble_coeff").is_null()) {
    if (!j.at("temporal_ensemble_coeff").is_number()) {
      fail(StatusCode::kDataLoss, path.string() + ": temporal_ensemble_coeff must be a number or null");
    }
    m.temporal_ensemble_coeff = j.at("temporal_ensemble_coeff").get<double>();
  }
}

// Normalisation mapping: feature type -> mode; a type missing from it means IDENTITY.
std::map<std::string, LeRobotMode> read_normalization_mapping(const ConfigReader& cfg, const fs::path& path) {
  std::map<std::string, LeRobotMode> out;
  const auto& mapping = cfg.at("normalization_mapping");
  if (!mapping.is_object()) fail(StatusCode::kDataLoss, path.string() + ": normalization_mapping must be an object");
  for (const auto& [type, mode] : mapping.items()) {
    if (!mode.is_string()) fail(StatusCode::kDataLoss, path.string() + ": normalization_mapping[" + type + "] must be a string");
    out[type] = parse_mode(mode.get<std::string>(), path.string());
  }
  return out;
}

// The input features into `m`: cameras, observation.state and the first ENV feature.
std::vector<Feature> read_input_features(const ConfigReader& cfg, const fs::path& path, ModelConfig& m,
                                         std::vector<std::string>& notes) {
  std::vector<Feature> inputs = read_features(cfg, "input_features");
  bool have_env = false;
  for (const auto& f : inputs) {
    if (f.type == "VISUAL") {
      if (f.shape.size() != 3 || f.shape[0] != 3) {
        fail(StatusCode::kInvalidArgument, path.string() + ": camera \"" + f.key + "\" must have shape [3, H, W]");
      }
      m.cameras.push_back({f.key, static_cast<int>(f.shape[1]), static_cast<int>(f.shape[2])});
    } else if (f.type == "STATE") {
      if (f.key != "observation.state") {
        fail(StatusCode::kUnimplemented, path.string() + ": STATE feature \"" + f.key +
             "\" is not used by LeRobot's ACT (only \"observation.state\" is)");
      }
      if (f.shape.size() != 1) fail(StatusCode::kInvalidArgument, path.string() + ": observation.state must be 1-D");
      m.state_key = f.key;
      m.state_dim = static_cast<int>(f.shape[0]);
    } else if (f.type == "ENV") {
      if (f.shape.size() != 1) fail(StatusCode::kInvalidArgument, path.string() + ": \"" + f.key + "\" must be 1-D");
      if (have_env) {
        notes.push_back("input feature \"" + f.key + "\" (ENV) is ignored: LeRobot's ACT uses only the first ENV feature");
        continue;
      }
      have_env = true;
      m.env_state_key = f.key;
      m.env_state_dim = static_cast<int>(f.shape[0]);
    } else {
      fail(StatusCode::kUnimplemented, path.string() + ": input feature \"" + f.key + "\" has type \"" + f.type +
           "\", which ACT does not use");
    }
  }
  if (m.state_dim == 0) {
    notes.push_back("the config has no observation.state; LeRobot's own eval code requires it, actengine runs without it");
  }
  return inputs;
}

// The one output feature ACT has, the action vector, into m.action_dim.
void read_action_feature(const ConfigReader& cfg, const fs::path& path, ModelConfig& m) {
  bool have_action = false;
  for (const auto& f : read_features(cfg, "output_features")) {
    if (f.key == "action" && f.type == "ACTION") {
      if (f.shape.size() != 1) fail(StatusCode::kInvalidArgument, path.string() + ": action must be 1-D");
      m.action_dim = static_cast<int>(f.shape[0]);
      // Names given with the feature (as a LeRobot dataset's features have them) name the actions,
      // when they fit (act_convert --action-names replaces them).
      if (ModelConfig::action_names_problem(f.names, m.action_dim).empty()) m.action_names = f.names;
      have_action = true;
    } else {
      fail(StatusCode::kUnimplemented, path.string() + ": output feature \"" + f.key + "\" is not ACT's \"action\"");
    }
  }
  if (!have_action) fail(StatusCode::kInvalidArgument, path.string() + ": output_features has no \"action\"");
}

// `path` names where the config came from in messages.
ParsedConfig parse_config(const OrderedJson& j, const fs::path& path, std::vector<std::string>& notes) {
  ConfigReader cfg(j, path.string());
  check_act_policy(j, cfg, path);
  ParsedConfig pc;
  read_architecture(j, cfg, path, pc.model);
  if (j.contains("latent_dim")) pc.latent_dim = cfg.get_int("latent_dim");
  pc.mapping = read_normalization_mapping(cfg, path);
  pc.inputs = read_input_features(cfg, path, pc.model, notes);
  read_action_feature(cfg, path, pc.model);
  return pc;
}

// -------------------------------------------------------------------------------- normalisation

struct NormVectors {  // y = (x - sub) / div * mul + add   (mul/add implied by the mode)
  NormMode mode = NormMode::kIdentity;
  std::vector<float> sub, div;
};
struct UnnormVectors {  // x = (y + shift) * scale + offset
  NormMode mode = NormMode::kIdentity;
  std::vector<float> shift, scale, offset;
};

// Where a checkpoint keeps its statistics: a lookup "stat name -> values" for a feature.
using StatLookup = std::function<std::optional<std::vector<float>>(const std::string& key, const std::string& stat)>;

std::pair<std::string, std::string> stat_names(LeRobotMode mode) {
  switch (mode) {
    case LeRobotMode::kMeanStd: return {"mean", "std"};
    case LeRobotMode::kMinMax: return {"min", "max"};
    case LeRobotMode::kQuantiles: return {"q01", "q99"};
    case LeRobotMode::kQuantile10: return {"q10", "q90"};
    case LeRobotMode::kIdentity: break;
  }
  return {"", ""};
}

// Reads the two statistics of a feature and checks their size. nullopt when absent (caller decides).
std::optional<std::pair<std::vector<float>, std::vector<float>>> read_stats(const StatLookup& lookup, const std::string& key,
                                                                           LeRobotMode mode, size_t expected,
                                                                           const std::string& where) {
  const auto [a_name, b_name] = stat_names(mode);
  auto a = lookup(key, a_name);
  auto b = lookup(key, b_name);
  if (!a && !b) return std::nullopt;
  if (!a || !b) fail(StatusCode::kNotFound, where + ": feature \"" + key + "\" has \"" + (a ? a_name : b_name) +
                     "\" but not \"" + (a ? b_name : a_name) + "\"");
  if (a->size() != expected || b->size() != expected) {
    fail(StatusCode::kInvalidArgument, where + ": statistics of \"" + key + "\" have " + std::to_string(a->size()) +
         " values, expected " + std::to_string(expected));
  }
  for (size_t i = 0; i < expected; ++i) {
    if (!std::isfinite((*a)[i]) || !std::isfinite((*b)[i])) {
      fail(StatusCode::kInvalidArgument, where + ": statistics of \"" + key +
           "\" are not finite (LeRobot leaves them at infinity when they were never set)");
    }
  }
  return std::make_pair(std::move(*a), std::move(*b));
}

// LeRobot's formulas (spec §3.1), in float32 like LeRobot, with the eps placement of each layout.
NormVectors make_norm(LeRobotMode mode, const std::vector<float>& a, const std::vector<float>& b, float eps, bool legacy) {
  NormVectors n;
  if (mode == LeRobotMode::kIdentity) return n;
  n.sub = a;
  n.div.resize(a.size());
  if (mode == LeRobotMode::kMeanStd) {
    n.mode = NormMode::kMeanStd;
    for (size_t i = 0; i < a.size(); ++i) n.div[i] = b[i] + eps;
  } else {
    n.mode = NormMode::kMinMax;
    for (size_t i = 0; i < a.size(); ++i) {
      const float range = b[i] - a[i];
      n.div[i] = legacy ? range + kLegacyEps : (range == 0.0f ? eps : range);
    }
  }
  return n;
}

UnnormVectors make_unnorm(LeRobotMode mode, const std::vector<float>& a, const std::vector<float>& b, float eps, bool legacy) {
  UnnormVectors u;
  if (mode == LeRobotMode::kIdentity) return u;
  const size_t n = a.size();
  u.shift.assign(n, 0.0f);
  u.scale.resize(n);
  u.offset = a;
  if (mode == LeRobotMode::kMeanStd) {
    u.mode = NormMode::kMeanStd;
    u.scale = b;  // y * std + mean, no eps
  } else {
    u.mode = NormMode::kMinMax;
    u.shift.assign(n, 1.0f);
    for (size_t i = 0; i < n; ++i) {
      const float range = b[i] - a[i];
      // (y + 1) / 2 * R + min == (y + 1) * (R / 2) + min exactly (halving is exact).
      u.scale[i] = 0.5f * (legacy || range != 0.0f ? range : eps);
    }
  }
  return u;
}

// ------------------------------------------------------------------------------------ weights

class Weights {
 public:
  explicit Weights(const TensorSet& file) : file_(file) {}

  // Fetches a tensor as float, checking the shape; records it as used.
  std::vector<float> take(const std::string& name, const std::vector<int64_t>& shape) {
    const SafetensorsTensor* t = file_.find(name);
    if (!t) fail(StatusCode::kNotFound, file_.origin() + ": missing tensor \"" + name + "\" (expected " + shape_string(shape) + ")");
    if (t->shape != shape) {
      fail(StatusCode::kInvalidArgument, file_.origin() + ": tensor \"" + name + "\" has shape " + shape_string(t->shape) +
           ", the config implies " + shape_string(shape));
    }
    if (t->dtype != DType::kF32 && t->dtype != DType::kF16 && t->dtype != DType::kBF16) {
      fail(StatusCode::kInvalidArgument, file_.origin() + ": tensor \"" + name + "\" has dtype " + dtype_name(t->dtype) +
           "; expected F32, F16 or BF16");
    }
    used_.insert(name);
    std::vector<float> v = t->to_f32();
    for (float x : v) {
      if (!std::isfinite(x)) fail(StatusCode::kInvalidArgument, file_.origin() + ": tensor \"" + name + "\" contains NaN or Inf");
      // A finite 3e38 once converted without a word and made every action infinite.
      if (std::fabs(x) > kMaxWeightMagnitude) {
        char value[32];
        std::snprintf(value, sizeof value, "%g", x);
        fail(StatusCode::kInvalidArgument, file_.origin() + ": tensor \"" + name + "\" holds " + value +
             ": no trained network weight is that large (the limit is 1e6); is the checkpoint damaged?");
      }
    }
    return v;
  }
  bool has(const std::string& name) const { return file_.contains(name); }
  void mark_used(const std::string& name) { used_.insert(name); }
  bool used(const std::string& name) const { return used_.count(name) != 0; }

 private:
  const TensorSet& file_;
  std::set<std::string> used_;
};

bool is_training_only(const std::string& name) {
  return name.rfind("model.vae_encoder", 0) == 0 || name.rfind("normalize_targets.", 0) == 0;
}

// ------------------------------------------------------------------------------ folding helpers

using Mat = std::vector<float>;  // row-major

// y[o + j] = sum_i x[i] * w[o + j, i] + b[o + j] for j < N, accumulated in double, i in order: N
// independent chains of adds (N a constant, so the sums stay in registers).
template <int N>
void linear_d_outputs(const double* x, int in, const float* w, const float* b, int o, double* y) {
  double s[N];
  const float* wr[N];
  for (int j = 0; j < N; ++j) {
    s[j] = b ? b[o + j] : 0.0;
    wr[j] = w + static_cast<size_t>(o + j) * in;
  }
  for (int i = 0; i < in; ++i) {
    for (int j = 0; j < N; ++j) s[j] += x[i] * wr[j][i];
  }
  for (int j = 0; j < N; ++j) y[o + j] = s[j];
}

// out[r, o] = sum_i x[r, i] * w[o, i] + b[o], accumulated in double, i in order. Eight outputs at a
// time, each its own sum in the same order as alone (the same bits), where one chain of adds waited
// for each add before the next (the position tables of a default model's import, about 0.7 GMAC,
// were 6 % of act_bench's start by perf's samples, then 2.6 %).
std::vector<double> linear_d(const std::vector<double>& x, int rows, int in, const float* w, const float* b, int out) {
  constexpr int kOutputs = 8;
  std::vector<double> y(static_cast<size_t>(rows) * out);
  for (int r = 0; r < rows; ++r) {
    const double* xr = x.data() + static_cast<size_t>(r) * in;
    double* yr = y.data() + static_cast<size_t>(r) * out;
    int o = 0;
    for (; o + kOutputs <= out; o += kOutputs) linear_d_outputs<kOutputs>(xr, in, w, b, o, yr);
    for (; o < out; ++o) linear_d_outputs<1>(xr, in, w, b, o, yr);
  }
  return y;
}

std::vector<double> layernorm_d(const std::vector<double>& x, const Mat& gamma, const Mat& beta) {
  const size_t n = x.size();
  double mean = 0;
  for (double v : x) mean += v;
  mean /= static_cast<double>(n);
  double var = 0;
  for (double v : x) var += (v - mean) * (v - mean);
  var /= static_cast<double>(n);
  std::vector<double> y(n);
  for (size_t i = 0; i < n; ++i) y[i] = (x[i] - mean) / std::sqrt(var + 1e-5) * gamma[i] + beta[i];
  return y;
}

std::vector<double> to_double(const Mat& m) { return std::vector<double>(m.begin(), m.end()); }
Mat to_float(const std::vector<double>& m) { return Mat(m.begin(), m.end()); }

// The 2-D sinusoidal camera embedding as LeRobot computes it in float32 (spec §4.5), [h*w, D] row-major.
Mat camera_pos_embed(int h, int w, int D) {
  const int d = D / 2;
  constexpr float kTwoPi = static_cast<float>(2.0 * M_PI);
  std::vector<float> inv_freq(d);
  for (int k = 0; k < d; ++k) {
    const float exponent = static_cast<float>(2 * (k / 2)) / static_cast<float>(d);
    inv_freq[k] = std::pow(10000.0f, exponent);
  }
  Mat pe(static_cast<size_t>(h) * w * D);
  for (int r = 0; r < h; ++r) {
    const float y = static_cast<float>(r + 1) / (static_cast<float>(h) + 1e-6f) * kTwoPi;
    for (int c = 0; c < w; ++c) {
      const float x = static_cast<float>(c + 1) / (static_cast<float>(w) + 1e-6f) * kTwoPi;
      float* row = pe.data() + (static_cast<size_t>(r) * w + c) * D;
      for (int k = 0; k < d; ++k) {
        const float ya = y / inv_freq[k];
        const float xa = x / inv_freq[k];
        row[k] = (k % 2 == 0) ? std::sin(ya) : std::cos(ya);
        row[d + k] = (k % 2 == 0) ? std::sin(xa) : std::cos(xa);
      }
    }
  }
  return pe;
}

// A bias table [rows, width]: columns [0, pos_cols) get pos @ W[0:pos_cols]^T + b, the rest just b.
Mat bias_table(const Mat& pos, int rows, int D, const Mat& w, const Mat& b, int width, int pos_cols) {
  Mat table(static_cast<size_t>(rows) * width);
  const std::vector<double> pd = to_double(pos);
  const std::vector<double> proj = linear_d(pd, rows, D, w.data(), b.data(), pos_cols);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < width; ++c) {
      table[static_cast<size_t>(r) * width + c] =
          c < pos_cols ? static_cast<float>(proj[static_cast<size_t>(r) * pos_cols + c]) : b[c];
    }
  }
  return table;
}

// --------------------------------------------------------------------------------- the import

class Importer {
 public:
  /// `dir` is the checkpoint folder for the current layout's processor files; empty for a legacy
  /// state dict held in memory.
  Importer(fs::path dir, std::string layout) : dir_(std::move(dir)) { out_.layout = std::move(layout); }
  /// Current-layout normalisation with the statistics in `stats` instead of processor files.
  explicit Importer(const TensorSet& stats) : external_stats_(&stats) { out_.layout = "current"; }

  /// The config is parsed and validated before `open_weights` is called, so a config problem is
  /// reported as such even when the weights are missing too.
  ImportedModel run(const OrderedJson& config_json, const fs::path& config_path,
                    const std::function<const TensorSet&()>& open_weights) {
    ParsedConfig pc = parse_config(config_json, config_path, out_.notes);
    ModelConfig& m = pc.model;
    m.validate();
    const TensorSet& file = open_weights();
    Weights w(file);

    import_normalisation(pc, file, w);
    import_backbone(m, w);
    import_transformer(pc, w);

    // Every tensor must be either used or known to be training-only: anything else means the
    // checkpoint does not match its config.
    std::vector<std::string> unexpected;
    for (const auto& name : file.names()) {
      const auto& t = file.get(name);
      out_.checkpoint_tensors++;
      out_.checkpoint_values += t.elements();
      if (w.used(name)) continue;
      if (is_training_only(name)) {
        out_.training_only_tensors++;
        out_.training_only_values += t.elements();
      } else {
        unexpected.push_back(name);
      }
    }
    if (!unexpected.empty()) {
      std::string list;
      for (size_t i = 0; i < unexpected.size() && i < 8; ++i) list += (i ? ", " : "") + ("\"" + unexpected[i] + "\"");
      if (unexpected.size() > 8) list += ", ... (" + std::to_string(unexpected.size()) + " in all)";
      fail(StatusCode::kInvalidArgument, file.origin() + ": tensors the config does not account for: " + list +
           " (does config.json belong to these weights?)");
    }
    out_.config = m;
    return std::move(out_);
  }

 private:
  void add(std::string name, std::vector<int64_t> shape, Mat values) {
    out_.tensors.push_back({std::move(name), std::move(shape), std::move(values)});
  }

  // ---- normalisation
  // Where each direction's statistics come from (inputs: the preprocessor, the action: the
  // postprocessor), with its eps and the mode of each feature type. The lookups may point into
  // in_file and out_file, so a StatSources stays where it was made.
  struct StatSources {
    StatSources() = default;
    StatSources(const StatSources&) = delete;
    StatSources& operator=(const StatSources&) = delete;

    float eps_in = kLegacyEps, eps_out = kLegacyEps;
    std::map<std::string, LeRobotMode> map_in, map_out;
    StatLookup in_lookup, out_lookup;
    std::optional<SafetensorsFile> in_file, out_file;
    std::string in_where, out_where;
  };

  static LeRobotMode mode_of(const std::map<std::string, LeRobotMode>& modes, const std::string& type) {
    const auto it = modes.find(type);
    return it == modes.end() ? LeRobotMode::kIdentity : it->second;
  }

  // Legacy layout: the statistics are buffers in the weights file itself.
  static void legacy_stat_sources(const ParsedConfig& pc, const TensorSet& weights_file, Weights& w, StatSources& s) {
    for (LeRobotMode mode : [&] { std::vector<LeRobotMode> v; for (auto& [t, md] : pc.mapping) v.push_back(md); return v; }()) {
      if (mode == LeRobotMode::kQuantiles || mode == LeRobotMode::kQuantile10) {
        fail(StatusCode::kInvalidArgument, "legacy checkpoint uses QUANTILES normalisation, which only the current layout has");
      }
    }
    const TensorSet* file = &weights_file;
    Weights* used = &w;
    s.in_lookup = [file, used](const std::string& key, const std::string& stat) -> std::optional<std::vector<float>> {
      std::string flat = key;
      for (char& c : flat) {
        if (c == '.') c = '_';
      }
      const std::string name = "normalize_inputs.buffer_" + flat + "." + stat;
      if (!file->contains(name)) return std::nullopt;
      used->mark_used(name);
      return file->get(name).to_f32();
    };
    s.out_lookup = [file, used](const std::string&, const std::string& stat) -> std::optional<std::vector<float>> {
      // If the buffers shared memory when saved, safetensors kept only normalize_targets.* (spec §10.2).
      for (const std::string prefix : {"unnormalize_outputs.buffer_action.", "normalize_targets.buffer_action."}) {
        if (file->contains(prefix + stat)) {
          used->mark_used(prefix + stat);
          return file->get(prefix + stat).to_f32();
        }
      }
      return std::nullopt;
    };
    s.in_where = s.out_where = weights_file.origin();
  }

  // Statistics given apart from the checkpoint (a .pth import's --stats), one set for both directions.
  void external_stat_sources(StatSources& s) const {
    s.in_lookup = s.out_lookup = [this](const std::string& key, const std::string& stat) -> std::optional<std::vector<float>> {
      const SafetensorsTensor* t = external_stats_->find(key + "." + stat);
      if (!t) return std::nullopt;
      return t->to_f32();
    };
    s.in_where = s.out_where = external_stats_->origin();
  }

  // Reads one processor pipeline's normaliser step: its eps, its own mode map if it has one, and
  // its state file.
  void read_processor_step(const std::string& pipeline_file, const std::string& registry_name, float& eps,
                           std::map<std::string, LeRobotMode>& modes, std::optional<SafetensorsFile>& state,
                           std::string& where) const {
    const fs::path path = dir_ / pipeline_file;
    const ProcessorStep parsed = parse_processor_step(detail::read_json_file(path.string()), registry_name, path.string());
    if (parsed.eps) eps = *parsed.eps;
    if (parsed.norm_map) {
      modes.clear();  // the step's own map is what LeRobot runs
      for (const auto& [type, mode] : *parsed.norm_map) modes[type] = parse_mode(mode, path.string());
    }
    const fs::path state_path = dir_ / parsed.state_file;
    if (!fs::exists(state_path)) fail(StatusCode::kNotFound, "missing normalisation statistics " + state_path.string());
    state.emplace(SafetensorsFile::open(state_path.string()));
    where = state_path.string();
  }

  // Current layout: the pre- and postprocessor pipelines name a safetensors file of statistics each.
  void processor_stat_sources(StatSources& s) const {
    if (!fs::exists(dir_ / "policy_postprocessor.json")) {
      fail(StatusCode::kNotFound, (dir_ / "policy_postprocessor.json").string() + " is missing (current-layout checkpoint)");
    }
    read_processor_step("policy_preprocessor.json", "normalizer_processor", s.eps_in, s.map_in, s.in_file, s.in_where);
    read_processor_step("policy_postprocessor.json", "unnormalizer_processor", s.eps_out, s.map_out, s.out_file, s.out_where);
    auto from_file = [](const std::optional<SafetensorsFile>& f) {
      return [&f](const std::string& key, const std::string& stat) -> std::optional<std::vector<float>> {
        const std::string name = key + "." + stat;
        if (!f->contains(name)) return std::nullopt;
        return f->get(name).to_f32();
      };
    };
    s.in_lookup = from_file(s.in_file);
    s.out_lookup = from_file(s.out_file);
  }

  // Every input's normalisation, as m.input_norm and its sub/div tensors.
  void import_input_norms(ParsedConfig& pc, const StatSources& s, bool legacy) {
    ModelConfig& m = pc.model;
    for (const auto& f : pc.inputs) {
      if (f.type == "ENV" && f.key != m.env_state_key) continue;
      const LeRobotMode mode = mode_of(s.map_in, f.type);
      if (mode == LeRobotMode::kIdentity) {
        m.input_norm.emplace_back(f.key, NormMode::kIdentity);
        continue;
      }
      const size_t n = static_cast<size_t>(f.type == "VISUAL" ? 3 : f.shape[0]);
      auto stats = read_stats(s.in_lookup, f.key, mode, n, s.in_where);
      if (!stats) {
        if (legacy || external_stats_) fail(StatusCode::kNotFound, s.in_where + ": no normalisation statistics for \"" + f.key + "\"");
        // Current layout: LeRobot passes a feature without statistics through unchanged.
        out_.notes.push_back("no statistics for \"" + f.key + "\" in " + s.in_where + ": it is not normalised (as LeRobot does)");
        m.input_norm.emplace_back(f.key, NormMode::kIdentity);
        continue;
      }
      const NormVectors nv = make_norm(mode, stats->first, stats->second, s.eps_in, legacy);
      m.input_norm.emplace_back(f.key, nv.mode);
      add(bn::norm_sub(f.key), {static_cast<int64_t>(n)}, nv.sub);
      add(bn::norm_div(f.key), {static_cast<int64_t>(n)}, nv.div);
    }
  }

  // The action's un-normalisation, as m.action_norm and its shift/scale/offset tensors.
  void import_action_unnorm(ModelConfig& m, const StatSources& s, bool legacy) {
    const LeRobotMode action_mode = mode_of(s.map_out, "ACTION");
    std::optional<std::pair<std::vector<float>, std::vector<float>>> action_stats;
    if (action_mode != LeRobotMode::kIdentity) {
      action_stats = read_stats(s.out_lookup, "action", action_mode, static_cast<size_t>(m.action_dim), s.out_where);
      if (!action_stats) {
        if (legacy || external_stats_) fail(StatusCode::kNotFound, s.out_where + ": no un-normalisation statistics for \"action\"");
        out_.notes.push_back("no statistics for \"action\" in " + s.out_where + ": actions are not un-normalised (as LeRobot does)");
      }
    }
    if (action_stats) {
      const UnnormVectors u = make_unnorm(action_mode, action_stats->first, action_stats->second, s.eps_out, legacy);
      m.action_norm = u.mode;
      const std::vector<int64_t> shape = {m.action_dim};
      add(bn::kUnnormShift, shape, u.shift);
      add(bn::kUnnormScale, shape, u.scale);
      add(bn::kUnnormOffset, shape, u.offset);
    } else {
      m.action_norm = NormMode::kIdentity;
    }
  }

  void import_normalisation(ParsedConfig& pc, const TensorSet& weights_file, Weights& w) {
    const bool legacy = out_.layout == "legacy";
    StatSources s;
    s.map_in = s.map_out = pc.mapping;
    if (legacy) {
      legacy_stat_sources(pc, weights_file, w, s);
    } else if (external_stats_) {
      external_stat_sources(s);
    } else {
      processor_stat_sources(s);
    }
    import_input_norms(pc, s, legacy);
    import_action_unnorm(pc.model, s, legacy);
    for (const auto& [type, mode] : s.map_in) {
      if (mode == LeRobotMode::kQuantiles || mode == LeRobotMode::kQuantile10) {
        out_.notes.push_back(std::string(type) + " uses " + (mode == LeRobotMode::kQuantiles ? "QUANTILES (q01/q99)" : "QUANTILE10 (q10/q90)") +
                             ", run as MIN_MAX over those quantiles");
      }
    }
  }

  // ---- backbone: fold FrozenBatchNorm into every conv
  void fold_conv(Weights& w, const ConvSpec& c) {
    const std::string p = "model.backbone.";
    const int k = c.kernel;
    const Mat weight = w.take(p + c.name + ".weight", {c.out_c, c.in_c, k, k});
    const std::vector<int64_t> vec = {c.out_c};
    const Mat gamma = w.take(p + c.bn + ".weight", vec);
    const Mat beta = w.take(p + c.bn + ".bias", vec);
    const Mat mean = w.take(p + c.bn + ".running_mean", vec);
    const Mat var = w.take(p + c.bn + ".running_var", vec);
    Mat folded(weight.size());
    Mat bias(c.out_c);
    for (int o = 0; o < c.out_c; ++o) {
      if (var[o] < 0.0f) fail(StatusCode::kInvalidArgument, "model.backbone." + c.bn + ".running_var is negative");
      const double scale = gamma[o] / std::sqrt(static_cast<double>(var[o]) + kBatchNormEps);
      bias[o] = static_cast<float>(beta[o] - mean[o] * scale);
      // [O, I, KH, KW] -> [O, KH, KW, I] so a patch of an NHWC image is one contiguous row.
      for (int i = 0; i < c.in_c; ++i) {
        for (int y = 0; y < k; ++y) {
          for (int x = 0; x < k; ++x) {
            const size_t src = ((static_cast<size_t>(o) * c.in_c + i) * k + y) * k + x;
            const size_t dst = ((static_cast<size_t>(o) * k + y) * k + x) * c.in_c + i;
            folded[dst] = static_cast<float>(weight[src] * scale);
          }
        }
      }
    }
    add(bn::conv_weight(c.name), {c.out_c, k, k, c.in_c}, std::move(folded));
    add(bn::conv_bias(c.name), vec, std::move(bias));
  }

  void import_backbone(const ModelConfig& m, Weights& w) {
    fold_conv(w, m.stem());
    for (const auto& stage : m.backbone_stages()) {
      for (const auto& block : stage) {
        for (const auto& c : block.convs) fold_conv(w, c);
        if (block.has_downsample) fold_conv(w, block.downsample);
      }
    }
  }

  // ---- transformer, with the observation-independent parts folded
  struct Attn {
    Mat in_w, in_b, out_w, out_b;
  };
  Attn take_attn(Weights& w, const std::string& p, int D) {
    return {w.take(p + ".in_proj_weight", {3 * D, D}), w.take(p + ".in_proj_bias", {3 * D}),
            w.take(p + ".out_proj.weight", {D, D}), w.take(p + ".out_proj.bias", {D})};
  }

  void take_ffn_and_norms(Weights& w, const std::string& src, const std::string& dst_prefix, const ModelConfig& m,
                          int n_norms) {
    const int D = m.dim_model, F = m.dim_feedforward;
    const int ffn_in = m.activation == Activation::kGlu ? F / 2 : F;
    add(dst_prefix + "linear1.weight", {F, D}, w.take(src + "linear1.weight", {F, D}));
    add(dst_prefix + "linear1.bias", {F}, w.take(src + "linear1.bias", {F}));
    add(dst_prefix + "linear2.weight", {D, ffn_in}, w.take(src + "linear2.weight", {D, ffn_in}));
    add(dst_prefix + "linear2.bias", {D}, w.take(src + "linear2.bias", {D}));
    for (int i = 1; i <= n_norms; ++i) {
      const std::string n = "norm" + std::to_string(i);
      add(dst_prefix + n + ".weight", {D}, w.take(src + n + ".weight", {D}));
      add(dst_prefix + n + ".bias", {D}, w.take(src + n + ".bias", {D}));
    }
  }

  // Input projections. The latent input is zero at inference, so its token is the bias alone.
  void import_input_projections(const ParsedConfig& pc, Weights& w) {
    const ModelConfig& m = pc.model;
    const int D = m.dim_model;
    const std::string p = "model.";
    w.take(p + "encoder_latent_input_proj.weight", {D, pc.latent_dim});
    add(bn::kLatentToken, {D}, w.take(p + "encoder_latent_input_proj.bias", {D}));
    add(bn::kImgProjWeight, {D, m.feature_channels()},
        w.take(p + "encoder_img_feat_input_proj.weight", {D, m.feature_channels(), 1, 1}));
    add(bn::kImgProjBias, {D}, w.take(p + "encoder_img_feat_input_proj.bias", {D}));
    if (m.state_dim > 0) {
      add(bn::kStateProjWeight, {D, m.state_dim}, w.take(p + "encoder_robot_state_input_proj.weight", {D, m.state_dim}));
      add(bn::kStateProjBias, {D}, w.take(p + "encoder_robot_state_input_proj.bias", {D}));
    }
    if (m.env_state_dim > 0) {
      add(bn::kEnvProjWeight, {D, m.env_state_dim}, w.take(p + "encoder_env_state_input_proj.weight", {D, m.env_state_dim}));
      add(bn::kEnvProjBias, {D}, w.take(p + "encoder_env_state_input_proj.bias", {D}));
    }
  }

  // The encoder; returns its positions P [N, D] (learned 1-D rows, then each camera's 2-D
  // sinusoid), which the decoder's cross-attention keys need too.
  Mat import_encoder(const ModelConfig& m, Weights& w) {
    const int D = m.dim_model, N = m.n_tokens();
    const std::string p = "model.";
    const int n1d = m.n_1d_tokens();
    Mat pos = w.take(p + "encoder_1d_feature_pos_embed.weight", {n1d, D});
    for (const auto& cam : m.cameras) {
      const Mat pe = camera_pos_embed(m.feature_height(cam), m.feature_width(cam), D);
      pos.insert(pos.end(), pe.begin(), pe.end());
    }
    add(bn::kEncoderPos, {N, D}, pos);

    // Encoder layers: q = (x + P) Wq^T + bq = x Wq^T + (P Wq^T + bq), likewise k; v gets no positions.
    for (int l = 0; l < m.n_encoder_layers; ++l) {
      const std::string src = p + "encoder.layers." + std::to_string(l) + ".";
      Attn a = take_attn(w, src + "self_attn", D);
      add(bn::enc(l, "in_proj.bias"), {N, 3 * D}, bias_table(pos, N, D, a.in_w, a.in_b, 3 * D, 2 * D));
      add(bn::bias_vector(bn::enc(l, "in_proj.bias")), {3 * D}, a.in_b);
      add(bn::enc(l, "in_proj.weight"), {3 * D, D}, std::move(a.in_w));
      add(bn::enc(l, "out_proj.weight"), {D, D}, std::move(a.out_w));
      add(bn::enc(l, "out_proj.bias"), {D}, std::move(a.out_b));
      take_ffn_and_norms(w, src, bn::enc(l, ""), m, 2);
    }
    if (m.pre_norm) {
      add(bn::kEncoderNormWeight, {D}, w.take(p + "encoder.norm.weight", {D}));
      add(bn::kEncoderNormBias, {D}, w.take(p + "encoder.norm.bias", {D}));
    }
    return pos;
  }

  // Decoder layer 0: its input is zero, so its self-attention block is the same for every
  // observation. Every position's self-attention value is v = u Wv^T + bv with the same u (0
  // post-norm, LayerNorm1(0) = beta1 pre-norm), so attention returns v whatever the weights, and
  // the block output y1 is one D-vector; stored with the cross-attention queries it implies.
  void fold_first_decoder_self_attn(const ModelConfig& m, const Attn& self, const Mat& n1w, const Mat& n1b,
                                    const Mat& n2w, const Mat& n2b, const Mat& qpos, const Mat& cross_q_w,
                                    const Mat& cross_q_b) {
    const int D = m.dim_model, T = m.chunk_size;
    const std::vector<double> u = m.pre_norm ? to_double(n1b) : std::vector<double>(D, 0.0);
    const std::vector<double> v = linear_d(u, 1, D, self.in_w.data() + 2 * static_cast<size_t>(D) * D,
                                           self.in_b.data() + 2 * D, D);
    const std::vector<double> attn_out = linear_d(v, 1, D, self.out_w.data(), self.out_b.data(), D);
    const std::vector<double> y1 = m.pre_norm ? attn_out : layernorm_d(attn_out, n1w, n1b);
    // Cross-attention queries: (y1 + Q) post-norm or (LayerNorm2(y1) + Q) pre-norm, projected.
    const std::vector<double> q_base = m.pre_norm ? layernorm_d(y1, n2w, n2b) : y1;
    std::vector<double> q_in(static_cast<size_t>(T) * D);
    for (int t = 0; t < T; ++t) {
      for (int c = 0; c < D; ++c) q_in[static_cast<size_t>(t) * D + c] = q_base[c] + qpos[static_cast<size_t>(t) * D + c];
    }
    add(bn::dec(0, "const_y"), {D}, to_float(y1));
    add(bn::dec(0, "cross_q"), {T, D}, to_float(linear_d(q_in, T, D, cross_q_w.data(), cross_q_b.data(), D)));
  }

  // Decoder layer l, its queries' positions `qpos` [T, D] folded into biases, its cross-attention
  // keys given the encoder positions `pos`.
  void import_decoder_layer(const ModelConfig& m, Weights& w, int l, const Mat& qpos, const Mat& pos) {
    const int D = m.dim_model, T = m.chunk_size, N = m.n_tokens();
    const std::string src = "model.decoder.layers." + std::to_string(l) + ".";
    Attn self = take_attn(w, src + "self_attn", D);
    Attn cross = take_attn(w, src + "multihead_attn", D);
    const Mat n1w = w.take(src + "norm1.weight", {D}), n1b = w.take(src + "norm1.bias", {D});
    const Mat n2w = w.take(src + "norm2.weight", {D}), n2b = w.take(src + "norm2.bias", {D});
    const Mat cross_q_w(cross.in_w.begin(), cross.in_w.begin() + static_cast<ptrdiff_t>(D) * D);
    const Mat cross_q_b(cross.in_b.begin(), cross.in_b.begin() + D);
    if (l == 0) {
      fold_first_decoder_self_attn(m, self, n1w, n1b, n2w, n2b, qpos, cross_q_w, cross_q_b);
    } else {
      add(bn::dec(l, "in_proj.bias"), {T, 3 * D}, bias_table(qpos, T, D, self.in_w, self.in_b, 3 * D, 2 * D));
      add(bn::dec(l, "in_proj.weight"), {3 * D, D}, std::move(self.in_w));
      add(bn::dec(l, "out_proj.weight"), {D, D}, std::move(self.out_w));
      add(bn::dec(l, "out_proj.bias"), {D}, std::move(self.out_b));
      add(bn::dec(l, "cross_q_proj.bias"), {T, D}, bias_table(qpos, T, D, cross_q_w, cross_q_b, D, D));
      add(bn::dec(l, "cross_q_proj.weight"), {D, D}, cross_q_w);
    }
    // Cross-attention keys get the encoder positions, values the bare memory.
    const Mat kv_w(cross.in_w.begin() + static_cast<ptrdiff_t>(D) * D, cross.in_w.end());
    const Mat kv_b(cross.in_b.begin() + D, cross.in_b.end());
    add(bn::dec(l, "cross_kv_proj.bias"), {N, 2 * D}, bias_table(pos, N, D, kv_w, kv_b, 2 * D, D));
    add(bn::bias_vector(bn::dec(l, "cross_kv_proj.bias")), {2 * D}, kv_b);
    add(bn::dec(l, "cross_kv_proj.weight"), {2 * D, D}, kv_w);
    add(bn::dec(l, "cross_out_proj.weight"), {D, D}, std::move(cross.out_w));
    add(bn::dec(l, "cross_out_proj.bias"), {D}, std::move(cross.out_b));
    add(bn::dec(l, "norm1.weight"), {D}, n1w);
    add(bn::dec(l, "norm1.bias"), {D}, n1b);
    add(bn::dec(l, "norm2.weight"), {D}, n2w);
    add(bn::dec(l, "norm2.bias"), {D}, n2b);
    take_ffn_and_norms(w, src, bn::dec(l, ""), m, 0);
    add(bn::dec(l, "norm3.weight"), {D}, w.take(src + "norm3.weight", {D}));
    add(bn::dec(l, "norm3.bias"), {D}, w.take(src + "norm3.bias", {D}));
  }

  void import_transformer(const ParsedConfig& pc, Weights& w) {
    const ModelConfig& m = pc.model;
    const int D = m.dim_model, T = m.chunk_size;
    const std::string p = "model.";
    import_input_projections(pc, w);
    const Mat pos = import_encoder(m, w);
    const Mat qpos = w.take(p + "decoder_pos_embed.weight", {T, D});
    for (int l = 0; l < m.n_decoder_layers; ++l) import_decoder_layer(m, w, l, qpos, pos);
    add(bn::kDecoderNormWeight, {D}, w.take(p + "decoder.norm.weight", {D}));
    add(bn::kDecoderNormBias, {D}, w.take(p + "decoder.norm.bias", {D}));
    add(bn::kHeadWeight, {m.action_dim, D}, w.take(p + "action_head.weight", {m.action_dim, D}));
    add(bn::kHeadBias, {m.action_dim}, w.take(p + "action_head.bias", {m.action_dim}));
  }

  fs::path dir_;
  const TensorSet* external_stats_ = nullptr;
  ImportedModel out_;
};

}  // namespace

ProcessorStep parse_processor_step(const nlohmann::ordered_json& pipeline, const std::string& registry_name,
                                   const std::string& where) {
  if (!pipeline.is_object() || !pipeline.contains("steps") || !pipeline["steps"].is_array()) {
    fail(StatusCode::kDataLoss, where + ": expected {\"steps\": [...]}");
  }
  for (const auto& s : pipeline["steps"]) {
    if (!s.is_object() || !s.contains("registry_name") || s["registry_name"] != registry_name) continue;
    ProcessorStep step;
    const auto config = s.contains("config") ? s["config"] : OrderedJson::object();
    if (config.is_object() && config.contains("eps")) {
      const auto& eps = config["eps"];
      // Read as double: a value outside float's range must be an error, not an overflowing cast.
      const double value = eps.is_number() ? eps.get<double>() : -1.0;
      if (!(value >= 0.0 && value <= std::numeric_limits<float>::max())) {
        fail(StatusCode::kDataLoss, where + ": eps must be a finite non-negative number");
      }
      step.eps = static_cast<float>(value);
    }
    if (config.is_object() && config.contains("norm_map") && config["norm_map"].is_object()) {
      step.norm_map.emplace();
      for (const auto& [type, mode] : config["norm_map"].items()) {
        if (!mode.is_string()) fail(StatusCode::kDataLoss, where + ": norm_map values must be strings");
        (*step.norm_map)[type] = mode.get<std::string>();
      }
    }
    if (!s.contains("state_file") || !s["state_file"].is_string()) {
      fail(StatusCode::kDataLoss, where + ": step " + registry_name + " has no state_file");
    }
    step.state_file = s["state_file"].get<std::string>();
    if (step.state_file.empty() || step.state_file.find('/') != std::string::npos ||
        step.state_file.find("..") != std::string::npos) {
      fail(StatusCode::kDataLoss, where + ": state_file must be a file name in the checkpoint folder");
    }
    return step;
  }
  fail(StatusCode::kNotFound, where + ": no \"" + registry_name + "\" step; cannot tell how to normalise");
}

ImportedModel import_lerobot_checkpoint(const std::string& checkpoint_dir) {
  const fs::path dir(checkpoint_dir);
  if (!fs::is_directory(dir)) fail(StatusCode::kNotFound, "checkpoint folder not found: " + checkpoint_dir);
  const fs::path config_path = dir / "config.json";
  if (!fs::exists(config_path)) {
    fail(StatusCode::kNotFound, "not a LeRobot checkpoint folder: " + config_path.string() + " is missing");
  }
  const OrderedJson config = detail::read_json_file(config_path.string());
  std::optional<SafetensorsFile> weights;
  const auto open_weights = [&]() -> const TensorSet& {
    const fs::path path = dir / "model.safetensors";
    if (!fs::exists(path)) fail(StatusCode::kNotFound, "checkpoint has no weights: " + path.string() + " is missing");
    return weights.emplace(SafetensorsFile::open(path.string()));
  };
  const std::string layout = fs::exists(dir / "policy_preprocessor.json") ? "current" : "legacy";
  return Importer(dir, layout).run(config, config_path, open_weights);
}

ModelConfig lerobot_model_config(const nlohmann::ordered_json& config, const std::string& where) {
  std::vector<std::string> notes;
  ModelConfig m = parse_config(config, where, notes).model;
  m.validate();
  return m;
}

ImportedModel import_lerobot_state_dict(const nlohmann::ordered_json& config, const TensorSet& state_dict) {
  return Importer({}, "legacy").run(config, state_dict.origin() + " config", [&]() -> const TensorSet& { return state_dict; });
}

ImportedModel import_lerobot_state_dict(const nlohmann::ordered_json& config, const TensorSet& state_dict,
                                        const TensorSet& stats) {
  return Importer(stats).run(config, state_dict.origin() + " config", [&]() -> const TensorSet& { return state_dict; });
}

ActbWriter fp32_blob(const ImportedModel& model) {
  ActbWriter writer;
  writer.set_producer(std::string("act_convert (actengine) from a ") + model.layout + "-layout LeRobot checkpoint");
  writer.set_config(model.config.to_json());
  for (const auto& t : model.tensors) writer.add_f32_ref(t.name, t.shape, t.values);
  return writer;
}

size_t write_fp32_blob(const ImportedModel& model, const std::string& path) { return fp32_blob(model).write(path); }

}  // namespace act
