#include "graph/ops_int8.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>

#include "actengine/status.h"
#include "graph/gemm_tiling.h"

namespace act::graph {

static_assert(kAlignedBufferAlign % kernels::kGemmS8PackedAlign == 0, "packed weights live in AlignedBuffers");

namespace {

constexpr size_t kElementwiseChunk = 1 << 16;  // elements per quantize/dequantize task
constexpr int kQuantizeTileRows = 32;
constexpr size_t kChannelBlock = 64;           // a multiple of every gemm_s8 NR

size_t ceil_div(size_t a, size_t b) { return (a + b - 1) / b; }
// `bytes` rounded up to whole 64-byte lines, the alignment packed weights need.
size_t round_up_to_packed_align(size_t bytes) { return ceil_div(bytes, kernels::kGemmS8PackedAlign) * kernels::kGemmS8PackedAlign; }

// Symmetric int8 parameters for values in [-absmax, absmax].
kernels::QuantS8 symmetric_quant(float absmax) {
  kernels::QuantS8 q;
  if (absmax > 0.0f && std::isfinite(absmax)) q.scale = absmax / 127.0f;
  return q;
}

}  // namespace

// --------------------------------------------------------------------------------- PackedWeights

PackedWeights::PackedWeights(const kernels::GemmS8Kernels& kernels, int n, int k, const int8_t* w, const int32_t* bias,
                             int32_t a_zero_point, bool unsigned_activations) {
  check(k >= 1 && k <= kernels::kGemmS8MaxK, StatusCode::kUnimplemented,
        "an int8 layer with " + std::to_string(k) + " inputs per output (the INT8 kernels take at most " +
            std::to_string(kernels::kGemmS8MaxK) + ")");
  buffer_ = AlignedBuffer(kernels.packed_size(n, k));
  if (unsigned_activations) {
    check(kernels.pack_u8a != nullptr, StatusCode::kInternal, "unsigned activations on a gemm_s8 variant without them");
    kernels.pack_u8a(n, k, w, static_cast<size_t>(k), bias, a_zero_point, buffer_.data());
  } else {
    repack(kernels, n, k, w, bias, a_zero_point);
  }
}

void PackedWeights::repack(const kernels::GemmS8Kernels& kernels, int n, int k, const int8_t* w, const int32_t* bias,
                           int32_t a_zero_point) {
  kernels.pack(n, k, w, static_cast<size_t>(k), bias, a_zero_point, buffer_.data());
}

// --------------------------------------------------------------------------- Quantize / Dequantize

QuantizeOp::QuantizeOp(size_t elements, kernels::QuantS8 q, ValueId input, ValueId output)
    : elements_(elements), q_(q), dynamic_(false) {
  inputs = {input};
  outputs = {output};
}

QuantizeOp::QuantizeOp(size_t elements, ValueId input, ValueId output, ValueId params)
    : elements_(elements), dynamic_(true) {
  inputs = {input};
  outputs = {output, params};
}

void QuantizeOp::run(const RunContext& ctx) const {
  const float* x = ctx.data(inputs[0]);
  int8_t* y = ctx.data_s8(outputs[0]);
  const size_t tasks = ceil_div(elements_, kElementwiseChunk);
  kernels::QuantS8 q = q_;
  if (dynamic_) {
    // Each thread keeps its running max |x| in its scratch; the caller reduces them.
    const int threads = ctx.pool().threads();
    for (int t = 0; t < threads; ++t) ctx.scratch(t)[0] = 0.0f;
    ctx.pool().parallel_for(tasks, [&](size_t task, int thread) {
      const size_t begin = task * kElementwiseChunk;
      float lo, hi;
      ctx.kernels().quant.minmax(std::min(kElementwiseChunk, elements_ - begin), x + begin, &lo, &hi);
      float& absmax = ctx.scratch(thread)[0];
      absmax = std::max({absmax, -lo, hi});
    });
    float absmax = 0.0f;
    for (int t = 0; t < threads; ++t) absmax = std::max(absmax, ctx.scratch(t)[0]);
    q = symmetric_quant(absmax);
    float* params = ctx.data(outputs[1]);
    params[0] = q.scale;
    params[1] = static_cast<float>(q.zero_point);
  }
  const float inv_scale = 1.0f / q.scale;
  ctx.pool().parallel_for(tasks, [&](size_t task, int) {
    const size_t begin = task * kElementwiseChunk;
    ctx.kernels().quant.quantize(std::min(kElementwiseChunk, elements_ - begin), x + begin, inv_scale, q.zero_point, y + begin);
  });
}

DequantizeOp::DequantizeOp(size_t elements, kernels::QuantS8 q, ValueId input, ValueId output)
    : elements_(elements), q_(q) {
  inputs = {input};
  outputs = {output};
}

void DequantizeOp::run(const RunContext& ctx) const {
  const int8_t* x = ctx.data_s8(inputs[0]);
  float* y = ctx.data(outputs[0]);
  ctx.pool().parallel_for(ceil_div(elements_, kElementwiseChunk), [&](size_t task, int) {
    const size_t begin = task * kElementwiseChunk;
    ctx.kernels().quant.dequantize(std::min(kElementwiseChunk, elements_ - begin), x + begin, q_.scale, q_.zero_point, y + begin);
  });
}

// ------------------------------------------------------------------------------------- ConvS8

namespace {

// The int32 bias of the s8-out epilogue: bias / (s_in * s_w[n]), rounded and saturated (none
// without a float bias).
std::vector<int32_t> integer_bias(int n, const float* bias, float input_scale, const float* w_scale) {
  std::vector<int32_t> out(bias != nullptr ? static_cast<size_t>(n) : 0);
  for (size_t c = 0; c < out.size(); ++c) {
    const double v = std::nearbyint(static_cast<double>(bias[c]) / (static_cast<double>(input_scale) * w_scale[c]));
    out[c] = static_cast<int32_t>(std::clamp(v, -2147483648.0, 2147483647.0));
  }
  return out;
}

// The s8-out epilogue's per-channel multipliers: s_in * s_w[n] / s_out.
std::vector<float> requant_scales(int n, float input_scale, const float* w_scale, float output_scale) {
  std::vector<float> out(static_cast<size_t>(n));
  for (size_t c = 0; c < out.size(); ++c) out[c] = input_scale * w_scale[c] / output_scale;
  return out;
}

}  // namespace

ConvS8Op::ConvS8Op(const kernels::GemmS8Kernels& kernels, const ConvS8Spec& spec, ValueId input, ValueId output)
    : spec_(spec), tile_pixels_(kernels::conv_s8_tile_pixels(spec.shape)),
      packed_(kernels, spec.shape.out_c, spec.shape.patch_size(), spec.weight,
              spec.s8_out ? integer_bias(spec.shape.out_c, spec.bias, spec.input_q.scale, spec.w_scale).data() : nullptr,
              spec.input_params != kNoValue ? 0 : spec.input_q.zero_point + (spec.unsigned_input ? 128 : 0),
              spec.unsigned_input) {
  check(!spec.s8_out || spec.input_params == kNoValue, StatusCode::kInternal, "an int8-out conv needs static input parameters");
  check(!spec.unsigned_input || spec.input_params == kNoValue, StatusCode::kInternal, "unsigned conv input with dynamic parameters");
  if (spec.s8_out) requant_scale_ = requant_scales(spec.shape.out_c, spec.input_q.scale, spec.w_scale, spec.output_q.scale);
  inputs = {input};
  if (spec.input_params != kNoValue) inputs.push_back(spec.input_params);
  if (spec.residual != kNoValue) inputs.push_back(spec.residual);
  outputs = {output};
}

void ConvS8Op::fuse_max_pool(int kernel, int stride, int pad, ValueId pooled) {
  check(spec_.residual == kNoValue && !max_pool_, StatusCode::kInternal,
        "ConvS8Op: a max-pool fused into a conv with a residual or a pool already");
  max_pool_ = FusedMaxPool::over(spec_.shape, kernel, stride, pad);
  outputs.push_back(pooled);
}

size_t ConvS8Op::band_offset() const {
  return round_up_to_packed_align(kernels::conv_s8_scratch_bytes(spec_.shape, tile_pixels_));
}

size_t ConvS8Op::scratch_per_thread() const {
  size_t bytes = kernels::conv_s8_scratch_bytes(spec_.shape, tile_pixels_);
  if (max_pool_) bytes = band_offset() + max_pool_->band_bytes(static_cast<size_t>(spec_.shape.out_w) * spec_.shape.out_c);
  return ceil_div(bytes, sizeof(float));
}

double ConvS8Op::macs() const {
  return static_cast<double>(spec_.shape.out_h) * spec_.shape.out_w * spec_.shape.out_c * spec_.shape.patch_size();
}

// How a convolution's output is cut into tasks: pixel tiles times blocks of output channels.
struct ConvS8Op::Tasks {
  EvenSplit pixel_split;
  size_t n = 0;  // output channels
  size_t pixel_tiles = 0, channels_per_block = 0, channel_blocks = 0;
  bool channel_major = false;  // all pixel tiles of a channel block, then the next block

