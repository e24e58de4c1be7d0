#include "graph/ops_int8.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>

#include "weights/blob/error.h"

namespace act::graph {

namespace {

constexpr size_t kElementwiseChunk = 1 << 16;  // elements per quantize/dequantize task
constexpr int kLinearTileRows = 120;           // a multiple of every gemm_s8 MR
constexpr int kLinearTileCols = 256;           // a multiple of every gemm_s8 NR
constexpr int kQuantizeTileRows = 32;
constexpr size_t kChannelBlock = 64;           // a multiple of every gemm_s8 NR

size_t ceil_div(size_t a, size_t b) { return (a + b - 1) / b; }

// Symmetric int8 parameters for values in [-absmax, absmax].
kernels::QuantS8 symmetric_quant(float absmax) {
  kernels::QuantS8 q;
  if (absmax > 0.0f && std::isfinite(absmax)) q.scale = absmax / 127.0f;
  return q;
}

}  // namespace

// ------------------------------------------------------------------------------ PackedWeights

void PackedWeights::Free::operator()(void* p) const { std::free(p); }

PackedWeights::PackedWeights(const kernels::GemmS8Kernels& kernels, int n, int k, const int8_t* w, const int32_t* bias,
                             int32_t a_zero_point) {
  check(k >= 1 && k <= kernels::kGemmS8MaxK, ErrorCode::kUnimplemented,
        "an int8 layer with " + std::to_string(k) + " inputs per output (the INT8 kernels take at most " +
            std::to_string(kernels::kGemmS8MaxK) + ")");
  const size_t bytes = kernels.packed_size(n, k);
  const size_t rounded = (bytes + kernels::kGemmS8PackedAlign - 1) / kernels::kGemmS8PackedAlign * kernels::kGemmS8PackedAlign;
  void* p = std::aligned_alloc(kernels::kGemmS8PackedAlign, rounded);
  if (p == nullptr) throw std::bad_alloc();
  buffer_.reset(p);
  kernels.pack(n, k, w, static_cast<size_t>(k), bias, a_zero_point, p);
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

// The int32 bias of the s8-out epilogue: bias / (s_in * s_w[n]), rounded and saturated.
std::vector<int32_t> integer_bias(const ConvS8Spec& s) {
  std::vector<int32_t> out(static_cast<size_t>(s.shape.out_c));
  for (size_t n = 0; n < out.size(); ++n) {
    const double v = std::nearbyint(static_cast<double>(s.bias[n]) / (static_cast<double>(s.input_q.scale) * s.w_scale[n]));
    out[n] = static_cast<int32_t>(std::clamp(v, -2147483648.0, 2147483647.0));
  }
  return out;
}

}  // namespace

ConvS8Op::ConvS8Op(const kernels::GemmS8Kernels& kernels, const ConvS8Spec& spec, ValueId input, ValueId output)
    : spec_(spec), tile_pixels_(kernels::conv_s8_tile_pixels(spec.shape)),
      packed_(kernels, spec.shape.out_c, spec.shape.patch_size(), spec.weight,
              spec.s8_out ? integer_bias(spec).data() : nullptr, spec.input_params == kNoValue ? spec.input_q.zero_point : 0) {
  check(!spec.s8_out || spec.input_params == kNoValue, ErrorCode::kInternal, "an int8-out conv needs static input parameters");
  if (spec.s8_out) {
    requant_scale_.resize(static_cast<size_t>(spec.shape.out_c));
    for (size_t n = 0; n < requant_scale_.size(); ++n) {
      requant_scale_[n] = spec.input_q.scale * spec.w_scale[n] / spec.output_q.scale;
    }
  }
  inputs = {input};
  if (spec.input_params != kNoValue) inputs.push_back(spec.input_params);
  if (spec.residual != kNoValue) inputs.push_back(spec.residual);
  outputs = {output};
}

size_t ConvS8Op::scratch_per_thread() const {
  return ceil_div(kernels::conv_s8_scratch_bytes(spec_.shape, tile_pixels_), sizeof(float));
}

double ConvS8Op::macs() const {
  return static_cast<double>(spec_.shape.out_h) * spec_.shape.out_w * spec_.shape.out_c * spec_.shape.patch_size();
}

void ConvS8Op::run(const RunContext& ctx) const {
  kernels::QuantS8 in_q = spec_.input_q;
  if (spec_.input_params != kNoValue) {
    const float* params = ctx.data(spec_.input_params);
    in_q = {params[0], static_cast<int32_t>(params[1])};
  }
  const kernels::ConvS8 conv{spec_.shape, &ctx.kernels().gemm_s8, packed_.data(), static_cast<int8_t>(in_q.zero_point)};
  const int8_t* x = ctx.data_s8(inputs[0]);
  const int pixels = spec_.shape.out_h * spec_.shape.out_w;
  const size_t n = static_cast<size_t>(spec_.shape.out_c);
  // Few pixel tiles (the deep layers): split the output channels too, in blocks of 64, so every
  // thread gets work without each one streaming all the weights.
  const size_t pixel_tiles = ceil_div(static_cast<size_t>(pixels), static_cast<size_t>(tile_pixels_));
  const size_t wanted = 4 * static_cast<size_t>(ctx.pool().threads());
  const size_t channel_blocks =
      pixel_tiles >= wanted ? 1 : std::min(ceil_div(wanted, pixel_tiles), ceil_div(n, kChannelBlock));
  const size_t channels_per_block = ceil_div(ceil_div(n, channel_blocks), kChannelBlock) * kChannelBlock;
  const size_t tasks = pixel_tiles * channel_blocks;
  struct Tile {
    int p0, count;
    kernels::ConvChannels channels;
  };
  const auto tile = [&](size_t task) {
    const int p0 = static_cast<int>(task / channel_blocks) * tile_pixels_;
    const size_t c0 = (task % channel_blocks) * channels_per_block;
    const int c1 = static_cast<int>(std::min(n, c0 + channels_per_block));
    return Tile{p0, std::min(tile_pixels_, pixels - p0), {static_cast<int>(std::min(c0, n)), c1}};
  };
  if (spec_.s8_out) {
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
    ctx.pool().parallel_for(tasks, [&](size_t task, int thread) {
      const Tile t = tile(task);
      if (t.channels.begin < t.channels.end) kernels::conv_s8_s8out(conv, x, out, t.p0, t.count, ctx.scratch_s8(thread), t.channels);
    });
  } else {
    kernels::GemmS8OutF32 out;
    out.c = ctx.data(outputs[0]);
    out.ldc = n;
    out.w_scale = spec_.w_scale;
    out.a_scale = in_q.scale;
    out.bias = spec_.bias;
    if (spec_.residual != kNoValue) {
      out.residual = ctx.data(spec_.residual);
      out.ldr = n;
    }
    out.relu = spec_.relu;
    ctx.pool().parallel_for(tasks, [&](size_t task, int thread) {
      const Tile t = tile(task);
      if (t.channels.begin < t.channels.end) kernels::conv_s8_f32out(conv, x, out, t.p0, t.count, ctx.scratch_s8(thread), t.channels);
    });
  }
}

// ------------------------------------------------------------------------------------ LinearS8

LinearS8Op::LinearS8Op(const kernels::GemmS8Kernels& kernels, int rows, int in, int out, MatrixRef x, const int8_t* weight,
                       const float* w_scale, MatrixRef bias, MatrixRef residual, Epilogue epilogue, ValueId output,
                       ValueId quantized_x, ValueId row_scale, ValueId row_zero_point)
    : rows_(rows), in_(in), out_(out), x_(x), bias_(bias), residual_(residual), weight_(weight), w_scale_(w_scale),
      epilogue_(epilogue), packed_(kernels, out, in, weight, nullptr, 0) {
  const bool bias_table = bias_.ld != 0;
  const bool has_residual = residual_.value != kNoValue || residual_.constant != nullptr;
  check(!(bias_table && has_residual), ErrorCode::kInternal, "LinearS8Op: a per-row bias table and a residual together");
  for (const MatrixRef* r : {&x_, &bias_, &residual_}) {
    if (r->value != kNoValue) inputs.push_back(r->value);
  }
  outputs = {output, quantized_x, row_scale, row_zero_point};
}

void LinearS8Op::run(const RunContext& ctx) const {
  const float* x = x_.resolve(ctx);
  int8_t* qx = ctx.data_s8(outputs[1]);
  float* row_scale = ctx.data(outputs[2]);
  int32_t* row_zero_point = ctx.data_s32(outputs[3]);
  const size_t in = static_cast<size_t>(in_);
  ctx.pool().parallel_for(ceil_div(static_cast<size_t>(rows_), kQuantizeTileRows), [&](size_t task, int) {
    const int r0 = static_cast<int>(task) * kQuantizeTileRows;
    const int rows = std::min(kQuantizeTileRows, rows_ - r0);
    kernels::quantize_rows_dynamic_f32_s8(ctx.kernels().quant, rows, in_, x + static_cast<size_t>(r0) * x_.ld, x_.ld, qx + r0 * in, in,
                                          row_scale + r0, row_zero_point + r0);
  });

  kernels::GemmS8Args args;
  args.m = rows_;
  args.n = out_;
  args.k = in_;
  args.a = qx;
  args.lda = in;
  args.packed_w = packed_.data();
  args.a_row_zero_point = row_zero_point;
  kernels::GemmS8OutF32 o;
  o.c = ctx.data(outputs[0]);
  o.ldc = static_cast<size_t>(out_);
  o.w_scale = w_scale_;
  o.a_row_scale = row_scale;
  o.relu = epilogue_ == Epilogue::kRelu;
  const bool has_bias = bias_.value != kNoValue || bias_.constant != nullptr;
  const bool has_residual = residual_.value != kNoValue || residual_.constant != nullptr;
  if (has_bias && bias_.ld != 0) {  // a per-row table rides in the residual slot
    o.residual = bias_.resolve(ctx);
    o.ldr = bias_.ld;
  } else {
    if (has_bias) o.bias = bias_.resolve(ctx);
    if (has_residual) {
      o.residual = residual_.resolve(ctx);
      o.ldr = residual_.ld;
    }
  }
  const size_t col_tiles = ceil_div(static_cast<size_t>(out_), kLinearTileCols);
  const size_t row_tiles = ceil_div(static_cast<size_t>(rows_), kLinearTileRows);
  ctx.pool().parallel_for(col_tiles * row_tiles, [&](size_t task, int) {
    const int c0 = static_cast<int>(task % col_tiles) * kLinearTileCols;
    const int r0 = static_cast<int>(task / col_tiles) * kLinearTileRows;
    const int c1 = std::min(out_, c0 + kLinearTileCols);
    const int r1 = std::min(rows_, r0 + kLinearTileRows);
    ctx.kernels().gemm_s8.f32out(args, o, r0, r1, c0, c1);
    if (epilogue_ == Epilogue::kGelu) {
      for (int r = r0; r < r1; ++r) ctx.kernels().elementwise.gelu(static_cast<size_t>(c1 - c0), o.c + static_cast<size_t>(r) * o.ldc + c0);
    }
  });
}

}  // namespace act::graph
