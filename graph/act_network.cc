#include "graph/act_network.h"

#include <algorithm>
#include <numeric>

#include "actengine/status.h"
#include "weights/blob/blob_names.h"

namespace act::graph {

namespace bn = blob_names;

namespace {
std::string cam_prefix(size_t camera) { return "cam" + std::to_string(camera) + "."; }
}  // namespace

const float* ActNetwork::weight(const std::string& name, const std::vector<int64_t>& shape) {
  return tensors_.f32(name, shape);
}

// Dtype, scales and zero points of int8 tensors were checked with the config (blob_model_config).
const ActbTensor* ActNetwork::int8_weight(const std::string& name, const std::vector<int64_t>& shape) {
  const ActbTensor* t = tensors_.find(name);
  return t != nullptr && t->dtype == DType::kI8 ? &tensors_.get(name, shape) : nullptr;
}

const float* ActNetwork::bias_table(const std::string& table, int rows, int width, const std::string& weight_name,
                                    int pos_cols) {
  const size_t elements = static_cast<size_t>(rows) * static_cast<size_t>(width);
  float* out = owned_tables_.emplace_back(elements * sizeof(float)).floats();
  if (tensors_.find(table) != nullptr) {
    // FP32 blobs keep the bias vector beside the table, for inspection.
    if (tensors_.find(bn::bias_vector(table)) != nullptr) weight(bn::bias_vector(table), {width});
    const float* stored = weight(table, {rows, width});
    std::copy(stored, stored + elements, out);  // read at every inference: into huge pages, off the file mapping
    return out;
  }
  // Rebuild: table[r][c] = bias[c] + (c < pos_cols ? W[c] . pos[r] : 0), with the weights the
  // layer runs with (dequantized when int8).
  const int D = config_.dim_model;
  const float* bias = weight(bn::bias_vector(table), {width});
  const float* pos = weight(bn::kEncoderPos, {rows, D});
  std::vector<float> w(static_cast<size_t>(pos_cols) * D);
  if (const ActbTensor* q8 = int8_weight(weight_name, {width, D})) {
    const auto* q = reinterpret_cast<const int8_t*>(q8->data);
    for (size_t i = 0; i < w.size(); ++i) w[i] = static_cast<float>(q[i]) * q8->quant.scales[i / static_cast<size_t>(D)];
  } else {
    const float* f = weight(weight_name, {width, D});
    std::copy(f, f + w.size(), w.begin());
  }
  std::vector<float> packed(kernels::gemm_f32_packed_floats(kernels_.gemm_f32.nr, pos_cols, D));
  kernels::gemm_f32_pack(kernels_.gemm_f32.nr, pos_cols, D, w.data(), static_cast<size_t>(D), packed.data());
  kernels_.gemm_f32.packed({.m = rows, .n = pos_cols, .k = D, .a = pos, .lda = static_cast<size_t>(D),
                             .packed_b = packed.data(), .c = out, .ldc = static_cast<size_t>(width), .epilogue = {}});
  for (int r = 0; r < rows; ++r) {
    float* row = out + static_cast<size_t>(r) * width;
    for (int c = 0; c < width; ++c) row[c] = c < pos_cols ? row[c] + bias[c] : bias[c];
  }
  return out;
}

ActNetwork::Tensor ActNetwork::as_f32(const Tensor& t) {
  if (!t.s8) return t;
  if (auto it = converted_.find(t.id); it != converted_.end() && !it->second.s8) return it->second;
  check(t.params == kNoValue, StatusCode::kInternal, "dequantizing a dynamically quantized value");
  const Value v = graph_.value(t.id);  // a copy: add_value() below may reallocate the value list
  const std::string name = v.name + ".f32";
  const ValueId y = graph_.add_value(name, v.shape);
  add(std::make_unique<DequantizeOp>(v.elements, t.q, t.id, y), name);
  return converted_[t.id] = Tensor{y, false, {}, kNoValue};
}

float* ActNetwork::camera_input(size_t camera) {
  const ValueId id = camera_inputs_.at(camera);
  return graph_.value(id).dtype == DataType::kF32 ? graph_.data(id) : nullptr;
}

int8_t* ActNetwork::camera_input_s8(size_t camera) {
  const ValueId id = camera_inputs_.at(camera);
  return graph_.value(id).dtype == DataType::kF32 ? nullptr : graph_.data_s8(id);
}

bool ActNetwork::camera_input_unsigned(size_t camera) const {
  return graph_.value(camera_inputs_.at(camera)).dtype == DataType::kU8;
}

kernels::QuantS8 ActNetwork::camera_input_quant(size_t camera) const {
  return graph_.value(camera_inputs_.at(camera)).quant.value_or(kernels::QuantS8{});
}

ActNetwork::Tensor ActNetwork::as_s8(const Tensor& t) {
  if (t.s8) return t;
  if (auto it = converted_.find(t.id); it != converted_.end() && it->second.s8 && it->second.params == kNoValue) return it->second;
  const Value v = graph_.value(t.id);  // a copy: add_value() below may reallocate the value list
  const ActivationQuant& a = quant_.activation(v.name);
  const kernels::QuantS8 q{a.scale, a.zero_point};
  const std::string name = v.name + ".s8";
  const ValueId y = graph_.add_value(name, v.shape, DataType::kS8);
  graph_.value(y).quant = q;
  add(std::make_unique<QuantizeOp>(v.elements, q, t.id, y), name);
  return converted_[t.id] = Tensor{y, true, q, kNoValue};
}

ActNetwork::Tensor ActNetwork::as_dynamic_s8(const Tensor& t) {
  check(!t.s8, StatusCode::kInternal, "dynamic quantization of an int8 value");
  if (auto it = converted_.find(t.id); it != converted_.end() && it->second.params != kNoValue) return it->second;
  const Value v = graph_.value(t.id);  // a copy: add_value() below may reallocate the value list
  const std::string name = v.name + ".s8dyn";
  const ValueId y = graph_.add_value(name, v.shape, DataType::kS8);
  const ValueId params = graph_.add_value(name + ".params", {2});
  add(std::make_unique<QuantizeOp>(v.elements, t.id, y, params), name);
  return converted_[t.id] = Tensor{y, true, {}, params};
}

ActNetwork::Tensor ActNetwork::conv(const ConvSpec& c, const Tensor& x, int& h, int& w, bool relu, const Tensor* residual,
                                    const std::string& name) {
  const auto s = kernels::Conv2dShape::square(h, w, c.in_c, c.out_c, c.kernel, c.stride, c.pad, c.dilation);
  h = s.out_h;
  w = s.out_w;
  const std::vector<int64_t> w_shape = {c.out_c, c.kernel, c.kernel, c.in_c};
  const std::vector<int64_t> y_shape = {s.out_h, s.out_w, s.out_c};
  const float* bias = weight(bn::conv_bias(c.name), {c.out_c});
  const ActbTensor* q8 = int8_weight(bn::conv_weight(c.name), w_shape);
  if (q8 == nullptr) {
    const Tensor xf = as_f32(x);
    const ValueId res = residual ? as_f32(*residual).id : kNoValue;
    const ValueId y = graph_.add_value(name, y_shape);
    add_layer(std::make_unique<Conv2dOp>(packed_weight(bn::conv_weight(c.name), w_shape), s, bias, relu, xf.id, res, y), name, y,
              bn::conv_weight(c.name), false);
    calibration_point(CalibrationRole::kConvOutput, y);
    return Tensor{y, false, {}, kNoValue};
  }
  ConvS8Spec spec;
  spec.shape = s;
  spec.weight = reinterpret_cast<const int8_t*>(q8->data);
  spec.w_scale = q8->quant.scales.data();
  spec.bias = bias;
  spec.relu = relu;
  if (!quant_.static_activations()) {
    // Dynamic: quantize the float input at run time, float out (bias, residual, ReLU in float).
    const Tensor xq = as_dynamic_s8(as_f32(x));
    spec.input_params = xq.params;
    spec.s8_out = false;
    if (residual) spec.residual = as_f32(*residual).id;
    const ValueId y = graph_.add_value(name, y_shape);
    add_layer(std::make_unique<ConvS8Op>(kernels_.gemm_s8, spec, xq.id, y), name, y, bn::conv_weight(c.name), true);
    calibration_point(CalibrationRole::kConvOutput, y);
    return Tensor{y, false, {}, kNoValue};
  }
  const Tensor xq = as_s8(x);
  spec.input_q = xq.q;
  spec.unsigned_input = graph_.value(xq.id).dtype == DataType::kU8;
  const ActivationQuant& oq = quant_.activation(name);
  spec.output_q = {oq.scale, oq.zero_point};
  if (residual) {
    const Tensor r = as_s8(*residual);
    spec.residual = r.id;
    spec.residual_q = r.q;
  }
  const ValueId y = graph_.add_value(name, y_shape, DataType::kS8);
  graph_.value(y).quant = spec.output_q;
  add_layer(std::make_unique<ConvS8Op>(kernels_.gemm_s8, spec, xq.id, y), name, y, bn::conv_weight(c.name), true);
  return Tensor{y, true, spec.output_q, kNoValue};
}

void ActNetwork::add(std::unique_ptr<Op> op, const std::string& name) {
  op->name = name;
  op->stage = stage_;
  graph_.add_op(std::move(op));
}

void ActNetwork::add_layer(std::unique_ptr<Op> op, const std::string& name, ValueId output, const std::string& weight_name,
                           bool int8) {
  layers_.push_back({op.get(), output, weight_name, int8});
  add(std::move(op), name);
}

std::shared_ptr<const PackedF32Weights> ActNetwork::packed_weight(const std::string& name, const std::vector<int64_t>& shape) {
  std::shared_ptr<const PackedF32Weights>& packed = packed_weights_[name];
  if (packed == nullptr) {
    const int n = static_cast<int>(shape[0]);
    const int k = static_cast<int>(shape_elements(shape) / static_cast<uint64_t>(n));
    const float* w = weight(name, shape);  // checks the blob's tensor either way
    if (packed_weights_from_ != nullptr) {
      const auto& theirs = packed_weights_from_->packed_weights_;
      const auto it = theirs.find(name);
      if (it != theirs.end() && it->second->rows() == n && it->second->cols() == k &&
          it->second->panel_width() == kernels_.gemm_f32.nr) {
        packed = it->second;
      }
    }
    if (packed == nullptr) packed = std::make_shared<const PackedF32Weights>(kernels_.gemm_f32, n, k, w);
    tensors_.release(name);  // the panels are the only copy from here on
  }
  return packed;
}

void ActNetwork::calibration_point(CalibrationRole role, ValueId value) {
  if (stage_ == Stage::kBackbone) calibration_points_.push_back({role, camera_, value, "", -1});
}

void ActNetwork::note_linear_input(const MatrixRef& x, int rows, int in, const std::string& weight_name) {
  if (const ValueId whole = whole_value(x, rows, in); whole != kNoValue && stage_ != Stage::kOther) {
    const bool seen = std::any_of(calibration_points_.begin(), calibration_points_.end(),
                                  [&](const CalibrationPoint& p) { return p.value == whole; });
    if (!seen) calibration_points_.push_back({CalibrationRole::kLinearInput, 0, whole, weight_name, -1});
  }
}

ValueId ActNetwork::linear(const std::string& out_name, int rows, int in, int out, MatrixRef x, const std::string& weight_name,
                           MatrixRef bias, MatrixRef residual, Epilogue epilogue, ValueId output) {
  note_linear_input(x, rows, in, weight_name);
  const ValueId y = output != kNoValue ? output : graph_.add_value(out_name, {rows, out});
  if (const ActbTensor* q8 = int8_weight(weight_name, {out, in})) {
    RowCodes x_codes = producer_row_codes(x, rows, in);
    const auto from = x_codes.present() ? LinearS8Op::InputCodes::kFromProducer : LinearS8Op::InputCodes::kQuantizedHere;
    if (!x_codes.present()) x_codes = add_row_codes(out_name + ".x", rows, in, linear_input_quant(x, rows, in));
    auto op = std::make_unique<LinearS8Op>(kernels_.gemm_s8, rows, in, out, x, x_codes, from,
                                           reinterpret_cast<const int8_t*>(q8->data), q8->quant.scales.data(), bias,
                                           residual, epilogue, y);
    row_codes_writers_[y] = op.get();
    add_layer(std::move(op), out_name, y, weight_name, true);
    return y;
  }
  auto op = std::make_unique<LinearOp>(packed_weight(weight_name, {out, in}), rows, in, out, x, bias, residual, epilogue, y);
  add_layer(std::move(op), out_name, y, weight_name, false);
  return y;
}

ValueId ActNetwork::layernorm(const std::string& out_name, int rows, ValueId x, const std::string& weight_prefix) {
  const int D = config_.dim_model;
  const ValueId y = graph_.add_value(out_name, {rows, D});
  const float* gamma = weight(weight_prefix + ".weight", {D});
  const float* beta = weight(weight_prefix + ".bias", {D});
  // Right after the int8 linear that wrote x (post-norm: its residual add), the linear normalizes
  // its own rows; its codes, if any are asked for, become the norm's.
  auto* linear = dynamic_cast<LinearS8Op*>(graph_.ops().back().get());
  if (linear != nullptr && linear->row_output() == x && !row_codes_.contains(x)) {
    linear->fuse_layernorm(gamma, beta, y);
    row_codes_writers_.erase(x);
    row_codes_writers_[y] = linear;
    return y;
  }
  auto op = std::make_unique<LayerNormOp>(rows, D, gamma, beta, x, y);
  row_codes_writers_[y] = op.get();
  add(std::move(op), out_name);
  return y;
}

// `name` by value: it may be a graph value's name, and adding values may move it.
RowCodes ActNetwork::add_row_codes(std::string name, int rows, int cols, std::optional<kernels::QuantS8> fixed) {
  RowCodes codes;
  codes.codes = graph_.add_value(name + "_s8", {rows, cols}, DataType::kS8);
  codes.cols = cols;
  codes.fixed = fixed;
  if (fixed) {
    graph_.value(codes.codes).quant = fixed;
  } else {
    codes.scale = graph_.add_value(name + "_scale", {rows});
    codes.zero_point = graph_.add_value(name + "_zero_point", {rows}, DataType::kS32);
  }
  return codes;
}

ValueId ActNetwork::whole_value(const MatrixRef& x, int rows, int cols) const {
  const bool whole = x.value != kNoValue && x.col_offset == 0 && x.ld == static_cast<size_t>(cols) &&
                     graph_.value(x.value).shape == std::vector<int64_t>{rows, cols};
  return whole ? x.value : kNoValue;
}

std::optional<kernels::QuantS8> ActNetwork::linear_input_quant(const MatrixRef& x, int rows, int cols) const {
  const ValueId v = whole_value(x, rows, cols);
  if (v == kNoValue) return std::nullopt;
  const auto it = quant_.activations.find(graph_.value(v).name);
  if (it == quant_.activations.end()) return std::nullopt;
  return kernels::QuantS8{it->second.scale, it->second.zero_point};
}

RowCodes ActNetwork::producer_row_codes(const MatrixRef& x, int rows, int cols) {
  if (whole_value(x, rows, cols) == kNoValue) return {};
  if (auto it = row_codes_.find(x.value); it != row_codes_.end()) return it->second;
  const auto writer = row_codes_writers_.find(x.value);
  if (writer == row_codes_writers_.end()) return {};
  const RowCodes codes = add_row_codes(graph_.value(x.value).name, rows, cols, linear_input_quant(x, rows, cols));
  writer->second->write_row_codes(codes);
  return row_codes_[x.value] = codes;
}

ValueId ActNetwork::attention(const std::string& out_name, int nq, int nk, MatrixRef q, MatrixRef k, MatrixRef v) {
  const int D = config_.dim_model;
  const ValueId y = graph_.add_value(out_name, {nq, D});
  if (config_.precision == Precision::kInt8 && quant_.int8_attention) {
    add(std::make_unique<AttentionS8Op>(kernels_.gemm_s8, nq, nk, D, config_.n_heads, q, k, v, y), out_name);
  } else {
    add(std::make_unique<AttentionOp>(kernels_.gemm_f32, nq, nk, D, config_.n_heads, q, k, v, y), out_name);
  }
  return y;
}

ActNetwork::Tensor ActNetwork::camera_image(size_t camera) {
  const CameraConfig& cam = config_.cameras[camera];
  const std::string p = cam_prefix(camera);
  const std::vector<int64_t> image_shape = {cam.height, cam.width, 3};
  // An int8 stem with static activations quantizes the image with fixed parameters: the engine
  // writes those codes itself (what as_s8() would make of the float image), no float image; stored
  // unsigned where the kernels take unsigned activations (no row sums in the stem's GEMM).
  const ActbTensor* stem_weight = tensors_.find(bn::conv_weight(config_.stem().name));
  const bool s8_image = quant_.static_activations() && stem_weight != nullptr && stem_weight->dtype == DType::kI8;
  Tensor image;
  if (s8_image) {
    const ActivationQuant& a = quant_.activation(p + "image");
    const kernels::QuantS8 q{a.scale, a.zero_point};
    const bool stored_unsigned = kernels_.gemm_s8.pack_u8a != nullptr;
    image = Tensor{graph_.add_input(p + "image", image_shape, stored_unsigned ? DataType::kU8 : DataType::kS8), true, q,
                   kNoValue};
    graph_.value(image.id).quant = q;
  } else {
    image = Tensor{graph_.add_input(p + "image", image_shape), false, {}, kNoValue};
    calibration_point(CalibrationRole::kCameraImage, image.id);
  }
  camera_inputs_.push_back(image.id);
  return image;
}

ActNetwork::Tensor ActNetwork::stem_and_max_pool(const std::string& p, const Tensor& image, int& h, int& w) {
  Tensor x = conv(config_.stem(), image, h, w, true, nullptr, p + "backbone.stem");
  const int pooled_h = kernels::Conv2dShape::out_dim(h, 3, 2, 1, 1);
  const int pooled_w = kernels::Conv2dShape::out_dim(w, 3, 2, 1, 1);
  const std::string pool_name = p + "backbone.maxpool";
  const ValueId pooled = graph_.add_value(pool_name, {pooled_h, pooled_w, 64}, x.s8 ? DataType::kS8 : DataType::kF32);
  // The stem (float, or int8 with an int8 or float output) runs its max-pool itself
  // (fuse_max_pool): conv() added it last.
  Op* stem = graph_.ops().back().get();
  check(stem->outputs[0] == x.id, StatusCode::kInternal, "the stem is not the last op");
  if (auto* int8_stem = dynamic_cast<ConvS8Op*>(stem)) {
    int8_stem->fuse_max_pool(3, 2, 1, pooled);
  } else {
    dynamic_cast<Conv2dOp&>(*stem).fuse_max_pool(3, 2, 1, pooled);
  }
  if (x.s8) {
    graph_.value(pooled).quant = x.q;  // max commutes with quantization: same parameters
    layers_.push_back({stem, pooled, "", true});
  } else {
    calibration_point(CalibrationRole::kMaxPoolOutput, pooled);
  }
  x.id = pooled;
  h = pooled_h;
  w = pooled_w;
  return x;
}

ActNetwork::Tensor ActNetwork::residual_stages(const std::string& p, Tensor x, int& h, int& w) {
  const auto stages = config_.backbone_stages();
  for (size_t s = 0; s < stages.size(); ++s) {
    for (size_t b = 0; b < stages[s].size(); ++b) {
      const BlockSpec& block = stages[s][b];
      const std::string bp = p + "backbone.layer" + std::to_string(s + 1) + "." + std::to_string(b) + ".";
      int sh = h, sw = w;
      Tensor shortcut = x;
      if (block.has_downsample) shortcut = conv(block.downsample, x, sh, sw, false, nullptr, bp + "downsample");
      Tensor y = x;
      int bh = h, bw = w;
      for (size_t i = 0; i < block.convs.size(); ++i) {
        const bool last = i + 1 == block.convs.size();
        const std::string name = last && b + 1 == stages[s].size() ? p + "backbone.layer" + std::to_string(s + 1)
                                                                    : bp + "conv" + std::to_string(i + 1);
        // The last conv of a block adds the shortcut, then ReLU (fused).
        y = conv(block.convs[i], y, bh, bw, true, last ? &shortcut : nullptr, name);
      }
      x = y;
      h = bh;
      w = bw;
    }
  }
  return x;
}

// 1x1 input projection with bias: the NHWC feature map is already [h*w tokens, C] row-major.
ValueId ActNetwork::image_projection(const std::string& p, const Tensor& x, int h, int w, int first_row) {
  const int C = config_.feature_channels(), D = config_.dim_model;
  const std::string proj_name = p + "img_feat_proj";
  const float* proj_bias = weight(bn::kImgProjBias, {D});
  const ValueId y = graph_.add_row_view(proj_name, encoder_tokens_, first_row, h * w);  // written in place
  if (const ActbTensor* q8 = int8_weight(bn::kImgProjWeight, {D, C}); q8 != nullptr && x.s8) {
    // Static int8 features: the projection is a 1x1 int8 conv with a float output.
    ConvS8Spec spec;
    spec.shape = kernels::Conv2dShape::square(h, w, C, D, 1, 1, 0);
    spec.weight = reinterpret_cast<const int8_t*>(q8->data);
    spec.w_scale = q8->quant.scales.data();
    spec.bias = proj_bias;
    spec.input_q = x.q;
    spec.s8_out = false;
    add_layer(std::make_unique<ConvS8Op>(kernels_.gemm_s8, spec, x.id, y), proj_name, y, bn::kImgProjWeight, true);
    calibration_point(CalibrationRole::kImageProjection, y);
    return y;
  }
  linear(proj_name, h * w, C, D, MatrixRef::of(as_f32(x).id, static_cast<size_t>(C)), bn::kImgProjWeight,
         MatrixRef::of_constant(proj_bias, 0), {}, Epilogue::kNone, y);
  calibration_point(CalibrationRole::kImageProjection, y);
  return y;
}

ValueId ActNetwork::backbone(size_t camera, int first_row) {
  const CameraConfig& cam = config_.cameras[camera];
  const std::string p = cam_prefix(camera);
  camera_ = camera;
  const Tensor image = camera_image(camera);
  int h = cam.height, w = cam.width;
  const Tensor pooled = stem_and_max_pool(p, image, h, w);
  const Tensor features = residual_stages(p, pooled, h, w);
  return image_projection(p, features, h, w, first_row);
}

ValueId ActNetwork::ffn(const std::string& prefix, int rows, ValueId x, ValueId residual, const std::string& out_name) {
  const int D = config_.dim_model, F = config_.dim_feedforward;
  const bool glu = config_.activation == Activation::kGlu;
  const Epilogue act = config_.activation == Activation::kRelu ? Epilogue::kRelu
                       : config_.activation == Activation::kGelu ? Epilogue::kGelu
                                                                  : Epilogue::kNone;
  ValueId h = linear(out_name + ".ffn_hidden", rows, D, F, MatrixRef::of(x, static_cast<size_t>(D)), prefix + "linear1.weight",
                     MatrixRef::of_constant(weight(prefix + "linear1.bias", {F}), 0), {}, act);
  int hidden = F;
  if (glu) {
    hidden = F / 2;
    const ValueId g = graph_.add_value(out_name + ".ffn_glu", {rows, hidden});
    auto op = std::make_unique<GluOp>(rows, F, h, g);
    add(std::move(op), out_name + ".ffn_glu");
    h = g;
  }
  const ValueId y = linear(out_name, rows, hidden, D, MatrixRef::of(h, static_cast<size_t>(hidden)), prefix + "linear2.weight",
                           MatrixRef::of_constant(weight(prefix + "linear2.bias", {D}), 0),
                           MatrixRef::of(residual, static_cast<size_t>(D)));
  if (!glu && act != Epilogue::kGelu) tag_ffn_hidden(h);  // GELU has no int32 epilogue: no requantizing
  return y;
}

void ActNetwork::tag_ffn_hidden(ValueId h) {
  const int ffn = 1 + std::accumulate(calibration_points_.begin(), calibration_points_.end(), -1,
                                      [](int most, const CalibrationPoint& p) { return std::max(most, p.ffn); });
  for (CalibrationPoint& p : calibration_points_) {
    if (p.role == CalibrationRole::kLinearInput && p.value == h) p.ffn = ffn;
  }
}

ValueId ActNetwork::self_attention_block(const std::string& p, int rows, ValueId x, const std::string& w) {
  const int D = config_.dim_model;
  const size_t d = static_cast<size_t>(D);
  const ValueId attn_in = config_.pre_norm ? layernorm(p + ".norm1", rows, x, w + "norm1") : x;
  // One GEMM for q, k and v; the positions' share of q and k is in the per-token bias table.
  const ValueId qkv = linear(p + ".qkv", rows, D, 3 * D, MatrixRef::of(attn_in, d), w + "in_proj.weight",
                             MatrixRef::of_constant(bias_table(w + "in_proj.bias", rows, 3 * D, w + "in_proj.weight", 2 * D), 3 * d));
  const ValueId a = attention(p + ".attn", rows, rows, MatrixRef::of(qkv, 3 * d, 0), MatrixRef::of(qkv, 3 * d, d),
                              MatrixRef::of(qkv, 3 * d, 2 * d));
  const ValueId out = linear(p + ".attn_out", rows, D, D, MatrixRef::of(a, d), w + "out_proj.weight",
                             MatrixRef::of_constant(weight(w + "out_proj.bias", {D}), 0), MatrixRef::of(x, d));
  return config_.pre_norm ? out : layernorm(p + ".norm1", rows, out, w + "norm1");
}

ValueId ActNetwork::encoder_layer(int l, ValueId x) {
  const int N = config_.n_tokens();
  const std::string p = "encoder_layer" + std::to_string(l);
  const std::string w = bn::enc(l, "");
  const ValueId x1 = self_attention_block(p, N, x, w);
  const ValueId ffn_in = config_.pre_norm ? layernorm(p + ".norm2", N, x1, w + "norm2") : x1;
  const bool last = l + 1 == config_.n_encoder_layers;
  ValueId out = ffn(w, N, ffn_in, x1, config_.pre_norm ? p + "_out" : p + ".ffn_out");
  if (!config_.pre_norm) out = layernorm(p + "_out", N, out, w + "norm2");
  if (last && config_.pre_norm) return layernorm("encoder_out", N, out, "encoder.norm");
  return out;
}

ValueId ActNetwork::decoder_layer(int l, ValueId y, ValueId memory) {
  const int D = config_.dim_model, N = config_.n_tokens(), T = config_.chunk_size;
  const size_t d = static_cast<size_t>(D);
  const std::string p = "decoder_layer" + std::to_string(l);
  const std::string w = bn::dec(l, "");

  // Self-attention block -> y1 (a constant row for layer 0, whose input is zero).
  MatrixRef y1;
  MatrixRef cross_q;
  if (l == 0) {
    // The norms of its self-attention block (norm1, and pre-norm the queries' norm2) are folded into
    // const_y and cross_q: present for inspection.
    const std::vector<std::string> folded = config_.pre_norm ? std::vector<std::string>{"norm1", "norm2"}
                                                             : std::vector<std::string>{"norm1"};
    for (const std::string& norm : folded) {
      weight(w + norm + ".weight", {D});
      weight(w + norm + ".bias", {D});
    }
    y1 = MatrixRef::of_constant(weight(w + "const_y", {D}), 0);
    cross_q = MatrixRef::of_constant(weight(w + "cross_q", {T, D}), d);
  } else {
    const ValueId s = self_attention_block(p, T, y, w);
    y1 = MatrixRef::of(s, d);
    const ValueId q_in = config_.pre_norm ? layernorm(p + ".norm2", T, s, w + "norm2") : s;
    const ValueId q = linear(p + ".cross_q", T, D, D, MatrixRef::of(q_in, d), w + "cross_q_proj.weight",
                             MatrixRef::of_constant(weight(w + "cross_q_proj.bias", {T, D}), d));
    cross_q = MatrixRef::of(q, d);
  }
  // Cross-attention over the encoder memory: keys carry the encoder positions (folded into the bias table).
  const ValueId kv = linear(p + ".cross_kv", N, D, 2 * D, MatrixRef::of(memory, d), w + "cross_kv_proj.weight",
                            MatrixRef::of_constant(bias_table(w + "cross_kv_proj.bias", N, 2 * D, w + "cross_kv_proj.weight", D), 2 * d));
  const ValueId c = attention(p + ".cross_attn", T, N, cross_q, MatrixRef::of(kv, 2 * d, 0), MatrixRef::of(kv, 2 * d, d));
  ValueId y2 = linear(p + ".cross_out", T, D, D, MatrixRef::of(c, d), w + "cross_out_proj.weight",
                      MatrixRef::of_constant(weight(w + "cross_out_proj.bias", {D}), 0), y1);
  if (!config_.pre_norm) y2 = layernorm(p + ".norm2", T, y2, w + "norm2");
  const ValueId ffn_in = config_.pre_norm ? layernorm(p + ".norm3", T, y2, w + "norm3") : y2;
  ValueId out = ffn(w, T, ffn_in, y2, config_.pre_norm ? p + "_out" : p + ".ffn_out");
  if (!config_.pre_norm) out = layernorm(p + "_out", T, out, w + "norm3");
  return out;
}

ValueId ActNetwork::external_features(size_t camera) {
  const CameraConfig& cam = config_.cameras[camera];
  const ValueId features = graph_.add_input(cam_prefix(camera) + "features",
                                            {config_.feature_height(cam) * config_.feature_width(cam), config_.dim_model});
  camera_inputs_.push_back(features);
  return features;
}

ActNetwork::ActNetwork(const ModelConfig& config, BlobTensors& tensors, const kernels::KernelConfig& kernels,
                       bool external_backbone, const ActNetwork* packed_weights_from)
    : config_(config), tensors_(tensors), kernels_(kernels), packed_weights_from_(packed_weights_from) {
  // blob_model_config checked that an int8 blob has its quantization section.
  if (config_.precision == Precision::kInt8) quant_ = QuantConfig::from_json(tensors_.blob().config().at("quantization"));
  const int D = config_.dim_model, N = config_.n_tokens(), T = config_.chunk_size;
  const size_t d = static_cast<size_t>(D);

  std::vector<ConcatRowsOp::Part> tokens;
  tokens.push_back({MatrixRef::of_constant(weight(bn::kLatentToken, {D}), d), 1});
  // The state tokens are projected by the concatenation (ConcatRowsOp): their weights are always float.
  if (config_.state_dim > 0) {
    const int S = config_.state_dim;
    state_input_ = graph_.add_input("state", {1, S});
    tokens.push_back({MatrixRef::of(state_input_, static_cast<size_t>(S)), 1, packed_weight(bn::kStateProjWeight, {D, S}),
                      weight(bn::kStateProjBias, {D})});
  }
  if (config_.env_state_dim > 0) {
    const int E = config_.env_state_dim;
    env_input_ = graph_.add_input("env_state", {1, E});
    tokens.push_back({MatrixRef::of(env_input_, static_cast<size_t>(E)), 1, packed_weight(bn::kEnvProjWeight, {D, E}),
                      weight(bn::kEnvProjBias, {D})});
  }
  // The image features follow those rows: each camera's projection writes its rows in place (the
  // concatenation then skips them; an external backbone's features are inputs, copied).
  encoder_tokens_ = graph_.add_value("encoder_in_tokens", {N, D});
  int token_row = static_cast<int>(tokens.size());
  stage_ = Stage::kBackbone;
  for (size_t c = 0; c < config_.cameras.size(); ++c) {
    const ValueId feats = external_backbone ? external_features(c) : backbone(c, token_row);
    const int rows = static_cast<int>(graph_.value(feats).shape[0]);
    tokens.push_back({MatrixRef::of(feats, d), rows});
    token_row += rows;
  }
  if (external_backbone) {
    tensors_.skip("backbone.");
    tensors_.skip(bn::kImgProjWeight);
    tensors_.skip(bn::kImgProjBias);
  }
  check(token_row == N, StatusCode::kInternal, "the encoder's tokens do not add up to n_tokens");
  stage_ = Stage::kEncoder;
  ValueId x = encoder_tokens_;
  auto concat = std::make_unique<ConcatRowsOp>(D, std::move(tokens), x);
  add(std::move(concat), "encoder_in_tokens");
  weight(bn::kEncoderPos, {N, D});  // present for inspection; its effect is folded into the bias tables

  for (int l = 0; l < config_.n_encoder_layers; ++l) x = encoder_layer(l, x);
  const ValueId memory = x;

  stage_ = Stage::kDecoder;
  ValueId y = kNoValue;
  for (int l = 0; l < config_.n_decoder_layers; ++l) y = decoder_layer(l, y, memory);
  const ValueId out = layernorm("decoder_out", T, y, "decoder.norm");
  const int A = config_.action_dim;
  // After an int8 linear that runs decoder.norm, the (float) action head runs in its tasks too.
  auto* last = dynamic_cast<LinearS8Op*>(graph_.ops().back().get());
  if (last != nullptr && last->row_output() == out && int8_weight(bn::kHeadWeight, {A, D}) == nullptr) {
    note_linear_input(MatrixRef::of(out, d), T, D, bn::kHeadWeight);
    actions_ = graph_.add_value("actions_normalized", {T, A});
    last->fuse_head(packed_weight(bn::kHeadWeight, {A, D}), weight(bn::kHeadBias, {A}), actions_);
  } else {
    actions_ = linear("actions_normalized", T, D, A, MatrixRef::of(out, d), bn::kHeadWeight,
                      MatrixRef::of_constant(weight(bn::kHeadBias, {A}), 0));
  }
  graph_.mark_output(actions_);

  // Activation parameters are looked up by value name: one naming no value would never be used.
  // (An external backbone's values, all of camera branches "camN.", are elsewhere.)
  for (const auto& [name, q] : quant_.activations) {
    if (graph_.find(name) == kNoValue && !(external_backbone && name.starts_with("cam"))) {
      fail(StatusCode::kDataLoss, "'" + tensors_.blob().path() + "': quantization parameters for \"" + name +
           "\", which is no value of the network");
    }
  }
  packed_weights_from_ = nullptr;  // it need not outlive the build
}

}  // namespace act::graph
