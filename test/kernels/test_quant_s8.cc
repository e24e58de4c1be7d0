// Float <-> int8 conversions (kernels/quant/quant_s8.h): the reference against naive definitions
// written here from the header's rule, on edge cases (ties, NaN, infinities, saturation, constant /
// all-negative / huge / tiny rows); then every variant bit for bit against the reference.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <string>
#include <random>
#include <vector>

#include "kernels/quant/quant_s8.h"
#include "kernels/quant/quant_s8_variants.h"
#include "test/kernels/kernel_test_util.h"

namespace act::kernels {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// The normative variant, which the rule tests check; the SIMD variants must give its bits.
const QuantS8Kernels& reference() { return *quant_s8_table_ref(); }

// The header's rule, one float operation per line (the kernels build without FMA contraction and
// so does this test: volatile stops the compiler from fusing the multiply and the add).
int8_t quantize_naive(float x, float inv_scale, int32_t zero_point) {
  volatile float v = x * inv_scale;
  float w = v + static_cast<float>(zero_point);
  if (!(w > -128.0f)) w = -128.0f;  // NaN -> -128
  if (w > 127.0f) w = 127.0f;
  return static_cast<int8_t>(std::nearbyint(w));
}

// Uniform in [lo, hi], drawn in [0, 1) and scaled so that spans beyond FLT_MAX work too.
std::vector<float> random_floats(size_t n, std::mt19937& rng, float lo, float hi) {
  std::uniform_real_distribution<float> d(0.0f, 1.0f);
  std::vector<float> v(n);
  for (auto& x : v) {
    const float t = d(rng);
    x = lo * (1.0f - t) + hi * t;
  }
  return v;
}

TEST(QuantS8, ChooseCoversTheRangeAndKeepsZeroExact) {
  const std::pair<float, float> ranges[] = {{-1.0f, 1.0f}, {-3.0f, 0.5f}, {0.25f, 7.0f}, {-9.0f, -2.0f},
                                            {-1e-3f, 4e-3f}, {-60000.0f, 1.0f}, {0.0f, 1.0f}, {-1.0f, 0.0f}};
  for (const auto& [lo, hi] : ranges) {
    const QuantS8 q = choose_quant_s8(lo, hi);
    ASSERT_GT(q.scale, 0.0f);
    ASSERT_GE(q.zero_point, -128);
    ASSERT_LE(q.zero_point, 127);
    const float inv = 1.0f / q.scale;
    const float zero_f = 0.0f;
    int8_t zero;
    reference().quantize(1, &zero_f, inv, q.zero_point, &zero);
    EXPECT_EQ(zero, q.zero_point) << "0.0 must be exact for range " << lo << ".." << hi;
    // Both ends (and 0) are representable within half a step (plus float rounding).
    for (float x : {std::min(lo, 0.0f), std::max(hi, 0.0f)}) {
      int8_t c;
      reference().quantize(1, &x, inv, q.zero_point, &c);
      float back;
      reference().dequantize(1, &c, q.scale, q.zero_point, &back);
      EXPECT_LE(std::fabs(back - x), 0.5f * q.scale * 1.001f + 1e-30f) << lo << ".." << hi << " at " << x;
    }
  }
}

TEST(QuantS8, ChooseDegenerateHugeAndTinyRanges) {
  const QuantS8 zero = choose_quant_s8(0.0f, 0.0f);
  EXPECT_EQ(zero.scale, 1.0f);
  EXPECT_EQ(zero.zero_point, 0);
  // A span beyond FLT_MAX: finite scale, finite inverse, ends still covered.
  const QuantS8 huge = choose_quant_s8(-FLT_MAX, FLT_MAX);
  ASSERT_TRUE(std::isfinite(huge.scale));
  ASSERT_TRUE(std::isfinite(1.0f / huge.scale));
  EXPECT_NEAR(huge.scale, 2.0f * (FLT_MAX / 255.0f), FLT_MAX / 255.0f * 1e-6f);
  EXPECT_TRUE(huge.zero_point == 0 || huge.zero_point == -1) << huge.zero_point;
  // A denormal span: the inverse would overflow, so the scale is FLT_MIN.
  const QuantS8 tiny = choose_quant_s8(0.0f, 1e-44f);
  EXPECT_EQ(tiny.scale, FLT_MIN);
  EXPECT_TRUE(std::isfinite(1.0f / tiny.scale));
  EXPECT_EQ(tiny.zero_point, -128);
}

TEST(QuantS8, QuantizeMatchesTheRule) {
  std::mt19937 rng(3);
  for (float inv : {1.0f, 0.37f, 255.0f / 6.0f, 1e-3f, 3e5f}) {
    for (int32_t zp : {-128, -1, 0, 5, 127}) {
      auto x = random_floats(131, rng, -300.0f / inv, 300.0f / inv);
      x.insert(x.end(), {0.0f, -0.0f, kInf, -kInf, kNaN, -kNaN, FLT_MAX, -FLT_MAX, FLT_MIN, 1e-45f});
      std::vector<int8_t> y(x.size() + 1, 99);
      reference().quantize(x.size(), x.data(), inv, zp, y.data());
      for (size_t i = 0; i < x.size(); ++i) {
        ASSERT_EQ(y[i], quantize_naive(x[i], inv, zp)) << "x=" << x[i] << " inv=" << inv << " zp=" << zp;
      }
      EXPECT_EQ(y.back(), 99) << "wrote past n";
    }
  }
}

TEST(QuantS8, QuantizeTiesToEvenNaNAndSaturation) {
  const float x[] = {0.5f, 1.5f, 2.5f, -0.5f, -1.5f, -2.5f, 126.5f, -127.5f, 1e9f, -1e9f, kInf, -kInf, kNaN};
  const int8_t want[] = {0, 2, 2, 0, -2, -2, 126, -128, 127, -128, 127, -128, -128};
  int8_t y[std::size(x)];
  reference().quantize(std::size(x), x, 1.0f, 0, y);
  for (size_t i = 0; i < std::size(x); ++i) EXPECT_EQ(y[i], want[i]) << "x=" << x[i];
}

TEST(QuantS8, DequantizeIsExact) {
  std::vector<int8_t> q(256);
  for (int i = 0; i < 256; ++i) q[i] = static_cast<int8_t>(i - 128);
  for (float scale : {1.0f, 0.013f, 3e-30f, 1e30f}) {
    for (int32_t zp : {-128, 0, 17, 127}) {
      std::vector<float> y(q.size());
      reference().dequantize(q.size(), q.data(), scale, zp, y.data());
      for (size_t i = 0; i < q.size(); ++i) {
        const float d = static_cast<float>(q[i]) - static_cast<float>(zp);  // exact: small integers
        ASSERT_EQ(y[i], d * scale) << "q=" << int{q[i]} << " scale=" << scale << " zp=" << zp;
      }
    }
  }
}

TEST(QuantS8, MinMaxIgnoresNaN) {
  float lo, hi;
  const float a[] = {kNaN, 3.0f, -2.0f, kNaN, 7.5f, -0.5f};
  reference().minmax(std::size(a), a, &lo, &hi);
  EXPECT_EQ(lo, -2.0f);
  EXPECT_EQ(hi, 7.5f);
  const float all_nan[] = {kNaN, kNaN, kNaN};
  reference().minmax(std::size(all_nan), all_nan, &lo, &hi);
  EXPECT_EQ(lo, kInf);
  EXPECT_EQ(hi, -kInf);
  const float one = -4.0f;
  reference().minmax(1, &one, &lo, &hi);
  EXPECT_EQ(lo, -4.0f);
  EXPECT_EQ(hi, -4.0f);
  const float inf[] = {1.0f, kInf, -kInf};
  reference().minmax(std::size(inf), inf, &lo, &hi);
  EXPECT_EQ(lo, -kInf);
  EXPECT_EQ(hi, kInf);
}

// Each row: the parameters of choose_quant_s8(row min, row max) and the row quantized with them;
// the round trip is within half a step (a quarter-percent margin for float rounding).
void check_rows_dynamic(int rows, int cols, const std::vector<float>& x, size_t ldx) {
  const size_t ldy = static_cast<size_t>(cols) + 3;
  std::vector<int8_t> y(rows * ldy, 99);
  std::vector<float> scale(rows, -1.0f);
  std::vector<int32_t> zp(rows, 1000);
  quantize_rows_dynamic_f32_s8(reference(), rows, cols, x.data(), ldx, y.data(), ldy, scale.data(), zp.data());
  for (int r = 0; r < rows; ++r) {
    const float* xr = x.data() + r * ldx;
    float lo = kInf, hi = -kInf;
    for (int c = 0; c < cols; ++c) {
      lo = std::min(lo, xr[c]);
      hi = std::max(hi, xr[c]);
    }
    const QuantS8 q = choose_quant_s8(lo, hi);
    ASSERT_EQ(scale[r], q.scale) << "row " << r;
    ASSERT_EQ(zp[r], q.zero_point) << "row " << r;
    for (int c = 0; c < cols; ++c) {
      const int8_t v = y[r * ldy + c];
      ASSERT_EQ(v, quantize_naive(xr[c], 1.0f / q.scale, q.zero_point)) << "row " << r << " col " << c;
      const float back = q.scale * (static_cast<float>(v) - static_cast<float>(q.zero_point));
      ASSERT_LE(std::fabs(back - xr[c]), 0.5f * q.scale * 1.0025f) << "row " << r << " col " << c << " x " << xr[c];
    }
    for (size_t c = cols; c < ldy; ++c) ASSERT_EQ(y[r * ldy + c], 99) << "wrote into the row gap";
  }
}

TEST(QuantS8, RowsDynamicRandomAndStrided) {
  std::mt19937 rng(9);
  for (int cols : {1, 7, 16, 33, 512}) {
    const int rows = 5;
    const size_t ldx = static_cast<size_t>(cols) + 5;
    std::vector<float> x = random_floats(rows * ldx, rng, -4.0f, 9.0f);
    check_rows_dynamic(rows, cols, x, ldx);
  }
}

TEST(QuantS8, RowsDynamicEdgeRows) {
  const int cols = 37;
  std::vector<std::vector<float>> rows = {
      std::vector<float>(cols, 0.0f),     // all zero: scale 1, zp 0
      std::vector<float>(cols, 3.25f),    // constant positive: [0, 3.25]
      std::vector<float>(cols, -0.125f),  // constant negative: [-0.125, 0]
  };
  std::mt19937 rng(4);
  rows.push_back(random_floats(cols, rng, -9.0f, -1.0f));       // all negative: zp 127
  rows.push_back(random_floats(cols, rng, 2.0f, 3.0f));         // all positive: zp -128
  rows.push_back(random_floats(cols, rng, -3e38f, 3e38f));      // span beyond FLT_MAX
  rows.push_back(random_floats(cols, rng, -1e-40f, 1e-40f));    // denormals
  rows.push_back(random_floats(cols, rng, -1e-3f, 2e-3f));      // small
  std::vector<float> x;
  for (const auto& r : rows) x.insert(x.end(), r.begin(), r.end());
  check_rows_dynamic(static_cast<int>(rows.size()), cols, x, cols);

  std::vector<float> scale(rows.size());
  std::vector<int32_t> zp(rows.size());
  std::vector<int8_t> y(x.size());
  quantize_rows_dynamic_f32_s8(reference(), static_cast<int>(rows.size()), cols, x.data(), cols, y.data(), cols, scale.data(),
                               zp.data());
  EXPECT_EQ(scale[0], 1.0f);
  EXPECT_EQ(zp[0], 0);
  EXPECT_EQ(zp[1], -128);
  EXPECT_EQ(y[cols], 127);  // 3.25 is the top of its range
  EXPECT_EQ(zp[2], 127);
  EXPECT_EQ(y[2 * cols], -128);
  EXPECT_EQ(zp[3], 127);
  EXPECT_EQ(zp[4], -128);
  for (float s : scale) EXPECT_TRUE(std::isfinite(s) && std::isfinite(1.0f / s)) << s;
}


// ---- every variant against the reference, bit for bit -------------------------------------------

// Values that hit every case of the rule: random in and beyond the range, ties, zeros, NaNs,
// infinities, extremes, denormals.
std::vector<float> edge_values(size_t n, std::mt19937& rng, float span) {
  std::vector<float> x = random_floats(n, rng, -1.5f * span, 1.5f * span);
  const float specials[] = {0.0f, -0.0f, 0.5f, 1.5f, -2.5f, 126.5f, -127.5f, kInf, -kInf, kNaN, FLT_MAX, -FLT_MAX,
                            FLT_MIN, 1e-45f, -1e-45f};
  for (size_t i = 0; i < x.size(); i += 7) x[i] = specials[(i / 7) % std::size(specials)];
  return x;
}

class QuantS8Variant : public ::testing::TestWithParam<Isa> {
 protected:
  const QuantS8Kernels& v() const { return test::table_of(GetParam(), &IsaTables::quant); }
  const QuantS8Kernels& ref() const { return *quant_s8_table_ref(); }
};

// Sizes around every vector width and unroll (1..70), and a transformer row.
std::vector<size_t> sizes() {
  std::vector<size_t> s;
  for (size_t n = 1; n <= 70; ++n) s.push_back(n);
  s.push_back(512);
  s.push_back(3200 + 5);
  return s;
}

TEST_P(QuantS8Variant, QuantizeIsBitExact) {
  std::mt19937 rng(31);
  for (size_t n : sizes()) {
    for (auto [inv, zp] : {std::pair{1.0f, 0}, std::pair{0.37f, -128}, std::pair{42.5f, 127}, std::pair{3e5f, -5}}) {
      const std::vector<float> x = edge_values(n, rng, 200.0f / inv);
      std::vector<int8_t> want(n + 8, 99), got(n + 8, 99);
      ref().quantize(n, x.data(), inv, zp, want.data());
      v().quantize(n, x.data(), inv, zp, got.data());
      ASSERT_EQ(got, want) << v().quantize_name << " n=" << n << " inv=" << inv << " zp=" << zp;
    }
  }
}

TEST_P(QuantS8Variant, DequantizeIsBitExact) {
  std::mt19937 rng(32);
  std::uniform_int_distribution<int> byte(-128, 127);
  for (size_t n : sizes()) {
    std::vector<int8_t> q(n);
    for (auto& b : q) b = static_cast<int8_t>(byte(rng));
    for (auto [scale, zp] : {std::pair{1.0f, 0}, std::pair{0.013f, -128}, std::pair{3e-30f, 127}, std::pair{1e30f, 3}}) {
      std::vector<float> want(n + 4, 9.0f), got(n + 4, 9.0f);
      ref().dequantize(n, q.data(), scale, zp, want.data());
      v().dequantize(n, q.data(), scale, zp, got.data());
      for (size_t i = 0; i < want.size(); ++i) {
        ASSERT_EQ(std::memcmp(&got[i], &want[i], 4), 0) << v().dequantize_name << " n=" << n << " at " << i;
      }
    }
  }
}

TEST_P(QuantS8Variant, MinMaxEqualsReference) {
  std::mt19937 rng(33);
  for (size_t n : sizes()) {
    for (int kind = 0; kind < 4; ++kind) {
      std::vector<float> x = edge_values(n, rng, 5.0f);
      if (kind == 1) x = random_floats(n, rng, -9.0f, -1.0f);  // no NaN, no infinity
      if (kind == 2) std::fill(x.begin(), x.end(), kNaN);
      if (kind == 3) {
        x = random_floats(n, rng, 1.0f, 2.0f);
        x[n - 1] = kNaN;  // a NaN in the tail
        x[n / 2] = -3.0f;
      }
      float lo_w, hi_w, lo, hi;
      ref().minmax(n, x.data(), &lo_w, &hi_w);
      v().minmax(n, x.data(), &lo, &hi);
      ASSERT_EQ(lo, lo_w) << v().minmax_name << " n=" << n << " kind " << kind;  // as floats: +-0 alike
      ASSERT_EQ(hi, hi_w) << v().minmax_name << " n=" << n << " kind " << kind;
    }
  }
}

TEST_P(QuantS8Variant, RowsDynamicIsBitExact) {
  std::mt19937 rng(34);
  for (int cols : {1, 15, 17, 64, 512, 515}) {
    const int rows = 9;
    const size_t ldx = static_cast<size_t>(cols) + 1, ldy = static_cast<size_t>(cols) + 2;
    std::vector<float> x = random_floats(rows * ldx, rng, -6.0f, 4.0f);
    std::fill(x.begin(), x.begin() + cols, 2.5f);                        // constant row
    for (int c = 0; c < cols; ++c) x[ldx + c] = -std::fabs(x[ldx + c]);  // all-negative row
    for (int c = 0; c < cols; ++c) x[2 * ldx + c] *= 1e37f;              // huge row
    x[3 * ldx] = kNaN;                                                   // a NaN in a row
    std::vector<int8_t> yw(rows * ldy, 99), y(rows * ldy, 99);
    std::vector<float> sw(rows), s(rows);
    std::vector<int32_t> zw(rows), z(rows);
    quantize_rows_dynamic_f32_s8(ref(), rows, cols, x.data(), ldx, yw.data(), ldy, sw.data(), zw.data());
    quantize_rows_dynamic_f32_s8(v(), rows, cols, x.data(), ldx, y.data(), ldy, s.data(), z.data());
    ASSERT_EQ(y, yw) << isa_name(GetParam()) << " cols=" << cols;
    ASSERT_EQ(s, sw);
    ASSERT_EQ(z, zw);
  }
}

// Rows with every kind of content: constant, all-negative, huge, tiny, all zero, a NaN, an
// infinity, all NaN, then random, in that order every 13 rows (so that every lane of a kernel's
// group of 16 rows meets them; rows of `cols` values, row stride ldx).
std::vector<float> symmetric_test_matrix(int rows, int cols, size_t ldx, std::mt19937& rng) {
  std::vector<float> x = random_floats(static_cast<size_t>(rows) * ldx, rng, -6.0f, 4.0f);
  for (int r = 0; r < rows; ++r) {
    if (r % 13 >= 8) continue;
    float* xr = x.data() + static_cast<size_t>(r) * ldx;
    for (int c = 0; c < cols; ++c) {
      switch (r % 13) {
        case 0: xr[c] = 2.5f; break;
        case 1: xr[c] = -std::fabs(xr[c]); break;
        case 2: xr[c] *= 1e37f; break;
        case 3: xr[c] *= 1e-40f; break;
        case 4: xr[c] = 0.0f; break;
        case 5: xr[c] = c == cols / 2 ? kNaN : xr[c]; break;
        case 6: xr[c] = c == cols - 1 ? -kInf : xr[c]; break;
        default: xr[c] = kNaN;
      }
    }
  }
  return x;
}

// Symmetric quantization as the attention op did it row by row before the multi-row kernels, from
// the reference's minmax and quantize: max |row| / 127 (at least FLT_MIN), inverse 0 for a zero
// or non-finite range.
void rows_symmetric_naive(int rows, int cols, const float* x, size_t ldx, int8_t* y, size_t ldy, float* row_scale) {
  for (int r = 0; r < rows; ++r) {
    const float* xr = x + static_cast<size_t>(r) * ldx;
    float lo, hi;
    reference().minmax(static_cast<size_t>(cols), xr, &lo, &hi);
    const float absmax = std::isfinite(lo) && std::isfinite(hi) ? std::max(-lo, hi) : 0.0f;
    row_scale[r] = std::max(absmax / 127.0f, FLT_MIN);
    reference().quantize(static_cast<size_t>(cols), xr, absmax > 0.0f ? 1.0f / row_scale[r] : 0.0f, 0,
                         y + static_cast<size_t>(r) * ldy);
  }
}

TEST_P(QuantS8Variant, RowsSymmetricMatchesPerRowPath) {
  std::mt19937 rng(35);
  for (int cols : {1, 3, 15, 16, 17, 33, 48, 63, 64, 65, 302, 515}) {
    for (int rows : {1, 11, 16, 37, 48}) {  // the AVX-512 variant's groups of 16 rows, the last one short
      const size_t ldx = static_cast<size_t>(cols) + 5, ldy = static_cast<size_t>(cols) + 2;
      const std::vector<float> x = symmetric_test_matrix(rows, cols, ldx, rng);
      std::vector<int8_t> yw(rows * ldy, 99), y(rows * ldy, 99);
      std::vector<float> sw(rows), s(rows, -1.0f);
      rows_symmetric_naive(rows, cols, x.data(), ldx, yw.data(), ldy, sw.data());
      v().quantize_rows_symmetric(rows, cols, x.data(), ldx, y.data(), ldy, s.data());
      ASSERT_EQ(y, yw) << v().rows_symmetric_name << " rows=" << rows << " cols=" << cols;  // padding untouched too
      ASSERT_EQ(0, std::memcmp(s.data(), sw.data(), s.size() * sizeof(float))) << v().rows_symmetric_name;
    }
  }
}

// Per column is per row of the transpose: the same codes (transposed back) and scales, which is
// what the attention op's values got from the float transposed copy this replaced.
TEST_P(QuantS8Variant, ColumnsSymmetricMatchesRowsOfTranspose) {
  std::mt19937 rng(36);
  for (int cols : {1, 3, 4, 7, 8, 15, 16, 17, 33, 64, 70}) {
    for (int rows : {1, 5, 302}) {
      const size_t ldt = static_cast<size_t>(rows) + 1;  // x^T [cols x rows]
      const std::vector<float> xt = symmetric_test_matrix(cols, rows, ldt, rng);
      const size_t ldx = static_cast<size_t>(cols) + 3, ldy = static_cast<size_t>(cols) + 1;
      std::vector<float> x(static_cast<size_t>(rows) * ldx, 7.0f);
      for (int r = 0; r < rows; ++r) {
        for (int c = 0; c < cols; ++c) x[r * ldx + c] = xt[c * ldt + r];
      }
      std::vector<int8_t> yt(static_cast<size_t>(cols) * rows), y(rows * ldy, 99);
      std::vector<float> sw(cols), s(cols, -1.0f);
      rows_symmetric_naive(cols, rows, xt.data(), ldt, yt.data(), static_cast<size_t>(rows), sw.data());
      v().quantize_columns_symmetric(rows, cols, x.data(), ldx, y.data(), ldy, s.data());
      for (int r = 0; r < rows; ++r) {
        for (int c = 0; c < cols; ++c) {
          ASSERT_EQ(y[r * ldy + c], yt[static_cast<size_t>(c) * rows + r])
              << v().columns_symmetric_name << " rows=" << rows << " cols=" << cols << " at " << r << "," << c;
        }
        for (size_t c = static_cast<size_t>(cols); c < ldy; ++c) ASSERT_EQ(y[r * ldy + c], 99) << "wrote past the row";
      }
      ASSERT_EQ(0, std::memcmp(s.data(), sw.data(), s.size() * sizeof(float))) << v().columns_symmetric_name;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Available, QuantS8Variant,
                         ::testing::ValuesIn(test::isas_under_test(&IsaTables::quant)),
                         test::isa_param_name);
GTEST_ALLOW_UNINSTANTIATED_PARAMETERIZED_TEST(QuantS8Variant);

// At every level CI requires, an Engine runs a SIMD quant variant (its own functions, not the
// reference's), and it is among the variants tested above.
TEST(QuantS8Variants, RequiredLevelsRunSimdVariants) {
  const QuantS8Kernels& ref = *quant_s8_table_ref();
  const std::vector<Isa> tested = test::isas_under_test(&IsaTables::quant);
  for (const std::optional<Isa>& isa : test::required_isas()) {
    ASSERT_TRUE(isa.has_value()) << "ACT_TEST_REQUIRE_ISAS names an unknown ISA";
    ASSERT_TRUE(cpu_supports(*isa)) << isa_name(*isa) << " is required but this CPU does not run it";
    const QuantS8Kernels& v = variant_for(*isa, &IsaTables::quant);
    EXPECT_NE(v.isa, Isa::kRef) << "no SIMD quant variant at " << isa_name(*isa);
    EXPECT_NE(v.quantize, ref.quantize);
    EXPECT_NE(v.dequantize, ref.dequantize);
    EXPECT_NE(v.minmax, ref.minmax);
    EXPECT_NE(std::string(v.quantize_name).find(isa_name(v.isa)), std::string::npos);
    if (std::getenv("ACT_ISA") == nullptr) {
      EXPECT_NE(std::find(tested.begin(), tested.end(), v.isa), tested.end()) << isa_name(v.isa) << " was not tested";
    }
  }
}

}  // namespace
}  // namespace act::kernels
