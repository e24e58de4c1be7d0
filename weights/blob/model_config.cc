#include "weights/blob/model_config.h"

#include <cstdio>

#include <algorithm>

#include <cmath>
#include <sstream>

#include "actengine/status.h"
#include "weights/blob/file_util.h"

namespace act {

const char* activation_name(Activation a) {
  switch (a) {
    case Activation::kRelu: return "relu";
    case Activation::kGelu: return "gelu";
    case Activation::kGlu: return "glu";
  }
  return "?";
}

const char* precision_name(Precision p) { return p == Precision::kInt8 ? "int8" : "fp32"; }

const char* norm_mode_name(NormMode m) {
  switch (m) {
    case NormMode::kIdentity: return "IDENTITY";
    case NormMode::kMeanStd: return "MEAN_STD";
    case NormMode::kMinMax: return "MIN_MAX";
  }
  return "?";
}

const std::vector<ResNetArchitecture>& resnet_architectures() {
  static const std::vector<ResNetArchitecture> kResNets = {{"resnet18", {2, 2, 2, 2}, false},
                                                           {"resnet34", {3, 4, 6, 3}, false},
                                                           {"resnet50", {3, 4, 6, 3}, true},
                                                           {"resnet101", {3, 4, 23, 3}, true},
                                                           {"resnet152", {3, 8, 36, 3}, true}};
  return kResNets;
}

const ResNetArchitecture* find_resnet(const std::string& name) {
  for (const ResNetArchitecture& a : resnet_architectures()) {
    if (name == a.name) return &a;
  }
  return nullptr;
}

std::string resnet_names() {
  std::string names;
  for (const ResNetArchitecture& a : resnet_architectures()) names += (names.empty() ? "" : ", ") + std::string(a.name);
  return names;
}

namespace {

int ceil_half(int n) { return (n + 1) / 2; }

ConvSpec conv(std::string name, std::string bn, int in_c, int out_c, int kernel, int stride, int dilation) {
  return {std::move(name), std::move(bn), in_c, out_c, kernel, stride, kernel == 1 ? 0 : dilation, dilation};
}

}  // namespace

ConvSpec ModelConfig::stem() const { return {"conv1", "bn1", 3, 64, 7, 2, 3, 1}; }

std::vector<std::vector<BlockSpec>> ModelConfig::backbone_stages() const {
  // torchvision ResNet._make_layer; with replace_final_stride_with_dilation, layer4 trades its stride
  // for dilation 2 in every block after the first.
  std::vector<std::vector<BlockSpec>> stages;
  int in_c = 64;
  int dilation = 1;
  for (size_t s = 0; s < backbone_blocks.size(); ++s) {
    const int planes = 64 << s;
    int stride = s == 0 ? 1 : 2;
    const int previous_dilation = dilation;
    if (s == 3 && dilate_layer4) {
      dilation *= stride;
      stride = 1;
    }
    const int out_c = bottleneck ? planes * 4 : planes;
    std::vector<BlockSpec> blocks;
    for (int b = 0; b < backbone_blocks[s]; ++b) {
      const std::string p = "layer" + std::to_string(s + 1) + "." + std::to_string(b) + ".";
      const int block_stride = b == 0 ? stride : 1;
      const int block_dilation = b == 0 ? previous_dilation : dilation;
      BlockSpec block;
      if (bottleneck) {
        block.convs.push_back(conv(p + "conv1", p + "bn1", in_c, planes, 1, 1, 1));
        block.convs.push_back(conv(p + "conv2", p + "bn2", planes, planes, 3, block_stride, block_dilation));
        block.convs.push_back(conv(p + "conv3", p + "bn3", planes, out_c, 1, 1, 1));
      } else {
        block.convs.push_back(conv(p + "conv1", p + "bn1", in_c, planes, 3, block_stride, block_dilation));
        block.convs.push_back(conv(p + "conv2", p + "bn2", planes, planes, 3, 1, block_dilation));
      }
      if (b == 0 && (block_stride != 1 || in_c != out_c)) {
        block.has_downsample = true;
        block.downsample = conv(p + "downsample.0", p + "downsample.1", in_c, out_c, 1, block_stride, 1);
      }
      blocks.push_back(std::move(block));
      in_c = out_c;
    }
    stages.push_back(std::move(blocks));
  }
  return stages;
}

int ModelConfig::feature_height(const CameraConfig& cam) const {
  int h = ceil_half(ceil_half(cam.height));  // stem, max-pool
  for (int s = 1; s < 4; ++s) {
    if (!(s == 3 && dilate_layer4)) h = ceil_half(h);
  }
  return h;
}

int ModelConfig::feature_width(const CameraConfig& cam) const {
  return feature_height(CameraConfig{cam.key, cam.width, cam.height});
}

int ModelConfig::n_tokens() const {
  int n = n_1d_tokens();
  for (const auto& cam : cameras) n += feature_height(cam) * feature_width(cam);
  return n;
}

std::vector<std::string> ModelConfig::input_keys() const {
  std::vector<std::string> keys;
  for (const auto& cam : cameras) keys.push_back(cam.key);
  if (state_dim > 0) keys.push_back(state_key);
  if (env_state_dim > 0) keys.push_back(env_state_key);
  return keys;
}

NormMode ModelConfig::input_norm_mode(const std::string& key) const {
  for (const auto& [k, mode] : input_norm) {
    if (k == key) return mode;
  }
  return NormMode::kIdentity;
}

ModelConfig::Macs ModelConfig::macs() const {
  Macs m;
  const double D = dim_model, F = dim_feedforward, N = n_tokens(), T = chunk_size;
  for (const auto& cam : cameras) {
    // Walk the same layout the graph runs, counting weight uses per output pixel.
    auto out = [](int n, const ConvSpec& c) { return (n + 2 * c.pad - c.dilation * (c.kernel - 1) - 1) / c.stride + 1; };
    auto count = [&](const ConvSpec& c, int h, int w) {
      m.backbone += static_cast<double>(c.in_c) * c.out_c * c.kernel * c.kernel * h * w;
    };
    const ConvSpec st = stem();
    int h = out(cam.height, st), w = out(cam.width, st);
    count(st, h, w);
    h = ceil_half(h);
    w = ceil_half(w);
    for (const auto& stage : backbone_stages()) {
      for (const auto& block : stage) {
        int bh = h, bw = w;
        for (const auto& c : block.convs) {
          bh = out(bh, c);
          bw = out(bw, c);
          count(c, bh, bw);
        }
        if (block.has_downsample) count(block.downsample, bh, bw);
        h = bh;
        w = bw;
      }
    }
    m.projections += static_cast<double>(feature_channels()) * D * h * w;
  }
  m.projections += 32.0 * D + static_cast<double>(state_dim) * D + static_cast<double>(env_state_dim) * D;
  m.encoder = n_encoder_layers * (4 * N * D * D + 2 * N * N * D + 2 * N * D * F);
  m.decoder = n_decoder_layers * (6 * T * D * D + 2 * T * T * D + 2 * N * D * D + 2 * T * N * D + 2 * T * D * F);
  m.head = T * D * action_dim;
  return m;
}

std::string ModelConfig::summary() const {
  std::ostringstream s;
  s << backbone << (dilate_layer4 ? " (dilated layer4)" : "") << ", D " << dim_model << ", " << n_heads
    << " heads, FFN " << dim_feedforward << " " << activation_name(activation) << ", " << n_encoder_layers << "+"
    << n_decoder_layers << " layers " << (pre_norm ? "pre-norm" : "post-norm") << ", chunk " << chunk_size
    << ", " << cameras.size() << (cameras.size() == 1 ? " camera" : " cameras");
  for (const auto& cam : cameras) s << " " << cam.height << "x" << cam.width;
  s << ", state " << state_dim;
  if (env_state_dim > 0) s << ", env state " << env_state_dim;
  s << ", action " << action_dim;
  return s.str();
}

std::string ModelConfig::deployment_problem(int n_action_steps, std::optional<double> temporal_ensemble_coeff,
                                            int chunk_size) {
  if (n_action_steps < 1 || n_action_steps > chunk_size) {
    return "n_action_steps " + std::to_string(n_action_steps) + " must be in [1, chunk_size " + std::to_string(chunk_size) + "]";
  }
  if (!temporal_ensemble_coeff) return "";
  if (std::string problem = ensemble_coeff_problem(*temporal_ensemble_coeff, chunk_size); !problem.empty()) return problem;
  if (n_action_steps != 1) {
    return "temporal ensembling needs n_action_steps == 1 (LeRobot's rule), got " + std::to_string(n_action_steps);
  }
  return "";
}

std::string ModelConfig::ensemble_coeff_problem(double coeff, int chunk_size) {
  if (!std::isfinite(coeff)) return "temporal_ensemble_coeff is not finite";
  if (std::fabs(coeff) * std::max(chunk_size - 1, 0) > kMaxEnsembleExponent) {
    char text[200];
    std::snprintf(text, sizeof text,
                  "temporal_ensemble_coeff %g with chunk_size %d: the ensemble weights exp(-coeff * i) overflow "
                  "float32 (|coeff| * (chunk_size - 1) must stay <= %g)",
                  coeff, chunk_size, kMaxEnsembleExponent);
    return text;
  }
  return "";
}

std::string ModelConfig::action_names_problem(const std::vector<std::string>& names, int action_dim) {
  if (names.size() != static_cast<size_t>(action_dim)) {
    return std::to_string(names.size()) + " action names for the model's " + std::to_string(action_dim) + " action values";
  }
  for (size_t i = 0; i < names.size(); ++i) {
    const std::string& name = names[i];
    if (name.find_first_not_of(" \t") == std::string::npos) return "action name " + std::to_string(i) + " is empty";
    if (name.find_first_of(",\"\r\n") != std::string::npos) {
      return "action name '" + name + "' holds a comma, a quote or a line break (a CSV column name cannot)";
    }
    if (std::find(names.begin(), names.begin() + static_cast<std::ptrdiff_t>(i), name) != names.begin() + static_cast<std::ptrdiff_t>(i)) {
      return "action name '" + name + "' is given twice";
    }
  }
  return "";
}

void ModelConfig::validate() const {
  auto bad = [](const std::string& msg) { fail(StatusCode::kInvalidArgument, "invalid model config: " + msg); };
  if (!action_names.empty()) {
    if (const std::string problem = action_names_problem(action_names, action_dim); !problem.empty()) bad(problem);
  }
  const ResNetArchitecture* resnet = find_resnet(backbone);
  if (resnet == nullptr) {
    bad("backbone \"" + backbone + "\" is not one this engine runs (" + resnet_names() + ")");
  } else if (backbone_blocks != resnet->blocks || bottleneck != resnet->bottleneck) {
    // The blocks build the network; the name is what reports show: they must agree.
    std::string blocks;
    for (int b : backbone_blocks) {
      if (!blocks.empty()) blocks += '+';
      blocks += std::to_string(b);
    }
    bad("backbone \"" + backbone + "\" does not have " + blocks + " blocks per stage" +
        (bottleneck ? " of bottlenecks" : " of basic blocks"));
  }
  if (dilate_layer4 && !bottleneck) {
    fail(StatusCode::kUnimplemented,
         "replace_final_stride_with_dilation needs a Bottleneck ResNet (resnet50+); torchvision refuses "
         "dilation in BasicBlock (" + backbone + ")");
  }
  if (cameras.empty()) {
    fail(StatusCode::kUnimplemented, "the model has no camera (VISUAL) input; image-less ACT is not supported");
  }
  for (const auto& cam : cameras) {
    if (cam.height < 1 || cam.width < 1 || cam.height > 8192 || cam.width > 8192) {
      bad("camera " + cam.key + " has size " + std::to_string(cam.height) + "x" + std::to_string(cam.width));
    }
  }
  if (state_dim < 0 || state_dim > 65536 || env_state_dim < 0 || env_state_dim > 65536) bad("state dimension out of range");
  if (action_dim < 1 || action_dim > 65536) bad("action_dim must be positive");
  if (dim_model < 4 || dim_model > 65536) bad("dim_model " + std::to_string(dim_model));
  if (n_heads < 1 || dim_model % n_heads != 0) {
    bad("dim_model " + std::to_string(dim_model) + " is not divisible by n_heads " + std::to_string(n_heads));
  }
  if (dim_model % 4 != 0) bad("dim_model must be a multiple of 4 (2-D sinusoidal embedding)");
  if (dim_feedforward < 1 || dim_feedforward > 1 << 20) bad("dim_feedforward " + std::to_string(dim_feedforward));
  if (activation == Activation::kGlu && dim_feedforward % 2 != 0) bad("glu needs an even dim_feedforward");
  if (n_encoder_layers < 1 || n_encoder_layers > 256) bad("n_encoder_layers " + std::to_string(n_encoder_layers));
  if (n_decoder_layers < 1 || n_decoder_layers > 256) bad("n_decoder_layers " + std::to_string(n_decoder_layers));
  if (chunk_size < 1 || chunk_size > 100000) bad("chunk_size " + std::to_string(chunk_size));
  if (const std::string problem = deployment_problem(n_action_steps, temporal_ensemble_coeff, chunk_size); !problem.empty()) {
    bad(problem);
  }
}

namespace {

nlohmann::json norm_to_json(NormMode m) { return norm_mode_name(m); }

NormMode norm_from_json(const nlohmann::json& j) {
  const std::string s = j.get<std::string>();
  if (s == "IDENTITY") return NormMode::kIdentity;
  if (s == "MEAN_STD") return NormMode::kMeanStd;
  if (s == "MIN_MAX") return NormMode::kMinMax;
  fail(StatusCode::kDataLoss, "unknown normalisation mode '" + s + "'");
}

Activation activation_from_string(const std::string& s) {
  if (s == "relu") return Activation::kRelu;
  if (s == "gelu") return Activation::kGelu;
  if (s == "glu") return Activation::kGlu;
  fail(StatusCode::kDataLoss, "unknown activation '" + s + "'");
}

// A precision this build cannot run is kUnimplemented (a newer converter's blob), not data loss.
Precision precision_from_string(const std::string& s) {
  if (s == "fp32") return Precision::kFp32;
  if (s == "int8") return Precision::kInt8;
  fail(StatusCode::kUnimplemented, "model config: precision '" + s + "' is not supported by this build (fp32, int8)");
}

}  // namespace

nlohmann::json ModelConfig::to_json() const {
  nlohmann::json j;
  j["backbone"] = backbone;
  j["backbone_blocks"] = backbone_blocks;
  j["bottleneck"] = bottleneck;
  j["dilate_layer4"] = dilate_layer4;
  j["cameras"] = nlohmann::json::array();
  for (const auto& cam : cameras) j["cameras"].push_back({{"key", cam.key}, {"height", cam.height}, {"width", cam.width}});
  j["state_key"] = state_key;
  j["state_dim"] = state_dim;
  j["env_state_key"] = env_state_key;
  j["env_state_dim"] = env_state_dim;
  j["action_dim"] = action_dim;
  if (!action_names.empty()) j["action_names"] = action_names;
  j["dim_model"] = dim_model;
  j["n_heads"] = n_heads;
  j["dim_feedforward"] = dim_feedforward;
  j["activation"] = activation_name(activation);
  j["n_encoder_layers"] = n_encoder_layers;
  j["n_decoder_layers"] = n_decoder_layers;
  j["pre_norm"] = pre_norm;
  j["chunk_size"] = chunk_size;
  j["n_action_steps"] = n_action_steps;
  j["temporal_ensemble_coeff"] = temporal_ensemble_coeff ? nlohmann::json(*temporal_ensemble_coeff) : nlohmann::json();
  j["input_norm"] = nlohmann::json::array();
  for (const auto& [key, mode] : input_norm) j["input_norm"].push_back({{"key", key}, {"mode", norm_to_json(mode)}});
  j["action_norm"] = norm_to_json(action_norm);
  j["precision"] = precision_name(precision);
  return j;
}

namespace {

// Every input feature has exactly one input_norm entry, and every entry is an input feature.
void check_input_norm(const ModelConfig& c) {
  const std::vector<std::string> keys = c.input_keys();
  std::vector<std::string> seen;
  for (const auto& [key, mode] : c.input_norm) {
    const std::string entry = "model config in blob: \"input_norm\" entry \"" + key + "\" ";
    if (std::find(keys.begin(), keys.end(), key) == keys.end()) fail(StatusCode::kDataLoss, entry + "is no input feature of the model");
    if (std::find(seen.begin(), seen.end(), key) != seen.end()) fail(StatusCode::kDataLoss, entry + "appears twice");
    seen.push_back(key);
  }
  for (const std::string& key : keys) {
    if (std::find(seen.begin(), seen.end(), key) == seen.end()) {
      fail(StatusCode::kDataLoss, "model config in blob: \"input_norm\" has no entry for the input feature \"" + key +
           "\" (its normalisation would be skipped)");
    }
  }
}

// The blob's integers are range-checked before narrowing (a float or a too-large integer made int is
// undefined or wraps silently).
int int_field(const nlohmann::json& j, const std::string& key) {
  int32_t v = 0;
  if (!detail::json_to_i32(j.at(key), &v)) {
    fail(StatusCode::kDataLoss, "malformed model config in blob: \"" + key + "\" must be a 32-bit integer");
  }
  return v;
}

}  // namespace

ModelConfig ModelConfig::from_json(const nlohmann::json& j) {
  ModelConfig c;
  try {
    c.backbone = j.at("backbone").get<std::string>();
    for (const auto& blocks : j.at("backbone_blocks")) {
      int32_t v = 0;
      if (!detail::json_to_i32(blocks, &v)) fail(StatusCode::kDataLoss, "malformed model config in blob: bad backbone_blocks");
      c.backbone_blocks.push_back(v);
    }
    c.bottleneck = j.at("bottleneck").get<bool>();
    c.dilate_layer4 = j.at("dilate_layer4").get<bool>();
    for (const auto& cam : j.at("cameras")) {
      c.cameras.push_back({cam.at("key").get<std::string>(), int_field(cam, "height"), int_field(cam, "width")});
    }
    c.state_key = j.at("state_key").get<std::string>();
    c.state_dim = int_field(j, "state_dim");
    c.env_state_key = j.at("env_state_key").get<std::string>();
    c.env_state_dim = int_field(j, "env_state_dim");
    c.action_dim = int_field(j, "action_dim");
    if (j.contains("action_names")) c.action_names = j.at("action_names").get<std::vector<std::string>>();
    c.dim_model = int_field(j, "dim_model");
    c.n_heads = int_field(j, "n_heads");
    c.dim_feedforward = int_field(j, "dim_feedforward");
    c.activation = activation_from_string(j.at("activation").get<std::string>());
    c.n_encoder_layers = int_field(j, "n_encoder_layers");
    c.n_decoder_layers = int_field(j, "n_decoder_layers");
    c.pre_norm = j.at("pre_norm").get<bool>();
    c.chunk_size = int_field(j, "chunk_size");
    c.n_action_steps = int_field(j, "n_action_steps");
    if (!j.at("temporal_ensemble_coeff").is_null()) c.temporal_ensemble_coeff = j.at("temporal_ensemble_coeff").get<double>();
    const nlohmann::json& input_norm = j.at("input_norm");
    if (!input_norm.is_array()) fail(StatusCode::kDataLoss, "malformed model config in blob: \"input_norm\" must be an array");
    for (const auto& e : input_norm) c.input_norm.emplace_back(e.at("key").get<std::string>(), norm_from_json(e.at("mode")));
    c.action_norm = norm_from_json(j.at("action_norm"));
    c.precision = precision_from_string(j.at("precision").get<std::string>());
  } catch (const nlohmann::json::exception& e) {
    fail(StatusCode::kDataLoss, std::string("malformed model config in blob: ") + e.what());
  }
  c.validate();
  check_input_norm(c);
  return c;
}

}  // namespace act
