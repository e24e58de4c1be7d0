// The ACT network (spec §4) built as a graph of ops from a ModelConfig and the tensors of an .actb
// blob. Inputs are normalised: one NHWC float image per camera, the state vectors. Output: the
// normalised action chunk [chunk_size, action_dim]. Weight pointers point into the blob's mapping.
//
// Each layer runs in the precision of its weights in the blob: FP32 ops for float tensors, INT8
// ops (ops_int8.h) for int8 ones, with the blob's QuantConfig saying how activations are
// quantized. Quantize/dequantize ops are inserted where a value crosses between the two.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "graph/graph.h"
#include "graph/ops_fp32.h"
#include "graph/ops_int8.h"
#include "weights/blob/actb.h"
#include "weights/blob/blob_tensors.h"
#include "weights/blob/model_config.h"
#include "weights/blob/quant_config.h"

namespace act::graph {

/// What a calibration point is: the value's place in a camera branch.
enum class CalibrationRole {
  kCameraImage,      ///< the normalised input image (its range is known exactly: never clipped)
  kConvOutput,       ///< a backbone conv (after its fused residual and ReLU)
  kMaxPoolOutput,    ///< the stem's max pool
  kImageProjection,  ///< the 1x1 projection of the backbone features to tokens
  kLinearInput,      ///< a transformer matrix that int8 linears read as codes (per tensor if chosen)
};

/// A float value whose range a static INT8 blob may record: every value of the camera branches
/// (all recorded), and the transformer's linear inputs (recorded for those the converter chooses
/// per-tensor codes for; the others stay per token). Its parameters are stored in the blob's
/// quantization section under the value's name (quant_config.h), which is where the builder of
/// the INT8 network looks them up.
struct CalibrationPoint {
  CalibrationRole role;
  size_t camera;       ///< camera branches only
  ValueId value;
  std::string reader;  ///< linear inputs: the weight of the first linear that reads the value
  /// Linear inputs: the FFN (0, 1, ... in graph order) whose hidden activation this is, when its
  /// hidden layer can requantize in its GEMM into per-tensor codes of it (what per tensor buys in
  /// speed); -1 for the other inputs (per tensor would only save finding each row's range there).
  int ffn = -1;
};

/// A layer's op and output, for the accuracy report: every conv and linear layer, and the max pool
/// when it computes in int8. `weight` names the layer as the blob does (its weight tensor, e.g.
/// "backbone.layer1.0.conv1.weight": the name of QuantConfig::float_layers and --keep-float); empty
/// for the max pool, which has none.
struct NetworkLayer {
  const Op* op;
  ValueId output;
  std::string weight;
  bool int8;
};

class ActNetwork {
 public:
  /// Builds the graph from `tensors` (of a blob whose config blob_model_config checked; every tensor
  /// the network uses is read through it) for the kernels of `kernels` (int8 weights are packed for
  /// its gemm_s8 variant). Both must outlive the network. Throws act::Error(kDataLoss) when a blob
  /// tensor is missing or has a shape that does not match the config, or when activation parameters
  /// name no value of the network.
  /// With `external_backbone` the cameras' backbones are not built: each camera's input is its
  /// backbone output, [feature_height * feature_width, dim_model] (camera_input), and the blob's
  /// backbone and image projection weights are left unused.
  /// With `packed_weights_from` (a network that need only live while this one is built), the float
  /// weights it packed under a name are shared, not packed again, where this blob's tensor of that
  /// name has their shape and this network's gemm_f32 reads their panels. The caller vouches that
  /// both blobs hold the same values under that name: the INT8 converter's trial engines, whose
  /// scratch blobs are all written from one imported model as its FP32 engine's blob is (a mixed
  /// search opens one per layer, each of which packed every float layer again).
  ActNetwork(const ModelConfig& config, BlobTensors& tensors, const kernels::KernelConfig& kernels,
             bool external_backbone = false, const ActNetwork* packed_weights_from = nullptr);

  void plan(int threads, bool keep_all_values) { graph_.plan(threads, keep_all_values); }
  void run(ThreadPool& pool, RunProfile* profile = nullptr) { graph_.run(pool, kernels_, profile); }

