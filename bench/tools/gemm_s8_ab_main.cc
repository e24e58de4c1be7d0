// The harness of gemm_s8_ab.sh: one gemm_s8 ISA file compiled twice (A: a git revision, B: the
// working tree; their kernels renamed by the script), both timed in this one process, in
// alternating rounds on the same data. Across processes a shared host moves identical runs by
// 5-15 %; rounds paired in one process by thread CPU time move 1-2 % (an A/A run shows how much).
//
//   gemm_s8_ab [--rounds N] SHAPE...   SHAPE = MxNxK[:s8|:f32|:s32][+zp], or
//                                             conv:HxWxC:OUT:KERNEL:STRIDE (NHWC, pad KERNEL / 2)
//
// A conv runs as the network runs it (conv_s8_s8out over tiles of pixels: its kernel rows read in
// place, or the stem's patches gathered), with the variant's table as its kernels.
// Per shape: the median time of A and of B (each round's best of 3 calls) and the median and
// 10th-90th percentiles of the rounds' B/A ratios. +zp gives A per-row zero points (the dynamic
// per-token linears); f32 output takes per-row scales and a bias, as the transformer's linears do.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "kernels/conv_s8/conv_s8.h"
#include "kernels/gemm_s8/gemm_s8.h"
#include "kernels/peak/peak_probe.h"

namespace act::kernels {
const GemmS8Kernels* ACT_AB_TABLE_A();
const GemmS8Kernels* ACT_AB_TABLE_B();
}  // namespace act::kernels

namespace {

using act::kernels::GemmS8Kernels;
using act::kernels::thread_cpu_seconds;

enum class Out { kS8, kF32, kS32 };

struct Shape {
  int m = 0, n = 0, k = 0;
  Out out = Out::kS8;
  bool row_zero_points = false;
  bool conv = false;
  act::kernels::Conv2dShape conv_shape;
};

bool parse_conv(const std::string& text, Shape& s) {
  int h = 0, w = 0, c = 0, out = 0, kernel = 0, stride = 0;
  char extra = 0;
  if (std::sscanf(text.c_str(), "conv:%dx%dx%d:%d:%d:%d%c", &h, &w, &c, &out, &kernel, &stride, &extra) != 6 || h < 1 ||
      w < 1 || c < 1 || out < 1 || kernel < 1 || stride < 1) {
    return false;
  }
  s.conv = true;
  s.conv_shape = act::kernels::Conv2dShape::square(h, w, c, out, kernel, stride, kernel / 2);
  s.m = s.conv_shape.out_h * s.conv_shape.out_w;
  s.n = out;
  s.k = s.conv_shape.patch_size();
  return true;
}

bool parse_shape(std::string text, Shape& s) {
  if (text.rfind("conv:", 0) == 0) return parse_conv(text, s);
  if (text.size() > 3 && text.compare(text.size() - 3, 3, "+zp") == 0) {
    s.row_zero_points = true;
    text.resize(text.size() - 3);
  }
  std::string kind = "s8";
  if (const size_t colon = text.find(':'); colon != std::string::npos) {
    kind = text.substr(colon + 1);
    text.resize(colon);
  }
  char extra = 0;
  if (std::sscanf(text.c_str(), "%dx%dx%d%c", &s.m, &s.n, &s.k, &extra) != 3 || s.m < 1 || s.n < 1 || s.k < 1) {
    return false;
  }
  const std::pair<const char*, Out> kinds[] = {{"s8", Out::kS8}, {"f32", Out::kF32}, {"s32", Out::kS32}};
  for (const auto& [name, out] : kinds) {
    if (kind == name) {
      s.out = out;
      return true;
    }
  }
  return false;
}

double percentile(std::vector<double> v, double p) {
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(p * static_cast<double>(v.size() - 1) + 0.5)];
}

struct AlignedFree {
  void operator()(void* p) const { std::free(p); }
};

// The shape as the output line names it.
std::string shape_label(const Shape& s) {
  const act::kernels::Conv2dShape& cs = s.conv_shape;
  char label[96];
  if (s.conv) {
    std::snprintf(label, sizeof label, "conv:%dx%dx%d:%d:%d:%d (M %d K %d)", cs.in_h, cs.in_w, cs.in_c, cs.out_c,
                  cs.kernel_h, cs.stride, s.m, s.k);
  } else {
    const char* kinds[] = {"s8", "f32", "s32"};
    std::snprintf(label, sizeof label, "%dx%dx%d:%s%s", s.m, s.n, s.k, kinds[static_cast<int>(s.out)],
                  s.row_zero_points ? "+zp" : "");
  }
  return label;
}

// `rounds` rounds of A's and B's best of 3 calls of run_once (by thread CPU time): their times
// and the rounds' B/A ratios.
template <class RunOnce>
void time_alternating(const RunOnce& run_once, const GemmS8Kernels& a, const GemmS8Kernels& b, int rounds,
                      std::vector<double>& ta, std::vector<double>& tb, std::vector<double>& ratio) {
  const auto best_of_3 = [&](const GemmS8Kernels& v) {
    double best = 1e30;
    for (int i = 0; i < 3; ++i) {
      const double t0 = thread_cpu_seconds();
      run_once(v);
      best = std::min(best, thread_cpu_seconds() - t0);
    }
    return best;
  };
  for (int r = 0; r < rounds; ++r) {
    // Which goes first alternates, so neither always runs on caches the other warmed.
    const bool a_first = r % 2 == 0;
    const double first = best_of_3(a_first ? a : b), second = best_of_3(a_first ? b : a);
    ta.push_back(a_first ? first : second);
    tb.push_back(a_first ? second : first);
    ratio.push_back(tb.back() / ta.back());
  }
}

