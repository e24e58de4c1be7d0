#include "weights/import/synthetic_model.h"

#include <cmath>
#include <random>

#include "actengine/status.h"

namespace act {

namespace {

// Platform-independent random numbers: mt19937's output is fixed by the standard; the
// distributions of <random> are not, so the transforms are ours.
class Random {
 public:
  explicit Random(uint32_t seed) : engine_(seed) {}
  double uniform(double lo, double hi) { return lo + (hi - lo) * (engine_() / 4294967296.0); }
  double normal() {  // Box-Muller
    const double u1 = (engine_() + 1.0) / 4294967297.0, u2 = engine_() / 4294967296.0;
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
  }
  std::vector<float> normal(size_t n, double stddev, double mean = 0.0) {
    std::vector<float> v(n);
    for (auto& x : v) x = static_cast<float>(mean + stddev * normal());
    return v;
  }
  std::vector<float> uniform(size_t n, double lo, double hi) {
    std::vector<float> v(n);
    for (auto& x : v) x = static_cast<float>(uniform(lo, hi));
    return v;
  }

 private:
  std::mt19937 engine_;
};

// "HxW" (height first, as the cameras' [3, H, W] shapes) with 1-5 digits each.
bool parse_size(const std::string& s, int* height, int* width) {
  const size_t x = s.find('x');
  auto digits = [](const std::string& part) {
    return !part.empty() && part.size() <= 5 && part.find_first_not_of("0123456789") == std::string::npos;
  };
  if (x == std::string::npos || !digits(s.substr(0, x)) || !digits(s.substr(x + 1))) return false;
  *height = std::stoi(s.substr(0, x));
  *width = std::stoi(s.substr(x + 1));
  return true;
}

size_t count(const std::vector<int64_t>& shape) { return static_cast<size_t>(shape_elements(shape)); }

}  // namespace

nlohmann::ordered_json synthetic_config(const std::string& name) {
  int height = 480, width = 640, state = 6, action = 6;
  if (name == "default") {
  } else if (name == "rover") {
    height = 360;
    state = action = 2;
  } else if (parse_size(name, &height, &width)) {
    if (width < 32 || height < 32 || width > 4096 || height > 4096) {
      fail(StatusCode::kInvalidArgument, "built-in model size " + name + " (height x width): both must be in [32, 4096]");
    }
  } else {
    fail(StatusCode::kInvalidArgument, "unknown built-in model \"" + name + "\" (default, rover, or HxW such as 480x640: height first)");
  }
  nlohmann::ordered_json c;
  c["type"] = "act";
  c["n_obs_steps"] = 1;
  c["normalization_mapping"] = {{"VISUAL", "MEAN_STD"}, {"STATE", "MEAN_STD"}, {"ACTION", "MEAN_STD"}};
  c["input_features"] = {{"observation.images.front", {{"type", "VISUAL"}, {"shape", {3, height, width}}}},
                         {"observation.state", {{"type", "STATE"}, {"shape", {state}}}}};
  c["output_features"] = {{"action", {{"type", "ACTION"}, {"shape", {action}}}}};
  c["chunk_size"] = 100;
  c["n_action_steps"] = 100;
  c["vision_backbone"] = "resnet18";
  c["replace_final_stride_with_dilation"] = false;
  c["pre_norm"] = false;
  c["dim_model"] = 512;
  c["n_heads"] = 8;
  c["dim_feedforward"] = 3200;
  c["feedforward_activation"] = "relu";
  c["n_encoder_layers"] = 4;
  c["n_decoder_layers"] = 1;
  c["use_vae"] = false;
  c["latent_dim"] = 32;
  c["temporal_ensemble_coeff"] = nullptr;
  return c;
}

namespace {

// Writes a random state dict of LeRobot's layout for `m`, tensor by tensor, from one random
// stream: the order of the calls fixes every value.
class SyntheticStateDict {
 public:
  SyntheticStateDict(const ModelConfig& m, OwnedTensorSet& dict, Random& rng) : m_(m), dict_(dict), rng_(rng) {}

  // Every convolution with its FrozenBatchNorm.
  void add_backbone() {
    conv_bn(m_.stem(), false);
    for (const auto& stage : m_.backbone_stages()) {
      for (const auto& block : stage) {
        for (size_t i = 0; i < block.convs.size(); ++i) conv_bn(block.convs[i], i + 1 == block.convs.size());
        if (block.has_downsample) conv_bn(block.downsample, true);
      }
    }
  }

  // Encoder and decoder layers, then the input projections, positions and the action head.
  void add_transformer(int latent) {
    const int D = m_.dim_model, T = m_.chunk_size;
    for (int l = 0; l < m_.n_encoder_layers; ++l) {
      const std::string e = p_ + "encoder.layers." + std::to_string(l) + ".";
      attention(e + "self_attn");
      ffn(e);
      norm(e + "norm1");
      norm(e + "norm2");
    }
    if (m_.pre_norm) norm(p_ + "encoder.norm");
    for (int l = 0; l < m_.n_decoder_layers; ++l) {
      const std::string d = p_ + "decoder.layers." + std::to_string(l) + ".";
      attention(d + "self_attn");
      attention(d + "multihead_attn");
      ffn(d);
      norm(d + "norm1");
      norm(d + "norm2");
      norm(d + "norm3");
    }
    norm(p_ + "decoder.norm");
    linear(p_ + "encoder_latent_input_proj", D, latent);
    if (m_.state_dim > 0) linear(p_ + "encoder_robot_state_input_proj", D, m_.state_dim);
    if (m_.env_state_dim > 0) linear(p_ + "encoder_env_state_input_proj", D, m_.env_state_dim);
    add(p_ + "encoder_img_feat_input_proj.weight", {D, m_.feature_channels(), 1, 1}, xavier(D, m_.feature_channels()));
    add(p_ + "encoder_img_feat_input_proj.bias", {D}, rng_.uniform(static_cast<size_t>(D), -0.1, 0.1));
    add(p_ + "encoder_1d_feature_pos_embed.weight", {m_.n_1d_tokens(), D},
        rng_.normal(static_cast<size_t>(m_.n_1d_tokens()) * D, 1.0));
    add(p_ + "decoder_pos_embed.weight", {T, D}, rng_.normal(static_cast<size_t>(T) * D, 1.0));
    linear(p_ + "action_head", m_.action_dim, D);
  }

