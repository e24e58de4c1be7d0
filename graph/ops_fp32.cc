#include "graph/ops_fp32.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "kernels/common/im2col.h"
#include "kernels/pool_s8/maxpool_s8.h"

namespace act::graph {

namespace {

constexpr int kConvTilePixels = 64;   // output pixels per conv task: im2col tile stays in L2
constexpr int kLinearTileCols = 128;  // output columns per linear task
constexpr int kLinearTileRows = 128;

size_t ceil_div(size_t a, size_t b) { return (a + b - 1) / b; }

// bias + residual + activation over a [rows, cols] tile of y (row stride ldy), rows from row0.
void apply_epilogue(const kernels::ElementwiseF32Kernels& k, float* y, size_t ldy, int row0, int rows, int col0, int cols,
                    const float* bias, size_t bias_ld, const float* residual, size_t residual_ld, Epilogue epilogue) {
  for (int r = 0; r < rows; ++r) {
    float* yr = y + static_cast<size_t>(r) * ldy;
    const size_t row = static_cast<size_t>(row0 + r);
    if (bias) {
      const float* br = bias + row * bias_ld + col0;
      for (int c = 0; c < cols; ++c) yr[c] += br[c];
    }
    if (residual) {
      const float* rr = residual + row * residual_ld + col0;
      for (int c = 0; c < cols; ++c) yr[c] += rr[c];
    }
    if (epilogue == Epilogue::kRelu) k.relu(static_cast<size_t>(cols), yr);
    if (epilogue == Epilogue::kGelu) k.gelu(static_cast<size_t>(cols), yr);
  }
}

}  // namespace

// ------------------------------------------------------------------------------------- Conv2d

Conv2dOp::Conv2dOp(const kernels::Conv2dShape& shape, const float* weight, const float* bias, bool relu, ValueId input,
                   ValueId residual, ValueId output)
    : s_(shape), weight_(weight), bias_(bias), relu_(relu), residual_(residual) {
  inputs = {input};
  if (residual != kNoValue) inputs.push_back(residual);
  outputs = {output};
}

bool Conv2dOp::direct() const { return s_.kernel_h == 1 && s_.kernel_w == 1 && s_.stride == 1 && s_.pad == 0; }

size_t Conv2dOp::scratch_per_thread() const {
  return direct() ? 0 : static_cast<size_t>(kConvTilePixels) * s_.patch_size();
}

double Conv2dOp::macs() const {
  return static_cast<double>(s_.out_h) * s_.out_w * s_.out_c * s_.patch_size();
}

void Conv2dOp::run(const RunContext& ctx) const {
  const float* x = ctx.data(inputs[0]);
  const float* residual = residual_ == kNoValue ? nullptr : ctx.data(residual_);
  float* y = ctx.data(outputs[0]);
  const int pixels = s_.out_h * s_.out_w;
  const int k = s_.patch_size();
  const size_t n = static_cast<size_t>(s_.out_c);
  ctx.pool().parallel_for(ceil_div(static_cast<size_t>(pixels), kConvTilePixels), [&](size_t task, int thread) {
    const int p0 = static_cast<int>(task) * kConvTilePixels;
    const int count = std::min(kConvTilePixels, pixels - p0);
    const float* a = x + static_cast<size_t>(p0) * s_.in_c;
    if (!direct()) {
      float* patches = ctx.scratch(thread);
      kernels::im2col_nhwc_f32(s_, x, p0, count, patches);
      a = patches;
    }
    float* yt = y + static_cast<size_t>(p0) * n;
    ctx.kernels().gemm_f32.nt(count, s_.out_c, k, a, static_cast<size_t>(k), weight_, static_cast<size_t>(k), yt, n);
    apply_epilogue(ctx.kernels().elementwise, yt, n, 0, count, 0, s_.out_c, bias_, 0, residual ? residual + static_cast<size_t>(p0) * n : nullptr, n,
                   relu_ ? Epilogue::kRelu : Epilogue::kNone);
  });
}

// ------------------------------------------------------------------------------------ MaxPool

MaxPoolOp::MaxPoolOp(int in_h, int in_w, int channels, int kernel, int stride, int pad, bool s8, ValueId input,
                     ValueId output)
    : in_h_(in_h), in_w_(in_w), channels_(channels), kernel_(kernel), stride_(stride), pad_(pad),
      out_h_(kernels::Conv2dShape::out_dim(in_h, kernel, stride, pad, 1)),
      out_w_(kernels::Conv2dShape::out_dim(in_w, kernel, stride, pad, 1)), s8_(s8) {
  inputs = {input};
  outputs = {output};
}

void MaxPoolOp::run(const RunContext& ctx) const {
  constexpr int kRows = 4;
  ctx.pool().parallel_for(ceil_div(static_cast<size_t>(out_h_), kRows), [&](size_t task, int) {
    const int r0 = static_cast<int>(task) * kRows;
    const int r1 = std::min(out_h_, r0 + kRows);
    if (s8_) {
      kernels::maxpool_nhwc_s8(ctx.kernels().maxpool_s8, in_h_, in_w_, channels_, kernel_, stride_, pad_, out_w_, ctx.data_s8(inputs[0]),
                               ctx.data_s8(outputs[0]), r0, r1);
    } else {
      kernels::maxpool_nhwc_f32(in_h_, in_w_, channels_, kernel_, stride_, pad_, out_h_, out_w_, ctx.data(inputs[0]),
                                ctx.data(outputs[0]), r0, r1);
    }
  });
}

// ------------------------------------------------------------------------------------- Linear

LinearOp::LinearOp(int rows, int in, int out, MatrixRef x, const float* weight, MatrixRef bias, MatrixRef residual,
                   Epilogue epilogue, ValueId output)
    : rows_(rows), in_(in), out_(out), x_(x), bias_(bias), residual_(residual), weight_(weight), epilogue_(epilogue) {
  for (const MatrixRef* r : {&x_, &bias_, &residual_}) {
    if (r->value != kNoValue) inputs.push_back(r->value);
  }
  outputs = {output};
}

void LinearOp::run(const RunContext& ctx) const {
  const float* x = x_.resolve(ctx);
  const bool has_bias = bias_.value != kNoValue || bias_.constant != nullptr;
  const bool has_residual = residual_.value != kNoValue || residual_.constant != nullptr;
  const float* bias = has_bias ? bias_.resolve(ctx) : nullptr;
  const float* residual = has_residual ? residual_.resolve(ctx) : nullptr;
  float* y = ctx.data(outputs[0]);
  const size_t col_tiles = ceil_div(static_cast<size_t>(out_), kLinearTileCols);
  const size_t row_tiles = ceil_div(static_cast<size_t>(rows_), kLinearTileRows);
  const size_t ldy = static_cast<size_t>(out_);
  ctx.pool().parallel_for(col_tiles * row_tiles, [&](size_t task, int) {
    const int c0 = static_cast<int>(task % col_tiles) * kLinearTileCols;
    const int r0 = static_cast<int>(task / col_tiles) * kLinearTileRows;
    const int cols = std::min(kLinearTileCols, out_ - c0);
    const int rows = std::min(kLinearTileRows, rows_ - r0);
    float* yt = y + static_cast<size_t>(r0) * ldy + c0;
    ctx.kernels().gemm_f32.nt(rows, cols, in_, x + static_cast<size_t>(r0) * x_.ld, x_.ld,
                         weight_ + static_cast<size_t>(c0) * in_, static_cast<size_t>(in_), yt, ldy);
    apply_epilogue(ctx.kernels().elementwise, yt, ldy, r0, rows, c0, cols, bias, bias_.ld, residual, residual_.ld, epilogue_);
  });
}

// ---------------------------------------------------------------------------------------- GLU

GluOp::GluOp(int rows, int cols_in, ValueId input, ValueId output) : rows_(rows), cols_in_(cols_in) {
  inputs = {input};
  outputs = {output};
}

void GluOp::run(const RunContext& ctx) const {
  const float* x = ctx.data(inputs[0]);
  float* y = ctx.data(outputs[0]);
  const int half = cols_in_ / 2;
  for (int r = 0; r < rows_; ++r) {
    const float* xr = x + static_cast<size_t>(r) * cols_in_;
    float* yr = y + static_cast<size_t>(r) * half;
    for (int c = 0; c < half; ++c) yr[c] = xr[c] / (1.0f + std::exp(-xr[half + c]));
  }
}

// ---------------------------------------------------------------------------------- LayerNorm

LayerNormOp::LayerNormOp(int rows, int cols, const float* gamma, const float* beta, ValueId input, ValueId output)
    : rows_(rows), cols_(cols), gamma_(gamma), beta_(beta) {
  inputs = {input};
  outputs = {output};
}

void LayerNormOp::run(const RunContext& ctx) const {
  const float* x = ctx.data(inputs[0]);
  float* y = ctx.data(outputs[0]);
  constexpr int kRows = 32;
  const size_t ld = static_cast<size_t>(cols_);
  ctx.pool().parallel_for(ceil_div(static_cast<size_t>(rows_), kRows), [&](size_t task, int) {
    const int r0 = static_cast<int>(task) * kRows;
    const int rows = std::min(kRows, rows_ - r0);
    ctx.kernels().elementwise.layernorm_rows(rows, cols_, x + r0 * ld, ld, gamma_, beta_, kLayerNormEps, y + r0 * ld, ld);
  });
}

// ---------------------------------------------------------------------------------- Attention

AttentionOp::AttentionOp(int nq, int nk, int dim, int heads, MatrixRef q, MatrixRef k, MatrixRef v, ValueId output)
    : nq_(nq), nk_(nk), dim_(dim), heads_(heads), q_(q), k_(k), v_(v) {
  for (const MatrixRef* r : {&q_, &k_, &v_}) {
    if (r->value != kNoValue) inputs.push_back(r->value);
  }
  outputs = {output};
}

namespace {
constexpr int kAttentionTileRows = 128;  // queries per task: K and V are packed once per task, so few big tiles
}

size_t AttentionOp::scratch_per_thread() const {
  const size_t hd = static_cast<size_t>(dim_ / heads_);
  return static_cast<size_t>(kAttentionTileRows) * (static_cast<size_t>(nk_) + hd);
}

void AttentionOp::run(const RunContext& ctx) const {
  const float* q = q_.resolve(ctx);
  const float* k = k_.resolve(ctx);
  const float* v = v_.resolve(ctx);
  float* out = ctx.data(outputs[0]);
  const int hd = dim_ / heads_;
  const float scale = 1.0f / std::sqrt(static_cast<float>(hd));
  const size_t row_tiles = ceil_div(static_cast<size_t>(nq_), kAttentionTileRows);
  ctx.pool().parallel_for(row_tiles * static_cast<size_t>(heads_), [&](size_t task, int thread) {
    const int h = static_cast<int>(task % static_cast<size_t>(heads_));
    const int r0 = static_cast<int>(task / static_cast<size_t>(heads_)) * kAttentionTileRows;
    const int rows = std::min(kAttentionTileRows, nq_ - r0);
    float* scores = ctx.scratch(thread);                        // [rows, nk]
    float* q_scaled = scores + static_cast<size_t>(kAttentionTileRows) * nk_;  // [rows, hd]
    // PyTorch scales q before q k^T; do the same so rounding matches.
    for (int r = 0; r < rows; ++r) {
      const float* qr = q + static_cast<size_t>(r0 + r) * q_.ld + static_cast<size_t>(h) * hd;
      for (int c = 0; c < hd; ++c) q_scaled[static_cast<size_t>(r) * hd + c] = qr[c] * scale;
    }
    ctx.kernels().gemm_f32.nt(rows, nk_, hd, q_scaled, static_cast<size_t>(hd), k + static_cast<size_t>(h) * hd, k_.ld, scores,
                         static_cast<size_t>(nk_));
    ctx.kernels().elementwise.softmax_rows(rows, nk_, scores, static_cast<size_t>(nk_));
    ctx.kernels().gemm_f32.nn(rows, hd, nk_, scores, static_cast<size_t>(nk_), v + static_cast<size_t>(h) * hd, v_.ld,
                         out + static_cast<size_t>(r0) * dim_ + static_cast<size_t>(h) * hd, static_cast<size_t>(dim_));
  });
}

// -------------------------------------------------------------------------------- ConcatRows

ConcatRowsOp::ConcatRowsOp(int cols, std::vector<Part> parts, ValueId output) : cols_(cols), parts_(std::move(parts)) {
  for (const auto& p : parts_) {
    if (p.source.value != kNoValue) inputs.push_back(p.source.value);
  }
  outputs = {output};
}

void ConcatRowsOp::run(const RunContext& ctx) const {
  float* y = ctx.data(outputs[0]);
  for (const auto& p : parts_) {
    const float* src = p.source.resolve(ctx);
    for (int r = 0; r < p.rows; ++r) {
      std::memcpy(y, src + static_cast<size_t>(r) * p.source.ld, static_cast<size_t>(cols_) * sizeof(float));
      y += cols_;
    }
  }
}

}  // namespace act::graph
