// The ONNX export: the Engine's graph (graph/act_network.h) translated op by op into ONNX nodes with
// Debian's libonnx protobuf classes, checked by onnx::checker and strict shape inference, then written
// atomically. Layouts: the engine's image values are NHWC [H, W, C], ONNX's are NCHW [1, C, H, W];
// token values are [rows, cols] in both.
#include <onnx/checker.h>
#include <onnx/onnx_pb.h>
#include <onnx/shape_inference/implementation.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include "actengine/onnx_export.h"
#include "actengine/status.h"
#include "engine/src/engine_impl.h"
#include "graph/act_network.h"
#include "kernels/config/kernel_config.h"
#include "weights/blob/actb.h"
#include "weights/blob/blob_names.h"
#include "weights/blob/blob_tensors.h"
#include "weights/blob/file_util.h"
#include "weights/blob/model_config.h"

namespace act {

namespace {

namespace bn = blob_names;
using graph::MatrixRef;
using graph::ValueId;

constexpr int kOpset = 17;

// A network value as the ONNX graph holds it.
struct OnnxValue {
  std::string name;
  bool nchw = false;                     // an image value [1, C, H, W] (engine: [H, W, C])
  std::optional<kernels::QuantS8> int8;  // an int8 tensor with these parameters (QDQ)
};

class OnnxBuilder {
 public:
  OnnxBuilder(graph::ActNetwork& network, BlobTensors& tensors, const OnnxExportOptions& options)
      : g_(network.graph()), config_(network.config()), tensors_(tensors), options_(options) {
    model_.set_ir_version(8);  // ONNX 1.12's IR; opset 17 needs IR >= 8
    model_.set_producer_name("actengine");
    model_.set_producer_version(version());
    auto* opset = model_.add_opset_import();
    opset->set_domain("");
    opset->set_version(kOpset);
    graph_ = model_.mutable_graph();
    graph_->set_name(options.part == OnnxPart::kFull ? "act_policy" : "act_backbone");
  }

  onnx::ModelProto build() {
    const bool full = options_.part == OnnxPart::kFull;
    for (size_t c = 0; c < config_.cameras.size(); ++c) add_camera_input(c);
    if (full && config_.state_dim > 0) add_vector_input(config_.state_key, "state", config_.state_dim);
    if (full && config_.env_state_dim > 0) add_vector_input(config_.env_state_key, "env_state", config_.env_state_dim);
    for (const auto& op : g_.ops()) {
      if (!full && op->stage != graph::Stage::kBackbone) continue;
      translate(*op);
    }
    if (full) {
      add_action_output();
    } else {
      for (size_t c = 0; c < config_.cameras.size(); ++c) add_feature_output(c);
    }
    return std::move(model_);
  }

 private:
  // ------------------------------------------------------------------------------ names, constants
  std::string fresh(const std::string& base) { return base + "_" + std::to_string(counter_++); }

  // An initializer of `type` with raw little-endian `data` (`bytes` long); returns its name.
  std::string constant(const std::string& base, onnx::TensorProto::DataType type, const std::vector<int64_t>& dims,
                       const void* data, size_t bytes) {
    onnx::TensorProto* t = graph_->add_initializer();
    t->set_name(fresh(base));
    t->set_data_type(type);
    for (int64_t d : dims) t->add_dims(d);
    t->set_raw_data(data, bytes);
    return t->name();
  }
  std::string constant_f32(const std::string& base, const std::vector<int64_t>& dims, std::vector<float> data) {
    return constant(base, onnx::TensorProto::FLOAT, dims, data.data(), data.size() * sizeof(float));
  }
  std::string constant_i8(const std::string& base, const std::vector<int64_t>& dims, const int8_t* data, size_t n) {
    return constant(base, onnx::TensorProto::INT8, dims, data, n);
  }
  std::string constant_i32(const std::string& base, const std::vector<int32_t>& values) {
    return constant(base, onnx::TensorProto::INT32, {static_cast<int64_t>(values.size())}, values.data(),
                    values.size() * sizeof(int32_t));
  }
  std::string constant_i64(const std::string& base, const std::vector<int64_t>& values) {
    return constant(base, onnx::TensorProto::INT64, {static_cast<int64_t>(values.size())}, values.data(),
                    values.size() * sizeof(int64_t));
  }
  std::string scalar_f32(const std::string& base, float v) { return constant_f32(base, {}, {v}); }
  // An activation's zero point as ONNX's uint8 (the engine's int8 code + 128: the same values).
  std::string activation_zero_point(int32_t zero_point) {
    const uint8_t b = static_cast<uint8_t>(zero_point + 128);
    return constant("zero_point", onnx::TensorProto::UINT8, {}, &b, 1);
  }

