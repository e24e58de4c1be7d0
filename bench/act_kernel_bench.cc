// act_kernel_bench: Google Benchmark microbenchmarks of the kernels over ACT's real shapes.
//   - peak/<instruction>: register-only loops of the multiply-accumulate instruction of each ISA,
//     this core's measured peak in GMAC/s;
//   - gemm_s8/<isa>/<shape>/threads:T: the GEMM over ACT's shapes (bench/shapes/act_gemm_s8.txt, or
//     the file named by ACT_BENCH_SHAPES);
//   - conv_s8/<isa>/<HxW>/<layer>/threads:T: every distinct ResNet18 convolution of a 480x640 and a
//     360x640 camera through conv_s8_s8out (tiled im2col + gemm_s8, ReLU fused), shapes derived
//     from the image size;
//   - gemm_f32/<isa>/<linear>/<tokens>/threads:T and conv_f32/<isa>/<HxW>/<layer>/threads:T: the
//     FP32 path's transformer linears (default and rover token counts) and convolutions (the graph's
//     op: packed gemm_f32, bias and ReLU fused, the 3x3 stride-1 ones as Winograd F(2x2, 3x3)),
//     pct_peak against the float FMA probe of the ISA (Winograd's counts the direct conv's MACs);
//   - attention_f32/<isa>/<tokens>/threads:T: the float attention op, 8 heads of QK^T, softmax,
//     PV on the packed gemm_f32, head dim 64, at 302 and 242 tokens;
//   - quant/, pool/, eltwise/<isa>/...: quantize, dequantize, dynamic per-row quantization, max-pool,
//     LayerNorm, softmax, softmax into int8 (bytes/s);
//   - thread_pool/dispatch/threads:T (an empty parallel section) and thread_pool/cache_line_round_trip
//     (a cache line from one thread to another and back: what each cross-core step costs).
// Counters: GMAC/s (M*N*K per second of wall time, 1 MAC = 2 ops), pct_peak (against that ISA's
// sustained probe rate, int8 or float as the kernel, measured at start-up by thread CPU time on T
// threads at once: the peak of T cores, graph/peak_together.h),
// at T = 1 also GMAC/s_cpu and pct_peak_cpu (by the thread's CPU time: what to read on a shared,
// loaded machine, where wall time includes time spent descheduled) and, for T > 1, speedup_vs_1t
// (the same benchmark's best single-thread time / this one's). Threads split the output into tiles
// over a persistent pool (graph/thread_pool.h); the kernels themselves never start threads.
// Wall-clock time throughout. On a shared machine use --benchmark_repetitions=N and read the "max"
// aggregate of GMAC/s (the "min" of time): the least disturbed repetition.
// Every variant the CPU can run is benchmarked; --benchmark_filter=avx512vnni picks one. The
// scalar reference runs on the smallest shape only (it is the specification, not a contender).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <random>
#include <sstream>
#include <thread>
#include <string>
#include <vector>

#include "actengine/engine.h"
#include "graph/gemm_tiling.h"
#include "graph/graph.h"
#include "graph/ops_fp32.h"
#include "graph/ops_int8.h"
#include "graph/peak_together.h"
#include "graph/thread_pool.h"
#include "kernels/peak/peak_probe.h"
#include "kernels/conv_s8/conv_s8.h"
#include "kernels/fp32/conv_f32.h"
#include "kernels/fp32/elementwise_f32.h"
#include "kernels/config/kernel_config.h"
#include "kernels/fp32/gemm_f32.h"
#include "kernels/gemm_s8/gemm_s8.h"
#include "kernels/pool_s8/maxpool_s8_variants.h"
#include "kernels/quant/quant_s8_variants.h"

namespace act::bench {
namespace {

using kernels::GemmS8Args;
using kernels::GemmS8Kernels;
using kernels::Isa;

struct Shape {
  std::string name;
  int m = 0, n = 0, k = 0;
  bool f32_out = false;
  uint64_t macs() const { return static_cast<uint64_t>(m) * n * k; }
};

std::vector<Shape> read_shapes(const std::string& path) {
  std::ifstream in(path);
  if (!in) {
    std::cerr << "act_kernel_bench: cannot read shapes file " << path << "\n";
    std::exit(1);
  }
  std::vector<Shape> shapes;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    Shape s;
    std::string out;
    if (!(ss >> s.name >> s.m >> s.n >> s.k >> out) || s.m < 1 || s.n < 1 || s.k < 1 || (out != "s8" && out != "f32")) {
      std::cerr << "act_kernel_bench: bad line in " << path << ": " << line << "\n";
      std::exit(1);
    }
    s.f32_out = out == "f32";
    shapes.push_back(s);
  }
  return shapes;
}

using kernels::PeakProbe;
using kernels::thread_cpu_seconds;

// Best repetition (largest GMAC/s, smallest time) for --benchmark_repetitions runs.
double stat_max(const std::vector<double>& v) { return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end()); }
double stat_min(const std::vector<double>& v) { return v.empty() ? 0.0 : *std::min_element(v.begin(), v.end()); }

void bm_probe(benchmark::State& state, const PeakProbe* p) {
  uint64_t macs = 0;
  for (auto _ : state) macs += p->fn(1u << 16);
  state.counters["GMAC/s"] = benchmark::Counter(static_cast<double>(macs) * 1e-9, benchmark::Counter::kIsRate);
}

struct Aligned {
  void operator()(void* p) const { std::free(p); }
};

