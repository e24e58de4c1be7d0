// act_kernel_bench: Google Benchmark microbenchmarks of the INT8 kernels, single thread.
//   - peak/<instruction>: register-only loops of the multiply-accumulate instruction of each ISA,
//     this core's measured peak in GMAC/s;
//   - gemm_s8/<isa>/<shape>: the GEMM over ACT's real shapes (bench/shapes/act_gemm_s8.txt, or the
//     file named by ACT_BENCH_SHAPES), counters GMAC/s (M*N*K per second, 1 MAC = 2 ops) and
//     pct_peak (against that ISA's sustained probe rate, measured once at start-up).
// Wall-clock time throughout. On a shared machine use --benchmark_repetitions=N and read the "max"
// aggregate of GMAC/s (the "min" of time): the least disturbed repetition.
// Every variant the CPU can run is benchmarked; --benchmark_filter=avx512vnni picks one. The
// scalar reference runs on the smallest shape only (it is the specification, not a contender).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "bench/peak_probe.h"
#include "kernels/gemm_s8/gemm_s8.h"

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

struct Probe {
  const char* name;
  Isa isa;
  uint64_t (*fn)(uint64_t);
  bool is_isa_peak;  // the one "% of peak" refers to
};

constexpr Probe kProbes[] = {
    {"vpdpbusd_zmm", Isa::kAvx512Vnni, peak_vpdpbusd_zmm, true},
    {"vpmaddwd_ymm", Isa::kAvx2, peak_vpmaddwd_ymm, true},
    {"vpmaddwd+vpaddd_ymm", Isa::kAvx2, peak_vpmaddwd_vpaddd_ymm, false},
    {"sdot", Isa::kNeonDot, peak_sdot, true},
};

// Sustained GMAC/s of a probe: a ~20 ms warm-up (wide-vector instructions lower the clock after a
// few tens of microseconds on many x86 cores, so a short burst would overstate the peak), then the
// best of 10 runs of ~2 ms, so that a run descheduled by other work on a shared machine does not
// lower the peak the kernels are compared against.
double measure_peak(const Probe& p) {
  auto run = [&](uint64_t iters) {
    const auto t0 = std::chrono::steady_clock::now();
    const uint64_t macs = p.fn(iters);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return static_cast<double>(macs) / s * 1e-9;
  };
  const double macs_per_iteration = static_cast<double>(p.fn(1));  // the probes need iterations >= 1
  const double warm = run(1u << 14);  // GMAC/s of a short run, to size the timed runs
  const auto iters_for = [&](double seconds) {
    return static_cast<uint64_t>(seconds * warm * 1e9 / macs_per_iteration) + 1;
  };
  run(iters_for(0.02));
  double best = 0.0;
  for (int rep = 0; rep < 10; ++rep) best = std::max(best, run(iters_for(0.002)));
  return best;
}

// Best repetition (largest GMAC/s, smallest time) for --benchmark_repetitions runs.
double stat_max(const std::vector<double>& v) { return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end()); }
double stat_min(const std::vector<double>& v) { return v.empty() ? 0.0 : *std::min_element(v.begin(), v.end()); }

void bm_probe(benchmark::State& state, const Probe* p) {
  uint64_t macs = 0;
  for (auto _ : state) macs += p->fn(1u << 16);
  state.counters["GMAC/s"] = benchmark::Counter(static_cast<double>(macs) * 1e-9, benchmark::Counter::kIsRate);
}

struct Aligned {
  void operator()(void* p) const { std::free(p); }
};

void bm_gemm(benchmark::State& state, const GemmS8Kernels* v, Shape s, double peak_gmacs) {
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
  for (auto _ : state) {
    if (s.f32_out) {
      v->f32out(g, of, 0, s.m, 0, s.n);
    } else {
      v->s8out(g, o8, 0, s.m, 0, s.n);
    }
    benchmark::ClobberMemory();
  }
  const double macs = static_cast<double>(s.macs()) * static_cast<double>(state.iterations());
  state.counters["GMAC/s"] = benchmark::Counter(macs * 1e-9, benchmark::Counter::kIsRate);
  if (peak_gmacs > 0) {
    state.counters["pct_peak"] = benchmark::Counter(macs * 1e-9 / peak_gmacs * 100.0, benchmark::Counter::kIsRate);
  }
  state.SetLabel(std::string(s.f32_out ? v->f32out_name : v->s8out_name) + " M=" + std::to_string(s.m) +
                 " N=" + std::to_string(s.n) + " K=" + std::to_string(s.k));
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

}  // namespace
}  // namespace act::bench

int main(int argc, char** argv) {
  using namespace act;
  benchmark::Initialize(&argc, argv);
  const char* shapes_env = std::getenv("ACT_BENCH_SHAPES");
  const std::vector<bench::Shape> shapes = bench::read_shapes(shapes_env != nullptr ? shapes_env : ACT_BENCH_SHAPES_FILE);

  std::map<kernels::Isa, double> peak;
  for (const bench::Probe& p : bench::kProbes) {
    if (!kernels::cpu_supports(p.isa) || p.fn(1) == 0) continue;
    benchmark::RegisterBenchmark((std::string("peak/") + p.name).c_str(), bench::bm_probe, &p)
        ->UseRealTime()
        ->ComputeStatistics("max", bench::stat_max)
        ->ComputeStatistics("min", bench::stat_min);
    if (p.is_isa_peak) {
      peak[p.isa] = bench::measure_peak(p);
      benchmark::AddCustomContext(std::string("peak_") + p.name + "_GMACps", std::to_string(peak[p.isa]));
    }
  }
  const bench::Shape* smallest = shapes.empty() ? nullptr : &shapes[0];
  for (const bench::Shape& s : shapes) {
    if (s.macs() < smallest->macs()) smallest = &s;
  }
  for (kernels::Isa isa : kernels::gemm_s8_available_isas()) {
    const kernels::GemmS8Kernels* v = kernels::gemm_s8_kernels(isa);
    for (const bench::Shape& s : shapes) {
      if (isa == kernels::Isa::kRef && &s != smallest) continue;
      const std::string name = std::string("gemm_s8/") + kernels::isa_name(isa) + "/" + s.name;
      benchmark::RegisterBenchmark(name.c_str(), bench::bm_gemm, v, s, peak.count(isa) ? peak[isa] : 0.0)
          ->Unit(benchmark::kMillisecond)
          ->UseRealTime()
          ->ComputeStatistics("max", bench::stat_max)
          ->ComputeStatistics("min", bench::stat_min);
    }
  }
  benchmark::AddCustomContext("cpu_model", bench::cpu_model());
  benchmark::AddCustomContext("threads", "1");
  benchmark::AddCustomContext("gemm_s8_variants",
                              kernels::isa_mask_names(kernels::gemm_s8_built_isas() & kernels::cpu_isa_mask()));
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
