// The FP32 ops of the ACT graph. Each op splits its work into tiles over the thread pool and calls
// the float kernels in kernels/fp32 for each tile.
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "graph/aligned_buffer.h"
#include "graph/fused_max_pool.h"
#include "graph/graph.h"
#include "kernels/common/conv2d_shape.h"
#include "kernels/fp32/conv_f32.h"
#include "kernels/fp32/fp32_kernels.h"

namespace act::graph {

enum class Epilogue { kNone, kRelu, kGelu };

/// The epsilon of every LayerNorm of ACT (torch.nn.LayerNorm's default).
inline constexpr float kLayerNormEps = 1e-5f;

// Each op's parameters are readable (const accessors) so that exporters can translate the graph.

/// What a linear op (float or int8 weights) computes: y[rows, out] = act(x W^T + bias [+ residual]).
struct LinearParams {
  int rows = 0, in = 0, out = 0;
  MatrixRef x, bias, residual;
  Epilogue epilogue = Epilogue::kNone;
};

/// Float weights [n x k] packed once, at graph build time, into the panels of one gemm_f32
/// variant (its nr); shared by the ops that use them (every camera's backbone), and the network's
/// only copy: ActNetwork releases the blob's once they are packed.
class PackedF32Weights {
 public:
  PackedF32Weights(const kernels::GemmF32Kernels& kernels, int n, int k, const float* w);
  /// The panels, for the variant about to run them; an error when its panels are not these.
  const float* for_kernels(const kernels::GemmF32Kernels& kernels) const;
  /// The weights as given, [n x k], unpacked from the panels (for exporters).
  std::vector<float> unpacked() const;
  /// y[rows, n] (row stride ldy) = x[rows, k] W^T + bias[n]: every column, one call of the GEMM
  /// (the few rows the token concatenation and a fused head project).
  void project_rows(const kernels::GemmF32Kernels& kernels, int rows, const float* x, size_t ldx, const float* bias,
                    float* y, size_t ldy) const;
  int rows() const { return n_; }
  int cols() const { return k_; }
  /// The columns of one panel (the gemm_f32 variant's nr).
  int panel_width() const { return nr_; }

 private:
  int nr_, n_, k_;
  AlignedBuffer panels_;  // floats
};

/// NHWC convolution with BatchNorm already folded: y = act(conv(x) + bias [+ residual]).
/// Weights [out_c, kh, kw, in_c], packed at build time. Tiles of output pixels
/// (kernels/fp32/conv_f32.h: im2col of one tile into per-thread scratch, or the input in place), or
/// for the 3x3 stride-1 convs tiles of 2x2 pixels in Winograd's transforms (winograd_f32.h).
class Conv2dOp : public Op {
 public:
  Conv2dOp(std::shared_ptr<const PackedF32Weights> weight, const kernels::Conv2dShape& shape, const float* bias, bool relu,
           ValueId input, ValueId residual, ValueId output);
  const char* type() const override {
    return winograd() ? "conv2d_f32_winograd" : max_pool_ ? "conv2d_f32+maxpool_f32" : "conv2d_f32";
  }
  std::string kernel(const kernels::KernelConfig& k) const override {
    if (winograd()) return std::string("winograd F(2x2,3x3) on ") + k.gemm_f32.name;
    return max_pool_ ? std::string(k.gemm_f32.name) + " + " + k.elementwise.max_taps_name : k.gemm_f32.name;
  }
  void run(const RunContext& ctx) const override;
  size_t scratch_per_thread() const override;
  /// The direct convolution's multiply-adds, the work the model asks for, also when Winograd does
  /// it with 2.25x fewer (its "% of peak" can then pass 100).
  double macs() const override;
  const kernels::Conv2dShape& shape() const { return s_; }
  /// Runs as Winograd F(2x2, 3x3) (kernels/fp32/winograd_f32.h): the 3x3 stride-1 convs of the
  /// ResNet blocks, weights transformed at build time.
  bool winograd() const { return winograd_.data() != nullptr; }
  std::vector<float> weight() const { return packed_->unpacked(); }  ///< [out_c, kh, kw, in_c]
  const float* bias() const { return bias_; }
  bool relu() const { return relu_; }
  ValueId residual() const { return residual_; }

  /// A max-pool of this conv's output (the stem's), run by this op as the int8 stem's is
  /// (ConvS8Op::fuse_max_pool): `pooled` becomes its second output; unless the conv's own output
  /// is read, it is computed and pooled band by band in scratch (19.7 MB never written at 480x640).
  void fuse_max_pool(int kernel, int stride, int pad, ValueId pooled);
  const std::optional<FusedMaxPool>& max_pool() const { return max_pool_; }

 private:
  size_t band_offset() const;  // a fused max-pool's band in a thread's scratch, after the conv's own