  onnx::NodeProto* node(const std::string& type, const std::vector<std::string>& inputs, const std::string& output) {
    onnx::NodeProto* n = graph_->add_node();
    n->set_op_type(type);
    n->set_name(output);
    for (const auto& i : inputs) n->add_input(i);
    n->add_output(output);
    return n;
  }
  std::string op1(const std::string& type, const std::vector<std::string>& inputs, const std::string& base) {
    const std::string out = fresh(base);
    node(type, inputs, out);
    return out;
  }
  static void attr_int(onnx::NodeProto* n, const std::string& name, int64_t v) {
    auto* a = n->add_attribute();
    a->set_name(name);
    a->set_type(onnx::AttributeProto::INT);
    a->set_i(v);
  }
  static void attr_ints(onnx::NodeProto* n, const std::string& name, const std::vector<int64_t>& v) {
    auto* a = n->add_attribute();
    a->set_name(name);
    a->set_type(onnx::AttributeProto::INTS);
    for (int64_t x : v) a->add_ints(x);
  }
  static void attr_float(onnx::NodeProto* n, const std::string& name, float v) {
    auto* a = n->add_attribute();
    a->set_name(name);
    a->set_type(onnx::AttributeProto::FLOAT);
    a->set_f(v);
  }

  void declare(onnx::ValueInfoProto* info, const std::string& name, const std::vector<int64_t>& shape) {
    info->set_name(name);
    auto* tensor = info->mutable_type()->mutable_tensor_type();
    tensor->set_elem_type(onnx::TensorProto::FLOAT);
    for (int64_t d : shape) tensor->mutable_shape()->add_dim()->set_dim_value(d);
  }

  // ---------------------------------------------------------------------------- inputs and outputs
  bool normalize_inside() const { return options_.normalization == OnnxNormalization::kInside; }

  // x -> the network's normalised input: (x - sub) / div [* 2 - 1], statistics shaped `dims`.
  std::string normalize(const std::string& key, const std::string& x, const std::vector<int64_t>& dims, size_t n) {
    const NormMode mode = config_.input_norm_mode(key);
    if (!normalize_inside() || mode == NormMode::kIdentity) return x;
    const std::vector<int64_t> shape = {static_cast<int64_t>(n)};
    const float* sub = tensors_.f32(bn::norm_sub(key), shape);
    const float* div = tensors_.f32(bn::norm_div(key), shape);
    std::string y = op1("Sub", {x, constant_f32("norm_sub", dims, {sub, sub + n})}, "normalized");
    y = op1("Div", {y, constant_f32("norm_div", dims, {div, div + n})}, "normalized");
    if (mode == NormMode::kMinMax) {
      y = op1("Mul", {y, scalar_f32("two", 2.0f)}, "normalized");
      y = op1("Sub", {y, scalar_f32("one", 1.0f)}, "normalized");
    }
    return y;
  }

  void add_camera_input(size_t c) {
    const CameraConfig& cam = config_.cameras[c];
    declare(graph_->add_input(), cam.key, {1, 3, cam.height, cam.width});
    const ValueId image = g_.find("cam" + std::to_string(c) + ".image");
    const std::string normalized = normalize(cam.key, cam.key, {1, 3, 1, 1}, 3);
    // A static INT8 stem's input is the image's int8 codes (the engine quantizes the pixels itself):
    // here, as any static quantization, a QDQ pair with its parameters.
    const std::optional<kernels::QuantS8>& q = g_.value(image).quant;
    values_[image] = q ? OnnxValue{quantize(normalized, *q), true, q} : OnnxValue{normalized, true, std::nullopt};
  }

  void add_vector_input(const std::string& key, const std::string& value, int n) {
    declare(graph_->add_input(), key, {1, n});
    values_[g_.find(value)] = {normalize(key, key, {1, n}, static_cast<size_t>(n)), false, std::nullopt};
  }

  void add_action_output() {
    const int T = config_.chunk_size, A = config_.action_dim;
    std::string y = float_of(g_.find("actions_normalized"));
    if (normalize_inside() && config_.action_norm != NormMode::kIdentity) {
      const std::vector<int64_t> shape = {A};
      const size_t a = static_cast<size_t>(A);
      const float* shift = tensors_.f32(bn::kUnnormShift, shape);
      const float* scale = tensors_.f32(bn::kUnnormScale, shape);
      const float* offset = tensors_.f32(bn::kUnnormOffset, shape);
      y = op1("Add", {y, constant_f32("unnorm_shift", {1, A}, {shift, shift + a})}, "action_raw");
      y = op1("Mul", {y, constant_f32("unnorm_scale", {1, A}, {scale, scale + a})}, "action_raw");
      y = op1("Add", {y, constant_f32("unnorm_offset", {1, A}, {offset, offset + a})}, "action_raw");
    }
    node("Reshape", {y, constant_i64("shape", {1, T, A})}, "action");
    declare(graph_->add_output(), "action", {1, T, A});
  }

  void add_feature_output(size_t c) {
    const ValueId feats = g_.find("cam" + std::to_string(c) + ".img_feat_proj");
    const auto it = features_nchw_.find(feats);
    check(it != features_nchw_.end(), StatusCode::kInternal, "camera " + std::to_string(c) + ": no backbone features");
    const CameraConfig& cam = config_.cameras[c];
    const std::string name = cam.key + ".features";
    node("Identity", {it->second}, name);
    declare(graph_->add_output(), name,
            {1, config_.dim_model, config_.feature_height(cam), config_.feature_width(cam)});
  }

