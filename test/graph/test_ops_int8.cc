// The INT8 ops against their float twins, and the float attention against a naive scalar
// softmax(Q K^T / sqrt(d)) V, for every ISA level this CPU runs (each a KernelConfig, so every
// gemm_s8, quant and element-wise variant an Engine can use is exercised through the ops).
//
// Tolerances are the quantization error itself, bounded per output: with |dx| <= s_x / 2 (input
// rounding; the range covers the data, so nothing clips) and |dw| <= s_w[n] / 2 (weights, symmetric
// per output channel), each product x w differs by at most |x| |dw| + |w| |dx| + |dx| |dw|; an int8
// output adds its own rounding (s_out / 2) and the integer bias's (s_x s_w[n] / 2 per output).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <type_traits>
#include <vector>

#include "graph/graph.h"
#include "graph/ops_fp32.h"
#include "graph/ops_int8.h"
#include "graph/thread_pool.h"
#include "kernels/config/kernel_config.h"
#include "kernels/quant/quant_s8.h"
#include "kernels/quant/quant_s8_variants.h"
#include "test/kernels/kernel_test_util.h"

namespace act::graph {
namespace {

std::vector<float> uniform(size_t n, std::mt19937& rng, float lo, float hi) {
  std::uniform_real_distribution<float> d(lo, hi);
  std::vector<float> v(n);
  for (float& x : v) x = d(rng);
  return v;
}

// Symmetric per-output-channel int8 weights of w [n x k], as the converter makes them.
struct QuantizedWeights {
  std::vector<int8_t> q;
  std::vector<float> scale;
  std::vector<float> dequantized;
};

QuantizedWeights quantize_weights(const std::vector<float>& w, int n, int k) {
  QuantizedWeights out;
  out.q.resize(w.size());
  out.dequantized.resize(w.size());
  out.scale.resize(static_cast<size_t>(n));
  for (int o = 0; o < n; ++o) {
    const float* row = w.data() + static_cast<size_t>(o) * k;
    float absmax = 0.0f;
    for (int i = 0; i < k; ++i) absmax = std::max(absmax, std::fabs(row[i]));
    const float s = absmax > 0.0f ? absmax / 127.0f : 1.0f;
    out.scale[static_cast<size_t>(o)] = s;
    for (int i = 0; i < k; ++i) {
      const size_t j = static_cast<size_t>(o) * k + i;
      out.q[j] = static_cast<int8_t>(std::clamp(std::nearbyint(w[j] / s), -127.0f, 127.0f));
      out.dequantized[j] = static_cast<float>(out.q[j]) * s;
    }
  }
  return out;
}

// The bound on |sum_i x_i w_i - sum_i x~_i w~_i| for one output (see the file comment).
double product_error_bound(const float* x, const float* w, int k, double s_x, double s_w) {
  double bound = 0.0;
  for (int i = 0; i < k; ++i) {
    bound += std::fabs(x[i]) * s_w / 2 + std::fabs(w[i]) * s_x / 2 + s_x * s_w / 4;
  }
  return bound;
}

class OpsPerIsa : public ::testing::TestWithParam<kernels::Isa> {
 protected:
  kernels::KernelConfig config() const { return kernels::kernel_config_for(GetParam()); }
  ThreadPool pool_{2};
};

// Conv2dShape patches of one output pixel: the im2col row, taps in the padding 0.
std::vector<float> patch_of(const kernels::Conv2dShape& s, const std::vector<float>& x, int pixel) {
  std::vector<float> patch(static_cast<size_t>(s.patch_size()), 0.0f);
  const int oy = pixel / s.out_w, ox = pixel % s.out_w;
  size_t j = 0;
  for (int ky = 0; ky < s.kernel_h; ++ky) {
    for (int kx = 0; kx < s.kernel_w; ++kx) {
      const int iy = oy * s.stride - s.pad + ky * s.dilation, ix = ox * s.stride - s.pad + kx * s.dilation;
      for (int c = 0; c < s.in_c; ++c, ++j) {
        if (iy >= 0 && iy < s.in_h && ix >= 0 && ix < s.in_w) {
          patch[j] = x[(static_cast<size_t>(iy) * s.in_w + ix) * s.in_c + c];
        }
      }
    }
  }
  return patch;
}

// ConvS8Op (static input quantization, int8 weights) against Conv2dOp with the float weights, with
// a float (dequantized) output and with an int8 output + ReLU, for the 3x3 and 1x1/2 shapes of a
// ResNet block, the stem's 7x7/2, and a 3x3 whose weights pass L2 (1.7 MB: blocks of channels in
// channel-major tasks, six blocks of 64, the last one ragged).
TEST_P(OpsPerIsa, ConvS8MatchesFloatConvWithinQuantizationError) {
  const kernels::KernelConfig k = config();
  std::mt19937 rng(7);
  for (const auto& s : {kernels::Conv2dShape::square(9, 11, 16, 40, 3, 1, 1),
                        kernels::Conv2dShape::square(10, 7, 24, 70, 1, 2, 0),
                        kernels::Conv2dShape::square(13, 12, 3, 64, 7, 2, 3),
                        kernels::Conv2dShape::square(5, 4, 512, 360, 3, 1, 1)}) {
    const int pixels = s.out_h * s.out_w, K = s.patch_size();
    const std::vector<float> x = uniform(static_cast<size_t>(s.in_h) * s.in_w * s.in_c, rng, -1.0f, 3.0f);
    const std::vector<float> w = uniform(static_cast<size_t>(s.out_c) * K, rng, -0.5f, 0.5f);
    const std::vector<float> bias = uniform(static_cast<size_t>(s.out_c), rng, -1.0f, 1.0f);
    const QuantizedWeights qw = quantize_weights(w, s.out_c, K);
    const kernels::QuantS8 in_q = kernels::choose_quant_s8(-1.0f, 3.0f);
    // The int8 output's range: the float outputs' (ReLU'd), with a margin for the error.
    float out_max = 0.0f;
    for (int p = 0; p < pixels; ++p) {
      const std::vector<float> patch = patch_of(s, x, p);
      for (int o = 0; o < s.out_c; ++o) {
        float y = bias[static_cast<size_t>(o)];
        for (int i = 0; i < K; ++i) y += patch[static_cast<size_t>(i)] * w[static_cast<size_t>(o) * K + i];
        out_max = std::max(out_max, y);
      }
    }
    const float out_range = 1.25f * out_max + 1.0f;

    for (bool s8_out : {false, true}) {
      Graph g;
      const ValueId in = g.add_input("x", {s.in_h, s.in_w, s.in_c});
      const ValueId in_s8 = g.add_value("x_s8", {s.in_h, s.in_w, s.in_c}, DataType::kS8);
      const ValueId y_float = g.add_value("y_float", {pixels, s.out_c});
      g.add_op(std::make_unique<QuantizeOp>(x.size(), in_q, in, in_s8));
      g.add_op(std::make_unique<Conv2dOp>(std::make_shared<PackedF32Weights>(k.gemm_f32, s.out_c, s.patch_size(), w.data()), s,
                                                 bias.data(), s8_out, in, kNoValue, y_float));
      ConvS8Spec spec;
      spec.shape = s;
      spec.weight = qw.q.data();
      spec.w_scale = qw.scale.data();
      spec.bias = bias.data();
      spec.input_q = in_q;
      spec.s8_out = s8_out;
      spec.relu = s8_out;
      spec.output_q = kernels::choose_quant_s8(0.0f, out_range);
      const ValueId y_q = g.add_value("y_q", {pixels, s.out_c}, s8_out ? DataType::kS8 : DataType::kF32);
      g.add_op(std::make_unique<ConvS8Op>(k.gemm_s8, spec, in_s8, y_q));
      g.mark_output(y_float);
      g.mark_output(y_q);
      g.plan(pool_.threads(), true);
      std::copy(x.begin(), x.end(), g.data(in));
      g.run(pool_, k);

      const float* yf = g.data(y_float);
      for (int p = 0; p < pixels; ++p) {
        const std::vector<float> patch = patch_of(s, x, p);
        for (int o = 0; o < s.out_c; ++o) {
          const size_t i = static_cast<size_t>(p) * s.out_c + o;
          const double s_w = qw.scale[static_cast<size_t>(o)];
          double bound = product_error_bound(patch.data(), w.data() + static_cast<size_t>(o) * K, K, in_q.scale, s_w);
          float got;
          if (s8_out) {
            ASSERT_LT(yf[i], out_range) << "the output range must cover the data";
            got = spec.output_q.scale * (static_cast<float>(g.data_s8(y_q)[i]) - static_cast<float>(spec.output_q.zero_point));
            bound += spec.output_q.scale / 2 + in_q.scale * s_w / 2;
          } else {
            got = g.data(y_q)[i];
          }
          ASSERT_NEAR(got, yf[i], bound + 1e-5 * (1 + std::fabs(yf[i])))
              << kernels::isa_name(GetParam()) << " " << s.kernel_h << "x" << s.kernel_w << "/" << s.stride
              << (s8_out ? " s8 out" : " f32 out") << " pixel " << p << " channel " << o;
        }
      }
    }
  }
}

// Runs a conv with a fused 3x3/2 max-pool (pad 1) from `make_conv(input, conv output, pooled)`
// twice, its own output kept (computed whole, then pooled) and not (computed and pooled band by
// band in scratch), and checks that both pooled outputs are the max over each window's in-image
// outputs of the conv alone.
template <typename T>
T* data_of(Graph& g, ValueId v) {
  if constexpr (std::is_same_v<T, float>) return g.data(v);
  else return g.data_s8(v);
}

template <typename In, typename T>
void expect_fused_max_pool_is_the_max_of_the_conv(
    const kernels::Conv2dShape& s, const std::vector<In>& x, ThreadPool& pool, const kernels::KernelConfig& k,
    const std::function<std::unique_ptr<Op>(ValueId, ValueId, ValueId)>& make_conv, const std::string& what) {
  constexpr DataType in_type = std::is_same_v<In, float> ? DataType::kF32 : DataType::kS8;
  constexpr DataType type = std::is_same_v<T, float> ? DataType::kF32 : DataType::kS8;
  const auto data = [](Graph& g, ValueId v) { return data_of<T>(g, v); };
  const int pooled_h = kernels::Conv2dShape::out_dim(s.out_h, 3, 2, 1, 1), pooled_w = kernels::Conv2dShape::out_dim(s.out_w, 3, 2, 1, 1);
  std::vector<T> conv_out, pooled[2];
  for (const bool keep : {true, false}) {
    Graph g;
    const ValueId in = g.add_input("x", {s.in_h, s.in_w, s.in_c}, in_type);
    const ValueId y = g.add_value("y", {s.out_h, s.out_w, s.out_c}, type);
    const ValueId p = g.add_value("pooled", {pooled_h, pooled_w, s.out_c}, type);
    g.add_op(make_conv(in, y, p));
    g.mark_output(p);
    g.plan(pool.threads(), keep);
    ASSERT_EQ(g.value(y).read, keep) << "the conv's own output is read only when kept: the band path runs otherwise";
    std::copy(x.begin(), x.end(), data_of<In>(g, in));
    g.run(pool, k);
    pooled[keep].assign(data(g, p), data(g, p) + static_cast<size_t>(pooled_h) * pooled_w * s.out_c);
    if (keep) conv_out.assign(data(g, y), data(g, y) + static_cast<size_t>(s.out_h) * s.out_w * s.out_c);
  }
  for (int py = 0; py < pooled_h; ++py) {
    for (int px = 0; px < pooled_w; ++px) {
      for (int c = 0; c < s.out_c; ++c) {
        T want = std::numeric_limits<T>::lowest();
        for (int iy = std::max(0, 2 * py - 1); iy < std::min(s.out_h, 2 * py + 2); ++iy) {
          for (int ix = std::max(0, 2 * px - 1); ix < std::min(s.out_w, 2 * px + 2); ++ix) {
            want = std::max(want, conv_out[(static_cast<size_t>(iy) * s.out_w + ix) * s.out_c + c]);
          }
        }
        const size_t i = (static_cast<size_t>(py) * pooled_w + px) * s.out_c + c;
        for (const bool keep : {true, false}) {
          ASSERT_EQ(pooled[keep][i], want) << what << " " << s.in_h << "x" << s.in_w << " k" << s.kernel_h << " threads "
                                           << pool.threads() << (keep ? " whole" : " in bands") << " pooled (" << py
                                           << ", " << px << ") channel " << c;
        }
      }
    }
  }
}

// Shapes whose pooled rows split unevenly over 1 and 2 threads, tasks of several bands (the
// 190-row one: 48 or 12 pooled rows a task, all in one band; the 640-wide one: its 10 pooled rows in
// one task on one thread, in bands of 4 (int8) or 1 (float), as the stems'), a single row.
std::vector<kernels::Conv2dShape> fused_max_pool_shapes() {
  return {kernels::Conv2dShape::square(45, 37, 3, 64, 7, 2, 3), kernels::Conv2dShape::square(20, 9, 8, 16, 3, 1, 1),
          kernels::Conv2dShape::square(190, 12, 3, 16, 7, 2, 3), kernels::Conv2dShape::square(2, 5, 3, 8, 7, 2, 3),
          kernels::Conv2dShape::square(40, 640, 3, 64, 7, 2, 3)};
}

// A max-pool fused into an int8 conv (the stem's) is the max of the conv's output, int8 or float
// (dynamic mode's stem).
TEST_P(OpsPerIsa, ConvS8WithFusedMaxPoolEqualsTheMaxOfItsOutput) {
  const kernels::KernelConfig k = config();
  std::mt19937 rng(17);
  ThreadPool one(1);
  for (const auto& s : fused_max_pool_shapes()) {
    const int K = s.patch_size();
    std::vector<int8_t> x(static_cast<size_t>(s.in_h) * s.in_w * s.in_c);
    std::uniform_int_distribution<int> code(-128, 127);
    for (int8_t& v : x) v = static_cast<int8_t>(code(rng));
    const QuantizedWeights qw = quantize_weights(uniform(static_cast<size_t>(s.out_c) * K, rng, -0.5f, 0.5f), s.out_c, K);
    const std::vector<float> bias = uniform(static_cast<size_t>(s.out_c), rng, -1.0f, 1.0f);
    ConvS8Spec spec;
    spec.shape = s;
    spec.weight = qw.q.data();
    spec.w_scale = qw.scale.data();
    spec.bias = bias.data();
    spec.input_q = kernels::choose_quant_s8(-1.0f, 1.0f);
    spec.relu = true;
    spec.output_q = kernels::choose_quant_s8(0.0f, 2.0f);
    const auto make_conv = [&](const ConvS8Spec& with) {
      return [&k, with](ValueId in, ValueId y, ValueId pooled) {
        auto conv = std::make_unique<ConvS8Op>(k.gemm_s8, with, in, y);
        conv->fuse_max_pool(3, 2, 1, pooled);
        return conv;
      };
    };
    ConvS8Spec float_out = spec;
    float_out.s8_out = false;
    for (ThreadPool* pool : {&one, &pool_}) {
      expect_fused_max_pool_is_the_max_of_the_conv<int8_t, int8_t>(s, x, *pool, k, make_conv(spec),
                                                                  std::string("int8 ") + kernels::isa_name(GetParam()));
      expect_fused_max_pool_is_the_max_of_the_conv<int8_t, float>(
          s, x, *pool, k, make_conv(float_out), std::string("int8 to float ") + kernels::isa_name(GetParam()));
    }
  }
}

// The float stem's fused max-pool likewise (bias and ReLU, so that some windows are all zero).
TEST_P(OpsPerIsa, FloatConvWithFusedMaxPoolEqualsTheMaxOfItsOutput) {
  const kernels::KernelConfig k = config();
  std::mt19937 rng(18);
  ThreadPool one(1);
  for (const auto& s : fused_max_pool_shapes()) {
    const std::vector<float> x = uniform(static_cast<size_t>(s.in_h) * s.in_w * s.in_c, rng, -1.0f, 1.0f);
    const std::vector<float> w = uniform(static_cast<size_t>(s.out_c) * s.patch_size(), rng, -0.5f, 0.5f);
    const std::vector<float> bias = uniform(static_cast<size_t>(s.out_c), rng, -1.0f, 1.0f);
    const auto packed = std::make_shared<PackedF32Weights>(k.gemm_f32, s.out_c, s.patch_size(), w.data());
    for (ThreadPool* pool : {&one, &pool_}) {
      expect_fused_max_pool_is_the_max_of_the_conv<float, float>(
          s, x, *pool, k,
          [&](ValueId in, ValueId y, ValueId pooled) {
            auto conv = std::make_unique<Conv2dOp>(packed, s, bias.data(), true, in, kNoValue, y);
            conv->fuse_max_pool(3, 2, 1, pooled);
            return conv;
          },
          std::string("float ") + kernels::isa_name(GetParam()));
    }
  }
}

// Per token without `fixed`, else per tensor with those parameters.
RowCodes row_codes(Graph& g, const std::string& name, int rows, int cols, std::optional<kernels::QuantS8> fixed = {}) {
  RowCodes codes;
  codes.codes = g.add_value(name + "_s8", {rows, cols}, DataType::kS8);
  codes.cols = cols;
  codes.fixed = fixed;
  if (!fixed) {
    codes.scale = g.add_value(name + "_scale", {rows});
    codes.zero_point = g.add_value(name + "_zero_point", {rows}, DataType::kS32);
  }
  return codes;
}

// LinearS8Op (activations quantized per row at run time) against LinearOp with the float weights:
// bias, a residual, ReLU; rows around the tile sizes.
TEST_P(OpsPerIsa, LinearS8MatchesFloatLinearWithinQuantizationError) {
  const kernels::KernelConfig k = config();
  std::mt19937 rng(8);
  const int in = 96, out = 70;
  for (int rows : {1, 7, 130}) {
    for (Epilogue epilogue : {Epilogue::kNone, Epilogue::kRelu}) {
     for (const bool per_tensor : {false, true}) {
      std::vector<float> x = uniform(static_cast<size_t>(rows) * in, rng, -2.0f, 2.0f);
      for (int r = 0; r < rows; ++r) x[static_cast<size_t>(r) * in] = 8.0f * static_cast<float>(r % 3);  // row ranges differ
      const auto [lo, hi] = std::minmax_element(x.begin(), x.end());
      const std::optional<kernels::QuantS8> fixed =
          per_tensor ? std::optional(kernels::choose_quant_s8(*lo, *hi)) : std::nullopt;
      const std::vector<float> w = uniform(static_cast<size_t>(out) * in, rng, -0.3f, 0.3f);
      const std::vector<float> bias = uniform(static_cast<size_t>(out), rng, -1.0f, 1.0f);
      const std::vector<float> residual = uniform(static_cast<size_t>(rows) * out, rng, -1.0f, 1.0f);
      const QuantizedWeights qw = quantize_weights(w, out, in);

      Graph g;
      const ValueId xv = g.add_input("x", {rows, in});
      const ValueId rv = g.add_input("residual", {rows, out});
      const ValueId y_float = g.add_value("y_float", {rows, out});
      const ValueId y_q = g.add_value("y_q", {rows, out});
      const RowCodes x_codes = row_codes(g, "x", rows, in, fixed);
      const MatrixRef xr = MatrixRef::of(xv, in), br = MatrixRef::of_constant(bias.data(), 0), rr = MatrixRef::of(rv, out);
      g.add_op(std::make_unique<LinearOp>(std::make_shared<PackedF32Weights>(k.gemm_f32, out, in, w.data()), rows, in, out, xr, br, rr,
                                          epilogue, y_float));
      g.add_op(std::make_unique<LinearS8Op>(k.gemm_s8, rows, in, out, xr, x_codes, LinearS8Op::InputCodes::kQuantizedHere,
                                            qw.q.data(), qw.scale.data(), br, rr, epilogue, y_q));
      g.mark_output(y_float);
      g.mark_output(y_q);
      g.plan(pool_.threads(), true);
      std::copy(x.begin(), x.end(), g.data(xv));
      std::copy(residual.begin(), residual.end(), g.data(rv));
      g.run(pool_, k);

      for (int r = 0; r < rows; ++r) {
        const double s_x = per_tensor ? fixed->scale : g.data(x_codes.scale)[r];
        for (int o = 0; o < out; ++o) {
          const size_t i = static_cast<size_t>(r) * out + o;
          const double bound = product_error_bound(x.data() + static_cast<size_t>(r) * in, w.data() + static_cast<size_t>(o) * in,
                                                   in, s_x, qw.scale[static_cast<size_t>(o)]);
          ASSERT_NEAR(g.data(y_q)[i], g.data(y_float)[i], bound + 1e-5 * (1 + std::fabs(g.data(y_float)[i])))
              << kernels::isa_name(GetParam()) << (per_tensor ? " per tensor" : " per token") << " rows " << rows << " row "
              << r << " column " << o;
        }
      }
     }
    }
  }
}

// A linear whose output codes are per tensor (the FFN's hidden layer in a static blob) requantizes
// in the GEMM, its input per tensor or per token: its codes against its float twin's output (the
// same input codes, float out) quantized with the output's parameters: at most one code apart (the
// requantization rounds where the float epilogue does not), and rarely that; the float output, made
// when something reads it, is exactly the codes' value. Ragged rows and columns, 1 and 2 threads.
TEST_P(OpsPerIsa, LinearS8RequantizesIntoPerTensorCodes) {
  const kernels::KernelConfig k = config();
  std::mt19937 rng(17);
  const int in = 72, out = 200;
  const QuantizedWeights w = quantize_weights(uniform(static_cast<size_t>(out) * in, rng, -0.3f, 0.3f), out, in);
  const std::vector<float> bias = uniform(static_cast<size_t>(out), rng, -1.0f, 1.0f);
  ThreadPool one(1);
  for (ThreadPool* pool : {&one, &pool_}) {
   for (const std::optional<kernels::QuantS8> x_q : {std::optional(kernels::choose_quant_s8(-2.0f, 3.0f)),
                                                      std::optional<kernels::QuantS8>()}) {
    for (int rows : {1, 7, 67, 131}) {
      for (Epilogue epilogue : {Epilogue::kNone, Epilogue::kRelu}) {
        const kernels::QuantS8 y_q = epilogue == Epilogue::kRelu ? kernels::choose_quant_s8(0.0f, 4.0f)
                                                                 : kernels::choose_quant_s8(-4.0f, 4.0f);
        const std::vector<float> x = uniform(static_cast<size_t>(rows) * in, rng, -2.0f, 3.0f);
        Graph g;
        const ValueId xv = g.add_input("x", {rows, in});
        const ValueId y_requantized = g.add_value("y_requantized", {rows, out}), y_float = g.add_value("y_float", {rows, out});
        const RowCodes x_codes = row_codes(g, "x", rows, in, x_q), y_codes = row_codes(g, "y", rows, out, y_q);
        const MatrixRef xr = MatrixRef::of(xv, in), br = MatrixRef::of_constant(bias.data(), 0);
        auto& requantizing = g.add_op(std::make_unique<LinearS8Op>(k.gemm_s8, rows, in, out, xr, x_codes,
                                                                   LinearS8Op::InputCodes::kQuantizedHere, w.q.data(),
                                                                   w.scale.data(), br, MatrixRef{}, epilogue, y_requantized));
        requantizing.write_row_codes(y_codes);
        ASSERT_EQ(requantizing.kernel(k), std::string(k.quant.quantize_name) + " + " + k.gemm_s8.s8out_name);
        g.add_op(std::make_unique<LinearS8Op>(k.gemm_s8, rows, in, out, xr, x_codes, LinearS8Op::InputCodes::kFromProducer,
                                              w.q.data(), w.scale.data(), br, MatrixRef{}, epilogue, y_float));
        g.mark_output(y_requantized);
        g.mark_output(y_float);
        g.mark_output(y_codes.codes);
        g.plan(pool->threads(), false);
        std::copy(x.begin(), x.end(), g.data(xv));
        g.run(*pool, k);

        const size_t n = static_cast<size_t>(rows) * out;
        std::vector<int8_t> want(n);
        kernels::quant_s8_table_ref()->quantize(n, g.data(y_float), 1.0f / y_q.scale, y_q.zero_point, want.data());
        const int8_t* got = g.data_s8(y_codes.codes);
        size_t off_by_one = 0;
        for (size_t i = 0; i < n; ++i) {
          ASSERT_LE(std::abs(got[i] - want[i]), 1) << kernels::isa_name(GetParam()) << " threads " << pool->threads()
                                                   << " rows " << rows << " element " << i;
          off_by_one += got[i] != want[i];
          const float value = y_q.scale * (static_cast<float>(got[i]) - static_cast<float>(y_q.zero_point));
          ASSERT_EQ(g.data(y_requantized)[i], value) << kernels::isa_name(GetParam()) << " element " << i;
          if (epilogue == Epilogue::kRelu) {
            ASSERT_GE(got[i], y_q.zero_point);
          }
        }
        EXPECT_LE(off_by_one, n / 50) << kernels::isa_name(GetParam()) << " rows " << rows
                                      << (x_q ? " per-tensor input" : " per-token input");
      }
    }
   }
  }
}

// The transformer's chain LayerNorm -> linear -> FFN hidden (ReLU or GELU) -> linear + residual, with
// each int8 linear's input codes written by the op producing it (fused), against the same chain with
// every linear quantizing its own input: the same bits, for ragged row counts on 1 and 2 threads
// (whole-row tasks quantizing their rows, and column tiles followed by a pass of their own).
TEST_P(OpsPerIsa, RowCodesWrittenByProducersGiveTheSameBits) {
  const kernels::KernelConfig k = config();
  std::mt19937 rng(21);
  const int dim = 64, hidden = 200;
  const std::vector<float> gamma = uniform(dim, rng, 0.5f, 1.5f), beta = uniform(dim, rng, -0.5f, 0.5f);
  const QuantizedWeights w1 = quantize_weights(uniform(static_cast<size_t>(hidden) * dim, rng, -0.3f, 0.3f), hidden, dim);
  const QuantizedWeights w2 = quantize_weights(uniform(static_cast<size_t>(dim) * hidden, rng, -0.3f, 0.3f), dim, hidden);
  const std::vector<float> b1 = uniform(hidden, rng, -1.0f, 1.0f), b2 = uniform(dim, rng, -1.0f, 1.0f);
  ThreadPool one(1);
  // Per tensor too, with GELU (with ReLU the fused hidden layer requantizes instead: tested above).
  struct Codes {
    Epilogue act;
    std::optional<kernels::QuantS8> normed, h;
  };
  const std::vector<Codes> kinds = {{Epilogue::kRelu, {}, {}},
                                    {Epilogue::kGelu, {}, {}},
                                    {Epilogue::kGelu, kernels::choose_quant_s8(-2.5f, 3.0f), kernels::choose_quant_s8(-0.2f, 6.0f)}};
  for (ThreadPool* pool : {&one, &pool_}) {
    for (int rows : {1, 5, 13, 67, 131}) {
      for (const auto& [act, normed_q, h_q] : kinds) {
        std::vector<float> x = uniform(static_cast<size_t>(rows) * dim, rng, -3.0f, 3.0f);
        std::vector<float> outputs[2];
        for (const bool fused : {false, true}) {
          Graph g;
          const ValueId xv = g.add_input("x", {rows, dim});
          const ValueId normed = g.add_value("normed", {rows, dim});
          const ValueId h = g.add_value("h", {rows, hidden});
          const ValueId y = g.add_value("y", {rows, dim});
          auto& norm = g.add_op(std::make_unique<LayerNormOp>(rows, dim, gamma.data(), beta.data(), xv, normed));
          const auto source = fused ? LinearS8Op::InputCodes::kFromProducer : LinearS8Op::InputCodes::kQuantizedHere;
          const RowCodes normed_codes = row_codes(g, "normed", rows, dim, normed_q), h_codes = row_codes(g, "h", rows, hidden, h_q);
          if (fused) norm.write_row_codes(normed_codes);
          auto& linear1 = g.add_op(std::make_unique<LinearS8Op>(
              k.gemm_s8, rows, dim, hidden, MatrixRef::of(normed, dim), normed_codes, source, w1.q.data(), w1.scale.data(),
              MatrixRef::of_constant(b1.data(), 0), MatrixRef{}, act, h));
          if (fused) linear1.write_row_codes(h_codes);
          g.add_op(std::make_unique<LinearS8Op>(k.gemm_s8, rows, hidden, dim, MatrixRef::of(h, hidden), h_codes, source,
                                                w2.q.data(), w2.scale.data(), MatrixRef::of_constant(b2.data(), 0),
                                                MatrixRef::of(normed, dim), Epilogue::kNone, y));
          g.mark_output(y);
          g.plan(pool->threads(), false);
          std::copy(x.begin(), x.end(), g.data(xv));
          g.run(*pool, k);
          outputs[fused].assign(g.data(y), g.data(y) + static_cast<size_t>(rows) * dim);
        }
        ASSERT_EQ(0, std::memcmp(outputs[0].data(), outputs[1].data(), outputs[0].size() * sizeof(float)))
            << kernels::isa_name(GetParam()) << " threads " << pool->threads() << " rows " << rows
            << (normed_q ? " per tensor" : " per token");
      }
    }
  }
}

// The encoder's input tokens: a constant row, a projected state row, a projected env-state row in
// the middle of a band, then feature rows. Each projected row has the bits of a LinearOp over the
// same weights; the other rows are copies. Ragged feature counts (bands of 32 rows), 1 and 2 threads.
TEST_P(OpsPerIsa, ConcatRowsProjectsItsStateRowsAsALinearDoes) {
  const kernels::KernelConfig k = config();
  std::mt19937 rng(55);
  const int cols = 72, state_dim = 6, env_dim = 3;
  const std::vector<float> latent = uniform(cols, rng, -1.0f, 1.0f);
  const std::vector<float> w_state = uniform(static_cast<size_t>(cols) * state_dim, rng, -1.0f, 1.0f);
  const std::vector<float> w_env = uniform(static_cast<size_t>(cols) * env_dim, rng, -1.0f, 1.0f);
  const std::vector<float> b_state = uniform(cols, rng, -1.0f, 1.0f), b_env = uniform(cols, rng, -1.0f, 1.0f);
  const auto packed_state = std::make_shared<const PackedF32Weights>(k.gemm_f32, cols, state_dim, w_state.data());
  const auto packed_env = std::make_shared<const PackedF32Weights>(k.gemm_f32, cols, env_dim, w_env.data());
  ThreadPool one(1);
  for (ThreadPool* pool : {&one, &pool_}) {
    for (const int features : {1, 29, 30, 95}) {
      const std::vector<float> state = uniform(state_dim, rng, -2.0f, 2.0f), env = uniform(env_dim, rng, -2.0f, 2.0f);
      const std::vector<float> feats = uniform(static_cast<size_t>(features) * cols, rng, -2.0f, 2.0f);
      const int rows = features + 3;
      Graph g;
      const ValueId sv = g.add_input("state", {1, state_dim});
      const ValueId ev = g.add_input("env", {1, env_dim});
      const ValueId fv = g.add_input("features", {features, cols});
      const ValueId tokens = g.add_value("tokens", {rows, cols});
      const ValueId state_row = g.add_value("state_row", {1, cols});
      const ValueId env_row = g.add_value("env_row", {1, cols});
      // The place of the env row: after the state row, or (with 29 or 30 features) the last in a band.
      std::vector<ConcatRowsOp::Part> parts = {{MatrixRef::of_constant(latent.data(), cols), 1},
                                               {MatrixRef::of(sv, state_dim), 1, packed_state, b_state.data()}};
      const bool env_last = features == 29 || features == 30;
      if (!env_last) parts.push_back({MatrixRef::of(ev, env_dim), 1, packed_env, b_env.data()});
      parts.push_back({MatrixRef::of(fv, cols), features});
      if (env_last) parts.push_back({MatrixRef::of(ev, env_dim), 1, packed_env, b_env.data()});
      g.add_op(std::make_unique<ConcatRowsOp>(cols, parts, tokens));
      g.add_op(std::make_unique<LinearOp>(packed_state, 1, state_dim, cols, MatrixRef::of(sv, state_dim),
                                          MatrixRef::of_constant(b_state.data(), 0), MatrixRef{}, Epilogue::kNone, state_row));
      g.add_op(std::make_unique<LinearOp>(packed_env, 1, env_dim, cols, MatrixRef::of(ev, env_dim),
                                          MatrixRef::of_constant(b_env.data(), 0), MatrixRef{}, Epilogue::kNone, env_row));
      for (ValueId v : {tokens, state_row, env_row}) g.mark_output(v);
      g.plan(pool->threads(), false);
      std::copy(state.begin(), state.end(), g.data(sv));
      std::copy(env.begin(), env.end(), g.data(ev));
      std::copy(feats.begin(), feats.end(), g.data(fv));
      g.run(*pool, k);
      const auto row = [&](int r) { return g.data(tokens) + static_cast<size_t>(r) * cols; };
      const size_t bytes = cols * sizeof(float);
      const std::string where = std::string(kernels::isa_name(GetParam())) + " threads " + std::to_string(pool->threads()) +
                                " features " + std::to_string(features);
      EXPECT_EQ(0, std::memcmp(row(0), latent.data(), bytes)) << where;
      EXPECT_EQ(0, std::memcmp(row(1), g.data(state_row), bytes)) << where;
      EXPECT_EQ(0, std::memcmp(row(env_last ? rows - 1 : 2), g.data(env_row), bytes)) << where;
      EXPECT_EQ(0, std::memcmp(row(env_last ? 2 : 3), feats.data(), static_cast<size_t>(features) * bytes)) << where;
      float expected_state0 = b_state[0];  // and the projection is one: its first output by hand
      for (int i = 0; i < state_dim; ++i) expected_state0 += state[static_cast<size_t>(i)] * w_state[static_cast<size_t>(i)];
      EXPECT_NEAR(row(1)[0], expected_state0, 1e-4f) << where;
    }
  }
}

// Post-norm's tail: linear + residual -> LayerNorm -> LayerNorm -> a linear reading the last norm's
// codes, and a float head (6 columns) of the last norm's rows. With both norms and the head fused
// into the first linear (LinearS8Op::fuse_layernorm, fuse_head), against LayerNormOps and a
// LinearOp of their own: the same bits in both norms' outputs, the next linear's and the head's,
// for ragged row counts on 1 and 2 threads (whole-row tasks, and column tiles followed by a pass of
// their own), per-token and per-tensor codes, and with the linear's own output kept or in scratch.
TEST_P(OpsPerIsa, LayerNormsAndHeadFusedIntoTheLinearGiveTheSameBits) {
  const kernels::KernelConfig k = config();
  std::mt19937 rng(34);
  const int in = 72, dim = 136;
  const QuantizedWeights w1 = quantize_weights(uniform(static_cast<size_t>(dim) * in, rng, -0.3f, 0.3f), dim, in);
  const QuantizedWeights w2 = quantize_weights(uniform(static_cast<size_t>(dim) * dim, rng, -0.3f, 0.3f), dim, dim);
  const std::vector<float> b1 = uniform(dim, rng, -1.0f, 1.0f);
  const std::vector<float> gamma1 = uniform(dim, rng, 0.5f, 1.5f), beta1 = uniform(dim, rng, -0.5f, 0.5f);
  const std::vector<float> gamma2 = uniform(dim, rng, 0.5f, 1.5f), beta2 = uniform(dim, rng, -0.5f, 0.5f);
  const int head_cols = 6;
  const std::vector<float> w_head = uniform(static_cast<size_t>(head_cols) * dim, rng, -0.3f, 0.3f);
  const std::vector<float> b_head = uniform(head_cols, rng, -1.0f, 1.0f);
  const auto head = std::make_shared<const PackedF32Weights>(k.gemm_f32, head_cols, dim, w_head.data());
  ThreadPool one(1);
  for (ThreadPool* pool : {&one, &pool_}) {
    for (int rows : {1, 5, 13, 67, 131}) {
      for (const std::optional<kernels::QuantS8> normed_q : {std::optional<kernels::QuantS8>{}, std::optional(kernels::choose_quant_s8(-2.5f, 3.0f))}) {
        for (const bool keep_all : {false, true}) {
          const std::vector<float> x = uniform(static_cast<size_t>(rows) * in, rng, -3.0f, 3.0f);
          const std::vector<float> residual = uniform(static_cast<size_t>(rows) * dim, rng, -2.0f, 2.0f);
          std::vector<float> results[2][5];  // [fused][linear, norm1, norm2, y, head]
          for (const bool fused : {false, true}) {
            Graph g;
            const ValueId xv = g.add_input("x", {rows, in});
            const ValueId rv = g.add_input("residual", {rows, dim});
            const ValueId lin = g.add_value("linear", {rows, dim});
            const ValueId n1 = g.add_value("norm1", {rows, dim});
            const ValueId n2 = g.add_value("norm2", {rows, dim});
            const ValueId y = g.add_value("y", {rows, dim});
            const ValueId actions = g.add_value("actions", {rows, head_cols});
            auto& linear = g.add_op(std::make_unique<LinearS8Op>(
                k.gemm_s8, rows, in, dim, MatrixRef::of(xv, in), row_codes(g, "x", rows, in),
                LinearS8Op::InputCodes::kQuantizedHere, w1.q.data(), w1.scale.data(), MatrixRef::of_constant(b1.data(), 0),
                MatrixRef::of(rv, dim), Epilogue::kNone, lin));
            const RowCodes n2_codes = row_codes(g, "norm2", rows, dim, normed_q);
            if (fused) {
              linear.fuse_layernorm(gamma1.data(), beta1.data(), n1);
              linear.fuse_layernorm(gamma2.data(), beta2.data(), n2);
              linear.write_row_codes(n2_codes);
              linear.fuse_head(head, b_head.data(), actions);
            } else {
              g.add_op(std::make_unique<LayerNormOp>(rows, dim, gamma1.data(), beta1.data(), lin, n1));
              g.add_op(std::make_unique<LayerNormOp>(rows, dim, gamma2.data(), beta2.data(), n1, n2)).write_row_codes(n2_codes);
              g.add_op(std::make_unique<LinearOp>(head, rows, dim, head_cols, MatrixRef::of(n2, dim),
                                                  MatrixRef::of_constant(b_head.data(), 0), MatrixRef{}, Epilogue::kNone, actions));
            }
            g.add_op(std::make_unique<LinearS8Op>(k.gemm_s8, rows, dim, dim, MatrixRef::of(n2, dim), n2_codes,
                                                  LinearS8Op::InputCodes::kFromProducer, w2.q.data(), w2.scale.data(),
                                                  MatrixRef{}, MatrixRef::of(n1, dim), Epilogue::kNone, y));
            g.mark_output(y);
            g.mark_output(actions);
            g.plan(pool->threads(), keep_all);
            std::copy(x.begin(), x.end(), g.data(xv));
            std::copy(residual.begin(), residual.end(), g.data(rv));
            g.run(*pool, k);
            const ValueId kept[] = {lin, n1, n2, y, actions};
            for (int i = 0; i < 5; ++i) {
              results[fused][i].assign(g.data(kept[i]), g.data(kept[i]) + g.value(kept[i]).elements);
            }
          }
          for (int i = keep_all ? 0 : 3; i < 5; ++i) {  // intermediates are kept only with keep_all
            ASSERT_EQ(0, std::memcmp(results[0][i].data(), results[1][i].data(), results[0][i].size() * sizeof(float)))
                << kernels::isa_name(GetParam()) << " threads " << pool->threads() << " rows " << rows << " value " << i
                << (normed_q ? " per tensor" : " per token") << (keep_all ? " kept" : "");
          }
        }
      }
    }
  }
}

// A constant per-row bias table whose last columns are the same in every row (the fused qkv's value
// third) is read there as a bias vector: the same bits as the table read whole (from a graph value,
// which the op cannot inspect), with ReLU, on 1 and 2 threads.
TEST_P(OpsPerIsa, LinearS8BiasTableWithSharedColumnsGivesTheSameBits) {
  const kernels::KernelConfig k = config();
  std::mt19937 rng(5);
  const int in = 72, out = 200, per_row_cols = 130;
  const QuantizedWeights w = quantize_weights(uniform(static_cast<size_t>(out) * in, rng, -0.3f, 0.3f), out, in);
  ThreadPool one(1);
  for (ThreadPool* pool : {&one, &pool_}) {
    for (int rows : {1, 7, 131}) {
      std::vector<float> table = uniform(static_cast<size_t>(rows) * out, rng, -1.0f, 1.0f);
      for (int r = 1; r < rows; ++r) {
        std::copy_n(table.begin() + per_row_cols, out - per_row_cols, table.begin() + static_cast<ptrdiff_t>(r) * out + per_row_cols);
      }
      const std::vector<float> x = uniform(static_cast<size_t>(rows) * in, rng, -2.0f, 2.0f);
      Graph g;
      const ValueId xv = g.add_input("x", {rows, in}), tv = g.add_input("table", {rows, out});
      const ValueId y_constant = g.add_value("y_constant", {rows, out}), y_value = g.add_value("y_value", {rows, out});
      const MatrixRef xr = MatrixRef::of(xv, in);
      g.add_op(std::make_unique<LinearS8Op>(k.gemm_s8, rows, in, out, xr, row_codes(g, "xc", rows, in),
                                            LinearS8Op::InputCodes::kQuantizedHere, w.q.data(), w.scale.data(),
                                            MatrixRef::of_constant(table.data(), out), MatrixRef{}, Epilogue::kRelu, y_constant));
      g.add_op(std::make_unique<LinearS8Op>(k.gemm_s8, rows, in, out, xr, row_codes(g, "xv", rows, in),
                                            LinearS8Op::InputCodes::kQuantizedHere, w.q.data(), w.scale.data(),
                                            MatrixRef::of(tv, out), MatrixRef{}, Epilogue::kRelu, y_value));
      g.mark_output(y_constant);
      g.mark_output(y_value);
      g.plan(pool->threads(), false);
      std::copy(x.begin(), x.end(), g.data(xv));
      std::copy(table.begin(), table.end(), g.data(tv));
      g.run(*pool, k);
      ASSERT_EQ(0, std::memcmp(g.data(y_constant), g.data(y_value), table.size() * sizeof(float)))
          << kernels::isa_name(GetParam()) << " threads " << pool->threads() << " rows " << rows;
    }
  }
}

// softmax(Q K^T / sqrt(d)) V per head, in double.
std::vector<double> attention_naive(const std::vector<float>& q, const std::vector<float>& k, const std::vector<float>& v,
                                    int nq, int nk, int dim, int heads) {
  const int hd = dim / heads;
  std::vector<double> out(static_cast<size_t>(nq) * dim);
  std::vector<double> p(static_cast<size_t>(nk));
  for (int h = 0; h < heads; ++h) {
    for (int i = 0; i < nq; ++i) {
      double mx = -INFINITY;
      for (int j = 0; j < nk; ++j) {
        double dot = 0;
        for (int c = 0; c < hd; ++c) dot += double{q[static_cast<size_t>(i) * dim + h * hd + c]} * k[static_cast<size_t>(j) * dim + h * hd + c];
        p[static_cast<size_t>(j)] = dot / std::sqrt(static_cast<double>(hd));
        mx = std::max(mx, p[static_cast<size_t>(j)]);
      }
      double sum = 0;
      for (double& e : p) sum += (e = std::exp(e - mx));
      for (int c = 0; c < hd; ++c) {
        double acc = 0;
        for (int j = 0; j < nk; ++j) acc += p[static_cast<size_t>(j)] / sum * v[static_cast<size_t>(j) * dim + h * hd + c];
        out[static_cast<size_t>(i) * dim + h * hd + c] = acc;
      }
    }
  }
  return out;
}

// Runs one attention op (float or int8: `int8` chooses) on random q, k, v of these sizes, with k
// and v side by side in one value as the fused projection makes them; returns its output and the
// naive definition's.
struct AttentionRun {
  std::vector<float> got;
  std::vector<double> want;
};
AttentionRun run_attention(const kernels::KernelConfig& k, ThreadPool& pool, bool int8, int nq, int nk, int dim, int heads,
                           std::mt19937& rng) {
  const std::vector<float> q = uniform(static_cast<size_t>(nq) * dim, rng, -2.0f, 2.0f);
  const std::vector<float> kk = uniform(static_cast<size_t>(nk) * dim, rng, -2.0f, 2.0f);
  const std::vector<float> v = uniform(static_cast<size_t>(nk) * dim, rng, -1.0f, 1.0f);
  Graph g;
  const ValueId qv = g.add_input("q", {nq, dim});
  const ValueId kv = g.add_input("kv", {nk, 2 * dim});
  const ValueId out = g.add_value("out", {nq, dim});
  const MatrixRef qr = MatrixRef::of(qv, dim), kr = MatrixRef::of(kv, 2 * dim, 0), vr = MatrixRef::of(kv, 2 * dim, dim);
  if (int8) {
    g.add_op(std::make_unique<AttentionS8Op>(k.gemm_s8, nq, nk, dim, heads, qr, kr, vr, out));
  } else {
    g.add_op(std::make_unique<AttentionOp>(k.gemm_f32, nq, nk, dim, heads, qr, kr, vr, out));
  }
  g.mark_output(out);
  g.plan(pool.threads(), false);
  std::copy(q.begin(), q.end(), g.data(qv));
  for (int j = 0; j < nk; ++j) {
    std::copy_n(kk.data() + static_cast<size_t>(j) * dim, dim, g.data(kv) + static_cast<size_t>(j) * 2 * dim);
    std::copy_n(v.data() + static_cast<size_t>(j) * dim, dim, g.data(kv) + static_cast<size_t>(j) * 2 * dim + dim);
  }
  g.run(pool, k);
  return {std::vector<float>(g.data(out), g.data(out) + static_cast<size_t>(nq) * dim),
          attention_naive(q, kk, v, nq, nk, dim, heads)};
}

// AttentionOp against the naive definition: self-attention over a fused qkv value (column slices,
// as the encoder uses it) and cross-attention with fewer queries than keys; query counts that leave
// a ragged tile.
TEST_P(OpsPerIsa, AttentionMatchesNaiveSoftmaxAttention) {
  std::mt19937 rng(9);
  for (auto [nq, nk] : {std::pair{37, 37}, std::pair{130, 45}, std::pair{1, 9}}) {
    const AttentionRun r = run_attention(config(), pool_, false, nq, nk, 64, 4, rng);
    for (size_t i = 0; i < r.want.size(); ++i) {
      ASSERT_NEAR(r.got[i], r.want[i], 2e-5 * (1 + std::fabs(r.want[i])))
          << kernels::isa_name(GetParam()) << " " << nq << "x" << nk << " at " << i;
    }
  }
}

// AttentionS8Op against the naive definition, on the shapes above and ragged ones (key counts that
// are no multiple of any GEMM tile, several query blocks). Its error is quantization's: the
// probabilities per row (8 bits), queries per row, keys per token, values per channel (7 bits plus sign);
// on these inputs the worst output error stays below 1.5 % of the largest |v| (the outputs are
// convex combinations of v's rows), and the RMS error below 0.4 % of it.
TEST_P(OpsPerIsa, AttentionS8MatchesNaiveSoftmaxAttentionWithinQuantizationError) {
  std::mt19937 rng(11);
  for (auto [nq, nk] : {std::pair{37, 37}, std::pair{130, 45}, std::pair{1, 9}, std::pair{251, 302}}) {
    const AttentionRun r = run_attention(config(), pool_, true, nq, nk, 64, 4, rng);
    double worst = 0, squares = 0;
    for (size_t i = 0; i < r.want.size(); ++i) {
      const double err = std::fabs(r.got[i] - r.want[i]);
      worst = std::max(worst, err);
      squares += err * err;
    }
    const double rms = std::sqrt(squares / static_cast<double>(r.want.size()));
    EXPECT_LT(worst, 0.015) << kernels::isa_name(GetParam()) << " " << nq << "x" << nk;
    EXPECT_LT(rms, 0.004) << kernels::isa_name(GetParam()) << " " << nq << "x" << nk;
  }
}

INSTANTIATE_TEST_SUITE_P(CpuIsas, OpsPerIsa, ::testing::ValuesIn(kernels::cpu_isas()),
                         kernels::test::isa_param_name);

}  // namespace
}  // namespace act::graph
