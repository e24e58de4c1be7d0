// Winograd F(2x2, 3x3) (winograd_f32.h) on every gemm_f32 variant this CPU runs, the scalar
// reference's included: against the exact convolution in double, with bias, residual and ReLU, on
// odd and even sizes (tiles cut by the image's edge), one pixel, and ranges of tiles (the tiles
// outside left untouched). The SIMD variants give the same bits as each other: the transforms
// only add and subtract, in the same order on every ISA, and the GEMM is one FMA chain per output.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include "kernels/fp32/winograd_f32.h"
#include "test/kernels/kernel_test_util.h"

namespace act::kernels {
namespace {

constexpr float kSentinel = 12345.0f;

struct Case {
  int h, w, in_c, out_c;
  bool bias, residual, relu;
  int tile_begin = 0, count = -1;  // -1: every tile
};

std::string describe(const Case& c) {
  return std::to_string(c.h) + "x" + std::to_string(c.w) + "x" + std::to_string(c.in_c) + " -> " + std::to_string(c.out_c) +
         " bias " + std::to_string(c.bias) + " residual " + std::to_string(c.residual) + " relu " + std::to_string(c.relu) +
         " tiles " + std::to_string(c.tile_begin) + "+" + std::to_string(c.count);
}

// Runs one case; checks every output against the exact conv; returns the output.
std::vector<float> check_case(const GemmF32Kernels& g, const Case& c) {
  const Conv2dShape s = Conv2dShape::square(c.h, c.w, c.in_c, c.out_c, 3, 1, 1);
  EXPECT_TRUE(winograd_f32_applies(s, GemmF32Activation::kRelu));
  std::mt19937 rng(static_cast<uint32_t>(c.h * 1000 + c.w * 10 + c.in_c + c.out_c));
  std::uniform_real_distribution<float> d(-1.0f, 1.0f);
  const size_t pixels = static_cast<size_t>(c.h) * static_cast<size_t>(c.w);
  std::vector<float> x(pixels * c.in_c), w(static_cast<size_t>(c.out_c) * 9 * c.in_c), bias(c.out_c), res(pixels * c.out_c);
  for (auto* v : {&x, &w, &bias, &res}) {
    for (float& e : *v) e = d(rng);
  }
  std::vector<float> packed(winograd_f32_packed_floats(g.nr, s));
  winograd_f32_pack(g.nr, s, w.data(), packed.data());
  std::vector<float> y(pixels * c.out_c, kSentinel), scratch(winograd_f32_scratch_floats(s));
  GemmF32Epilogue e;
  if (c.bias) e.bias = bias.data();
  if (c.residual) {
    e.residual = res.data();
    e.residual_ld = static_cast<size_t>(c.out_c);
  }
  e.activation = c.relu ? GemmF32Activation::kRelu : GemmF32Activation::kNone;
  const int tiles = winograd_f32_tiles(s), count = c.count < 0 ? tiles - c.tile_begin : c.count;
  winograd_f32(g, s, packed.data(), x.data(), y.data(), e, c.tile_begin, count, scratch.data());

  const int tiles_w = (c.w + 1) / 2;
  const double eps = std::ldexp(1.0, -24), k = 9.0 * c.in_c;
  int failures = 0;
  for (int oy = 0; oy < c.h; ++oy) {
    for (int ox = 0; ox < c.w; ++ox) {
      const int tile = (oy / 2) * tiles_w + ox / 2;
      const bool written = tile >= c.tile_begin && tile < c.tile_begin + count;
      for (int o = 0; o < c.out_c; ++o) {
        const size_t at = (static_cast<size_t>(oy) * c.w + ox) * c.out_c + o;
        if (!written) {
          if (y[at] != kSentinel && ++failures <= 3) ADD_FAILURE() << g.name << " " << describe(c) << ": wrote tile " << tile;
          continue;
        }
        double sum = 0.0, mag = 0.0;
        for (int ky = 0; ky < 3; ++ky) {
          for (int kx = 0; kx < 3; ++kx) {
            const int iy = oy + ky - 1, ix = ox + kx - 1;
            if (iy < 0 || iy >= c.h || ix < 0 || ix >= c.w) continue;
            for (int i = 0; i < c.in_c; ++i) {
              const double t = static_cast<double>(x[(static_cast<size_t>(iy) * c.w + ix) * c.in_c + i]) *
                               w[((static_cast<size_t>(o) * 3 + ky) * 3 + kx) * c.in_c + i];
              sum += t;
              mag += std::fabs(t);
            }
          }
        }
        if (c.bias) sum += bias[o];
        if (c.residual) sum += res[at];
        const double want = c.relu ? std::max(sum, 0.0) : sum;
        const double tol = 8.0 * k * eps * mag + 4.0 * eps * (std::fabs(sum) + 2.0);
        if (!(std::fabs(y[at] - want) <= tol) && ++failures <= 3) {
          ADD_FAILURE() << g.name << " " << describe(c) << ": y(" << oy << "," << ox << "," << o << ") = " << y[at]
                        << ", want " << want << " within " << tol;
        }
      }
    }
  }
  return y;
}

TEST(WinogradF32, EveryVariantMatchesTheExactConvolution) {
  const auto isas = test::isas_under_test(&IsaTables::gemm_f32);
  ASSERT_FALSE(isas.empty());
  const Case cases[] = {
      {6, 8, 16, 16, true, false, true},          // whole tiles
      {7, 5, 32, 48, true, true, true},           // odd sizes: tiles cut by the bottom and right edges
      {1, 1, 16, 32, false, false, false},        // one pixel: every tap but the centre in the padding
      {9, 11, 48, 80, true, true, false, 7, 11},  // a range of tiles from the middle, ragged rows
      {4, 3, 64, 16, false, true, true, 3, 2},    // the last tiles, a narrow image
      {15, 20, 16, 144, true, false, true},       // layer4's image, more tiles than one block (96)
      {20, 22, 16, 16, true, true, true, 10, 100},  // a range over two blocks
  };
  for (const Case& c : cases) {
    const std::vector<float>* simd = nullptr;
    std::vector<std::vector<float>> outputs;
    outputs.reserve(isas.size());
    for (Isa isa : isas) {
      const GemmF32Kernels& g = test::table_of(isa, &IsaTables::gemm_f32);
      outputs.push_back(check_case(g, c));
      if (isa == Isa::kRef) continue;
      if (simd == nullptr) {
        simd = &outputs.back();
      } else {
        EXPECT_EQ(outputs.back(), *simd) << g.name << " " << describe(c) << ": not the other SIMD variants' bits";
      }
    }
  }
}

TEST(WinogradF32, AppliesOnlyToPaddedStrideOne3x3OfWholeChannelGroups) {
  const Conv2dShape ok = Conv2dShape::square(8, 8, 64, 64, 3, 1, 1);
  EXPECT_TRUE(winograd_f32_applies(ok, GemmF32Activation::kRelu));
  EXPECT_FALSE(winograd_f32_applies(ok, GemmF32Activation::kGelu));
  EXPECT_FALSE(winograd_f32_applies(Conv2dShape::square(8, 8, 64, 64, 3, 2, 1), GemmF32Activation::kNone));
  EXPECT_FALSE(winograd_f32_applies(Conv2dShape::square(8, 8, 64, 64, 1, 1, 0), GemmF32Activation::kNone));
  EXPECT_FALSE(winograd_f32_applies(Conv2dShape::square(8, 8, 64, 64, 3, 1, 2, 2), GemmF32Activation::kNone));
  EXPECT_FALSE(winograd_f32_applies(Conv2dShape::square(8, 8, 3, 64, 3, 1, 1), GemmF32Activation::kNone));
  EXPECT_FALSE(winograd_f32_applies(Conv2dShape::square(8, 8, 64, 40, 3, 1, 1), GemmF32Activation::kNone));
}

}  // namespace
}  // namespace act::kernels