  // ---------------------------------------------------------------------------------- operands
  const OnnxValue& value(ValueId id) {
    const auto it = values_.find(id);
    check(it != values_.end(), StatusCode::kInternal, "ONNX export: value \"" + g_.value(id).name + "\" used before it is made");
    return it->second;
  }

  std::string dequantize(const std::string& x, const kernels::QuantS8& q) {
    return op1("DequantizeLinear", {x, scalar_f32("scale", q.scale), activation_zero_point(q.zero_point)}, "dq");
  }
  std::string quantize(const std::string& x, const kernels::QuantS8& q) {
    return op1("QuantizeLinear", {x, scalar_f32("scale", q.scale), activation_zero_point(q.zero_point)}, "q");
  }
  // The value as a float ONNX tensor (dequantized when int8).
  // One DequantizeLinear per int8 value, shared by its readers, as ONNX Runtime's quantizer writes
  // them (its QDQ fusion gives each reader its own copy; separate twins were merged and then kept
  // the convolutions that read a block's output in float).
  std::string float_of(ValueId id) {
    const OnnxValue& v = value(id);
    if (!v.int8) return v.name;
    const auto [it, added] = dequantized_.try_emplace(id);
    if (added) it->second = dequantize(v.name, *v.int8);
    return it->second;
  }
  // A float image value in NCHW.
  std::string float_nchw(ValueId id) {
    check(value(id).nchw, StatusCode::kInternal, "ONNX export: \"" + g_.value(id).name + "\" is no image");
    return float_of(id);
  }

  // A matrix operand as an ONNX tensor of [rows, cols] (a broadcast row stays [1, cols]).
  std::string matrix(const MatrixRef& ref, int rows, int cols, const std::string& base) {
    if (ref.value == graph::kNoValue) {
      const size_t r = ref.ld == 0 ? 1 : static_cast<size_t>(rows), n = static_cast<size_t>(cols);
      std::vector<float> data(r * n);
      for (size_t i = 0; i < r; ++i) {
        std::copy_n(ref.constant + ref.col_offset + i * ref.ld, n, data.begin() + static_cast<std::ptrdiff_t>(i * n));
      }
      return constant_f32(base, {static_cast<int64_t>(r), cols}, std::move(data));
    }
    std::string x = float_of(ref.value);
    const graph::Value& v = g_.value(ref.value);
    if (value(ref.value).nchw) x = tokens_of_nchw(x, v.shape);
    if (ref.col_offset == 0 && static_cast<int64_t>(ref.ld) == cols && v.shape[0] == rows) return x;
    const int64_t c0 = static_cast<int64_t>(ref.col_offset);
    return op1("Slice", {x, constant_i64("starts", {0, c0}), constant_i64("ends", {rows, c0 + cols}),
                         constant_i64("axes", {0, 1})}, base);
  }

  // [1, C, H, W] -> [H * W, C] (the engine's row-major NHWC tokens).
  std::string tokens_of_nchw(const std::string& x, const std::vector<int64_t>& engine_shape) {
    const int64_t h = engine_shape[0], w = engine_shape.size() == 3 ? engine_shape[1] : 1;
    const int64_t c = engine_shape.back();
    const std::string flat = op1("Reshape", {x, constant_i64("shape", {c, h * w})}, "flat");
    onnx::NodeProto* t = node("Transpose", {flat}, fresh("tokens"));
    attr_ints(t, "perm", {1, 0});
    return t->output(0);
  }

  // --------------------------------------------------------------------------------- translation
  void set(ValueId id, OnnxValue v) { values_[id] = std::move(v); }

  void translate(const graph::Op& op) {
    if (const auto* conv = dynamic_cast<const graph::Conv2dOp*>(&op)) return conv_f32(*conv);
    if (const auto* conv = dynamic_cast<const graph::ConvS8Op*>(&op)) return conv_s8(*conv);
    if (const auto* lin = dynamic_cast<const graph::LinearOp*>(&op)) {
      const std::vector<float> w = lin->weight();
      return linear(op, lin->params(), w.data(), nullptr, nullptr);
    }
    if (const auto* lin = dynamic_cast<const graph::LinearS8Op*>(&op)) {
      linear(op, lin->params(), nullptr, lin->weight(), lin->w_scale(), lin->input_quant());
      ValueId x = op.outputs[0];
      for (const auto& norm : lin->fused_layernorms()) {
        layernorm(x, norm.gamma, norm.beta, norm.output);
        x = norm.output;
      }
      if (const auto& head = lin->fused_head()) {
        const int rows = static_cast<int>(g_.value(x).shape[0]);
        set(head->output, {projection(*head->weight, MatrixRef::of(x, static_cast<size_t>(head->weight->cols())), rows, head->bias),
                           false, std::nullopt});
      }
      return;
    }
    if (const auto* ln = dynamic_cast<const graph::LayerNormOp*>(&op)) {
      return layernorm(op.inputs[0], ln->gamma(), ln->beta(), op.outputs[0]);
    }
    if (const auto* att = dynamic_cast<const graph::AttentionOp*>(&op)) return attention(att->params(), op.outputs[0]);
    // Int8 attention quantizes its keys and values at every run, which has no fixed QDQ form: the
    // export computes it in float, as the QDQ model's other run-time-quantized activations.
    if (const auto* att = dynamic_cast<const graph::AttentionS8Op*>(&op)) return attention(att->params(), op.outputs[0]);
    if (const auto* cat = dynamic_cast<const graph::ConcatRowsOp*>(&op)) return concat(*cat);
    if (dynamic_cast<const graph::GluOp*>(&op) != nullptr) return glu(op);
    if (const auto* q = dynamic_cast<const graph::QuantizeOp*>(&op)) {
      // A dynamic quantization (scale computed per run) has no QDQ form: the value stays float.
      const OnnxValue& in = value(op.inputs[0]);
      return set(op.outputs[0], q->dynamic() ? in : OnnxValue{quantize(in.name, q->quant()), in.nchw, q->quant()});
    }
    if (dynamic_cast<const graph::DequantizeOp*>(&op) != nullptr) {
      const OnnxValue& in = value(op.inputs[0]);
      return set(op.outputs[0], {float_of(op.inputs[0]), in.nchw, std::nullopt});
    }
    fail(StatusCode::kUnimplemented, "ONNX export: no translation for op \"" + op.name + "\" (" + op.type() + ")");
  }