// One persistent pool per thread count, shared by every benchmark.
ThreadPool& pool(int threads) {
  static std::map<int, std::unique_ptr<ThreadPool>> pools;
  auto& p = pools[threads];
  if (!p) p = std::make_unique<ThreadPool>(threads);
  return *p;
}

// Best single-thread seconds per iteration of each benchmark (keyed without the thread count), for
// the speedup counter of the multi-thread runs, which are registered after the single-thread one.
std::map<std::string, double>& single_thread_seconds() {
  static std::map<std::string, double> m;
  return m;
}

// Times the benchmark loop, sets GMAC/s (and pct_peak when peak_gmacs, the peak of `threads`
// threads, is > 0), and records or compares the single-thread time.
template <class Body>
void run_timed(benchmark::State& state, const std::string& key, int threads, double macs_per_iter, double peak_gmacs,
               Body body) {
  double seconds = 0.0, cpu_seconds = 0.0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    const double c0 = thread_cpu_seconds();
    body();
    benchmark::ClobberMemory();
    cpu_seconds += thread_cpu_seconds() - c0;
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  const double iters = static_cast<double>(state.iterations());
  const double macs = macs_per_iter * iters;
  if (macs > 0) {
    state.counters["GMAC/s"] = benchmark::Counter(macs * 1e-9, benchmark::Counter::kIsRate);
    if (peak_gmacs > 0) {
      state.counters["pct_peak"] =
          benchmark::Counter(macs * 1e-9 / peak_gmacs * 100.0, benchmark::Counter::kIsRate);
    }
    // Single thread on a shared machine: the rate by this thread's CPU time, robust to being
    // descheduled (the probe is measured the same way).
    if (threads == 1 && cpu_seconds > 0) {
      state.counters["GMAC/s_cpu"] = macs * 1e-9 / cpu_seconds;
      if (peak_gmacs > 0) state.counters["pct_peak_cpu"] = macs * 1e-9 / cpu_seconds / peak_gmacs * 100.0;
    }
  }
  const double per_iter = seconds / iters;
  auto& t1 = single_thread_seconds();
  if (threads == 1) {
    if (t1.count(key) == 0 || per_iter < t1[key]) t1[key] = per_iter;
  } else if (t1.count(key) != 0) {
    state.counters["speedup_vs_1t"] = t1[key] / per_iter;
  }
}

void bm_gemm(benchmark::State& state, const GemmS8Kernels* v, Shape s, double peak_gmacs, int threads,
             std::string key) {
  std::mt19937 rng(42);
  std::uniform_int_distribution<int> byte(-128, 127), weight(-127, 127);
  const size_t lda = static_cast<size_t>(s.k);
  std::vector<int8_t> a(static_cast<size_t>(s.m) * lda + kernels::kGemmS8ReadSlack);
  for (auto& x : a) x = static_cast<int8_t>(byte(rng));
  std::vector<int8_t> w(static_cast<size_t>(s.n) * s.k);
  for (auto& x : w) x = static_cast<int8_t>(weight(rng));
  std::vector<int32_t> bias(static_cast<size_t>(s.n), 1000);
  std::unique_ptr<uint8_t, Aligned> packed(
      static_cast<uint8_t*>(std::aligned_alloc(kernels::kGemmS8PackedAlign, v->packed_size(s.n, s.k))));
  v->pack(s.n, s.k, w.data(), static_cast<size_t>(s.k), s.f32_out ? nullptr : bias.data(), -3, packed.get());

  GemmS8Args g;
  g.m = s.m;
  g.n = s.n;
  g.k = s.k;
  g.a = a.data();
  g.lda = lda;
  g.packed_w = packed.get();
  std::vector<float> scale(static_cast<size_t>(s.n), 1e-3f), fbias(static_cast<size_t>(s.n), 0.5f);
  std::vector<int32_t> row_zp(static_cast<size_t>(s.m), 7);
  std::vector<float> row_scale(static_cast<size_t>(s.m), 0.01f);
  std::vector<int8_t> c8;
  std::vector<float> c32;
  kernels::GemmS8OutS8 o8;
  kernels::GemmS8OutF32 of;
  if (s.f32_out) {
    // Per-token dynamic quantization, as the transformer linears will run.
    c32.resize(static_cast<size_t>(s.m) * s.n);
    g.a_row_zero_point = row_zp.data();
    of.c = c32.data();
    of.ldc = static_cast<size_t>(s.n);
    of.w_scale = scale.data();
    of.a_row_scale = row_scale.data();
    of.bias = fbias.data();
  } else {
    c8.resize(static_cast<size_t>(s.m) * s.n);
    o8.c = c8.data();
    o8.ldc = static_cast<size_t>(s.n);
    o8.scale = scale.data();
    o8.qmin = 0;  // ReLU, as most ResNet convolutions
  }
  const graph::GemmTiling t =
      graph::gemm_tiling(s.m, s.n, v->mr, v->nr, threads, false, static_cast<size_t>(s.k) * static_cast<size_t>(s.n));
  ThreadPool& tp = pool(threads);
  run_timed(state, key, threads, static_cast<double>(s.macs()), peak_gmacs, [&] {
    tp.parallel_for(t.count(), [&](size_t task, int) {
      int m0, m1, n0, n1;
      t.rect(task, m0, m1, n0, n1);
      if (s.f32_out) {
        v->f32out(g, of, m0, m1, n0, n1);
      } else {
        v->s8out(g, o8, m0, m1, n0, n1);
      }
    });
  });
  state.SetLabel(std::string(s.f32_out ? v->f32out_name : v->s8out_name) + " M=" + std::to_string(s.m) +
                 " N=" + std::to_string(s.n) + " K=" + std::to_string(s.k));
}

