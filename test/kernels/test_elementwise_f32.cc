// The float element-wise variants (xsimd per ISA) against the scalar reference, with the bounds
// stated in kernels/fp32/elementwise_f32.h: relu and add bit-exact; layernorm, softmax and GELU
// within a stated tolerance. Sizes cover every vector width and ragged tail, rows are strided.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "kernels/fp32/elementwise_f32.h"
#include "test/kernels/kernel_test_util.h"

namespace act::kernels {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

std::vector<float> random_floats(size_t n, std::mt19937& rng, float lo, float hi) {
  std::uniform_real_distribution<float> d(lo, hi);
  std::vector<float> v(n);
  for (auto& x : v) x = d(rng);
  return v;
}

std::vector<int> col_sizes() {
  std::vector<int> s;
  for (int n = 1; n <= 40; ++n) s.push_back(n);
  for (int n : {63, 64, 65, 302, 512, 515}) s.push_back(n);
  return s;
}

class ElementwiseF32Variant : public ::testing::TestWithParam<Isa> {
 protected:
  const ElementwiseF32Kernels& v() const { return test::table_of(GetParam(), &IsaTables::elementwise); }
  const ElementwiseF32Kernels& ref() const { return *elementwise_f32_table_ref(); }
};

TEST_P(ElementwiseF32Variant, ReluAndAddAreBitExact) {
  std::mt19937 rng(41);
  for (int n : col_sizes()) {
    std::vector<float> x = random_floats(n + 3, rng, -2.0f, 2.0f);
    x[0] = -0.0f;
    if (n > 2) x[2] = kNaN;
    std::vector<float> a = x, b = x;
    ref().relu(n, a.data());
    v().relu(n, b.data());
    ASSERT_EQ(std::memcmp(a.data(), b.data(), b.size() * 4), 0) << v().relu_name << " n=" << n;
    const std::vector<float> y = random_floats(n, rng, -1e3f, 1e3f);
    std::vector<float> sa(n + 2, 7.0f), sb(n + 2, 7.0f);
    ref().add(n, x.data(), y.data(), sa.data());
    v().add(n, x.data(), y.data(), sb.data());
    ASSERT_EQ(std::memcmp(sa.data(), sb.data(), sb.size() * 4), 0) << v().add_name << " n=" << n;
  }
  // In place.
  std::vector<float> p = random_floats(37, rng, -1.0f, 1.0f), q = p;
  ref().add(37, p.data(), p.data(), p.data());
  v().add(37, q.data(), q.data(), q.data());
  EXPECT_EQ(p, q);
}

// The max-pool's channel max: bit-exact on ragged channel counts and tap counts, NaN and -0 among
// the taps (a NaN first tap stays, a later one never wins), over a run of three windows a stride
// apart and, for one window, into one of the taps.
TEST_P(ElementwiseF32Variant, MaxTapsIsBitExact) {
  std::mt19937 rng(43);
  for (int channels : col_sizes()) {
    for (int ntaps : {1, 2, 3, 9, 32}) {
      constexpr int kPixels = 3;
      const size_t step = 2 * static_cast<size_t>(channels) + 1;  // a stride-2 pool's, plus one
      std::vector<std::vector<float>> taps(static_cast<size_t>(ntaps));
      std::vector<const float*> pointers;
      for (auto& t : taps) {
        t = random_floats((kPixels - 1) * step + static_cast<size_t>(channels), rng, -3.0f, 3.0f);
        t[0] = -0.0f;
        if (channels > 2) t[2] = rng() % 2 ? kNaN : t[2];
        pointers.push_back(t.data());
      }
      std::vector<float> a(kPixels * static_cast<size_t>(channels) + 2, 7.0f), b = a, naive = a;
      ref().max_taps(pointers.data(), ntaps, kPixels, step, channels, a.data());
      v().max_taps(pointers.data(), ntaps, kPixels, step, channels, b.data());
      ASSERT_EQ(std::memcmp(a.data(), b.data(), b.size() * 4), 0) << v().max_taps_name << " channels " << channels << " taps " << ntaps;
      for (int i = 0; i < kPixels; ++i) {  // window by window, as the driver's border pixels
        std::vector<const float*> window;
        for (const float* p : pointers) window.push_back(p + static_cast<size_t>(i) * step);
        v().max_taps(window.data(), ntaps, 1, 0, channels, naive.data() + static_cast<size_t>(i) * channels);
      }
      ASSERT_EQ(std::memcmp(naive.data(), b.data(), b.size() * 4), 0) << v().max_taps_name << " run against window by window";
      // Into the first tap.
      std::vector<float> first_ref = taps[0], first_v = taps[0];
      pointers[0] = first_ref.data();
      ref().max_taps(pointers.data(), ntaps, 1, 0, channels, first_ref.data());
      pointers[0] = first_v.data();
      v().max_taps(pointers.data(), ntaps, 1, 0, channels, first_v.data());
      ASSERT_EQ(std::memcmp(first_ref.data(), first_v.data(), static_cast<size_t>(channels) * 4), 0) << v().max_taps_name << " in place";
      ASSERT_EQ(std::memcmp(first_ref.data(), a.data(), static_cast<size_t>(channels) * 4), 0) << "in place gives the same";
    }
  }
}

TEST_P(ElementwiseF32Variant, LayerNormWithinTolerance) {
  std::mt19937 rng(42);
  for (int cols : col_sizes()) {
    const int rows = 3;
    const size_t ldx = cols + 5, ldy = cols + 2;
    // Rows with a large common offset test the two-pass variance.
    for (float offset : {0.0f, 50.0f}) {
      std::vector<float> x = random_floats(rows * ldx, rng, -3.0f + offset, 5.0f + offset);
      const std::vector<float> g = random_floats(cols, rng, -1.0f, 1.0f), b = random_floats(cols, rng, -1.0f, 1.0f);
      std::vector<float> ya(rows * ldy, 9.0f), yb(rows * ldy, 9.0f);
      ref().layernorm_rows(rows, cols, x.data(), ldx, g.data(), b.data(), 1e-5f, ya.data(), ldy);
      v().layernorm_rows(rows, cols, x.data(), ldx, g.data(), b.data(), 1e-5f, yb.data(), ldy);
      for (int r = 0; r < rows; ++r) {
        // Rounding x - mean in float costs ulp(mean) / std in y: the bound scales with |mean| / std.
        double mean = 0, var = 0;
        for (int c = 0; c < cols; ++c) mean += x[r * ldx + c];
        mean /= cols;
        for (int c = 0; c < cols; ++c) var += (x[r * ldx + c] - mean) * (x[r * ldx + c] - mean);
        const double cond = 1.0 + std::fabs(mean) / std::sqrt(var / cols + 1e-5);
        for (int c = 0; c < cols; ++c) {
          const float want = ya[r * ldy + c], got = yb[r * ldy + c];
          ASSERT_LE(std::fabs(want - got), 1e-6 * cond * (std::fabs(want) + 1.0))
              << v().layernorm_name << " cols=" << cols << " offset " << offset << " row " << r << " col " << c;
        }
      }
      for (int r = 0; r < rows; ++r) {
        for (size_t c = cols; c < ldy; ++c) ASSERT_EQ(yb[r * ldy + c], 9.0f) << "wrote into the row gap";
      }
    }
  }
}

TEST_P(ElementwiseF32Variant, SoftmaxWithinTolerance) {
  std::mt19937 rng(43);
  for (int cols : col_sizes()) {
    const int rows = 4;
    const size_t ld = cols + 3;
    std::vector<float> x = random_floats(rows * ld, rng, -12.0f, 12.0f);
    x[0] = 80.0f;  // large logits must not overflow
    x[ld] = -80.0f;
    std::vector<float> a = x, b = x;
    ref().softmax_rows(rows, cols, a.data(), ld);
    v().softmax_rows(rows, cols, b.data(), ld);
    for (size_t i = 0; i < a.size(); ++i) {
      ASSERT_LE(std::fabs(a[i] - b[i]), std::max(2e-6f * a[i], 1e-9f))
          << v().softmax_name << " cols=" << cols << " at " << i << ": " << a[i] << " vs " << b[i];
    }
  }
}

// A NaN logit anywhere in a row (first, in a whole batch, in the ragged end) makes that row's
// probabilities NaN, and the int8 softmax's row scale NaN, as std::exp makes the reference's: the
// SIMD exp's clamp must not turn it into a tiny finite number. The other row stays finite.
TEST_P(ElementwiseF32Variant, SoftmaxNaNLogitMakesItsRowNaN) {
  std::mt19937 rng(44);
  for (int cols : col_sizes()) {
    for (int at : {0, cols / 2, cols - 1}) {
      const size_t ld = static_cast<size_t>(cols) + 1;
      std::vector<float> x = random_floats(2 * ld, rng, -4.0f, 4.0f);
      x[static_cast<size_t>(at)] = kNaN;
      std::vector<float> p = x;
      v().softmax_rows(2, cols, p.data(), ld);
      std::vector<int8_t> codes(2 * ld);
      float scale[2];
      v().softmax_rows_s8(2, cols, x.data(), ld, codes.data(), ld, scale);
      for (int c = 0; c < cols; ++c) {
        ASSERT_TRUE(std::isnan(p[static_cast<size_t>(c)])) << v().softmax_name << " cols=" << cols << " NaN at " << at << ", " << c;
        ASSERT_TRUE(std::isfinite(p[ld + static_cast<size_t>(c)])) << v().softmax_name << " cols=" << cols;
      }
      EXPECT_TRUE(std::isnan(scale[0])) << v().softmax_s8_name << " cols=" << cols << " NaN at " << at;
      EXPECT_TRUE(std::isfinite(scale[1])) << v().softmax_s8_name << " cols=" << cols;
    }
  }
}

// The fused softmax + int8: every variant within the stated bounds of the reference, and the
// reference's dequantized probabilities within half a code (plus float rounding) of the softmax.
TEST_P(ElementwiseF32Variant, SoftmaxS8WithinToleranceAndHalfACodeOfTheSoftmax) {
  std::mt19937 rng(12);
  for (int cols : col_sizes()) {
    const int rows = 3;
    const size_t ld = static_cast<size_t>(cols) + 5;
    std::vector<float> x = random_floats(rows * ld, rng, -6.0f, 6.0f);
    // The last row spans far more than the codes' range, its exps down to far below 2^-125 (where
    // the SIMD exp's argument is clamped), around a large logit.
    for (size_t c = 0; c < static_cast<size_t>(cols); ++c) x[2 * ld + c] = 60.0f + 4.0f * (x[2 * ld + c] - 6.0f) * 8.0f;
    std::vector<int8_t> y_ref(rows * ld), y(rows * ld);
    float scale_ref[rows], scale[rows];
    ref().softmax_rows_s8(rows, cols, x.data(), ld, y_ref.data(), ld, scale_ref);
    v().softmax_rows_s8(rows, cols, x.data(), ld, y.data(), ld, scale);
    for (int r = 0; r < rows; ++r) {
      EXPECT_NEAR(scale[r], scale_ref[r], 4e-6 * scale_ref[r]) << v().softmax_s8_name << " cols=" << cols;
      std::vector<float> p(x.begin() + static_cast<std::ptrdiff_t>(r * ld), x.begin() + static_cast<std::ptrdiff_t>(r * ld + cols));
      ref().softmax_rows(1, cols, p.data(), ld);
      float p_max = 0.0f;
      for (float pc : p) p_max = std::max(p_max, pc);
      for (int c = 0; c < cols; ++c) {
        const size_t i = r * ld + static_cast<size_t>(c);
        EXPECT_LE(std::abs(int{y[i]} - int{y_ref[i]}), 1) << v().softmax_s8_name << " cols=" << cols << " at " << c;
        const float dequantized = scale_ref[r] * static_cast<float>(int{y_ref[i]} - kSoftmaxS8ZeroPoint);
        ASSERT_NEAR(dequantized, p[static_cast<size_t>(c)], 0.5f * scale_ref[r] + 1e-6f * p_max) << "cols=" << cols << " at " << c;
      }
      EXPECT_EQ(*std::max_element(y_ref.begin() + static_cast<std::ptrdiff_t>(r * ld),
                                  y_ref.begin() + static_cast<std::ptrdiff_t>(r * ld + cols)), 127)
          << "the largest probability takes the top code";
    }
  }
}

TEST_P(ElementwiseF32Variant, GeluWithinTolerance) {
  std::mt19937 rng(44);
  for (int n : col_sizes()) {
    std::vector<float> x = random_floats(n, rng, -6.0f, 6.0f);
    if (n > 3) {
      x[1] = 0.0f;
      x[2] = -10.0f;
      x[3] = 10.0f;
    }
    std::vector<float> a = x, b = x;
    ref().gelu(n, a.data());
    v().gelu(n, b.data());
    for (int i = 0; i < n; ++i) {
      ASSERT_TRUE(test::ulp_distance(a[i], b[i]) <= 4 || std::fabs(a[i] - b[i]) <= 1e-7f)
          << v().gelu_name << " x=" << x[i] << ": " << a[i] << " vs " << b[i];
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Available, ElementwiseF32Variant,
                         ::testing::ValuesIn(test::isas_under_test(&IsaTables::elementwise)),
                         test::isa_param_name);
GTEST_ALLOW_UNINSTANTIATED_PARAMETERIZED_TEST(ElementwiseF32Variant);

// At every level CI requires, an Engine runs a SIMD element-wise variant (its own functions, not
// the reference's), and it is among the variants tested above.
TEST(ElementwiseF32Variants, RequiredLevelsRunSimdVariants) {
  const ElementwiseF32Kernels& ref = *elementwise_f32_table_ref();
  const std::vector<Isa> tested = test::isas_under_test(&IsaTables::elementwise);
  for (const std::optional<Isa>& isa : test::required_isas()) {
    ASSERT_TRUE(isa.has_value()) << "ACT_TEST_REQUIRE_ISAS names an unknown ISA";
    ASSERT_TRUE(cpu_supports(*isa)) << isa_name(*isa) << " is required but this CPU does not run it";
    const ElementwiseF32Kernels& v = variant_for(*isa, &IsaTables::elementwise);
    EXPECT_NE(v.isa, Isa::kRef) << "no SIMD element-wise variant at " << isa_name(*isa);
    EXPECT_NE(v.layernorm_rows, ref.layernorm_rows);
    EXPECT_NE(v.softmax_rows, ref.softmax_rows);
    EXPECT_NE(v.softmax_rows_s8, ref.softmax_rows_s8);
    EXPECT_NE(v.gelu, ref.gelu);
    if (std::getenv("ACT_ISA") == nullptr) {
      EXPECT_NE(std::find(tested.begin(), tested.end(), v.isa), tested.end()) << isa_name(v.isa) << " was not tested";
    }
  }
}

}  // namespace
}  // namespace act::kernels