  // Conv weights OHWI -> OIHW.
  static std::vector<size_t> ohwi_to_oihw(const kernels::Conv2dShape& s) {
    const size_t O = static_cast<size_t>(s.out_c), H = static_cast<size_t>(s.kernel_h), W = static_cast<size_t>(s.kernel_w),
                 I = static_cast<size_t>(s.in_c);
    std::vector<size_t> from(O * H * W * I);
    size_t k = 0;
    for (size_t o = 0; o < O; ++o)
      for (size_t i = 0; i < I; ++i)
        for (size_t y = 0; y < H; ++y)
          for (size_t x = 0; x < W; ++x) from[k++] = ((o * H + y) * W + x) * I + i;
    return from;
  }

  // A Conv node over NCHW x; `weight` float OIHW, `bias` a float [out_c] tensor; adds the residual
  // and ReLU. Returns the float output.
  std::string conv_node(const kernels::Conv2dShape& s, const std::string& x, const std::string& weight, const std::string& bias,
                        const std::string& residual, bool relu, const std::string& base) {
    onnx::NodeProto* n = node("Conv", {x, weight, bias}, fresh(base));
    attr_ints(n, "kernel_shape", {s.kernel_h, s.kernel_w});
    attr_ints(n, "strides", {s.stride, s.stride});
    attr_ints(n, "pads", {s.pad, s.pad, s.pad, s.pad});
    attr_ints(n, "dilations", {s.dilation, s.dilation});
    std::string y = n->output(0);
    if (!residual.empty()) y = op1("Add", {y, residual}, base);
    if (relu) y = op1("Relu", {y}, base);
    return y;
  }

  // Int8 parameters for a conv's sum before its residual is added. out = [relu](sum + residual)
  // reaches its whole range from every residual only with sum in [out_lo - r_hi, out_hi - r_lo]
  // (out_lo clipped to 0 by the ReLU), but that needs the two at opposite extremes at once; half of
  // it keeps the step near the mean of the residual's and the output's steps, which clipped less
  // than the output's own step and rounded finer than the whole range on the test checkpoints.
  static kernels::QuantS8 residual_sum_quant(const kernels::QuantS8& residual, const kernels::QuantS8& out, bool relu) {
    const auto lo = [](const kernels::QuantS8& q) { return (-128.0f - static_cast<float>(q.zero_point)) * q.scale; };
    const auto hi = [](const kernels::QuantS8& q) { return (127.0f - static_cast<float>(q.zero_point)) * q.scale; };
    const float out_lo = relu ? std::max(lo(out), 0.0f) : lo(out);
    return kernels::choose_quant_s8(0.5f * (out_lo - hi(residual)), 0.5f * (hi(out) - lo(residual)));
  }
  std::string bias_f32(const float* bias, int n) { return constant_f32("bias", {n}, {bias, bias + n}); }

  // A bias as the int32 accumulator units of an int8 product (x_scale * w_scale[j]), behind a
  // DequantizeLinear: the form ONNX Runtime's QDQ fusion needs to run the Conv or Gemm on its int8
  // kernels (a float bias keeps the whole node in float). Rounded against the float scale the
  // DequantizeLinear carries, so that its output is the float bias's nearest.
  std::string bias_s32(const float* bias, int n, float x_scale, const float* w_scale) {
    std::vector<int32_t> q(static_cast<size_t>(n));
    std::vector<float> scale(static_cast<size_t>(n));
    for (size_t j = 0; j < q.size(); ++j) {
      scale[j] = x_scale * w_scale[j];
      const double v = std::nearbyint(static_cast<double>(bias[j]) / scale[j]);
      q[j] = static_cast<int32_t>(std::clamp(v, -2147483647.0, 2147483647.0));
    }
    onnx::NodeProto* dq = node("DequantizeLinear",
                               {constant_i32("bias_s32", q), constant_f32("bias_scale", {n}, std::move(scale)),
                                constant_i32("bias_zero_point", std::vector<int32_t>(q.size(), 0))},
                               fresh("bias"));
    attr_int(dq, "axis", 0);
    return dq->output(0);
  }