// The packed FP32 GEMM on a shape's float GEMM view: weights packed once, bias and ReLU fused (as
// the convolutions and linears run it); threads split the output as bm_gemm does.
void bm_gemm_f32(benchmark::State& state, const kernels::GemmF32Kernels* g, Shape s, double peak_gmacs, int threads,
                 std::string key) {
  std::mt19937 rng(42);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<float> a(static_cast<size_t>(s.m) * s.k), w(static_cast<size_t>(s.n) * s.k), bias(static_cast<size_t>(s.n));
  for (auto* v : {&a, &w, &bias}) {
    for (float& x : *v) x = u(rng);
  }
  std::vector<float> packed(kernels::gemm_f32_packed_floats(g->nr, s.n, s.k)), c(static_cast<size_t>(s.m) * s.n);
  kernels::gemm_f32_pack(g->nr, s.n, s.k, w.data(), static_cast<size_t>(s.k), packed.data());
  const graph::GemmTiling t = graph::gemm_tiling(s.m, s.n, g->mr, g->nr, threads);
  ThreadPool& tp = pool(threads);
  run_timed(state, key, threads, static_cast<double>(s.macs()), peak_gmacs, [&] {
    tp.parallel_for(t.count(), [&](size_t task, int) {
      int m0, m1, n0, n1;
      t.rect(task, m0, m1, n0, n1);
      kernels::GemmF32PackedArgs args;
      args.m = m1 - m0;
      args.n = n1 - n0;
      args.k = s.k;
      args.a = a.data() + static_cast<size_t>(m0) * s.k;
      args.lda = static_cast<size_t>(s.k);
      args.packed_b = packed.data();
      args.col0 = n0;
      args.c = c.data() + static_cast<size_t>(m0) * s.n + n0;
      args.ldc = static_cast<size_t>(s.n);
      args.epilogue.bias = bias.data() + n0;
      args.epilogue.activation = kernels::GemmF32Activation::kRelu;
      g->packed(args);
    });
  });
  state.SetLabel(std::string(g->name) + " M=" + std::to_string(s.m) + " N=" + std::to_string(s.n) +
                 " K=" + std::to_string(s.k));
}

// ---- convolutions -----------------------------------------------------------------------------

struct ConvBench {
  std::string name;
  kernels::Conv2dShape shape;
  bool unsigned_input = false;  ///< input codes stored as uint8 (GemmS8Kernels::pack_u8a), as the stem's
  uint64_t macs() const {
    return static_cast<uint64_t>(shape.out_h) * shape.out_w * shape.out_c * static_cast<uint64_t>(shape.patch_size());
  }
};

kernels::Conv2dShape conv_shape(int h, int w, int cin, int cout, int kernel, int stride) {
  return kernels::Conv2dShape::square(h, w, cin, cout, kernel, stride, kernel / 2);
}

// Every distinct convolution of ResNet18 (torchvision's BasicBlock layout) on an h x w image.
std::vector<ConvBench> resnet18_convs(int h, int w) {
  std::vector<ConvBench> out;
  const kernels::Conv2dShape stem = conv_shape(h, w, 3, 64, 7, 2);
  out.push_back({"conv1_7x7s2", stem});
  // 3x3/2 max-pool, pad 1.
  int fh = kernels::Conv2dShape::out_dim(stem.out_h, 3, 2, 1, 1), fw = kernels::Conv2dShape::out_dim(stem.out_w, 3, 2, 1, 1);
  out.push_back({"layer1_3x3", conv_shape(fh, fw, 64, 64, 3, 1)});
  int c = 64;
  for (int layer = 2; layer <= 4; ++layer) {
    const std::string l = "layer" + std::to_string(layer);
    const kernels::Conv2dShape first = conv_shape(fh, fw, c, 2 * c, 3, 2);
    out.push_back({l + "_3x3s2", first});
    out.push_back({l + "_1x1s2ds", conv_shape(fh, fw, c, 2 * c, 1, 2)});
    fh = first.out_h;
    fw = first.out_w;
    c *= 2;
    out.push_back({l + "_3x3", conv_shape(fh, fw, c, c, 3, 1)});
  }
  return out;
}