  /// [H, W, 3] float; with an external backbone [h * w, dim_model]. Null when the camera's input is
  /// int8 (camera_input_s8).
  float* camera_input(size_t camera);
  /// A static INT8 stem takes its [H, W, 3] image as int8 codes with the calibrated parameters of
  /// camera_input_quant(), which the engine writes straight from the pixels (normalisation and
  /// quantization in one table lookup, no float image); null when the input is float. Stored
  /// unsigned (each code XOR 0x80, DataType::kU8) when camera_input_unsigned().
  int8_t* camera_input_s8(size_t camera);
  bool camera_input_unsigned(size_t camera) const;
  kernels::QuantS8 camera_input_quant(size_t camera) const;
  float* state_input() { return graph_.data(state_input_); }                          ///< [state_dim]
  float* env_state_input() { return graph_.data(env_input_); }                        ///< [env_state_dim]
  const float* actions_normalized() { return graph_.data(actions_); }                 ///< [T, A]

  Graph& graph() { return graph_; }
  const ModelConfig& config() const { return config_; }
  /// The float values calibration observes, in graph order (CalibrationPoint). It reads them from an
  /// FP32 network, where every value is float.
  const std::vector<CalibrationPoint>& calibration_points() const { return calibration_points_; }
  /// The conv and linear layers (and the int8 max pool), in graph order.
  const std::vector<NetworkLayer>& layers() const { return layers_; }
  /// The float weights this network packed or shared, by blob tensor name.
  const std::map<std::string, std::shared_ptr<const PackedF32Weights>>& packed_weights() const { return packed_weights_; }