  kernels::Conv2dShape s_;
  const float* bias_;
  bool relu_;
  ValueId residual_;
  int tile_pixels_;
  std::shared_ptr<const PackedF32Weights> packed_;
  AlignedBuffer winograd_;  // floats: the transformed weights, packed for packed_'s panel width; empty: direct
  std::optional<FusedMaxPool> max_pool_;
};

/// y[rows, out] = act(x W^T + bias [+ residual]). W is [out, in], packed at build time;
/// bias is a vector (ld 0) or a per-row table; the residual may be a broadcast row.
class LinearOp : public Op {
 public:
  LinearOp(std::shared_ptr<const PackedF32Weights> weight, int rows, int in, int out, MatrixRef x, MatrixRef bias,
           MatrixRef residual, Epilogue epilogue, ValueId output);
  const char* type() const override { return "linear_f32"; }
  std::string kernel(const kernels::KernelConfig& k) const override { return k.gemm_f32.name; }
  void run(const RunContext& ctx) const override;
  double macs() const override { return static_cast<double>(rows_) * in_ * out_; }
  LinearParams params() const { return {rows_, in_, out_, x_, bias_, residual_, epilogue_}; }
  std::vector<float> weight() const { return packed_->unpacked(); }  ///< [out, in]

 private:
  int rows_, in_, out_;
  MatrixRef x_, bias_, residual_;
  Epilogue epilogue_;
  std::shared_ptr<const PackedF32Weights> packed_;
};

/// GLU over the last axis: y = a * sigmoid(b), a the first half of each row, b the second.
class GluOp : public Op {
 public:
  GluOp(int rows, int cols_in, ValueId input, ValueId output);
  const char* type() const override { return "glu_f32"; }
  std::string kernel(const kernels::KernelConfig&) const override { return "scalar"; }
  void run(const RunContext& ctx) const override;

 private:
  int rows_, cols_in_;
};

class LayerNormOp : public Op, public RowCodesWriter {
 public:
  LayerNormOp(int rows, int cols, const float* gamma, const float* beta, ValueId input, ValueId output);
  const char* type() const override { return "layernorm_f32"; }
  std::string kernel(const kernels::KernelConfig& k) const override;
  void run(const RunContext& ctx) const override;
  /// The rows' int8 codes too, each few rows quantized right after they are normalized.
  void write_row_codes(const RowCodes& codes) override;
  const float* gamma() const { return gamma_; }
  const float* beta() const { return beta_; }

 private:
  int rows_, cols_;
  const float* gamma_;
  const float* beta_;
  RowCodes codes_;
};

/// The operands of multi-head attention, the same for the float and the int8 op (and what an
/// exporter reads): q [nq, dim], k and v [nk, dim] as matrix references (usually column slices of
/// one fused projection), `heads` heads of dim / heads columns.
struct AttentionParams {
  int nq, nk, dim, heads;
  MatrixRef q, k, v;
};

/// Multi-head scaled dot-product attention, no mask: out[:, head] = softmax(q_h k_h^T / sqrt(d)) v_h.
/// One task per head packs its keys and values once, then runs QK^T, softmax and P V on the packed
/// gemm_f32 of `gemm` one tile of queries at a time, the tile's scores never leaving L1.
class AttentionOp : public Op {
 public:
  AttentionOp(const kernels::GemmF32Kernels& gemm, int nq, int nk, int dim, int heads, MatrixRef q, MatrixRef k,
              MatrixRef v, ValueId output);
  const char* type() const override { return "attention_f32"; }
  std::string kernel(const kernels::KernelConfig& k) const override {
    return std::string(k.gemm_f32.name) + " + " + k.elementwise.softmax_name;
  }
  void run(const RunContext& ctx) const override;
  size_t scratch_per_thread() const override;
  double macs() const override { return 2.0 * nq_ * nk_ * dim_; }
  AttentionParams params() const { return {nq_, nk_, dim_, heads_, q_, k_, v_}; }

 private:
  int nq_, nk_, dim_, heads_;
  MatrixRef q_, k_, v_;
  int nr_;  ///< the panel width scratch is sized for
};

/// Stacks row blocks (graph values or constant rows) into one [rows, cols] value; a block may be
/// projected on the way (source W^T + bias, W [cols, source width]): the encoder's robot-state and
/// environment-state tokens, a row each. Projected here, they are no ops of their own: a one-row
/// linear ran no faster on two threads than on one, and cost a dispatch on every inference. A block
/// already in place (a row view of the output, written by its producer) is not copied.
class ConcatRowsOp : public Op {
 public:
  struct Part {
    MatrixRef source;
    int rows;
    std::shared_ptr<const PackedF32Weights> projection = nullptr;  ///< none: the rows as they are
    const float* bias = nullptr;                                    ///< the projection's [cols]
  };
  ConcatRowsOp(int cols, std::vector<Part> parts, ValueId output);
  const char* type() const override { return "concat_rows_f32"; }
  std::string kernel(const kernels::KernelConfig& k) const override;
  void run(const RunContext& ctx) const override;
  double macs() const override;
  const std::vector<Part>& parts() const { return parts_; }

 private:
  int cols_;
  std::vector<Part> parts_;
};

}  // namespace act::graph