void bm_conv(benchmark::State& state, const GemmS8Kernels* v, ConvBench cb, double peak_gmacs, int threads,
             std::string key) {
  const kernels::Conv2dShape& s = cb.shape;
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> byte(-128, 127), weight(-127, 127);
  std::vector<int8_t> x(static_cast<size_t>(s.in_h) * s.in_w * s.in_c + kernels::kGemmS8ReadSlack);
  for (auto& b : x) b = static_cast<int8_t>(byte(rng));
  const int k = s.patch_size();
  std::vector<int8_t> w(static_cast<size_t>(s.out_c) * k);
  for (auto& b : w) b = static_cast<int8_t>(weight(rng));
  std::vector<int32_t> bias(static_cast<size_t>(s.out_c), 1000);
  std::unique_ptr<uint8_t, Aligned> packed(
      static_cast<uint8_t*>(std::aligned_alloc(kernels::kGemmS8PackedAlign, v->packed_size(s.out_c, k))));
  // The same input either way: codes x with zero point -5, or their unsigned bytes x + 128 with 123.
  if (cb.unsigned_input) {
    for (auto& b : x) b = static_cast<int8_t>(b ^ 0x80);
    v->pack_u8a(s.out_c, k, w.data(), static_cast<size_t>(k), bias.data(), 123, packed.get());
  } else {
    v->pack(s.out_c, k, w.data(), static_cast<size_t>(k), bias.data(), -5, packed.get());
  }
  const kernels::ConvS8 conv{s, v, packed.get(), static_cast<int8_t>(cb.unsigned_input ? 123 - 256 : -5)};
  const int pixels = s.out_h * s.out_w;
  const int tile = kernels::conv_s8_tile_pixels(s);
  const int tiles = (pixels + tile - 1) / tile;
  std::vector<std::vector<int8_t>> scratch(static_cast<size_t>(threads),
                                           std::vector<int8_t>(kernels::conv_s8_scratch_bytes(s, tile)));
  std::vector<int8_t> y(static_cast<size_t>(pixels) * s.out_c);
  std::vector<float> scale(static_cast<size_t>(s.out_c), 1e-3f);
  kernels::GemmS8OutS8 o;
  o.c = y.data();
  o.ldc = static_cast<size_t>(s.out_c);
  o.scale = scale.data();
  o.out_zero_point = -128;
  o.qmin = -128;  // ReLU at the output zero point
  ThreadPool& tp = pool(threads);
  run_timed(state, key, threads, static_cast<double>(cb.macs()), peak_gmacs, [&] {
    tp.parallel_for(static_cast<size_t>(tiles), [&](size_t t, int thread) {
      const int p0 = static_cast<int>(t) * tile;
      kernels::conv_s8_s8out(conv, x.data(), o, p0, std::min(tile, pixels - p0), scratch[thread].data());
    });
  });
  state.SetLabel(std::string(v->s8out_name) + " " + std::to_string(s.in_h) + "x" + std::to_string(s.in_w) + "x" +
                 std::to_string(s.in_c) + " -> " + std::to_string(s.out_h) + "x" + std::to_string(s.out_w) + "x" +
                 std::to_string(s.out_c) + " k" + std::to_string(s.kernel_h) + "/" + std::to_string(s.stride) +
                 " tile " + std::to_string(tile));
}

// The float convolution as the FP32 graph runs it: its op (graph/ops_fp32.h) as a one-op graph,
// bias and ReLU fused; the 3x3 stride-1 convs as Winograd F(2x2, 3x3) (kernels/fp32/winograd_f32.h),
// the others on tiles of output pixels (kernels/fp32/conv_f32.h). pct_peak counts the direct
// convolution's MACs, so Winograd's can pass 100.
void bm_conv_f32(benchmark::State& state, kernels::Isa isa, ConvBench cb, double peak_gmacs, int threads, std::string key) {
  const kernels::KernelConfig config = kernels::kernel_config_for(isa);
  const kernels::Conv2dShape& s = cb.shape;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<float> w(static_cast<size_t>(s.out_c) * s.patch_size()), bias(static_cast<size_t>(s.out_c));
  for (auto* v : {&w, &bias}) {
    for (float& e : *v) e = u(rng);
  }
  graph::Graph g;
  const graph::ValueId x = g.add_input("x", {s.in_h * s.in_w, s.in_c});
  const graph::ValueId y = g.add_value("y", {s.out_h * s.out_w, s.out_c});
  auto packed = std::make_shared<const graph::PackedF32Weights>(config.gemm_f32, s.out_c, s.patch_size(), w.data());
  g.add_op(std::make_unique<graph::Conv2dOp>(packed, s, bias.data(), true, x, graph::kNoValue, y));
  g.mark_output(y);
  g.plan(threads, false);
  for (size_t i = 0; i < static_cast<size_t>(s.in_h) * s.in_w * s.in_c; ++i) g.data(x)[i] = u(rng);
  ThreadPool& tp = pool(threads);
  run_timed(state, key, threads, static_cast<double>(cb.macs()), peak_gmacs, [&] { g.run(tp, config); });
  state.SetLabel(g.ops()[0]->kernel(config) + " " + std::to_string(s.in_h) + "x" + std::to_string(s.in_w) + "x" +
                 std::to_string(s.in_c) + " -> " + std::to_string(s.out_h) + "x" + std::to_string(s.out_w) + "x" +
                 std::to_string(s.out_c) + " k" + std::to_string(s.kernel_h) + "/" + std::to_string(s.stride));
}

// ---- attention (f32) ---------------------------------------------------------------------------

constexpr int kHeads = 8, kHeadDim = 64;

// An attention op of `config` over one [T x 1536] value (Q, K, V its column slices: the fused QKV
// projection's layout), 8 heads of 64, as a one-op graph: `make(q, k, v, out)` builds the op.
template <class MakeOp>
void bm_attention_op(benchmark::State& state, const kernels::KernelConfig& config, int tokens, double peak_gmacs,
                     int threads, const std::string& key, MakeOp make) {
  const int d = kHeads * kHeadDim;
  graph::Graph g;
  const graph::ValueId qkv = g.add_input("qkv", {tokens, 3 * d});
  const graph::ValueId out = g.add_value("out", {tokens, d});
  g.add_op(make(graph::MatrixRef::of(qkv, 3 * d, 0), graph::MatrixRef::of(qkv, 3 * d, d), graph::MatrixRef::of(qkv, 3 * d, 2 * d), out));
  g.mark_output(out);
  g.plan(threads, false);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (size_t i = 0; i < static_cast<size_t>(tokens) * 3 * d; ++i) g.data(qkv)[i] = u(rng);
  ThreadPool& tp = pool(threads);
  const double macs = 2.0 * kHeads * tokens * static_cast<double>(tokens) * kHeadDim;
  run_timed(state, key, threads, macs, peak_gmacs, [&] { g.run(tp, config); });
  state.SetLabel(g.ops()[0]->kernel(config) + ", 8 heads x " + std::to_string(tokens) + "^2 x 64");
}