  // A conv's output value: an image, or (the 1x1 projection) tokens, kept also as NCHW features.
  void set_conv_output(ValueId out, const std::string& y, std::optional<kernels::QuantS8> q, int64_t out_h, int64_t out_w) {
    const graph::Value& v = g_.value(out);
    if (v.shape.size() == 3) return set(out, {y, true, q});
    features_nchw_[out] = y;
    // [h*w, D] in the engine: h and w from the conv's output shape.
    set(out, {tokens_of_nchw(y, {out_h, out_w, v.shape[1]}), false, q});
  }

  void conv_f32(const graph::Conv2dOp& op) {
    const kernels::Conv2dShape& s = op.shape();
    const std::vector<size_t> from = ohwi_to_oihw(s);
    const std::vector<float> ohwi = op.weight();
    std::vector<float> w(from.size());
    for (size_t i = 0; i < from.size(); ++i) w[i] = ohwi[from[i]];
    const std::string weight = constant_f32("weight", {s.out_c, s.in_c, s.kernel_h, s.kernel_w}, std::move(w));
    const std::string residual = op.residual() == graph::kNoValue ? "" : float_nchw(op.residual());
    const std::string y = conv_node(s, float_nchw(op.inputs[0]), weight, bias_f32(op.bias(), s.out_c), residual, op.relu(), "conv");
    set_conv_output(op.outputs[0], y, std::nullopt, s.out_h, s.out_w);
    if (const auto& pool = op.max_pool()) maxpool(op.outputs[0], op.outputs[1], pool->kernel, pool->stride, pool->pad);
  }

  // DequantizeLinear of int8 weights [rows, ...] with one scale per row (axis 0).
  std::string dequantized_weight(const int8_t* data, const std::vector<int64_t>& dims, const float* scales,
                                 const std::vector<size_t>& order) {
    size_t n = 1;
    for (int64_t d : dims) n *= static_cast<size_t>(d);
    std::vector<int8_t> w(n);
    for (size_t i = 0; i < n; ++i) w[i] = data[order.empty() ? i : order[i]];
    const size_t rows = static_cast<size_t>(dims[0]);
    const std::vector<int8_t> zeros(rows, 0);
    const std::string q = constant_i8("weight_s8", dims, w.data(), n);
    const std::string scale = constant_f32("weight_scale", {dims[0]}, {scales, scales + rows});
    const std::string zp = constant_i8("weight_zero_point", {dims[0]}, zeros.data(), rows);
    onnx::NodeProto* dq = node("DequantizeLinear", {q, scale, zp}, fresh("weight"));
    attr_int(dq, "axis", 0);
    return dq->output(0);
  }

  void conv_s8(const graph::ConvS8Op& op) {
    const graph::ConvS8Spec& spec = op.spec();
    const kernels::Conv2dShape& s = spec.shape;
    const std::string weight = dequantized_weight(spec.weight, {s.out_c, s.in_c, s.kernel_h, s.kernel_w}, spec.w_scale,
                                                  ohwi_to_oihw(s));
    // Static input parameters: the input is an int8 value; dynamic ones: it stayed float (translate()).
    const std::optional<kernels::QuantS8> x_q = value(op.inputs[0]).int8;
    const std::string x = float_nchw(op.inputs[0]);
    const std::string bias = x_q ? bias_s32(spec.bias, s.out_c, x_q->scale, spec.w_scale) : bias_f32(spec.bias, s.out_c);
    std::string y;
    const std::optional<kernels::QuantS8> residual_q =
        spec.residual == graph::kNoValue ? std::nullopt : value(spec.residual).int8;
    if (spec.s8_out && x_q && residual_q) {
      // The engine adds the residual to the conv's exact sum; ONNX Runtime runs an int8 ResNet block
      // as QLinearConv + QLinearAdd, so the sum is quantized once more in between, over the range
      // that sum needs for the block's output range to stay reachable (residual_sum_quant).
      const kernels::QuantS8 mid = residual_sum_quant(*residual_q, spec.output_q, spec.relu);
      y = dequantize(quantize(conv_node(s, x, weight, bias, "", false, "conv"), mid), mid);
      y = op1("Add", {y, float_nchw(spec.residual)}, "conv");
      if (spec.relu) y = op1("Relu", {y}, "conv");
    } else {
      const std::string residual = spec.residual == graph::kNoValue ? "" : float_nchw(spec.residual);
      y = conv_node(s, x, weight, bias, residual, spec.relu, "conv");
    }
    std::optional<kernels::QuantS8> q;
    if (spec.s8_out) {
      y = quantize(y, spec.output_q);
      q = spec.output_q;
    }
    set_conv_output(op.outputs[0], y, q, s.out_h, s.out_w);
    if (const auto& pool = op.max_pool()) maxpool(op.outputs[0], op.outputs[1], pool->kernel, pool->stride, pool->pad);
  }

