// The INT8 ops of the ACT graph, over the kernels in kernels/gemm_s8, conv_s8, pool_s8 and quant.
// Weights are int8 (symmetric, per output channel) and packed once, here, at graph build time for
// the gemm_s8 variant of the KernelConfig the graph runs with (RunContext::kernels(); the kernels
// check that the packed layout is their own).
//
// Two ways to quantize activations:
//   static   the scale and zero point of every backbone value come from calibration (in the blob);
//            the backbone stays int8 from conv to conv, requantization fused into each conv. The
//            transformer's linear inputs the converter chose per-tensor codes for too.
//   dynamic  the parameters are computed at run time from the data: per tensor (symmetric) for
//            conv inputs, per row (per token, asymmetric) for the other linear inputs.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "graph/aligned_buffer.h"
#include "graph/fused_max_pool.h"
#include "graph/graph.h"
#include "graph/ops_fp32.h"
#include "kernels/conv_s8/conv_s8.h"
#include "kernels/gemm_s8/gemm_s8.h"
#include "kernels/quant/quant_s8.h"

namespace act::graph {

/// Weights packed for one gemm_s8 variant, 64-byte aligned, owned by the op that uses them.
class PackedWeights {
 public:
  /// Packs w [n x k] (int8) with an optional int32 bias and the activation zero point folded in;
  /// with unsigned_activations, by kernels.pack_u8a for uint8 codes (a_zero_point in [0, 255]).
  PackedWeights(const kernels::GemmS8Kernels& kernels, int n, int k, const int8_t* w, const int32_t* bias,
                int32_t a_zero_point, bool unsigned_activations = false);
  /// Packs them again in place with another bias and zero point (the same size: no new memory).
  void repack(const kernels::GemmS8Kernels& kernels, int n, int k, const int8_t* w, const int32_t* bias, int32_t a_zero_point);
  const void* data() const { return buffer_.data(); }

 private:
  AlignedBuffer buffer_;
};

/// float -> int8 per tensor. Static: with fixed parameters. Dynamic: symmetric (zero point 0,
/// scale max|x| / 127) computed from the data at each run and written to `params` ([2] floats:
/// scale, zero point) for the consumer.
class QuantizeOp : public Op {
 public:
  QuantizeOp(size_t elements, kernels::QuantS8 q, ValueId input, ValueId output);                 // static
  QuantizeOp(size_t elements, ValueId input, ValueId output, ValueId params);                     // dynamic
  const char* type() const override { return "quantize_f32_s8"; }
  std::string kernel(const kernels::KernelConfig& k) const override { return k.quant.quantize_name; }
  void run(const RunContext& ctx) const override;
  size_t scratch_per_thread() const override { return 16; }
  bool dynamic() const { return dynamic_; }
  const kernels::QuantS8& quant() const { return q_; }  ///< static parameters

 private:
  size_t elements_;
  kernels::QuantS8 q_;
  bool dynamic_;
};

/// int8 -> float per tensor.
class DequantizeOp : public Op {
 public:
  DequantizeOp(size_t elements, kernels::QuantS8 q, ValueId input, ValueId output);
  const char* type() const override { return "dequantize_s8_f32"; }
  std::string kernel(const kernels::KernelConfig& k) const override { return k.quant.dequantize_name; }
  void run(const RunContext& ctx) const override;
  const kernels::QuantS8& quant() const { return q_; }

 private:
  size_t elements_;
  kernels::QuantS8 q_;
};

/// What a ConvS8Op reads and writes.
struct ConvS8Spec {
  kernels::Conv2dShape shape;
  const int8_t* weight = nullptr;  ///< OHWI [out_c, kh, kw, in_c]
  const float* w_scale = nullptr;  ///< [out_c]
  const float* bias = nullptr;     ///< [out_c] float (BatchNorm folded)
  /// Input parameters: static, or (when input_params is a value) dynamic from a QuantizeOp.
  kernels::QuantS8 input_q;
  ValueId input_params = kNoValue;
  /// The input is stored unsigned (DataType::kU8: code + 128), as kernels with pack_u8a read it
  /// without the signed kernels' row sums; static input parameters only.
  bool unsigned_input = false;
  /// Output: int8 with static parameters (requantized), or float (dequantized).
  bool s8_out = true;
  kernels::QuantS8 output_q;
  bool relu = false;
  /// Optional residual added before the ReLU: int8 (s8 out, with residual_q) or float (f32 out).
  ValueId residual = kNoValue;
  kernels::QuantS8 residual_q;
};

/// NHWC int8 convolution, BatchNorm folded, tiles of output pixels over the pool.
class ConvS8Op : public Op {
 public:
  ConvS8Op(const kernels::GemmS8Kernels& kernels, const ConvS8Spec& spec, ValueId input, ValueId output);
  const char* type() const override {
    if (max_pool_) return spec_.s8_out ? "conv2d_s8_s8+maxpool_s8" : "conv2d_s8_f32+maxpool_f32";
    return spec_.s8_out ? "conv2d_s8_s8" : "conv2d_s8_f32";
  }
  std::string kernel(const kernels::KernelConfig& k) const override {
    std::string gemm = spec_.s8_out ? k.gemm_s8.s8out_name : k.gemm_s8.f32out_name;
    if (spec_.unsigned_input) gemm += std::string(" (") + k.gemm_s8.pack_u8a_name + ")";
    if (!max_pool_) return gemm;
    return gemm + " + " + (spec_.s8_out ? k.maxpool_s8.max_taps_name : k.elementwise.max_taps_name);
  }
  void run(const RunContext& ctx) const override;
  size_t scratch_per_thread() const override;
  double macs() const override;
  const ConvS8Spec& spec() const { return spec_; }