// The float attention op (graph/ops_fp32.h: per head, keys and values packed, QK^T and PV on the
// packed gemm_f32, softmax between) with the kernels an Engine of this ISA level runs.
void bm_attention(benchmark::State& state, kernels::Isa isa, int tokens, double peak_gmacs, int threads, std::string key) {
  const kernels::KernelConfig config = kernels::kernel_config_for(isa);
  bm_attention_op(state, config, tokens, peak_gmacs, threads, key, [&](auto q, auto k, auto v, graph::ValueId out) {
    return std::make_unique<graph::AttentionOp>(config.gemm_f32, tokens, tokens, kHeads * kHeadDim, kHeads, q, k, v, out);
  });
}

// The int8 attention op (graph/ops_int8.h: both matmuls on gemm_s8, keys and values packed per
// run) on the same shape.
void bm_attention_s8(benchmark::State& state, kernels::Isa isa, int tokens, double peak_gmacs, int threads, std::string key) {
  const kernels::KernelConfig config = kernels::kernel_config_for(isa);
  bm_attention_op(state, config, tokens, peak_gmacs, threads, key, [&](auto q, auto k, auto v, graph::ValueId out) {
    return std::make_unique<graph::AttentionS8Op>(config.gemm_s8, tokens, tokens, kHeads * kHeadDim, kHeads, q, k, v, out);
  });
}

// ---- element-wise ops around the GEMMs (single thread, bytes/s of input + output) ---------------

void bm_quant_rows(benchmark::State& state, const kernels::QuantS8Kernels* k, int rows, int cols) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-3.0f, 5.0f);
  std::vector<float> x(static_cast<size_t>(rows) * cols);
  for (auto& v : x) v = u(rng);
  std::vector<int8_t> y(x.size());
  std::vector<float> sc(static_cast<size_t>(rows));
  std::vector<int32_t> zp(static_cast<size_t>(rows));
  for (auto _ : state) {
    kernels::quantize_rows_dynamic_f32_s8(*k, rows, cols, x.data(), cols, y.data(), cols, sc.data(), zp.data());
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations()) * static_cast<int64_t>(x.size()) * 5);
  state.SetLabel(std::string("minmax + ") + k->quantize_name);
}

// The int8 attention's keys (and, a block at a time, its queries): each 64-value head of every
// token of a [302 x 1536] qkv output quantized per row, symmetric.
void bm_quant_heads(benchmark::State& state, const kernels::QuantS8Kernels* k) {
  constexpr int kTokens = 302;
  constexpr size_t kLd = 3 * kHeads * kHeadDim;
  std::mt19937 rng(6);
  std::uniform_real_distribution<float> u(-3.0f, 5.0f);
  std::vector<float> x(kTokens * kLd);
  for (auto& v : x) v = u(rng);
  std::vector<int8_t> y(static_cast<size_t>(kHeads) * kTokens * kHeadDim);
  std::vector<float> scale(static_cast<size_t>(kHeads) * kTokens);
  for (auto _ : state) {
    for (size_t h = 0; h < size_t{kHeads}; ++h) {
      k->quantize_rows_symmetric(kTokens, kHeadDim, x.data() + h * kHeadDim, kLd, y.data() + h * kTokens * kHeadDim,
                                 kHeadDim, scale.data() + h * kTokens);
    }
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations()) * static_cast<int64_t>(y.size()) * 5);
  state.SetLabel(k->rows_symmetric_name);
}

void bm_dequant(benchmark::State& state, const kernels::QuantS8Kernels* k, size_t n) {
  std::vector<int8_t> q(n, 3);
  std::vector<float> y(n);
  for (auto _ : state) {
    k->dequantize(n, q.data(), 0.01f, -4, y.data());
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations()) * static_cast<int64_t>(n) * 5);
  state.SetLabel(k->dequantize_name);
}

// One parallel section that does nothing, a task per thread: what an op pays to use the pool (the
// workers are still spinning from the previous section, as between the ops of an inference).
void bm_dispatch(benchmark::State& state, int threads) {
  ThreadPool& tp = pool(threads);
  std::atomic<size_t> tasks_run{0};
  for (auto _ : state) {
    tp.parallel_for(static_cast<size_t>(threads), [&](size_t, int) { tasks_run.fetch_add(1, std::memory_order_relaxed); });
  }
  benchmark::DoNotOptimize(tasks_run.load());
}

// A cache line handed from one thread to another and back (an atomic counter each bumps in turn):
// the floor under every cross-thread step of an inference (a section's start and end, a row read
// from the other core). About 50-100 ns where two cores share an L3; 470 ns on a 2-vCPU EPYC guest
// whose vCPUs sit on different dies, where two threads scale worse than the kernels.
void bm_cache_line_round_trip(benchmark::State& state) {
  alignas(64) std::atomic<uint64_t> turn{0};
  std::atomic<bool> stop{false};
  std::thread partner([&] {
    for (uint64_t seen = 1; !stop.load(std::memory_order_relaxed); seen += 2) {
      while (turn.load(std::memory_order_acquire) != seen) {
        if (stop.load(std::memory_order_relaxed)) return;
      }
      turn.store(seen + 1, std::memory_order_release);
    }
  });
  uint64_t mine = 0;
  for (auto _ : state) {
    turn.store(mine + 1, std::memory_order_release);
    while (turn.load(std::memory_order_acquire) != mine + 2) {
    }
    mine += 2;
  }
  stop.store(true, std::memory_order_relaxed);
  partner.join();
}