  void maxpool(ValueId input, ValueId output, int kernel, int stride, int pad) {
    const OnnxValue& in = value(input);
    onnx::NodeProto* n = node("MaxPool", {float_nchw(input)}, fresh("maxpool"));
    attr_ints(n, "kernel_shape", {kernel, kernel});
    attr_ints(n, "strides", {stride, stride});
    attr_ints(n, "pads", {pad, pad, pad, pad});
    std::string y = n->output(0);
    // Max commutes with quantization: the output keeps the input's parameters.
    if (in.int8) y = quantize(y, *in.int8);
    set(output, {y, true, in.int8});
  }

  // y = act(x W^T + bias [+ residual]), W float, or int8 with per-row scales (dequantized in the graph).
  // x_q: the int8 linear reads its input as per-tensor codes with these parameters (a QDQ pair here).
  void linear(const graph::Op& op, const graph::LinearParams& p, const float* w_f32, const int8_t* w_s8, const float* w_scale,
              std::optional<kernels::QuantS8> x_q = std::nullopt) {
    const int in = p.in, out = p.out;
    const MatrixRef &x_ref = p.x, &bias = p.bias;
    const size_t w_size = static_cast<size_t>(out) * static_cast<size_t>(in);
    const bool image_input = x_ref.value != graph::kNoValue && value(x_ref.value).nchw;
    if (image_input) {
      // The 1x1 input projection over a feature map: a Conv, so that the backbone stays NCHW.
      const graph::Value& fm = g_.value(x_ref.value);
      const kernels::Conv2dShape s = kernels::Conv2dShape::square(static_cast<int>(fm.shape[0]), static_cast<int>(fm.shape[1]),
                                                                  in, out, 1, 1, 0);
      const std::string weight = w_s8 ? dequantized_weight(w_s8, {out, in, 1, 1}, w_scale, {})
                                      : constant_f32("weight", {out, in, 1, 1}, {w_f32, w_f32 + w_size});
      check(bias.value == graph::kNoValue && bias.ld == 0, StatusCode::kInternal, "ONNX export: projection bias is no vector");
      const std::string y = conv_node(s, float_nchw(x_ref.value), weight, bias_f32(bias.constant + bias.col_offset, out), "", false, "proj");
      set_conv_output(op.outputs[0], y, std::nullopt, s.out_h, s.out_w);
      return;
    }
    if (w_s8 != nullptr && !x_q) return set(op.outputs[0], {dynamic_product(p, w_s8, w_scale), false, std::nullopt});
    const std::string weight = w_s8 ? dequantized_weight(w_s8, {out, in}, w_scale, {})
                                    : constant_f32("weight", {out, in}, {w_f32, w_f32 + w_size});
    set(op.outputs[0], {product(p, weight, x_q, w_s8 ? w_scale : nullptr), false, std::nullopt});
  }

  // rows of x W^T + bias (W float, packed), for the rows an op projects itself (the token
  // concatenation's state rows, a linear's fused head).
  std::string projection(const graph::PackedF32Weights& w, const MatrixRef& x, int rows, const float* bias) {
    const int in = w.cols(), out = w.rows();
    const std::vector<float> unpacked = w.unpacked();
    return product({rows, in, out, x, MatrixRef::of_constant(bias, 0), {}, graph::Epilogue::kNone},
                   constant_f32("weight", {out, in}, unpacked), std::nullopt);
  }

  // act(x W^T + bias [+ residual]) as ONNX nodes, W the initializer `weight` [out, in].
  // With int8 input codes (x_q) and int8 weights (w_scale), a constant bias row goes in as int32
  // (bias_s32), so that ONNX Runtime runs the Gemm on its int8 kernels.
  std::string product(const graph::LinearParams& p, const std::string& weight, std::optional<kernels::QuantS8> x_q,
                      const float* w_scale = nullptr) {
    const int rows = p.rows, in = p.in, out = p.out;
    const MatrixRef &x_ref = p.x, &bias = p.bias;
    std::string x = matrix(x_ref, rows, in, "x");
    if (x_q) x = dequantize(quantize(x, *x_q), *x_q);
    const bool int8_bias = x_q && w_scale != nullptr && bias.value == graph::kNoValue && bias.ld == 0;
    const std::string b = int8_bias ? bias_s32(bias.constant + bias.col_offset, out, x_q->scale, w_scale)
                                    : matrix(bias, rows, out, "bias");
    onnx::NodeProto* gemm = node("Gemm", {x, weight, b}, fresh("linear"));
    attr_int(gemm, "transB", 1);
    return epilogue(p, gemm->output(0));
  }

