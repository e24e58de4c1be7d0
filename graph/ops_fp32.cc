#include "graph/ops_fp32.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "actengine/status.h"
#include "graph/gemm_tiling.h"
#include "kernels/fp32/winograd_f32.h"

namespace act::graph {

namespace {

// A linear task: up to 320 rows (all of ACT's tokens at its camera sizes) by 128 columns (rounded
// up to the panel width). Each task streams its columns' packed float weights once; with tasks of
// 128 rows the encoder's weights streamed three times, and its linears ran at 81-86 % of the FMA
// peak on one thread instead of 86-89 % (the A block of 320 rows x k 256 floats is 320 KB of L2).
constexpr int kLinearTileCols = 128;
constexpr int kLinearTileRows = 320;

kernels::GemmF32Activation activation_of(Epilogue e) {
  switch (e) {
    case Epilogue::kRelu:
      return kernels::GemmF32Activation::kRelu;
    case Epilogue::kGelu:
      return kernels::GemmF32Activation::kGelu;
    case Epilogue::kNone:
      break;
  }
  return kernels::GemmF32Activation::kNone;
}

}  // namespace

// ------------------------------------------------------------------------------------- Conv2d

PackedF32Weights::PackedF32Weights(const kernels::GemmF32Kernels& kernels, int n, int k, const float* w)
    : nr_(kernels.nr), n_(n), k_(k), panels_(kernels::gemm_f32_packed_floats(kernels.nr, n, k) * sizeof(float)) {
  kernels::gemm_f32_pack(nr_, n, k, w, static_cast<size_t>(k), panels_.floats());
}

std::vector<float> PackedF32Weights::unpacked() const {
  std::vector<float> w(static_cast<size_t>(n_) * static_cast<size_t>(k_));
  kernels::gemm_f32_unpack(nr_, n_, k_, panels_.floats(), w.data());
  return w;
}

const float* PackedF32Weights::for_kernels(const kernels::GemmF32Kernels& kernels) const {
  check(kernels.nr == nr_, StatusCode::kInternal,
        std::string("float weights packed in panels of ") + std::to_string(nr_) + " columns, run by " + kernels.name);
  return panels_.floats();
}

void PackedF32Weights::project_rows(const kernels::GemmF32Kernels& kernels, int rows, const float* x, size_t ldx,
                                    const float* bias, float* y, size_t ldy) const {
  kernels::GemmF32PackedArgs args;
  args.m = rows;
  args.n = n_;
  args.k = k_;
  args.a = x;
  args.lda = ldx;
  args.packed_b = for_kernels(kernels);
  args.c = y;
  args.ldc = ldy;
  args.epilogue = {bias, 0};
  kernels.packed(args);
}

Conv2dOp::Conv2dOp(std::shared_ptr<const PackedF32Weights> weight, const kernels::Conv2dShape& shape, const float* bias,
                   bool relu, ValueId input, ValueId residual, ValueId output)
    : s_(shape), bias_(bias), relu_(relu), residual_(residual), tile_pixels_(kernels::conv_f32_tile_pixels(shape)),
      packed_(std::move(weight)) {
  check(packed_->rows() == shape.out_c && packed_->cols() == shape.patch_size(), StatusCode::kInternal,
        "conv2d_f32: packed weights do not match the convolution's shape");
  if (kernels::winograd_f32_applies(shape, relu ? kernels::GemmF32Activation::kRelu : kernels::GemmF32Activation::kNone)) {
    const int nr = packed_->panel_width();
    winograd_ = AlignedBuffer(kernels::winograd_f32_packed_floats(nr, shape) * sizeof(float));
    kernels::winograd_f32_pack(nr, shape, packed_->unpacked().data(), winograd_.floats());
  }
  inputs = {input};
  if (residual != kNoValue) inputs.push_back(residual);
  outputs = {output};
}

void Conv2dOp::fuse_max_pool(int kernel, int stride, int pad, ValueId pooled) {
  check(residual_ == kNoValue && !max_pool_ && !winograd(), StatusCode::kInternal,
        "Conv2dOp: a max-pool fused into a conv with a residual, a pool already or Winograd's tiles");
  max_pool_ = FusedMaxPool::over(s_, kernel, stride, pad);
  outputs.push_back(pooled);
}

size_t Conv2dOp::band_offset() const {
  // In floats; a whole number of 64-byte lines so that the band starts as aligned as the scratch.
  constexpr size_t kLineFloats = 64 / sizeof(float);
  return (kernels::conv_f32_scratch_floats(s_, tile_pixels_) + kLineFloats - 1) / kLineFloats * kLineFloats;
}

size_t Conv2dOp::scratch_per_thread() const {
  if (winograd()) return kernels::winograd_f32_scratch_floats(s_);
  if (!max_pool_) return kernels::conv_f32_scratch_floats(s_, tile_pixels_);
  return band_offset() + max_pool_->band_bytes(static_cast<size_t>(s_.out_w) * s_.out_c * sizeof(float)) / sizeof(float);
}

double Conv2dOp::macs() const {
  return static_cast<double>(s_.out_h) * s_.out_w * s_.out_c * s_.patch_size();
}

void Conv2dOp::run(const RunContext& ctx) const {
  const kernels::ConvF32 conv{s_, &ctx.kernels().gemm_f32, packed_->for_kernels(ctx.kernels().gemm_f32)};
  const float* x = ctx.data(inputs[0]);
  float* y = ctx.data(outputs[0]);
  kernels::GemmF32Epilogue epilogue;
  epilogue.bias = bias_;
  if (residual_ != kNoValue) {
    epilogue.residual = ctx.data(residual_);
    epilogue.residual_ld = static_cast<size_t>(s_.out_c);
  }
  epilogue.activation = relu_ ? kernels::GemmF32Activation::kRelu : kernels::GemmF32Activation::kNone;
  const auto pool_rows = [&](const float* conv_rows, int q0, int q1, int conv_row0) {
    max_pool_->pool_rows(ctx.kernels().elementwise, s_, conv_rows, ctx.data(outputs[1]), q0, q1, conv_row0);
  };
  if (max_pool_ && !ctx.read(outputs[0])) {
    return run_in_pooled_bands(
        ctx.pool(), *max_pool_, s_, sizeof(float), kernels::kConvF32TileQuantum, tile_pixels_,
        [&](int thread) { return reinterpret_cast<std::byte*>(ctx.scratch(thread) + band_offset()); },
        [&](std::byte* band, int first, int count, int band_row0, int thread) {
          kernels::conv_f32(conv, x, reinterpret_cast<float*>(band), epilogue, first, count, ctx.scratch(thread),
                            band_row0 * s_.out_w);
        },
        [&](const std::byte* band, int q0, int q1, int band_row0) {
          pool_rows(reinterpret_cast<const float*>(band), q0, q1, band_row0);
        });
  }
  if (winograd()) {
    // Tasks of whole row tiles of the GEMM: 80 tiles (layer4's) in tasks of 40 gave each GEMM a 4-row tail.
    const EvenSplit tiles = split_evenly(kernels::winograd_f32_tiles(s_), conv.kernels->mr, kernels::kWinogradBlockTiles,
                                         ctx.pool().threads());
    ctx.pool().parallel_for(static_cast<size_t>(tiles.parts), [&](size_t task, int thread) {
      int t0, t1;
      tiles.range(static_cast<int>(task), t0, t1);
      kernels::winograd_f32(*conv.kernels, s_, winograd_.floats(), x, y, epilogue, t0, t1 - t0, ctx.scratch(thread));
    });
    return;
  }
  const EvenSplit tiles = split_evenly(s_.out_h * s_.out_w, kernels::kConvF32TileQuantum, tile_pixels_, ctx.pool().threads());
  ctx.pool().parallel_for(static_cast<size_t>(tiles.parts), [&](size_t task, int thread) {
    int p0, p1;
    tiles.range(static_cast<int>(task), p0, p1);
    kernels::conv_f32(conv, x, y, epilogue, p0, p1 - p0, ctx.scratch(thread));
  });
  if (max_pool_) run_pool_in_row_tasks(ctx.pool(), *max_pool_, [&](int q0, int q1) { pool_rows(y, q0, q1, 0); });
}

// ------------------------------------------------------------------------------------- Linear

LinearOp::LinearOp(std::shared_ptr<const PackedF32Weights> weight, int rows, int in, int out, MatrixRef x, MatrixRef bias,
                   MatrixRef residual, Epilogue epilogue, ValueId output)
    : rows_(rows), in_(in), out_(out), x_(x), bias_(bias), residual_(residual), epilogue_(epilogue),
      packed_(std::move(weight)) {
  check(packed_->rows() == out && packed_->cols() == in, StatusCode::kInternal,
        "linear_f32: packed weights do not match the layer's shape");
  for (const MatrixRef* r : {&x_, &bias_, &residual_}) {
    if (r->value != kNoValue) inputs.push_back(r->value);
  }
  outputs = {output};
}

void LinearOp::run(const RunContext& ctx) const {
  const kernels::GemmF32Kernels& gemm = ctx.kernels().gemm_f32;
  const float* packed = packed_->for_kernels(gemm);
  const float* x = x_.resolve(ctx);
  const bool has_bias = bias_.value != kNoValue || bias_.constant != nullptr;
  const bool has_residual = residual_.value != kNoValue || residual_.constant != nullptr;
  const float* bias = has_bias ? bias_.resolve(ctx) : nullptr;
  const float* residual = has_residual ? residual_.resolve(ctx) : nullptr;
  float* y = ctx.data(outputs[0]);
  // Whole panels per task, as many tasks of each size as the threads can share evenly; the rows too
  // when there are fewer panels than threads (the action head's 14 columns ran on one thread).
  const int threads = ctx.pool().threads();
  const int tile_cols = (kLinearTileCols + gemm.nr - 1) / gemm.nr * gemm.nr;
  const EvenSplit col_tiles = split_evenly(out_, gemm.nr, tile_cols, threads);
  const EvenSplit row_tiles = split_evenly(rows_, gemm.mr, kLinearTileRows, col_tiles.parts < threads ? threads : 1);
  const size_t ldy = static_cast<size_t>(out_);
  ctx.pool().parallel_for(static_cast<size_t>(col_tiles.parts) * static_cast<size_t>(row_tiles.parts), [&](size_t task, int) {
    int c0, c1, r0, r1;
    col_tiles.range(static_cast<int>(task % static_cast<size_t>(col_tiles.parts)), c0, c1);
    row_tiles.range(static_cast<int>(task / static_cast<size_t>(col_tiles.parts)), r0, r1);
    kernels::GemmF32PackedArgs args;
    args.m = r1 - r0;
    args.n = c1 - c0;
    args.k = in_;
    args.a = x + static_cast<size_t>(r0) * x_.ld;
    args.lda = x_.ld;
    args.packed_b = packed;
    args.col0 = c0;
    args.c = y + static_cast<size_t>(r0) * ldy + static_cast<size_t>(c0);
    args.ldc = ldy;
    if (bias) args.epilogue = {bias + static_cast<size_t>(r0) * bias_.ld + static_cast<size_t>(c0), bias_.ld};
    if (residual) {
      args.epilogue.residual = residual + static_cast<size_t>(r0) * residual_.ld + static_cast<size_t>(c0);
      args.epilogue.residual_ld = residual_.ld;
    }
    args.epilogue.activation = activation_of(epilogue_);
    gemm.packed(args);
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

std::string LayerNormOp::kernel(const kernels::KernelConfig& k) const {
  return codes_.present() ? std::string(k.elementwise.layernorm_name) + " + " + k.quant.quantize_name : k.elementwise.layernorm_name;
}

void LayerNormOp::write_row_codes(const RowCodes& codes) {
  check(!codes_.present() && codes.cols == cols_, StatusCode::kInternal, "LayerNormOp: row codes asked for twice or of another width");
  codes_ = codes;
  for (ValueId v : codes.values()) outputs.push_back(v);
}

void LayerNormOp::run(const RunContext& ctx) const {
  const float* x = ctx.data(inputs[0]);
  float* y = ctx.data(outputs[0]);
  constexpr int kMaxRows = 32;  // with codes, quantized while the task's 64 KB of rows are in L2
  const size_t ld = static_cast<size_t>(cols_);
  parallel_ranges(ctx.pool(), rows_, 1, kMaxRows, [&](int r0, int r1, int) {
    ctx.kernels().elementwise.layernorm_rows(r1 - r0, cols_, x + r0 * ld, ld, gamma_, beta_, kLayerNormEps, y + r0 * ld, ld);
    if (codes_.present()) codes_.write(ctx, y + r0 * ld, ld, r0, r1 - r0);
  });
}

// ---------------------------------------------------------------------------------- Attention

AttentionOp::AttentionOp(const kernels::GemmF32Kernels& gemm, int nq, int nk, int dim, int heads, MatrixRef q,
                         MatrixRef k, MatrixRef v, ValueId output)
    : nq_(nq), nk_(nk), dim_(dim), heads_(heads), q_(q), k_(k), v_(v), nr_(gemm.nr) {
  for (const MatrixRef* r : {&q_, &k_, &v_}) {
    if (r->value != kNoValue) inputs.push_back(r->value);
  }
  outputs = {output};
}

namespace {
// Queries per pass: a multiple of every gemm_f32 MR (1, 6, 8) whose scores ([rows x nk], 30 KB at
// ACT's 302 tokens in rows of 320) stay in L1 from QK^T through the softmax to P V.
constexpr int kAttentionTileRows = 24;

// The scores' row stride: the keys rounded up to whole panels, so that QK^T stores whole tiles (the
// packed keys' padding is zero: those scores are 0, and the softmax and P V never read them). The
// panel cut by the 302nd key went through the GEMM's stack tile and a scalar copy: a tenth slower.
int scores_ld(int nk, int nr) { return (nk + nr - 1) / nr * nr; }
}  // namespace

size_t AttentionOp::scratch_per_thread() const {
  const int hd = dim_ / heads_;
  return static_cast<size_t>(kAttentionTileRows) * (static_cast<size_t>(scores_ld(nk_, nr_)) + static_cast<size_t>(hd)) +
         kernels::gemm_f32_packed_floats(nr_, nk_, hd) + kernels::gemm_f32_packed_floats(nr_, hd, nk_);
}

void AttentionOp::run(const RunContext& ctx) const {
  const kernels::GemmF32Kernels& gemm = ctx.kernels().gemm_f32;
  check(gemm.nr == nr_, StatusCode::kInternal,
        "attention scratch sized for panels of " + std::to_string(nr_) + " columns, run by " + gemm.name);
  const float* q = q_.resolve(ctx);
  const float* k = k_.resolve(ctx);
  const float* v = v_.resolve(ctx);
  float* out = ctx.data(outputs[0]);
  const int hd = dim_ / heads_;
  const float scale = 1.0f / std::sqrt(static_cast<float>(hd));
  const int ld = scores_ld(nk_, nr_);
  // One task per head: its keys and values packed once, then one pass per tile of queries.
  ctx.pool().parallel_for(static_cast<size_t>(heads_), [&](size_t task, int thread) {
    const int h = static_cast<int>(task);
    float* scores = ctx.scratch(thread);                                         // [tile rows, ld]
    float* q_scaled = scores + static_cast<size_t>(kAttentionTileRows) * ld;     // [tile rows, hd]
    float* packed_k = q_scaled + static_cast<size_t>(kAttentionTileRows) * hd;
    float* packed_v = packed_k + kernels::gemm_f32_packed_floats(nr_, nk_, hd);
    kernels::gemm_f32_pack(nr_, nk_, hd, k + static_cast<size_t>(h) * hd, k_.ld, packed_k);
    kernels::gemm_f32_pack_transposed(nr_, hd, nk_, v + static_cast<size_t>(h) * hd, v_.ld, packed_v);
    for (int r0 = 0; r0 < nq_; r0 += kAttentionTileRows) {
      const int rows = std::min(kAttentionTileRows, nq_ - r0);
      // PyTorch scales q before q k^T; do the same so rounding matches.
      for (int r = 0; r < rows; ++r) {
        const float* qr = q + static_cast<size_t>(r0 + r) * q_.ld + static_cast<size_t>(h) * hd;
        for (int c = 0; c < hd; ++c) q_scaled[static_cast<size_t>(r) * hd + c] = qr[c] * scale;
      }
      gemm.packed({.m = rows, .n = ld, .k = hd, .a = q_scaled, .lda = static_cast<size_t>(hd), .packed_b = packed_k,
                   .c = scores, .ldc = static_cast<size_t>(ld), .epilogue = {}});
      ctx.kernels().elementwise.softmax_rows(rows, nk_, scores, static_cast<size_t>(ld));
      gemm.packed({.m = rows, .n = hd, .k = nk_, .a = scores, .lda = static_cast<size_t>(ld), .packed_b = packed_v,
                   .c = out + static_cast<size_t>(r0) * dim_ + static_cast<size_t>(h) * hd, .ldc = static_cast<size_t>(dim_),
                   .epilogue = {}});
    }
  });
}

// -------------------------------------------------------------------------------- ConcatRows

ConcatRowsOp::ConcatRowsOp(int cols, std::vector<Part> parts, ValueId output) : cols_(cols), parts_(std::move(parts)) {
  for (const auto& p : parts_) {
    check(p.projection == nullptr || (p.projection->rows() == cols && p.bias != nullptr), StatusCode::kInternal,
          "concat_rows_f32: a projection of another width, or without its bias");
    if (p.source.value != kNoValue) inputs.push_back(p.source.value);
  }
  outputs = {output};
}

std::string ConcatRowsOp::kernel(const kernels::KernelConfig& k) const {
  const bool projects = std::any_of(parts_.begin(), parts_.end(), [](const Part& p) { return p.projection != nullptr; });
  return projects ? std::string("memcpy + ") + k.gemm_f32.name : "memcpy";
}

double ConcatRowsOp::macs() const {
  double macs = 0;
  for (const auto& p : parts_) {
    if (p.projection != nullptr) macs += static_cast<double>(p.rows) * p.projection->cols() * cols_;
  }
  return macs;
}

void ConcatRowsOp::run(const RunContext& ctx) const {
  constexpr int kMaxRows = 32;
  float* y = ctx.data(outputs[0]);
  int total_rows = 0;
  for (const auto& p : parts_) total_rows += p.rows;
  // Bands of output rows over the pool; each band copies its rows from whichever parts they lie in.
  parallel_ranges(ctx.pool(), total_rows, 1, kMaxRows, [&](int begin, int end, int) {
    int part_start = 0;
    for (const auto& p : parts_) {
      const int from = std::max(begin, part_start), to = std::min(end, part_start + p.rows);
      const float* src = from < to ? p.source.resolve(ctx) + static_cast<size_t>(from - part_start) * p.source.ld : nullptr;
      if (from < to && p.projection != nullptr) {
        p.projection->project_rows(ctx.kernels().gemm_f32, to - from, src, p.source.ld, p.bias,
                                   y + static_cast<size_t>(from) * cols_, static_cast<size_t>(cols_));
      } else if (src != y + static_cast<size_t>(from) * cols_) {  // else written in place (a row view)
        for (int r = from; r < to; ++r) {
          std::memcpy(y + static_cast<size_t>(r) * cols_, src + static_cast<size_t>(r - from) * p.source.ld,
                      static_cast<size_t>(cols_) * sizeof(float));
        }
      }
      part_start += p.rows;
    }
  });
}

}  // namespace act::graph