void bm_maxpool(benchmark::State& state, const kernels::MaxPoolS8Kernels* k, int h, int w) {
  const int c = 64, oh = kernels::Conv2dShape::out_dim(h, 3, 2, 1, 1), ow = kernels::Conv2dShape::out_dim(w, 3, 2, 1, 1);
  std::vector<int8_t> x(static_cast<size_t>(h) * w * c, 1), y(static_cast<size_t>(oh) * ow * c);
  for (size_t i = 0; i < x.size(); ++i) x[i] = static_cast<int8_t>(i * 7);
  for (auto _ : state) {
    kernels::maxpool_nhwc_s8(*k, h, w, c, 3, 2, 1, ow, x.data(), y.data(), 0, oh);
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations()) * static_cast<int64_t>(x.size() + y.size()));
  state.SetLabel(std::string(k->max_taps_name) + " 3x3/2 " + std::to_string(h) + "x" + std::to_string(w) + "x64");
}

void bm_layernorm(benchmark::State& state, const kernels::ElementwiseF32Kernels* e, int rows, int cols) {
  std::vector<float> x(static_cast<size_t>(rows) * cols, 0.5f), y(x.size()), g(static_cast<size_t>(cols), 1.0f),
      b(static_cast<size_t>(cols), 0.0f);
  for (size_t i = 0; i < x.size(); ++i) x[i] = static_cast<float>(i % 97) * 0.01f;
  for (auto _ : state) {
    e->layernorm_rows(rows, cols, x.data(), cols, g.data(), b.data(), 1e-5f, y.data(), cols);
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations()) * static_cast<int64_t>(x.size()) * 8);
  state.SetLabel(e->layernorm_name);
}

void bm_softmax(benchmark::State& state, const kernels::ElementwiseF32Kernels* e, int rows, int cols) {
  std::vector<float> x0(static_cast<size_t>(rows) * cols), x(x0.size());
  for (size_t i = 0; i < x0.size(); ++i) x0[i] = static_cast<float>(i % 101) * 0.05f;
  for (auto _ : state) {
    state.PauseTiming();
    x = x0;
    state.ResumeTiming();
    e->softmax_rows(rows, cols, x.data(), cols);
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations()) * static_cast<int64_t>(x.size()) * 8);
  state.SetLabel(e->softmax_name);
}

// Attention's softmax straight into int8 codes (softmax_rows_s8) on the encoder's 8 heads of 302
// scores per query, bytes/s of float input + int8 output.
void bm_softmax_s8(benchmark::State& state, const kernels::ElementwiseF32Kernels* e, int rows, int cols) {
  std::vector<float> x(static_cast<size_t>(rows) * cols), scale(static_cast<size_t>(rows));
  for (size_t i = 0; i < x.size(); ++i) x[i] = static_cast<float>(i % 101) * 0.05f;
  std::vector<int8_t> y(x.size());
  for (auto _ : state) {
    e->softmax_rows_s8(rows, cols, x.data(), cols, y.data(), cols, scale.data());
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations()) * static_cast<int64_t>(x.size()) * 5);
  state.SetLabel(e->softmax_s8_name);
}

std::string cpu_model() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("model name", 0) == 0 || line.rfind("Model", 0) == 0) {
      const size_t colon = line.find(':');
      if (colon != std::string::npos) return line.substr(colon + 2);
    }
  }
  return "unknown";
}

// The measured peaks by ISA, for 1..max_threads threads (index T - 1).
using Peaks = std::vector<double>;
using PeakTable = std::map<kernels::Isa, Peaks>;

/// What every registration needs: the shapes, the thread counts and the peaks to rate against.
struct BenchPlan {
  std::vector<Shape> shapes;
  int max_threads = 1;
  PeakTable peak, peak_f32;  // the int8 and the float FMA probes' peaks
  std::vector<kernels::Isa> isas;

  /// The peak of t threads for kernels of `isa` (0: no probe).
  static double peak_of(const PeakTable& peaks, kernels::Isa isa, int t) {
    const auto it = peaks.find(isa);
    return it == peaks.end() ? 0.0 : it->second[static_cast<size_t>(t - 1)];
  }
};

benchmark::internal::Benchmark* with_stats(benchmark::internal::Benchmark* b) {
  return b->Unit(benchmark::kMillisecond)
      ->UseRealTime()
      ->ComputeStatistics("max", stat_max)
      ->ComputeStatistics("min", stat_min);
}

/// The ISA whose float FMA probe rates `isa`'s float kernels (kRef, which has no peak, if none).
kernels::Isa f32_peak_isa_of(kernels::Isa isa) {
  const kernels::PeakProbe* probe = kernels::isa_peak_probe(isa, kernels::PeakKind::kFp32);
  return probe != nullptr ? probe->isa : kernels::Isa::kRef;
}

/// Registers every probe as a benchmark and measures the ISA peaks on 1..max_threads threads at
/// once (they rate every kernel below, so they are taken before any of them runs).
void register_probes_and_measure_peaks(BenchPlan& plan) {
  for (int i = 0; i < kernels::kPeakProbeCount; ++i) {
    const kernels::PeakProbe& p = kernels::kPeakProbes[i];
    if (!kernels::cpu_supports(p.isa) || p.fn(1) == 0) continue;
    benchmark::RegisterBenchmark((std::string("peak/") + p.name).c_str(), bm_probe, &p)
        ->UseRealTime()
        ->ComputeStatistics("max", stat_max)
        ->ComputeStatistics("min", stat_min);
    if (p.is_isa_peak) {
      Peaks& peaks = (p.kind == kernels::PeakKind::kInt8 ? plan.peak : plan.peak_f32)[p.isa];
      for (int t = 1; t <= plan.max_threads; ++t) {
        peaks.push_back(graph::measure_peak_gmacs_together(p, t));
        benchmark::AddCustomContext(std::string("peak_") + p.name + "_GMACps" + (t > 1 ? "_threads:" + std::to_string(t) : ""),
                                    std::to_string(peaks.back()));
      }
    }
  }
}