  // An int8 linear whose input the engine quantizes per token at run time: ONNX has no per-row
  // dynamic quantization, so it is the form ONNX Runtime's own dynamic quantization writes (and
  // fuses into DynamicQuantizeMatMul): x quantized per tensor (uint8, asymmetric) by
  // DynamicQuantizeLinear, MatMulInteger with W^T int8, the product of the scales, then the bias.
  // Coarser than the engine's codes (one scale for every row), no finer.
  std::string dynamic_product(const graph::LinearParams& p, const int8_t* w_s8, const float* w_scale) {
    const int rows = p.rows, in = p.in, out = p.out;
    onnx::NodeProto* quant = graph_->add_node();
    quant->set_op_type("DynamicQuantizeLinear");
    const std::string xq = fresh("x_u8");
    quant->set_name(xq);
    quant->add_input(matrix(p.x, rows, in, "x"));
    for (const std::string& o : {xq, fresh("x_scale"), fresh("x_zero_point")}) quant->add_output(o);
    std::vector<int8_t> wt(static_cast<size_t>(in) * static_cast<size_t>(out));
    for (size_t i = 0; i < static_cast<size_t>(in); ++i) {
      for (size_t j = 0; j < static_cast<size_t>(out); ++j) wt[i * static_cast<size_t>(out) + j] = w_s8[j * static_cast<size_t>(in) + i];
    }
    const int8_t zero = 0;
    const std::string acc = op1("MatMulInteger", {xq, constant_i8("weight_t_s8", {in, out}, wt.data(), wt.size()), quant->output(2),
                                                  constant_i8("weight_zero_point", {}, &zero, 1)}, "linear");
    onnx::NodeProto* cast = node("Cast", {acc}, fresh("linear"));
    attr_int(cast, "to", onnx::TensorProto::FLOAT);
    const std::string scale = op1("Mul", {quant->output(1), constant_f32("weight_scale", {out}, {w_scale, w_scale + out})}, "scale");
    const std::string y = op1("Mul", {cast->output(0), scale}, "linear");
    return epilogue(p, op1("Add", {y, matrix(p.bias, rows, out, "bias")}, "linear"));
  }

  // A linear's residual and activation after its product y.
  std::string epilogue(const graph::LinearParams& p, std::string y) {
    const int rows = p.rows, out = p.out;
    const MatrixRef& residual = p.residual;
    if (residual.value != graph::kNoValue || residual.constant != nullptr) {
      y = op1("Add", {y, matrix(residual, rows, out, "residual")}, "linear");
    }
    if (p.epilogue == graph::Epilogue::kRelu) y = op1("Relu", {y}, "relu");
    if (p.epilogue == graph::Epilogue::kGelu) y = gelu(y);
    return y;
  }

  // Exact GELU (opset 17 has no Gelu): 0.5 x (1 + erf(x / sqrt 2)).
  std::string gelu(const std::string& x) {
    const std::string e = op1("Erf", {op1("Mul", {x, scalar_f32("inv_sqrt2", static_cast<float>(1.0 / std::numbers::sqrt2))}, "gelu")},
                              "gelu");
    const std::string one_plus = op1("Add", {e, scalar_f32("one", 1.0f)}, "gelu");
    return op1("Mul", {op1("Mul", {x, one_plus}, "gelu"), scalar_f32("half", 0.5f)}, "gelu");
  }

  void glu(const graph::Op& op) {
    const graph::Value& in = g_.value(op.inputs[0]);
    const int64_t half = in.shape[1] / 2;
    const std::string x = float_of(op.inputs[0]);
    const std::string a = op1("Slice", {x, constant_i64("starts", {0}), constant_i64("ends", {half}), constant_i64("axes", {1})}, "glu_a");
    const std::string b = op1("Slice", {x, constant_i64("starts", {half}), constant_i64("ends", {2 * half}), constant_i64("axes", {1})}, "glu_b");
    set(op.outputs[0], {op1("Mul", {a, op1("Sigmoid", {b}, "glu")}, "glu"), false, std::nullopt});
  }

  void layernorm(ValueId x, const float* gamma, const float* beta, ValueId output) {
    const int64_t D = g_.value(output).shape[1];
    const size_t d = static_cast<size_t>(D);
    onnx::NodeProto* n = node("LayerNormalization",
                              {float_of(x), constant_f32("gamma", {D}, {gamma, gamma + d}), constant_f32("beta", {D}, {beta, beta + d})},
                              fresh("layernorm"));
    attr_int(n, "axis", -1);
    attr_float(n, "epsilon", graph::kLayerNormEps);
    set(output, {n->output(0), false, std::nullopt});
  }

  // Multi-head attention: heads split by Reshape/Transpose, softmax(q k^T / sqrt(hd)) v.
  void attention(const graph::AttentionParams& op, graph::ValueId output) {
    const int D = config_.dim_model, H = op.heads, hd = D / H;
    const auto heads_of = [&](const MatrixRef& ref, int rows, const std::vector<int64_t>& perm, const std::string& base) {
      const std::string m = matrix(ref, rows, D, base);
      const std::string r = op1("Reshape", {m, constant_i64("shape", {rows, H, hd})}, base);
      onnx::NodeProto* t = node("Transpose", {r}, fresh(base));
      attr_ints(t, "perm", perm);
      return t->output(0);
    };
    const std::string q = heads_of(op.q, op.nq, {1, 0, 2}, "q");   // [H, nq, hd]
    const std::string k = heads_of(op.k, op.nk, {1, 2, 0}, "k");   // [H, hd, nk]
    const std::string v = heads_of(op.v, op.nk, {1, 0, 2}, "v");   // [H, nk, hd]
    const std::string scores = op1("Mul", {op1("MatMul", {q, k}, "scores"),
                                           scalar_f32("scale", 1.0f / std::sqrt(static_cast<float>(hd)))}, "scores");
    onnx::NodeProto* sm = node("Softmax", {scores}, fresh("probs"));
    attr_int(sm, "axis", -1);
    const std::string ctx = op1("MatMul", {sm->output(0), v}, "context");  // [H, nq, hd]
    onnx::NodeProto* t = node("Transpose", {ctx}, fresh("context"));
    attr_ints(t, "perm", {1, 0, 2});
    set(output, {op1("Reshape", {t->output(0), constant_i64("shape", {op.nq, D})}, "attention"), false, std::nullopt});
  }