  /// A max-pool of this conv's output (the stem's), run by this op: `pooled` becomes its second
  /// output. With an int8 output that nothing else reads (no kept intermediates), each task
  /// computes bands of its rows in scratch and pools them there (graph/fused_max_pool.h): the whole
  /// output (4.9 MB for the stem at 480x640) never goes to memory and back. Same bits either way
  /// (max is exact). A float output (dynamic mode's stem) is pooled after the whole conv.
  void fuse_max_pool(int kernel, int stride, int pad, ValueId pooled);
  const std::optional<FusedMaxPool>& max_pool() const { return max_pool_; }

 private:
  struct Tasks;
  size_t band_offset() const;  // a fused max-pool's band in a thread's scratch, after the conv's own
  Tasks plan_tasks(const RunContext& ctx) const;
  void run_s8_out(const RunContext& ctx, const kernels::ConvS8& conv, const int8_t* x, const Tasks& tasks) const;
  void run_f32_out(const RunContext& ctx, const kernels::ConvS8& conv, const int8_t* x, float a_scale,
                   const Tasks& tasks) const;

  ConvS8Spec spec_;
  int tile_pixels_;
  PackedWeights packed_;
  std::vector<float> requant_scale_;  // s8 out: s_in * s_w[n] / s_out
  std::optional<FusedMaxPool> max_pool_;
};

/// y[rows, out] = act(x W^T + bias [+ residual]) with W int8 and x read as the int8 codes `x_codes`,
/// per token (quantized per row at run time) or per tensor (calibrated parameters): written by this
/// op, or (kFromProducer) by the op that wrote x, which then need not be read at all. The bias is a
/// vector (ld 0) or a per-row table (then there must be no residual: the table takes the residual's
/// place in the kernel's epilogue). Asked to (write_row_codes), it also writes its output's codes,
/// each task quantizing the rows it has just computed when the tiling gives tasks whole rows; when
/// the output codes are per tensor and the epilogue is a constant bias and ReLU at most (the FFN's
/// hidden layer), the GEMM requantizes straight into them (no float pass at all), with the input's
/// per-row scales in its epilogue when the input is per token.
class LinearS8Op : public Op, public RowCodesWriter {
 public:
  enum class InputCodes { kQuantizedHere, kFromProducer };
  /// A LayerNorm over the op's output rows, run by the op (fuse_layernorm).
  struct FusedLayerNorm {
    const float* gamma;
    const float* beta;
    ValueId output;
  };
  LinearS8Op(const kernels::GemmS8Kernels& kernels, int rows, int in, int out, MatrixRef x, const RowCodes& x_codes,
             InputCodes x_codes_from, const int8_t* weight, const float* w_scale, MatrixRef bias, MatrixRef residual,
             Epilogue epilogue, ValueId output);
  const char* type() const override;
  std::string kernel(const kernels::KernelConfig& k) const override;
  void run(const RunContext& ctx) const override;
  /// With fused LayerNorms, the codes of the last one's output.
  void write_row_codes(const RowCodes& codes) override;
  /// A LayerNorm of the output (post-norm's norm after the residual add), run by this op: `normed`
  /// becomes an output. Tasks of whole rows normalize their rows while they are still in cache, and
  /// the linear's own float output then goes to the task's scratch only, unless something reads
  /// it; no op of its own, no pass over memory, no dispatch (a LayerNorm of the decoder's 100 rows
  /// ran 1.3-1.6x faster on two threads than on one). Called again, it normalizes the previous
  /// norm's output (the decoder's last layer, then decoder.norm). Same bits as LayerNormOp.
  void fuse_layernorm(const float* gamma, const float* beta, ValueId normed);
  const std::vector<FusedLayerNorm>& fused_layernorms() const { return norms_; }
  /// The output whose rows the op finishes last: the last fused norm's, else its own.
  ValueId row_output() const { return norms_.empty() ? outputs[0] : norms_.back().output; }
  /// A float linear of row_output()'s rows, `output` = rows W^T + bias (W [n, out] packed), run by
  /// this op's tasks on the rows they finish: the action head after decoder.norm, whose 28 us as
  /// an op of its own (100 rows, 6 columns) ran 1.5x faster on two threads than on one.
  struct FusedHead {
    std::shared_ptr<const PackedF32Weights> weight;
    const float* bias;
    ValueId output;
  };
  void fuse_head(std::shared_ptr<const PackedF32Weights> weight, const float* bias, ValueId output);
  const std::optional<FusedHead>& fused_head() const { return head_; }
  /// With output codes: one task's float rows, when nothing reads them from memory.
  size_t scratch_per_thread() const override;
  double macs() const override;
  LinearParams params() const { return {rows_, in_, out_, x_, bias_, residual_, epilogue_}; }
  /// The int8 weights' bytes (in x out): past L2, the GEMM's tasks split columns too (gemm_tiling).
  size_t weight_bytes() const { return static_cast<size_t>(in_) * static_cast<size_t>(out_); }
  const int8_t* weight() const { return weight_; }  ///< [out, in], unpacked (in the blob)
  const float* w_scale() const { return w_scale_; }
  /// The per-tensor parameters of the input codes, when they are.
  std::optional<kernels::QuantS8> input_quant() const { return x_codes_.fixed; }