/// gemm_s8 over the shape file, every variant; the reference on the smallest shape only.
void register_gemm_s8(const BenchPlan& plan) {
  const Shape* smallest = plan.shapes.empty() ? nullptr : &plan.shapes[0];
  for (const Shape& s : plan.shapes) {
    if (s.macs() < smallest->macs()) smallest = &s;
  }
  for (kernels::Isa isa : plan.isas) {
    const kernels::GemmS8Kernels* v = kernels::isa_tables(isa).gemm_s8;
    if (v == nullptr) continue;
    for (const Shape& s : plan.shapes) {
      if (isa == kernels::Isa::kRef && &s != smallest) continue;
      const std::string key = std::string("gemm_s8/") + kernels::isa_name(isa) + "/" + s.name;
      for (int t = 1; t <= (isa == kernels::Isa::kRef ? 1 : plan.max_threads); ++t) {
        const std::string name = key + "/threads:" + std::to_string(t);
        with_stats(benchmark::RegisterBenchmark(name.c_str(), bm_gemm, v, s, BenchPlan::peak_of(plan.peak, isa, t), t, key));
      }
    }
  }
}

/// The FP32 path's products, % of the float FMA probe of their ISA: the packed GEMM on every
/// transformer linear (the f32-out shapes) of the default config (302 tokens) and the rover's
/// (360x640: 242 tokens; the decoder's 100 queries are the same), then every convolution of both
/// cameras through conv_f32. SIMD variants only (the reference is checked by the tests).
void register_fp32(const BenchPlan& plan) {
  for (kernels::Isa isa : plan.isas) {
    const kernels::GemmF32Kernels* g = kernels::isa_tables(isa).gemm_f32;
    if (g == nullptr || isa == kernels::Isa::kRef) continue;
    const kernels::Isa f32_peak_isa = f32_peak_isa_of(isa);
    for (const Shape& s : plan.shapes) {
      if (!s.f32_out) continue;
      for (const int tokens : {302, 242}) {
        if (tokens != 302 && s.m != 302) continue;
        Shape linear = s;
        if (s.m == 302) linear.m = tokens;
        const std::string key = std::string("gemm_f32/") + kernels::isa_name(isa) + "/" + s.name + "/" + std::to_string(linear.m);
        for (int t = 1; t <= plan.max_threads; ++t) {
          const std::string name = key + "/threads:" + std::to_string(t);
          with_stats(benchmark::RegisterBenchmark(name.c_str(), bm_gemm_f32, g, linear,
                                                  BenchPlan::peak_of(plan.peak_f32, f32_peak_isa, t), t, key));
        }
      }
    }
    for (auto [h, w] : {std::pair{480, 640}, std::pair{360, 640}}) {
      for (const ConvBench& cb : resnet18_convs(h, w)) {
        const std::string key = std::string("conv_f32/") + kernels::isa_name(isa) + "/" + std::to_string(h) + "x" +
                                std::to_string(w) + "/" + cb.name;
        for (int t = 1; t <= plan.max_threads; ++t) {
          const std::string name = key + "/threads:" + std::to_string(t);
          with_stats(benchmark::RegisterBenchmark(name.c_str(), bm_conv_f32, isa, cb,
                                                  BenchPlan::peak_of(plan.peak_f32, f32_peak_isa, t), t, key));
        }
      }
    }
  }
}

/// Convolutions: the SIMD variants only (the reference's GEMM is checked by the tests).
void register_conv_s8(const BenchPlan& plan) {
  for (kernels::Isa isa : plan.isas) {
    const kernels::GemmS8Kernels* v = kernels::isa_tables(isa).gemm_s8;
    if (v == nullptr || isa == kernels::Isa::kRef) continue;
    for (auto [h, w] : {std::pair{480, 640}, std::pair{360, 640}}) {
      std::vector<ConvBench> convs = resnet18_convs(h, w);
      if (v->pack_u8a != nullptr) {  // the stem as the network runs it where the variant has one
        convs.insert(convs.begin() + 1, convs.front());
        convs[1].name += "_u8a";
        convs[1].unsigned_input = true;
      }
      for (const ConvBench& cb : convs) {
        const std::string key = std::string("conv_s8/") + kernels::isa_name(isa) + "/" + std::to_string(h) + "x" +
                                std::to_string(w) + "/" + cb.name;
        for (int t = 1; t <= plan.max_threads; ++t) {
          const std::string name = key + "/threads:" + std::to_string(t);
          with_stats(benchmark::RegisterBenchmark(name.c_str(), bm_conv, v, cb, BenchPlan::peak_of(plan.peak, isa, t), t, key));
        }
      }
    }
  }
}

