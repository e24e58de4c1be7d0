// ModelConfig: every fact about an ACT model that changes the computation. One struct, read from a
// LeRobot config.json at import and stored in (and read back from) the .actb blob's header. Shapes
// elsewhere are derived from it, never re-typed.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace act {

enum class Activation { kRelu, kGelu, kGlu };
enum class NormMode { kIdentity, kMeanStd, kMinMax };
/// The precision of a blob's weights: all float, or int8 layers (with a "quantization" section).
enum class Precision { kFp32, kInt8 };

const char* activation_name(Activation a);
const char* norm_mode_name(NormMode m);
/// "fp32" or "int8", the blob config's spelling.
const char* precision_name(Precision p);

struct CameraConfig {
  std::string key;  ///< e.g. "observation.images.front"
  int height = 0;
  int width = 0;
};

/// How one feature is (un)normalised. The statistics themselves are tensors in the blob:
/// "norm.<key>.sub" / "norm.<key>.div" for inputs:  y = (x - sub) / div * mul + add
/// (MEAN_STD: sub = mean, div = std + eps, mul 1, add 0; MIN_MAX: sub = min, div = range, mul 2, add -1)
/// and "unnorm.action.scale" / "unnorm.action.offset" / "unnorm.action.shift":
/// x = (y + shift) * scale + offset (MEAN_STD: 0, std, mean; MIN_MAX: 1, range / 2, min).
struct FeatureNorm {
  NormMode mode = NormMode::kIdentity;
};

/// One convolution of the backbone (BatchNorm folded in, so it has a bias).
struct ConvSpec {
  std::string name;  ///< torchvision path without "model.backbone.", e.g. "layer2.0.conv1"
  std::string bn;    ///< its BatchNorm path, e.g. "layer2.0.bn1"
  int in_c = 0, out_c = 0, kernel = 1, stride = 1, pad = 0, dilation = 1;
};

/// A residual block: convs[0..n) in sequence (ReLU after all but the last), plus an optional
/// downsample conv on the shortcut; out = ReLU(last conv + shortcut).
struct BlockSpec {
  std::vector<ConvSpec> convs;
  bool has_downsample = false;
  ConvSpec downsample;
};

/// A torchvision ResNet this engine runs: its name, blocks per stage and block type.
struct ResNetArchitecture {
  const char* name;
  std::vector<int> blocks;
  bool bottleneck;
};
/// Every backbone this engine runs (resnet18 ... resnet152): the one list the importer, the
/// config inference and the blob's checks share.
const std::vector<ResNetArchitecture>& resnet_architectures();
/// The architecture called `name`, or null.
const ResNetArchitecture* find_resnet(const std::string& name);
/// "resnet18, resnet34, resnet50, resnet101, resnet152", for messages.
std::string resnet_names();

struct ModelConfig {
  // Backbone.
  std::string backbone = "resnet18";    ///< resnet18/34/50/101/152
  std::vector<int> backbone_blocks;     ///< blocks per stage, e.g. {2,2,2,2}
  bool bottleneck = false;              ///< resnet50+: Bottleneck blocks (feature map 2048 channels)
  bool dilate_layer4 = false;           ///< replace_final_stride_with_dilation
  // Inputs / outputs, in token order.
  std::vector<CameraConfig> cameras;
  std::string state_key = "observation.state";
  int state_dim = 0;  ///< 0 = no robot state
  std::string env_state_key;
  int env_state_dim = 0;  ///< 0 = no environment state
  int action_dim = 0;
  /// The action dimensions' names (e.g. "steering", "throttle"; act_convert --action-names), for
  /// reports and recordings: empty (a blob from before they were stored, or none given) or one per
  /// action value. Stored in the blob only when given, so older engines read the blob unchanged.
  std::vector<std::string> action_names;
  // Transformer.
  int dim_model = 512;
  int n_heads = 8;
  int dim_feedforward = 3200;
  Activation activation = Activation::kRelu;
  int n_encoder_layers = 4;
  int n_decoder_layers = 1;
  bool pre_norm = false;
  // Chunking.
  int chunk_size = 100;
  int n_action_steps = 100;
  std::optional<double> temporal_ensemble_coeff;
  // Normalisation mode per input feature key (cameras, state, env) and for the action.
  std::vector<std::pair<std::string, NormMode>> input_norm;
  NormMode action_norm = NormMode::kIdentity;
  // Weights.
  Precision precision = Precision::kFp32;

  // Derived facts.
  /// The stem conv (7x7/2) and then, stage by stage, every residual block of the backbone.
  ConvSpec stem() const;
  std::vector<std::vector<BlockSpec>> backbone_stages() const;
  int head_dim() const { return dim_model / n_heads; }
  int feature_channels() const { return bottleneck ? 2048 : 512; }
  /// Feature-map size of a camera: ceil(H/32) x ceil(W/32), or /16 when layer4 is dilated.
  int feature_height(const CameraConfig& cam) const;
  int feature_width(const CameraConfig& cam) const;
  /// 1 (latent) + state? + env?
  int n_1d_tokens() const { return 1 + (state_dim > 0) + (env_state_dim > 0); }
  int n_tokens() const;  ///< encoder sequence length
  NormMode input_norm_mode(const std::string& key) const;
  /// Multiply-accumulates of one inference, by the formula of the spec (§8), split by stage.
  struct Macs {
    double backbone = 0, projections = 0, encoder = 0, decoder = 0, head = 0;
    double total() const { return backbone + projections + encoder + decoder + head; }
  };
  Macs macs() const;
  /// "resnet18, D 512, 8 heads, FFN 3200 relu, 4+1 layers post-norm, chunk 100, 1 camera 480x640, state 6, action 6"
  std::string summary() const;

  /// Largest |temporal_ensemble_coeff| * (chunk_size - 1): beyond it LeRobot's ensemble weights
  /// exp(-coeff * i) overflow float32 (at 88.7) and every ensembled action becomes NaN.
  static constexpr double kMaxEnsembleExponent = 80.0;
  /// Why `coeff` cannot weight a chunk of `chunk_size` rows, or "" when it can (finite, and within
  /// kMaxEnsembleExponent). One rule for the blob, the importer and the chunk scheduler.
  static std::string ensemble_coeff_problem(double coeff, int chunk_size);
  /// Why these deployment choices do not fit a chunk of `chunk_size` rows (LeRobot's ACTConfig rules:
  /// 1 <= n_action_steps <= chunk_size, ensembling needs n_action_steps == 1, ensemble_coeff_problem),
  /// or "" when they do.
  static std::string deployment_problem(int n_action_steps, std::optional<double> temporal_ensemble_coeff, int chunk_size);

  /// Why `names` cannot name `action_dim` action values (their count, an empty or repeated name, a
  /// comma, quote or line break, which a CSV header cannot hold), or "" when they can.
  static std::string action_names_problem(const std::vector<std::string>& names, int action_dim);

  /// Checks every invariant (a known backbone whose blocks match its name, positive dims, D % n_heads,
  /// D % 4, n_action_steps <= chunk_size, ensembling needs n_action_steps == 1, ...). Throws
  /// act::Error(kInvalidArgument / kUnimplemented).
  void validate() const;
  nlohmann::json to_json() const;
  /// The input feature keys, in token order: each camera's, then the state's and the environment
  /// state's when the model takes them.
  std::vector<std::string> input_keys() const;
  /// Parses and validates (input_norm must name every input feature once, and nothing else: a
  /// feature without an entry would silently go unnormalised); throws act::Error(kDataLoss) naming
  /// the missing or malformed field.
  static ModelConfig from_json(const nlohmann::json& j);
};

}  // namespace act