 private:
  /// True when the GEMM writes the output codes itself (requantizing, see above).
  bool requantizes() const { return !requant_scale_.empty(); }
  /// True when the float output rows have more to go through: LayerNorms, quantization, a head.
  bool finishes_rows() const { return y_codes_.present() || !norms_.empty() || head_.has_value(); }
  void run_requantized(const RunContext& ctx, const kernels::GemmS8Args& args) const;
  /// The fused LayerNorms, the output codes and the fused head of `rows` float output rows from row r0.
  void finish_rows(const RunContext& ctx, const float* y, size_t ldy, int r0, int rows) const;

  int rows_, in_, out_;
  MatrixRef x_, bias_, residual_;
  RowCodes x_codes_, y_codes_;
  InputCodes x_codes_from_;
  const int8_t* weight_;
  const float* w_scale_;
  Epilogue epilogue_;
  int mr_, nr_;  // the micro-tile of the gemm_s8 variant the weights are packed for (its tiling)
  int table_cols_;  // output columns that read a per-row bias table; the rest (if any) share row 0's
  const kernels::GemmS8Kernels* gemm_;  // the variant the weights are packed for
  PackedWeights packed_;
  std::vector<float> requant_scale_;  // requantizing: s_x * s_w[n] / s_y (per-token x: s_w[n] / s_y)
  std::vector<float> requant_bias_;   // requantizing a per-token x: bias[n] / s_y (else in the packed weights)
  std::vector<FusedLayerNorm> norms_;
  std::optional<FusedHead> head_;
};

/// softmax(q k^T / sqrt(d)) v per head with both matmuls on the int8 GEMM; AttentionOp is its float
/// twin (same operands, same output layout). Two stages: tasks of key rows quantize each key per
/// head (per token, symmetric) into the op's own buffer, then a task per head quantizes its values
/// (per channel, symmetric) and packs both as the GEMM's weight side; then a task per (head, block
/// of query rows) quantizes the queries per row, symmetric too (no zero-point correction in the
/// GEMM; the action chunk moves no more than with asymmetric rows), and the softmax writes its
/// probabilities straight into int8 (softmax_rows_s8: all 256 codes cover [0, max p] of each
/// row). The op's buffer makes a run of it single-threaded at the graph level, as the graph's own
/// arena already does.
class AttentionS8Op : public Op {
 public:
  AttentionS8Op(const kernels::GemmS8Kernels& kernels, int nq, int nk, int dim, int heads, MatrixRef q, MatrixRef k,
                MatrixRef v, ValueId output);
  const char* type() const override { return "attention_s8"; }
  std::string kernel(const kernels::KernelConfig& k) const override {
    return std::string(k.quant.rows_symmetric_name) + " + " + k.gemm_s8.f32out_name + " + " +
           k.elementwise.softmax_s8_name;
  }
  void run(const RunContext& ctx) const override;
  size_t scratch_per_thread() const override;
  double macs() const override { return 2.0 * nq_ * nk_ * dim_; }
  AttentionParams params() const { return {nq_, nk_, dim_, heads_, q_, k_, v_}; }

 private:
  /// Byte offsets, each 64-byte aligned: of a head's packed keys and values, their scales and its
  /// keys' codes in keys_values_ (head_bytes apart), and of each task's buffers in its thread's
  /// scratch.
  struct Layout {
    size_t packed_k, packed_v, k_scale, v_scale, k_s8, head_bytes;  // k_s8: the keys' codes
    size_t v_s8;                                                    // stage 1
    size_t q_s8, q_scale, scores, p_s8, p_scale;                    // stage 2
    size_t scratch_bytes;
  };
  void* head_at(size_t head, size_t offset) const;  // in keys_values_
  void quantize_keys(const RunContext& ctx, const float* k) const;
  void pack_keys_and_values(const RunContext& ctx, const float* v) const;
  void attend(const RunContext& ctx, const float* q, float* out) const;
  int nq_, nk_, dim_, heads_;
  MatrixRef q_, k_, v_;
  Layout layout_;
  AlignedBuffer keys_values_;
};

}  // namespace act::graph