/// Per element-wise variant: the float attention op at its level (% of its float FMA probe),
/// LayerNorm, softmax and softmax into int8.
void register_elementwise(const BenchPlan& plan) {
  for (kernels::Isa isa : plan.isas) {
    const kernels::ElementwiseF32Kernels* e = kernels::isa_tables(isa).elementwise;
    if (e == nullptr) continue;
    const kernels::Isa f32_peak_isa = f32_peak_isa_of(isa);
    for (int tokens : {302, 242}) {
      const std::string key = std::string("attention_f32/") + kernels::isa_name(isa) + "/" + std::to_string(tokens);
      for (int t = 1; t <= plan.max_threads; ++t) {
        const std::string name = key + "/threads:" + std::to_string(t);
        with_stats(benchmark::RegisterBenchmark(name.c_str(), bm_attention, isa, tokens,
                                                BenchPlan::peak_of(plan.peak_f32, f32_peak_isa, t), t, key));
      }
    }
    const std::string ew = std::string("eltwise/") + kernels::isa_name(isa);
    with_stats(benchmark::RegisterBenchmark((ew + "/layernorm/302x512").c_str(), bm_layernorm, e, 302, 512));
    with_stats(benchmark::RegisterBenchmark((ew + "/softmax/2416x302").c_str(), bm_softmax, e, 8 * 302, 302));
    with_stats(benchmark::RegisterBenchmark((ew + "/softmax_s8/2416x302").c_str(), bm_softmax_s8, e, 8 * 302, 302));
  }
}

/// The int8 attention: at each level with a gemm_s8 variant of its own (not the reference).
void register_attention_s8(const BenchPlan& plan) {
  for (kernels::Isa isa : plan.isas) {
    if (kernels::isa_tables(isa).gemm_s8 == nullptr || isa == kernels::Isa::kRef) continue;
    for (int tokens : {302, 242}) {
      const std::string key = std::string("attention_s8/") + kernels::isa_name(isa) + "/" + std::to_string(tokens);
      for (int t = 1; t <= plan.max_threads; ++t) {
        const std::string name = key + "/threads:" + std::to_string(t);
        with_stats(
            benchmark::RegisterBenchmark(name.c_str(), bm_attention_s8, isa, tokens, BenchPlan::peak_of(plan.peak, isa, t), t, key));
      }
    }
  }
}

/// Quantizers and the max-pool, every variant (bytes/s).
void register_quant_and_pool(const BenchPlan& plan) {
  for (kernels::Isa isa : plan.isas) {
    const kernels::QuantS8Kernels* k = kernels::isa_tables(isa).quant;
    if (k == nullptr) continue;
    const std::string qn = std::string("quant/") + kernels::isa_name(isa);
    for (auto [rows, cols] : {std::pair{302, 512}, std::pair{302, 3200}}) {
      const std::string name = qn + "/rows_dynamic/" + std::to_string(rows) + "x" + std::to_string(cols);
      with_stats(benchmark::RegisterBenchmark(name.c_str(), bm_quant_rows, k, rows, cols));
    }
    with_stats(benchmark::RegisterBenchmark((qn + "/rows_symmetric/8x302x64").c_str(), bm_quant_heads, k));
    with_stats(benchmark::RegisterBenchmark((qn + "/dequantize/154624").c_str(), bm_dequant, k, size_t{302 * 512}));
  }
  for (kernels::Isa isa : plan.isas) {
    const kernels::MaxPoolS8Kernels* k = kernels::isa_tables(isa).maxpool_s8;
    if (k == nullptr) continue;
    const std::string name = std::string("pool/") + kernels::isa_name(isa) + "/maxpool_3x3s2/240x320x64";
    with_stats(benchmark::RegisterBenchmark(name.c_str(), bm_maxpool, k, 240, 320));
  }
}

/// The thread pool's own costs: an empty parallel section, and a cache line's round trip.
void register_thread_pool(const BenchPlan& plan) {
  for (int t = 1; t <= plan.max_threads; ++t) {
    benchmark::RegisterBenchmark(("thread_pool/dispatch/threads:" + std::to_string(t)).c_str(), bm_dispatch, t)
        ->Unit(benchmark::kMicrosecond)
        ->UseRealTime();
  }
  if (plan.max_threads > 1) {
    benchmark::RegisterBenchmark("thread_pool/cache_line_round_trip", bm_cache_line_round_trip)
        ->Unit(benchmark::kNanosecond)
        ->UseRealTime();
  }
}

}  // namespace
}  // namespace act::bench

int main(int argc, char** argv) {
  using namespace act;
  // Google Benchmark owns the other flags; --version as every tool has it (the library's version).
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--version") == 0) {
      std::cout << "act_kernel_bench " << act::version() << "\n";
      return 0;
    }
  }
  benchmark::Initialize(&argc, argv);
  bench::BenchPlan plan;
  const char* shapes_env = std::getenv("ACT_BENCH_SHAPES");
  plan.shapes = bench::read_shapes(shapes_env != nullptr ? shapes_env : ACT_BENCH_SHAPES_FILE);
  plan.max_threads = std::min(2, ThreadPool::hardware_threads());
  bench::register_probes_and_measure_peaks(plan);
  // Every variant of every family this CPU runs: each ISA's own tables (isa_tables), not the
  // per-level configuration, so that no variant is measured twice.
  plan.isas = kernels::cpu_isas();
  bench::register_gemm_s8(plan);
  bench::register_fp32(plan);
  bench::register_conv_s8(plan);
  bench::register_elementwise(plan);
  bench::register_attention_s8(plan);
  bench::register_quant_and_pool(plan);
  bench::register_thread_pool(plan);
  benchmark::AddCustomContext("cpu_model", bench::cpu_model());
  benchmark::AddCustomContext("threads", "1.." + std::to_string(plan.max_threads) + " (see /threads:T)");
  benchmark::AddCustomContext("isas", kernels::isa_mask_names(kernels::cpu_isa_mask()));
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