// Runs both variants on one shape and prints the line.
void compare(const GemmS8Kernels& a, const GemmS8Kernels& b, const Shape& s, int rounds) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> byte(-128, 127), weight(-127, 127);
  // A: the GEMM's rows, or the conv's NHWC input.
  const act::kernels::Conv2dShape& cs = s.conv_shape;
  const size_t a_bytes = s.conv ? static_cast<size_t>(cs.in_h) * cs.in_w * cs.in_c : static_cast<size_t>(s.m) * s.k;
  std::vector<int8_t> x(a_bytes + act::kernels::kGemmS8ReadSlack);
  for (auto& v : x) v = static_cast<int8_t>(byte(rng));
  std::vector<int8_t> w(static_cast<size_t>(s.n) * s.k);
  for (auto& v : w) v = static_cast<int8_t>(weight(rng));
  std::vector<int32_t> bias(static_cast<size_t>(s.n), 1000), zero_points(static_cast<size_t>(s.m), 7);
  const size_t packed_bytes = (a.packed_size(s.n, s.k) + 63) / 64 * 64;
  std::unique_ptr<void, AlignedFree> packed(std::aligned_alloc(act::kernels::kGemmS8PackedAlign, packed_bytes));
  a.pack(s.n, s.k, w.data(), static_cast<size_t>(s.k), s.out == Out::kS8 ? bias.data() : nullptr, -3, packed.get());

  act::kernels::GemmS8Args g;
  g.m = s.m;
  g.n = s.n;
  g.k = s.k;
  g.a = x.data();
  g.lda = static_cast<size_t>(s.k);
  g.packed_w = packed.get();
  if (s.row_zero_points) g.a_row_zero_point = zero_points.data();
  std::vector<float> scale(static_cast<size_t>(s.n), 1e-3f), row_scale(static_cast<size_t>(s.m), 1e-2f),
      float_bias(static_cast<size_t>(s.n), 0.5f), c_f32(static_cast<size_t>(s.m) * s.n);
  std::vector<int8_t> c_s8(static_cast<size_t>(s.m) * s.n);
  std::vector<int32_t> c_s32(static_cast<size_t>(s.m) * s.n);
  act::kernels::GemmS8OutS8 o8;
  o8.c = c_s8.data();
  o8.ldc = static_cast<size_t>(s.n);
  o8.scale = scale.data();
  o8.qmin = 0;  // ReLU, as most convolutions
  act::kernels::GemmS8OutF32 of;
  of.c = c_f32.data();
  of.ldc = static_cast<size_t>(s.n);
  of.w_scale = scale.data();
  of.a_row_scale = row_scale.data();
  of.bias = float_bias.data();
  act::kernels::GemmS8OutS32 o32;
  o32.c = c_s32.data();
  o32.ldc = static_cast<size_t>(s.n);

  // A conv's input codes have zero point -3 (as packed); its output pixels go in the network's tiles.
  const int tile = s.conv ? act::kernels::conv_s8_tile_pixels(s.conv_shape) : 0;
  std::vector<int8_t> conv_scratch(s.conv ? act::kernels::conv_s8_scratch_bytes(s.conv_shape, tile) : 0);
  const auto run_once = [&](const GemmS8Kernels& v) {
    if (s.conv) {
      const act::kernels::ConvS8 conv{s.conv_shape, &v, packed.get(), -3};
      for (int p = 0; p < s.m; p += tile) act::kernels::conv_s8_s8out(conv, x.data(), o8, p, std::min(tile, s.m - p), conv_scratch.data());
      return;
    }
    switch (s.out) {
      case Out::kS8: v.s8out(g, o8, 0, s.m, 0, s.n); break;
      case Out::kF32: v.f32out(g, of, 0, s.m, 0, s.n); break;
      case Out::kS32: v.s32out(g, o32, 0, s.m, 0, s.n); break;
    }
  };
  std::vector<double> ta, tb, ratio;
  time_alternating(run_once, a, b, rounds, ta, tb, ratio);
  std::printf("%s  A %.4f ms  B %.4f ms  B/A %.3f (10-90 %%: %.3f-%.3f)\n", shape_label(s).c_str(), 1e3 * percentile(ta, 0.5),
              1e3 * percentile(tb, 0.5), percentile(ratio, 0.5), percentile(ratio, 0.1), percentile(ratio, 0.9));
}

}  // namespace

int main(int argc, char** argv) {
  int rounds = 40;
  std::vector<Shape> shapes;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--rounds" && i + 1 < argc) {
      rounds = std::max(1, std::atoi(argv[++i]));
      continue;
    }
    Shape s;
    if (!parse_shape(arg, s)) {
      std::fprintf(stderr, "gemm_s8_ab: bad shape '%s' (want MxNxK[:s8|:f32|:s32][+zp] or conv:HxWxC:OUT:KERNEL:STRIDE)\n", arg.c_str());
      return 2;
    }
    shapes.push_back(s);
  }
  if (shapes.empty()) {
    std::fprintf(stderr, "usage: gemm_s8_ab [--rounds N] MxNxK[:s8|:f32|:s32][+zp]|conv:HxWxC:OUT:KERNEL:STRIDE...\n");
    return 2;
  }
  const GemmS8Kernels* a = act::kernels::ACT_AB_TABLE_A();
  const GemmS8Kernels* b = act::kernels::ACT_AB_TABLE_B();
  if (a == nullptr || b == nullptr) {
    std::fprintf(stderr, "gemm_s8_ab: this CPU's build of the file has no kernels (wrong architecture)\n");
    return 1;
  }
  if (a->layout != b->layout) {
    std::fprintf(stderr, "gemm_s8_ab: A and B pack differently; this harness packs once for both\n");
    return 1;
  }
  for (const Shape& s : shapes) compare(*a, *b, s, rounds);
  return 0;
}
