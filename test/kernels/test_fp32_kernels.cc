// The FP32 kernels against naive definitions, on random shapes including ragged tiles, every
// stride / padding / dilation the ResNet backbones use: conv_f32 (tiles of kernel rows read in place
// or gathered by im2col, + the packed GEMM)
// with every variant this CPU runs, the max-pool, and the element-wise reference
// (test_elementwise_f32.cc holds the SIMD element-wise variants to it; test_gemm_f32.cc the GEMM).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <random>

#include "kernels/common/im2col.h"
#include "kernels/fp32/conv_f32.h"
#include "kernels/fp32/elementwise_f32.h"
#include "kernels/fp32/fp32_kernels.h"
#include "kernels/fp32/gemm_f32.h"
#include "test/kernels/kernel_test_util.h"

namespace act::kernels {
namespace {

std::vector<float> random_vector(size_t n, std::mt19937& rng, float lo = -1.0f, float hi = 1.0f) {
  std::uniform_real_distribution<float> d(lo, hi);
  std::vector<float> v(n);
  for (auto& x : v) x = d(rng);
  return v;
}

// Direct convolution in double: NHWC input, OHWI weights.
std::vector<double> conv_naive(const Conv2dShape& s, const std::vector<float>& x, const std::vector<float>& w) {
  std::vector<double> y(static_cast<size_t>(s.out_h) * s.out_w * s.out_c, 0.0);
  for (int oy = 0; oy < s.out_h; ++oy)
    for (int ox = 0; ox < s.out_w; ++ox)
      for (int o = 0; o < s.out_c; ++o) {
        double acc = 0.0;
        for (int ky = 0; ky < s.kernel_h; ++ky)
          for (int kx = 0; kx < s.kernel_w; ++kx) {
            const int iy = oy * s.stride - s.pad + ky * s.dilation, ix = ox * s.stride - s.pad + kx * s.dilation;
            if (iy < 0 || iy >= s.in_h || ix < 0 || ix >= s.in_w) continue;
            for (int c = 0; c < s.in_c; ++c)
              acc += static_cast<double>(x[(static_cast<size_t>(iy) * s.in_w + ix) * s.in_c + c]) *
                     w[((static_cast<size_t>(o) * s.kernel_h + ky) * s.kernel_w + kx) * s.in_c + c];
          }
        y[(static_cast<size_t>(oy) * s.out_w + ox) * s.out_c + o] = acc;
      }
  return y;
}

struct ConvF32Case {
  int h, w, cin, cout, kernel, stride, pad, dilation;
};

TEST(Fp32Kernels, ConvEqualsDirectConvolution) {
  std::mt19937 rng(7);
  const ConvF32Case cases[] = {
      {13, 17, 3, 8, 7, 2, 3, 1},   // stem, odd sizes
      {9, 11, 5, 7, 3, 1, 1, 1},    // 3x3/1
      {10, 7, 4, 6, 3, 2, 1, 1},    // 3x3/2
      {8, 9, 6, 5, 1, 2, 0, 1},     // 1x1/2 downsample
      {7, 6, 3, 4, 3, 1, 2, 2},     // dilated 3x3 (layer4 with dilation)
      {1, 1, 3, 2, 3, 1, 1, 1},     // a single pixel: everything but the centre tap is padding
      {20, 3, 16, 33, 3, 2, 1, 1},  // out_c not a multiple of anything
      {6, 5, 7, 9, 1, 1, 0, 1},     // 1x1/1: reads the input in place
      {9, 8, 2, 70, 3, 1, 1, 1},    // kernel rows of 6 floats: im2col
  };
  for (Isa isa : test::isas_under_test(&IsaTables::gemm_f32)) {
    const GemmF32Kernels& gemm = test::table_of(isa, &IsaTables::gemm_f32);
    for (const ConvF32Case& c : cases) {
      const Conv2dShape s = Conv2dShape::square(c.h, c.w, c.cin, c.cout, c.kernel, c.stride, c.pad, c.dilation);
      const auto x = random_vector(static_cast<size_t>(c.h) * c.w * c.cin, rng);
      const auto w = random_vector(static_cast<size_t>(c.cout) * s.patch_size(), rng);
      const auto expected = conv_naive(s, x, w);
      const int pixels = s.out_h * s.out_w;
      std::vector<float> y(static_cast<size_t>(pixels) * c.cout, NAN);
      std::vector<float> packed(gemm_f32_packed_floats(gemm.nr, c.cout, s.patch_size()));
      gemm_f32_pack(gemm.nr, c.cout, s.patch_size(), w.data(), static_cast<size_t>(s.patch_size()), packed.data());
      const ConvF32 conv{s, &gemm, packed.data()};
      // Ragged tiles: 5 pixels at a time, through conv_f32 (im2col into scratch, or in place).
      std::vector<float> scratch(conv_f32_scratch_floats(s, 5) + 1, NAN);
      for (int p0 = 0; p0 < pixels; p0 += 5) {
        conv_f32(conv, x.data(), y.data(), GemmF32Epilogue{}, p0, std::min(5, pixels - p0), scratch.data());
      }
      // Kernel rows read in place or patches gathered, the same products: the GEMM of the whole im2col.
      std::vector<float> patches(static_cast<size_t>(pixels) * s.patch_size()), y_im2col(y.size());
      im2col_nhwc_f32(s, x.data(), 0, pixels, patches.data());
      gemm.packed({.m = pixels, .n = c.cout, .k = s.patch_size(), .a = patches.data(), .lda = static_cast<size_t>(s.patch_size()),
                   .packed_b = packed.data(), .c = y_im2col.data(), .ldc = static_cast<size_t>(c.cout), .epilogue = {}});
      for (size_t i = 0; i < y.size(); ++i) {
        ASSERT_NEAR(y[i], expected[i], 1e-5 * (1 + std::fabs(expected[i])) * s.patch_size())
            << gemm.name << " case " << c.h << "x" << c.w << " k" << c.kernel << "/" << c.stride << " at " << i;
        ASSERT_EQ(y[i], y_im2col[i]) << gemm.name << " case " << c.h << "x" << c.w << " k" << c.kernel << "/" << c.stride << " at " << i;
      }
    }
  }
}

TEST(Fp32Kernels, MaxPoolIgnoresPadding) {
  // All-negative input: if padding (0) took part in the max, the border outputs would be 0.
  const int h = 7, w = 5, c = 3;
  std::mt19937 rng(1);
  const auto x = random_vector(static_cast<size_t>(h) * w * c, rng, -5.0f, -1.0f);
  const int oh = Conv2dShape::out_dim(h, 3, 2, 1, 1), ow = Conv2dShape::out_dim(w, 3, 2, 1, 1);
  std::vector<float> y(static_cast<size_t>(oh) * ow * c);
  maxpool_nhwc_f32(*elementwise_f32_table_ref(), h, w, c, 3, 2, 1, ow, x.data(), y.data(), 0, oh);
  for (int oy = 0; oy < oh; ++oy)
    for (int ox = 0; ox < ow; ++ox)
      for (int ch = 0; ch < c; ++ch) {
        float best = -INFINITY;
        for (int iy = std::max(0, oy * 2 - 1); iy <= std::min(h - 1, oy * 2 + 1); ++iy)
          for (int ix = std::max(0, ox * 2 - 1); ix <= std::min(w - 1, ox * 2 + 1); ++ix)
            best = std::max(best, x[(iy * w + ix) * c + ch]);
        EXPECT_EQ(y[(oy * ow + ox) * c + ch], best);
        EXPECT_LT(best, 0.0f);
      }
}

TEST(Fp32Kernels, LayerNormSoftmaxAndActivations) {
  const ElementwiseF32Kernels& ref = *elementwise_f32_table_ref();
  std::mt19937 rng(5);
  const int rows = 3, cols = 37;
  auto x = random_vector(rows * cols, rng, -3.0f, 5.0f);
  const auto gamma = random_vector(cols, rng), beta = random_vector(cols, rng);
  std::vector<float> y(rows * cols);
  ref.layernorm_rows(rows, cols, x.data(), cols, gamma.data(), beta.data(), 1e-5f, y.data(), cols);
  for (int r = 0; r < rows; ++r) {
    double mean = 0, var = 0;
    for (int c = 0; c < cols; ++c) mean += x[r * cols + c];
    mean /= cols;
    for (int c = 0; c < cols; ++c) var += (x[r * cols + c] - mean) * (x[r * cols + c] - mean);
    var /= cols;
    for (int c = 0; c < cols; ++c)
      EXPECT_NEAR(y[r * cols + c], (x[r * cols + c] - mean) / std::sqrt(var + 1e-5) * gamma[c] + beta[c], 1e-5);
  }
  auto s = x;
  s[0] = 80.0f;  // large logits must not overflow
  ref.softmax_rows(rows, cols, s.data(), cols);
  for (int r = 0; r < rows; ++r) {
    double sum = 0;
    for (int c = 0; c < cols; ++c) sum += s[r * cols + c];
    EXPECT_NEAR(sum, 1.0, 1e-5);
  }
  EXPECT_NEAR(s[0], 1.0, 1e-6);
  std::vector<float> g = {-3.0f, -0.5f, 0.0f, 0.7f, 4.0f};
  ref.gelu(g.size(), g.data());
  const double in[] = {-3.0, -0.5, 0.0, 0.7, 4.0};
  for (size_t i = 0; i < g.size(); ++i) EXPECT_NEAR(g[i], 0.5 * in[i] * (1 + std::erf(in[i] / std::sqrt(2.0))), 1e-6);
  std::vector<float> r = {-1.0f, 0.0f, 2.0f};
  ref.relu(r.size(), r.data());
  EXPECT_EQ(r, (std::vector<float>{0.0f, 0.0f, 2.0f}));
}

}  // namespace
}  // namespace act::kernels