 private:
  /// A backbone value as the builder tracks it: float, or int8 with static or run-time parameters.
  struct Tensor {
    ValueId id = kNoValue;
    bool s8 = false;
    kernels::QuantS8 q;             ///< static parameters of an int8 value
    ValueId params = kNoValue;      ///< run-time parameters of an int8 value (dynamic mode)
  };
  const float* weight(const std::string& name, const std::vector<int64_t>& shape);
  /// The tensor, checked against the shape, when it is int8 (per-channel scales along axis 0); else null.
  const ActbTensor* int8_weight(const std::string& name, const std::vector<int64_t>& shape);
  /// The float tensor `name` (of `shape`, [n, ...]) packed as an [n x rest] GEMM operand, once per
  /// network (or shared from packed_weights_from); its pages in the blob are released then.
  std::shared_ptr<const PackedF32Weights> packed_weight(const std::string& name, const std::vector<int64_t>& shape);
  /// A per-token bias table: from the blob, or rebuilt from its bias vector (blob_names.h).
  const float* bias_table(const std::string& table, int rows, int width, const std::string& weight_name, int pos_cols);
  Tensor as_f32(const Tensor& t);
  /// Static int8 (quantizing a float value with the parameters calibrated for it).
  Tensor as_s8(const Tensor& t);
  /// Dynamically quantized int8 (symmetric, per tensor, computed at run time).
  Tensor as_dynamic_s8(const Tensor& t);
  Tensor conv(const ConvSpec& c, const Tensor& x, int& h, int& w, bool relu, const Tensor* residual, const std::string& name);
  /// Appends an op to the graph, named and tagged with the stage being built.
  void add(std::unique_ptr<Op> op, const std::string& name);
  /// add() for a layer's op (recorded in layers_): `weight` its weight tensor ("" for the max pool).
  void add_layer(std::unique_ptr<Op> op, const std::string& name, ValueId output, const std::string& weight, bool int8);
  /// Records a float value of camera `camera_` (the branch being built) as a calibration point.
  void calibration_point(CalibrationRole role, ValueId value);
  /// Camera `camera`'s backbone and input projection, whose output is rows [first_row, first_row +
  /// h * w) of the encoder's input tokens (a row view: written in place).
  ValueId backbone(size_t camera, int first_row);
  /// backbone()'s steps: the camera's input (float, or int8 codes for a static int8 stem); the
  /// stem with its fused max-pool; the residual stages; the projection to tokens. h and w follow
  /// the feature map.
  Tensor camera_image(size_t camera);
  Tensor stem_and_max_pool(const std::string& p, const Tensor& image, int& h, int& w);
  Tensor residual_stages(const std::string& p, Tensor x, int& h, int& w);
  ValueId image_projection(const std::string& p, const Tensor& x, int h, int w, int first_row);
  /// The input that takes an external backbone's output for `camera` (its tokens, [h * w, D]).
  ValueId external_features(size_t camera);
  /// [LayerNorm1 (pre-norm)] -> fused qkv projection -> attention -> out projection + residual x
  /// [-> LayerNorm1 (post-norm)]. Weights under `w` ("in_proj.*", "out_proj.*", "norm1.*").
  ValueId self_attention_block(const std::string& prefix, int rows, ValueId x, const std::string& w);
  ValueId encoder_layer(int layer, ValueId x);
  ValueId decoder_layer(int layer, ValueId y, ValueId memory);
  ValueId ffn(const std::string& prefix, int rows, ValueId x, ValueId residual, const std::string& out_name);
  /// Tags the calibration point of an FFN's hidden activation h with the next FFN number (CalibrationPoint::ffn).
  void tag_ffn_hidden(ValueId h);
  /// Records a linear's whole input value as a calibration point (once).
  void note_linear_input(const MatrixRef& x, int rows, int in, const std::string& weight_name);
  /// `output`: the [rows, out] value to write (a row view), else a new one named out_name.
  ValueId linear(const std::string& out_name, int rows, int in, int out, MatrixRef x, const std::string& weight_name,
                 MatrixRef bias, MatrixRef residual = {}, Epilogue epilogue = Epilogue::kNone, ValueId output = kNoValue);
  ValueId layernorm(const std::string& out_name, int rows, ValueId x, const std::string& weight_prefix);
  /// Values for the row codes of a [rows, cols] matrix, named `name`_s8, _scale, _zero_point; per
  /// tensor (`fixed`), the codes alone.
  RowCodes add_row_codes(std::string name, int rows, int cols, std::optional<kernels::QuantS8> fixed);
  /// x as a whole [rows, cols] value (no column offset, no other width), or kNoValue.
  ValueId whole_value(const MatrixRef& x, int rows, int cols) const;
  /// The calibrated per-tensor parameters of a linear's input x, when the blob has them; none: per token.
  std::optional<kernels::QuantS8> linear_input_quant(const MatrixRef& x, int rows, int cols) const;
  /// The row codes of x written by the op that produces it (asked of it on first use), when x is a
  /// whole [rows, cols] value of such an op; else none.
  RowCodes producer_row_codes(const MatrixRef& x, int rows, int cols);
  ValueId attention(const std::string& out_name, int nq, int nk, MatrixRef q, MatrixRef k, MatrixRef v);

  ModelConfig config_;
  BlobTensors& tensors_;
  const kernels::KernelConfig& kernels_;
  QuantConfig quant_;  // empty for an FP32 network
  std::map<ValueId, Tensor> converted_;  // float <-> int8 conversions already in the graph
  std::map<ValueId, RowCodesWriter*> row_codes_writers_;  // ops that can write their output's row codes
  std::map<ValueId, RowCodes> row_codes_;                 // row codes already asked for, by value
  std::vector<AlignedBuffer> owned_tables_;  // the bias tables the ops read
  std::map<std::string, std::shared_ptr<const PackedF32Weights>> packed_weights_;  // by blob tensor name
  const ActNetwork* packed_weights_from_ = nullptr;  // while the constructor runs
  Graph graph_;
  ValueId encoder_tokens_ = kNoValue;  // the encoder's input [N, D]: latent, state rows, image features
  std::vector<ValueId> camera_inputs_;
  ValueId state_input_ = kNoValue;
  ValueId env_input_ = kNoValue;
  ValueId actions_ = kNoValue;
  Stage stage_ = Stage::kOther;  // the stage the builder is in (state tokens count as "other")
  size_t camera_ = 0;            // the camera branch being built (backbone stage)
  std::vector<CalibrationPoint> calibration_points_;
  std::vector<NetworkLayer> layers_;
};

}  // namespace act::graph