  struct Tile {
    int p0, count;
    kernels::ConvChannels channels;
  };
  size_t count() const { return pixel_tiles * channel_blocks; }
  Tile tile(size_t task) const {
    const size_t pixel_tile = channel_major ? task % pixel_tiles : task / channel_blocks;
    const size_t channel_block = channel_major ? task / pixel_tiles : task % channel_blocks;
    int p0, p1;
    pixel_split.range(static_cast<int>(pixel_tile), p0, p1);
    const size_t c0 = channel_block * channels_per_block;
    const int c1 = static_cast<int>(std::min(n, c0 + channels_per_block));
    return Tile{p0, p1 - p0, {static_cast<int>(std::min(c0, n)), c1}};
  }
};

ConvS8Op::Tasks ConvS8Op::plan_tasks(const RunContext& ctx) const {
  Tasks t;
  t.n = static_cast<size_t>(spec_.shape.out_c);
  const size_t n = t.n;
  // Tiles start on whole row tiles of this variant's MR (6 on VNNI), not on the lcm of every MR
  // (12): layer4's 300 pixels are 50 row tiles, 25 per thread, where 25 quanta of 12 split 12 / 13.
  t.pixel_split = split_evenly(spec_.shape.out_h * spec_.shape.out_w, ctx.kernels().gemm_s8.mr, tile_pixels_,
                               ctx.pool().threads());
  // Few pixel tiles (the deep layers): split the output channels too, in blocks of 64, so every
  // thread gets work without each one streaming all the weights.
  t.pixel_tiles = static_cast<size_t>(t.pixel_split.parts);
  const size_t wanted = 4 * static_cast<size_t>(ctx.pool().threads());
  const size_t bytes_per_channel = static_cast<size_t>(spec_.shape.patch_size());  // int8 weights
  // Weights past L2 (layer4's convs, 1.2-2.4 MB): blocks of output channels (64 times a power of
  // two, as even as the channels allow) whose weights fit half of L2, in channel-major task order,
  // so that a thread runs all pixel tiles of a block while its weights stay in its L2 (each pixel
  // tile streamed all of them from L3).
  t.channel_major = bytes_per_channel * n > kL2WeightBytes;
  t.channels_per_block = kChannelBlock;
  if (t.channel_major) {
    while (2 * t.channels_per_block < n && 2 * t.channels_per_block * bytes_per_channel <= kL2WeightBytes / 2) {
      t.channels_per_block *= 2;
    }
  } else if (t.pixel_tiles < wanted) {
    const size_t blocks = std::min(ceil_div(wanted, t.pixel_tiles), ceil_div(n, kChannelBlock));
    t.channels_per_block = ceil_div(ceil_div(n, blocks), kChannelBlock) * kChannelBlock;
  } else {
    t.channels_per_block = n;
  }
  t.channel_blocks = ceil_div(n, t.channels_per_block);
  return t;
}

void ConvS8Op::run(const RunContext& ctx) const {
  kernels::QuantS8 in_q = spec_.input_q;
  if (spec_.input_params != kNoValue) {
    const float* params = ctx.data(spec_.input_params);
    in_q = {params[0], static_cast<int32_t>(params[1])};
  }
  // The padding byte: the zero point's code, stored as the input stores its codes.
  const auto pad = static_cast<int8_t>(spec_.unsigned_input ? in_q.zero_point ^ 0x80 : in_q.zero_point);
  const kernels::ConvS8 conv{spec_.shape, &ctx.kernels().gemm_s8, packed_.data(), pad};
  const int8_t* x = ctx.data_s8(inputs[0]);
  const Tasks tasks = plan_tasks(ctx);
  if (spec_.s8_out) {
    run_s8_out(ctx, conv, x, tasks);
  } else {
    run_f32_out(ctx, conv, x, in_q.scale, tasks);
  }
}

// Requantized int8 output, with a fused max-pool either over bands in scratch (nothing else reads
// the conv's output) or after the whole conv.
void ConvS8Op::run_s8_out(const RunContext& ctx, const kernels::ConvS8& conv, const int8_t* x, const Tasks& tasks) const {
  const size_t n = tasks.n;
  kernels::GemmS8OutS8 out;
  out.c = ctx.data_s8(outputs[0]);
  out.ldc = n;
  out.scale = requant_scale_.data();
  out.out_zero_point = spec_.output_q.zero_point;
  out.qmin = spec_.relu ? spec_.output_q.zero_point : -128;
  if (spec_.residual != kNoValue) {
    out.residual = ctx.data_s8(spec_.residual);
    out.ldr = n;
    out.residual_zero_point = spec_.residual_q.zero_point;
    out.residual_scale = spec_.residual_q.scale / spec_.output_q.scale;
  }
  const kernels::Conv2dShape& s = spec_.shape;
  const auto pool_rows = [&](const int8_t* conv_rows, int q0, int q1, int conv_row0) {
    max_pool_->pool_rows(ctx.kernels().maxpool_s8, s, conv_rows, ctx.data_s8(outputs[1]), q0, q1, conv_row0);
  };
  if (max_pool_ && !ctx.read(outputs[0])) {
    return run_in_pooled_bands(
        ctx.pool(), *max_pool_, s, sizeof(int8_t), kernels::kConvS8TileQuantum, tile_pixels_,
        [&](int thread) { return reinterpret_cast<std::byte*>(ctx.scratch_s8(thread)) + band_offset(); },
        [&](std::byte* band, int first, int count, int band_row0, int thread) {
          kernels::GemmS8OutS8 band_out = out;
          band_out.c = reinterpret_cast<int8_t*>(band);
          kernels::conv_s8_s8out(conv, x, band_out, first, count, ctx.scratch_s8(thread), {}, band_row0 * s.out_w);
        },
        [&](const std::byte* band, int q0, int q1, int band_row0) {
          pool_rows(reinterpret_cast<const int8_t*>(band), q0, q1, band_row0);
        });
  }
  ctx.pool().parallel_for(tasks.count(), [&](size_t task, int thread) {
    const Tasks::Tile t = tasks.tile(task);
    if (t.channels.begin < t.channels.end) kernels::conv_s8_s8out(conv, x, out, t.p0, t.count, ctx.scratch_s8(thread), t.channels);
  });
  if (max_pool_) run_pool_in_row_tasks(ctx.pool(), *max_pool_, [&](int q0, int q1) { pool_rows(out.c, q0, q1, 0); });
}

// Float output (dequantized with the input's scale `a_scale`), a fused max-pool after the whole conv.
void ConvS8Op::run_f32_out(const RunContext& ctx, const kernels::ConvS8& conv, const int8_t* x, float a_scale,
                           const Tasks& tasks) const {
  kernels::GemmS8OutF32 out;
  out.c = ctx.data(outputs[0]);
  out.ldc = tasks.n;
  out.w_scale = spec_.w_scale;
  out.a_scale = a_scale;
  out.bias = spec_.bias;
  if (spec_.residual != kNoValue) {
    out.residual = ctx.data(spec_.residual);
    out.ldr = tasks.n;
  }
  out.relu = spec_.relu;
  ctx.pool().parallel_for(tasks.count(), [&](size_t task, int thread) {
    const Tasks::Tile t = tasks.tile(task);
    if (t.channels.begin < t.channels.end) kernels::conv_s8_f32out(conv, x, out, t.p0, t.count, ctx.scratch_s8(thread), t.channels);
  });
  if (max_pool_) {
    run_pool_in_row_tasks(ctx.pool(), *max_pool_, [&](int q0, int q1) {
      max_pool_->pool_rows(ctx.kernels().elementwise, spec_.shape, out.c, ctx.data(outputs[1]), q0, q1, 0);
    });
  }
}

// ------------------------------------------------------------------------------------ LinearS8

LinearS8Op::LinearS8Op(const kernels::GemmS8Kernels& kernels, int rows, int in, int out, MatrixRef x,
                       const RowCodes& x_codes, InputCodes x_codes_from, const int8_t* weight, const float* w_scale,
                       MatrixRef bias, MatrixRef residual, Epilogue epilogue, ValueId output)
    : rows_(rows), in_(in), out_(out), x_(x), bias_(bias), residual_(residual), x_codes_(x_codes),
      x_codes_from_(x_codes_from), weight_(weight), w_scale_(w_scale), epilogue_(epilogue), mr_(kernels.mr),
      nr_(kernels.nr), table_cols_(out), gemm_(&kernels),
      packed_(kernels, out, in, weight, nullptr, x_codes.per_tensor() ? x_codes.fixed->zero_point : 0) {
  const bool bias_table = bias_.ld != 0;
  const bool has_residual = residual_.value != kNoValue || residual_.constant != nullptr;
  check(!(bias_table && has_residual), StatusCode::kInternal, "LinearS8Op: a per-row bias table and a residual together");
  check(x_codes.cols == in, StatusCode::kInternal, "LinearS8Op: input codes of another width");
  const bool quantized_here = x_codes_from == InputCodes::kQuantizedHere;
  if (quantized_here && x_.value != kNoValue) inputs.push_back(x_.value);
  if (!quantized_here) inputs = x_codes.values();
  for (const MatrixRef* r : {&bias_, &residual_}) {
    if (r->value != kNoValue) inputs.push_back(r->value);
  }
  outputs = {output};
  if (quantized_here) {
    for (ValueId v : x_codes.values()) outputs.push_back(v);
  }
  // A constant per-row bias table whose last columns are the same in every row (the value third of
  // the fused qkv, whose share of the positions is nil) reads them as a bias vector from row 0:
  // fewer bytes streamed per run, the same sums (the table adds to float(acc) * scale + 0, never -0).
  if (bias_table && bias_.constant != nullptr) {
    const float* table = bias_.constant + bias_.col_offset;
    const auto same_in_every_row = [&](int c) {
      for (int r = 1; r < rows; ++r) {
        if (std::memcmp(table + static_cast<size_t>(r) * bias_.ld + c, table + c, sizeof(float)) != 0) return false;
      }
      return true;
    };
    int first_shared = out;
    while (first_shared > 0 && same_in_every_row(first_shared - 1)) --first_shared;
    table_cols_ = std::min(out, static_cast<int>(ceil_div(static_cast<size_t>(first_shared), static_cast<size_t>(nr_))) * nr_);
  }
}

const char* LinearS8Op::type() const {
  if (norms_.empty()) return x_codes_.per_tensor() ? "linear_s8" : "linear_s8_dyn";
  if (head_) return x_codes_.per_tensor() ? "linear_s8+layernorm_f32+linear_f32" : "linear_s8_dyn+layernorm_f32+linear_f32";
  return x_codes_.per_tensor() ? "linear_s8+layernorm_f32" : "linear_s8_dyn+layernorm_f32";
}

double LinearS8Op::macs() const {
  const double head = head_ ? static_cast<double>(rows_) * out_ * head_->weight->rows() : 0.0;
  return static_cast<double>(rows_) * in_ * out_ + head;
}

void LinearS8Op::fuse_head(std::shared_ptr<const PackedF32Weights> weight, const float* bias, ValueId output) {
  check(!head_ && weight->cols() == out_ && bias != nullptr, StatusCode::kInternal,
        "LinearS8Op: a second head, or one of another width");
  head_ = FusedHead{std::move(weight), bias, output};
  outputs.push_back(output);
}

std::string LinearS8Op::kernel(const kernels::KernelConfig& k) const {
  std::string variant = requantizes() ? k.gemm_s8.s8out_name : k.gemm_s8.f32out_name;
  if (x_codes_from_ == InputCodes::kQuantizedHere) variant = std::string(k.quant.quantize_name) + " + " + variant;
  if (!norms_.empty()) variant += std::string(" + ") + k.elementwise.layernorm_name;
  if (y_codes_.present() && !requantizes()) variant += std::string(" + ") + k.quant.quantize_name;
  if (head_) variant += std::string(" + ") + k.gemm_f32.name;
  return variant;
}

void LinearS8Op::fuse_layernorm(const float* gamma, const float* beta, ValueId normed) {
  check(!y_codes_.present(), StatusCode::kInternal, "LinearS8Op: a LayerNorm fused after the output's codes were asked for");
  norms_.push_back({gamma, beta, normed});
  outputs.push_back(normed);
}

void LinearS8Op::write_row_codes(const RowCodes& codes) {
  check(!y_codes_.present() && codes.cols == out_, StatusCode::kInternal, "LinearS8Op: row codes asked for twice or of another width");
  y_codes_ = codes;
  for (ValueId v : codes.values()) outputs.push_back(v);
  if (!norms_.empty()) return;  // the codes of the last norm's output: never requantized by the GEMM
  const bool constant_bias_vector = bias_.value == kNoValue && bias_.ld == 0;
  const bool has_residual = residual_.value != kNoValue || residual_.constant != nullptr;
  if (!y_codes_.per_tensor() || !constant_bias_vector || has_residual ||
      (epilogue_ != Epilogue::kNone && epilogue_ != Epilogue::kRelu)) {
    return;
  }
  const float s_y = y_codes_.fixed->scale;
  const float* bias = bias_.constant != nullptr ? bias_.constant + bias_.col_offset : nullptr;
  if (x_codes_.per_tensor()) {  // one input scale: the bias as int32 in the packed weights
    const float s_x = x_codes_.fixed->scale;
    const std::vector<int32_t> int_bias = integer_bias(out_, bias, s_x, w_scale_);
    packed_.repack(*gemm_, out_, in_, weight_, int_bias.empty() ? nullptr : int_bias.data(), x_codes_.fixed->zero_point);
    requant_scale_ = requant_scales(out_, s_x, w_scale_, s_y);
    return;
  }
  // Per-token input: the rows' scales go into the epilogue, the bias in float (output units).
  requant_scale_ = requant_scales(out_, 1.0f, w_scale_, s_y);
  if (bias != nullptr) {
    requant_bias_.resize(static_cast<size_t>(out_));
    for (size_t n = 0; n < requant_bias_.size(); ++n) requant_bias_[n] = bias[n] / s_y;
  }
}

namespace {
// `codes` of rows [0, rows) of x, in tasks of at most kQuantizeTileRows rows.
void write_codes_in_row_tiles(const RunContext& ctx, const RowCodes& codes, const float* x, size_t ldx, int rows) {
  parallel_ranges(ctx.pool(), rows, 1, kQuantizeTileRows, [&](int r0, int r1, int) {
    codes.write(ctx, x + static_cast<size_t>(r0) * ldx, ldx, r0, r1 - r0);
  });
}
}  // namespace

void LinearS8Op::run(const RunContext& ctx) const {
  const bool quantize_here = x_codes_from_ == InputCodes::kQuantizedHere;
  kernels::GemmS8Args args;
  args.m = rows_;
  args.n = out_;
  args.k = in_;
  args.a = ctx.data_s8(x_codes_.codes);
  args.lda = static_cast<size_t>(in_);
  args.packed_w = packed_.data();
  if (!x_codes_.per_tensor()) args.a_row_zero_point = ctx.data_s32(x_codes_.zero_point);
  if (requantizes()) {
    if (quantize_here) write_codes_in_row_tiles(ctx, x_codes_, x_.resolve(ctx), x_.ld, rows_);
    return run_requantized(ctx, args);
  }
  kernels::GemmS8OutF32 o;
  o.c = ctx.data(outputs[0]);
  o.ldc = static_cast<size_t>(out_);
  o.w_scale = w_scale_;
  if (x_codes_.per_tensor()) {
    o.a_scale = x_codes_.fixed->scale;
  } else {
    o.a_row_scale = ctx.data(x_codes_.scale);
  }
  o.relu = epilogue_ == Epilogue::kRelu;
  const bool has_bias = bias_.value != kNoValue || bias_.constant != nullptr;
  const bool has_residual = residual_.value != kNoValue || residual_.constant != nullptr;
  kernels::GemmS8OutF32 shared_bias_columns = o;  // columns [table_cols_, out_) of a bias table
  if (has_bias && bias_.ld != 0) {  // a per-row table rides in the residual slot
    o.residual = bias_.resolve(ctx);
    o.ldr = bias_.ld;
    shared_bias_columns.bias = o.residual;
  } else {
    if (has_bias) o.bias = bias_.resolve(ctx);
    if (has_residual) {
      o.residual = residual_.resolve(ctx);
      o.ldr = residual_.ld;
    }
  }
  const kernels::GemmS8Kernels& gemm = ctx.kernels().gemm_s8;
  const GemmTiling tiling =
      gemm_tiling(rows_, out_, gemm.mr, gemm.nr, ctx.pool().threads(), finishes_rows(), weight_bytes());
  // Tasks of whole rows normalize and quantize their rows while they are still in cache; else a
  // pass of its own. When nothing reads the float output (its readers take the codes or the
  // norm's output), those rows go to the task's scratch only, never to memory.
  const bool finish_per_task = finishes_rows() && tiling.cols.parts == 1;
  const bool f32_in_scratch = finish_per_task && !ctx.read(outputs[0]);
  // Likewise the input: tasks of whole rows quantize the rows they read first (no pass, no
  // dispatch of its own; the codes still in cache for the GEMM).
  const bool quantize_per_task = quantize_here && tiling.cols.parts == 1;
  const float* x = quantize_here ? x_.resolve(ctx) : nullptr;
  if (quantize_here && !quantize_per_task) write_codes_in_row_tiles(ctx, x_codes_, x, x_.ld, rows_);
  ctx.pool().parallel_for(tiling.count(), [&](size_t task, int thread) {
    int r0, r1, c0, c1;
    tiling.rect(task, r0, r1, c0, c1);
    if (quantize_per_task) x_codes_.write(ctx, x + static_cast<size_t>(r0) * x_.ld, x_.ld, r0, r1 - r0);
    // The task's rows as a GEMM of their own, starting at row r0.
    const size_t row = static_cast<size_t>(r0);
    kernels::GemmS8Args a = args;
    a.m = r1 - r0;
    a.a += row * a.lda;
    if (a.a_row_zero_point != nullptr) a.a_row_zero_point += row;
    kernels::GemmS8OutF32 to = o, shared = shared_bias_columns;
    to.c = shared.c = f32_in_scratch ? ctx.scratch(thread) : o.c + row * o.ldc;
    if (to.a_row_scale != nullptr) to.a_row_scale += row;
    shared.a_row_scale = to.a_row_scale;
    if (to.residual != nullptr) to.residual += row * to.ldr;
    const int split = std::clamp(table_cols_, c0, c1);
    if (c0 < split) gemm.f32out(a, to, 0, a.m, c0, split);
    if (split < c1) gemm.f32out(a, shared, 0, a.m, split, c1);
    if (epilogue_ == Epilogue::kGelu) {
      for (int r = 0; r < a.m; ++r) ctx.kernels().elementwise.gelu(static_cast<size_t>(c1 - c0), to.c + static_cast<size_t>(r) * to.ldc + c0);
    }
    if (finish_per_task) finish_rows(ctx, to.c, to.ldc, r0, a.m);
  });
  if (finishes_rows() && !finish_per_task) {
    parallel_ranges(ctx.pool(), rows_, 1, kQuantizeTileRows, [&](int r0, int r1, int) {
      finish_rows(ctx, o.c + static_cast<size_t>(r0) * o.ldc, o.ldc, r0, r1 - r0);
    });
  }
}

void LinearS8Op::finish_rows(const RunContext& ctx, const float* y, size_t ldy, int r0, int rows) const {
  const size_t ld = static_cast<size_t>(out_);
  for (const FusedLayerNorm& norm : norms_) {
    float* normed = ctx.data(norm.output) + static_cast<size_t>(r0) * ld;
    ctx.kernels().elementwise.layernorm_rows(rows, out_, y, ldy, norm.gamma, norm.beta, kLayerNormEps, normed, ld);
    y = normed;
    ldy = ld;
  }
  if (y_codes_.present()) y_codes_.write(ctx, y, ldy, r0, rows);
  if (head_) {
    const size_t n = static_cast<size_t>(head_->weight->rows());
    head_->weight->project_rows(ctx.kernels().gemm_f32, rows, y, ldy, head_->bias,
                                ctx.data(head_->output) + static_cast<size_t>(r0) * n, n);
  }
}

// The GEMM requantizes into the output codes (bias and ReLU in its int32 epilogue). The float
// output is made from the codes only when something reads it (the converter's per-layer report):
// it is then exactly what the next linear reads.
void LinearS8Op::run_requantized(const RunContext& ctx, const kernels::GemmS8Args& args) const {
  kernels::GemmS8OutS8 o;
  o.c = ctx.data_s8(y_codes_.codes);
  o.ldc = static_cast<size_t>(out_);
  o.scale = requant_scale_.data();
  if (!x_codes_.per_tensor()) o.a_row_scale = ctx.data(x_codes_.scale);
  if (!requant_bias_.empty()) o.bias = requant_bias_.data();
  o.out_zero_point = y_codes_.fixed->zero_point;
  o.qmin = epilogue_ == Epilogue::kRelu ? o.out_zero_point : -128;
  const kernels::GemmS8Kernels& gemm = ctx.kernels().gemm_s8;
  const GemmTiling tiling = gemm_tiling(rows_, out_, gemm.mr, gemm.nr, ctx.pool().threads(), false, weight_bytes());
  ctx.pool().parallel_for(tiling.count(), [&](size_t task, int) {
    int r0, r1, c0, c1;
    tiling.rect(task, r0, r1, c0, c1);
    gemm.s8out(args, o, r0, r1, c0, c1);
  });
  if (!ctx.read(outputs[0])) return;
  const size_t n = static_cast<size_t>(rows_) * static_cast<size_t>(out_);
  ctx.kernels().quant.dequantize(n, o.c, y_codes_.fixed->scale, y_codes_.fixed->zero_point, ctx.data(outputs[0]));
}

size_t LinearS8Op::scratch_per_thread() const {
  if (!finishes_rows() || requantizes()) return 0;
  // The largest whole-row task of any thread count: one thread's strips or two threads' tiles
  // (more threads get smaller ones).
  int tile_rows = 0;
  for (int threads : {1, 2}) tile_rows = std::max(tile_rows, gemm_tiling(rows_, out_, mr_, nr_, threads, true).rows.max_size());
  return static_cast<size_t>(tile_rows) * static_cast<size_t>(out_);
}

// ---------------------------------------------------------------------------------- AttentionS8

namespace {
// Query rows per task: a multiple of every gemm_s8 MR, small enough that the encoder's 8 heads give
// each of 2 threads many tasks (the tail of one late task is short), large enough for the GEMM.
constexpr int kAttentionS8BlockRows = 48;

// Lays out 64-byte aligned buffers one after another (packed weights must be aligned).
struct RegionLayout {
  size_t end = 0;
  size_t add(size_t bytes) {
    const size_t at = end;
    end = round_up_to_packed_align(at + bytes);
    return at;
  }
};

uint8_t* aligned_scratch(const RunContext& ctx, int thread) {
  const size_t misalignment = reinterpret_cast<uintptr_t>(ctx.scratch_s8(thread)) % kernels::kGemmS8PackedAlign;
  return reinterpret_cast<uint8_t*>(ctx.scratch_s8(thread)) + (misalignment ? kernels::kGemmS8PackedAlign - misalignment : 0);
}
}  // namespace

AttentionS8Op::AttentionS8Op(const kernels::GemmS8Kernels& kernels, int nq, int nk, int dim, int heads, MatrixRef q,
                             MatrixRef k, MatrixRef v, ValueId output)
    : nq_(nq), nk_(nk), dim_(dim), heads_(heads), q_(q), k_(k), v_(v) {
  for (const MatrixRef* r : {&q_, &k_, &v_}) {
    if (r->value != kNoValue) inputs.push_back(r->value);
  }
  outputs = {output};
  const size_t hd = static_cast<size_t>(dim / heads), n_keys = static_cast<size_t>(nk);
  const size_t rows = kAttentionS8BlockRows;
  // Each head's packed keys and values, shared by the tasks of its query blocks.
  RegionLayout head;
  layout_.packed_k = head.add(kernels.packed_size(nk, static_cast<int>(hd)));
  layout_.packed_v = head.add(kernels.packed_size(static_cast<int>(hd), nk));
  layout_.k_scale = head.add(n_keys * sizeof(float));
  layout_.v_scale = head.add(hd * sizeof(float));
  layout_.k_s8 = head.add(n_keys * hd);
  layout_.head_bytes = head.end;
  keys_values_ = AlignedBuffer(static_cast<size_t>(heads) * layout_.head_bytes);
  // A thread's scratch: the packing stage's int8 values, then one query block's buffers; int8
  // matrices the GEMM reads as A get the kernels' over-read slack.
  RegionLayout packing, block;
  layout_.v_s8 = packing.add(n_keys * hd);
  layout_.q_s8 = block.add(rows * hd + kernels::kGemmS8ReadSlack);
  layout_.q_scale = block.add(rows * sizeof(float));
  layout_.scores = block.add(rows * n_keys * sizeof(float));
  layout_.p_s8 = block.add(rows * n_keys + kernels::kGemmS8ReadSlack);
  layout_.p_scale = block.add(rows * sizeof(float));
  layout_.scratch_bytes = std::max(packing.end, block.end) + kernels::kGemmS8PackedAlign;  // room to align the start
}

size_t AttentionS8Op::scratch_per_thread() const { return ceil_div(layout_.scratch_bytes, sizeof(float)); }

void* AttentionS8Op::head_at(size_t head, size_t offset) const {
  return static_cast<void*>(keys_values_.data() + head * layout_.head_bytes + offset);
}

// Stage 1a, tasks of key rows (the row bands of the linear that wrote them, so that a thread
// reads rows in its own cache; a task per head read every row, half of them from the other
// core's: encoder attention 2-5 %, the decoder's cross attention 9 % faster on two threads):
// each key quantized per head, one int8 row per token, the 1 / sqrt(d) of the scores folded into
// its scale.
void AttentionS8Op::quantize_keys(const RunContext& ctx, const float* k) const {
  const kernels::KernelConfig& kc = ctx.kernels();
  const int hd = dim_ / heads_;
  const float inv_sqrt_hd = 1.0f / std::sqrt(static_cast<float>(hd));
  const size_t head_dim = static_cast<size_t>(hd);
  const EvenSplit key_rows = gemm_tiling(nk_, dim_, kc.gemm_s8.mr, kc.gemm_s8.nr, ctx.pool().threads()).rows;
  ctx.pool().parallel_for(static_cast<size_t>(key_rows.parts), [&](size_t task, int) {
    int r0, r1;
    key_rows.range(static_cast<int>(task), r0, r1);
    for (size_t head = 0; head < static_cast<size_t>(heads_); ++head) {
      float* k_scale = static_cast<float*>(head_at(head, layout_.k_scale)) + r0;
      kc.quant.quantize_rows_symmetric(r1 - r0, hd, k + static_cast<size_t>(r0) * k_.ld + head * head_dim, k_.ld,
                                       static_cast<int8_t*>(head_at(head, layout_.k_s8)) + static_cast<size_t>(r0) * head_dim,
                                       head_dim, k_scale);
      for (int j = 0; j < r1 - r0; ++j) k_scale[j] *= inv_sqrt_hd;
    }
  });
}

// Stage 1b, a task per head: its int8 keys, and its values quantized, packed as the GEMM's
// weight side.
void AttentionS8Op::pack_keys_and_values(const RunContext& ctx, const float* v) const {
  const kernels::KernelConfig& kc = ctx.kernels();
  const int hd = dim_ / heads_;
  const size_t head_dim = static_cast<size_t>(hd);
  ctx.pool().parallel_for(static_cast<size_t>(heads_), [&](size_t head, int thread) {
    uint8_t* scratch = aligned_scratch(ctx, thread);
    int8_t* v_s8 = reinterpret_cast<int8_t*>(scratch + layout_.v_s8);
    float* v_scale = static_cast<float*>(head_at(head, layout_.v_scale));
    const size_t column = head * head_dim;

    kc.gemm_s8.pack(nk_, hd, static_cast<const int8_t*>(head_at(head, layout_.k_s8)), head_dim, nullptr, 0,
                    head_at(head, layout_.packed_k));
    // Values: one scale per channel (the output columns of p v), quantized where they lie, one row
    // per token, and packed from that transposed view. The probabilities' zero point is the same for
    // every row: fold it into the packed values.
    kc.quant.quantize_columns_symmetric(nk_, hd, v + column, v_.ld, v_s8, head_dim, v_scale);
    kc.gemm_s8.pack_transposed(hd, nk_, v_s8, head_dim, nullptr, kernels::kSoftmaxS8ZeroPoint,
                               head_at(head, layout_.packed_v));
  });
}

// Stage 2, a task per (head, block of query rows): scores = q k^T / sqrt(d), softmax, then p v;
// both GEMMs [rows x n] = A [rows x k] times a packed operand.
// Blocks of whole micro-tiles of rows, as even as they can be (the decoder's 100 queries in blocks
// of 48 left a 4-row block per head).
// Tasks in block-major order when there are two blocks per thread or more (the encoder's 7): the
// pool gives each thread a contiguous range of tasks, so a thread reads the query rows and writes
// the output rows that it produced and that it reads next (the other core's L2 otherwise; encoder
// attention 2-4 % faster on two threads). The decoder's 3 blocks stay head-major (1.005x).
void AttentionS8Op::attend(const RunContext& ctx, const float* q, float* out) const {
  const kernels::KernelConfig& kc = ctx.kernels();
  const int hd = dim_ / heads_;
  const size_t n_keys = static_cast<size_t>(nk_), head_dim = static_cast<size_t>(hd);
  const EvenSplit blocks = split_evenly(nq_, kc.gemm_s8.mr, kAttentionS8BlockRows, 1);
  const size_t heads = static_cast<size_t>(heads_), n_blocks = static_cast<size_t>(blocks.parts);
  const bool block_major = n_blocks >= 2 * static_cast<size_t>(ctx.pool().threads());
  ctx.pool().parallel_for(n_blocks * heads, [&](size_t task, int thread) {
    const size_t head = block_major ? task % heads : task / n_blocks;
    int r0, r1;
    blocks.range(static_cast<int>(block_major ? task / heads : task % n_blocks), r0, r1);
    const int rows = r1 - r0;
    uint8_t* scratch = aligned_scratch(ctx, thread);
    int8_t* q_s8 = reinterpret_cast<int8_t*>(scratch + layout_.q_s8);
    float* q_scale = reinterpret_cast<float*>(scratch + layout_.q_scale);
    float* scores = reinterpret_cast<float*>(scratch + layout_.scores);
    int8_t* p_s8 = reinterpret_cast<int8_t*>(scratch + layout_.p_s8);
    float* p_scale = reinterpret_cast<float*>(scratch + layout_.p_scale);
    const size_t column = head * head_dim;
    // Neither A has zero points: the queries are symmetric, the probabilities' is in the packed values.
    const auto gemm = [&](int n, int k_len, const int8_t* a, size_t lda, const void* packed, const float* a_scale,
                          const float* w_scale, float* c, size_t ldc) {
      const kernels::GemmS8Args args{.m = rows, .n = n, .k = k_len, .a = a, .lda = lda, .packed_w = packed};
      const kernels::GemmS8OutF32 o{.c = c, .ldc = ldc, .w_scale = w_scale, .a_row_scale = a_scale};
      kc.gemm_s8.f32out(args, o, 0, rows, 0, n);
    };
    kc.quant.quantize_rows_symmetric(rows, hd, q + static_cast<size_t>(r0) * q_.ld + column, q_.ld, q_s8, head_dim,
                                     q_scale);
    gemm(nk_, hd, q_s8, head_dim, head_at(head, layout_.packed_k), q_scale,
         static_cast<const float*>(head_at(head, layout_.k_scale)), scores, n_keys);
    kc.elementwise.softmax_rows_s8(rows, nk_, scores, n_keys, p_s8, n_keys, p_scale);
    gemm(hd, nk_, p_s8, n_keys, head_at(head, layout_.packed_v), p_scale,
         static_cast<const float*>(head_at(head, layout_.v_scale)),
         out + static_cast<size_t>(r0) * static_cast<size_t>(dim_) + column, static_cast<size_t>(dim_));
  });
}

void AttentionS8Op::run(const RunContext& ctx) const {
  // The keys of every head must be quantized before any head's are packed.
  quantize_keys(ctx, k_.resolve(ctx));
  pack_keys_and_values(ctx, v_.resolve(ctx));
  attend(ctx, q_.resolve(ctx), ctx.data(outputs[0]));
}

}  // namespace act::graph