  void concat(const graph::ConcatRowsOp& op) {
    const int cols = static_cast<int>(g_.value(op.outputs[0]).shape[1]);
    std::vector<std::string> parts;
    for (const auto& p : op.parts()) {
      if (p.projection == nullptr) {
        parts.push_back(matrix(p.source, p.rows, cols, "token"));
        continue;
      }
      parts.push_back(projection(*p.projection, p.source, p.rows, p.bias));
    }
    onnx::NodeProto* n = node("Concat", parts, fresh("tokens"));
    attr_int(n, "axis", 0);
    set(op.outputs[0], {n->output(0), false, std::nullopt});
  }

 private:
  graph::Graph& g_;
  const ModelConfig& config_;
  BlobTensors& tensors_;
  OnnxExportOptions options_;
  onnx::ModelProto model_;
  onnx::GraphProto* graph_ = nullptr;
  std::map<ValueId, OnnxValue> values_;
  std::map<ValueId, std::string> features_nchw_;  // projection outputs as [1, D, h, w]
  std::map<ValueId, std::string> dequantized_;    // float_of's DequantizeLinear outputs
  int counter_ = 0;
};

std::vector<OnnxTensorInfo> tensor_infos(const google::protobuf::RepeatedPtrField<onnx::ValueInfoProto>& list) {
  std::vector<OnnxTensorInfo> infos;
  for (const auto& v : list) {
    OnnxTensorInfo info{v.name(), {}};
    for (const auto& d : v.type().tensor_type().shape().dim()) info.shape.push_back(d.dim_value());
    infos.push_back(std::move(info));
  }
  return infos;
}

// onnx::checker (full) and ONNX's strict shape inference, which must agree with the declared outputs.
void check_onnx_model(const onnx::ModelProto& model) {
  try {
    onnx::checker::check_model(model);
    onnx::ModelProto inferred = model;
    onnx::shape_inference::InferShapes(inferred, onnx::OpSchemaRegistry::Instance(),
                                       onnx::ShapeInferenceOptions(/*check_type=*/true, /*strict_mode=*/1,
                                                                   /*data_prop=*/true));
    onnx::checker::check_model(inferred);
  } catch (const std::exception& e) {
    fail(StatusCode::kInternal, std::string("the exported ONNX model fails ONNX's checker: ") + e.what());
  }
}

}  // namespace

StatusOr<OnnxPart> parse_onnx_part(std::string_view name) {
  if (name == "full") return OnnxPart::kFull;
  if (name == "backbone") return OnnxPart::kBackbone;
  return Status(StatusCode::kInvalidArgument, "unknown ONNX part \"" + std::string(name) + "\" (full or backbone)");
}

StatusOr<OnnxNormalization> parse_onnx_normalization(std::string_view name) {
  if (name == "in") return OnnxNormalization::kInside;
  if (name == "out") return OnnxNormalization::kOutside;
  return Status(StatusCode::kInvalidArgument, "unknown ONNX normalization \"" + std::string(name) +
                "\" (in: statistics inside the graph, out: the caller normalises)");
}

StatusOr<OnnxExportSummary> export_onnx(const std::string& blob_path, const std::string& onnx_path,
                                        const OnnxExportOptions& options) {
  OnnxExportSummary summary;
  Status s = guarded([&] {
    ActbFile blob = ActbFile::open(blob_path, /*verify_checksum=*/true, FileMapping::Mode::kMap);
    BlobTensors tensors(blob);
    const ModelConfig config = blob_model_config(blob);
    // The reference kernels: the network is only read (its rebuilt bias tables are computed with them).
    const kernels::KernelConfigChoice kernels = kernels::kernel_config("ref");
    check(kernels.config.has_value(), StatusCode::kInternal, kernels.error);
    graph::ActNetwork network(config, tensors, *kernels.config);
    summary.precision = precision_name(config.precision);
    if (config.precision == Precision::kInt8) summary.precision += " " + blob.config()["quantization"].value("mode", "?");

    const onnx::ModelProto model = OnnxBuilder(network, tensors, options).build();
    check_onnx_model(model);
    std::string bytes;
    if (!model.SerializeToString(&bytes)) fail(StatusCode::kInternal, "the ONNX model cannot be serialised (over 2 GB?)");
    detail::AtomicFileWriter out(onnx_path);
    out.write(bytes);
    out.commit();
    summary.inputs = tensor_infos(model.graph().input());
    summary.outputs = tensor_infos(model.graph().output());
    summary.nodes = static_cast<size_t>(model.graph().node_size());
    summary.bytes = bytes.size();
  });
  if (!s.ok()) return s;
  return summary;
}

}  // namespace act