  // Normalisation buffers (legacy layout): ImageNet statistics for images, dataset-like ones for
  // state and action.
  void add_normalisation() {
    for (const auto& cam : m_.cameras) {
      std::string flat = cam.key;
      for (char& ch : flat) {
        if (ch == '.') ch = '_';
      }
      add("normalize_inputs.buffer_" + flat + ".mean", {3, 1, 1}, {0.485f, 0.456f, 0.406f});
      add("normalize_inputs.buffer_" + flat + ".std", {3, 1, 1}, {0.229f, 0.224f, 0.225f});
    }
    const size_t state = static_cast<size_t>(m_.state_dim), action = static_cast<size_t>(m_.action_dim);
    if (m_.state_dim > 0) {
      add("normalize_inputs.buffer_observation_state.mean", {m_.state_dim}, rng_.normal(state, 1.0));
      add("normalize_inputs.buffer_observation_state.std", {m_.state_dim}, rng_.uniform(state, 0.5, 2.0));
    }
    add("unnormalize_outputs.buffer_action.mean", {m_.action_dim}, rng_.normal(action, 1.0));
    add("unnormalize_outputs.buffer_action.std", {m_.action_dim}, rng_.uniform(action, 0.5, 2.0));
  }

 private:
  void add(const std::string& name, std::vector<int64_t> shape, std::vector<float> v) {
    dict_.add_f32(name, std::move(shape), std::move(v));
  }
  void conv_bn(const ConvSpec& c, bool residual_branch_end) {
    const std::vector<int64_t> shape = {c.out_c, c.in_c, c.kernel, c.kernel};
    add(p_ + "backbone." + c.name + ".weight", shape,
        rng_.normal(count(shape), std::sqrt(2.0 / (c.in_c * c.kernel * c.kernel))));
    const std::string bn = p_ + "backbone." + c.bn + ".";
    const size_t n = static_cast<size_t>(c.out_c);
    // Damping the end of each residual branch keeps the residual stream from growing block by block.
    add(bn + "weight", {c.out_c}, residual_branch_end ? rng_.uniform(n, 0.2, 0.4) : rng_.uniform(n, 0.7, 1.1));
    add(bn + "bias", {c.out_c}, rng_.uniform(n, -0.1, 0.1));
    add(bn + "running_mean", {c.out_c}, rng_.normal(n, 0.1));
    add(bn + "running_var", {c.out_c}, rng_.uniform(n, 0.8, 1.2));
  }
  std::vector<float> xavier(int out, int in) {
    const double a = std::sqrt(6.0 / (in + out));
    return rng_.uniform(static_cast<size_t>(out) * in, -a, a);
  }
  void linear(const std::string& name, int out, int in) {
    add(name + ".weight", {out, in}, xavier(out, in));
    add(name + ".bias", {out}, rng_.uniform(static_cast<size_t>(out), -0.1, 0.1));
  }
  void norm(const std::string& name) {
    const int D = m_.dim_model;
    add(name + ".weight", {D}, rng_.uniform(static_cast<size_t>(D), 0.8, 1.2));
    add(name + ".bias", {D}, rng_.uniform(static_cast<size_t>(D), -0.1, 0.1));
  }
  void attention(const std::string& name) {
    const int D = m_.dim_model;
    add(name + ".in_proj_weight", {3 * D, D}, xavier(3 * D, D));
    add(name + ".in_proj_bias", {3 * D}, rng_.uniform(3 * static_cast<size_t>(D), -0.1, 0.1));
    linear(name + ".out_proj", D, D);
  }
  void ffn(const std::string& prefix) {
    const int D = m_.dim_model, F = m_.dim_feedforward;
    linear(prefix + "linear1", F, D);
    linear(prefix + "linear2", D, m_.activation == Activation::kGlu ? F / 2 : F);
  }

  const ModelConfig& m_;
  OwnedTensorSet& dict_;
  Random& rng_;
  const std::string p_ = "model.";
};

}  // namespace

OwnedTensorSet synthetic_state_dict(const nlohmann::ordered_json& config, uint32_t seed) {
  const ModelConfig m = lerobot_model_config(config, "built-in model config");
  OwnedTensorSet dict("built-in synthetic model");
  Random rng(seed);
  SyntheticStateDict writer(m, dict, rng);
  writer.add_backbone();
  writer.add_transformer(config.value("latent_dim", 32));
  writer.add_normalisation();
  return dict;
}

ImportedModel make_synthetic_model(const std::string& name, uint32_t seed) {
  const nlohmann::ordered_json config = synthetic_config(name);
  const OwnedTensorSet dict = synthetic_state_dict(config, seed);
  return import_lerobot_state_dict(config, dict);
}

}  // namespace act
