// The calibration range choices (minmax, percentile, mse) of weights/quantize/activation_ranges.h.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "weights/quantize/activation_ranges.h"

namespace act {
namespace {

std::vector<float> heavy_tailed(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::exponential_distribution<float> body(4.0f);
  std::vector<float> v(n);
  for (auto& x : v) x = body(rng);  // ReLU-like: >= 0, a long right tail
  v[n / 2] = 40.0f;                 // one outlier far beyond the body
  return v;
}

RangeObserver observe(const std::vector<float>& v) {
  RangeObserver o;
  o.observe_range(v);
  o.observe_histogram(v);
  return o;
}

TEST(RangeObserver, MinMaxCoversTheWholeRange) {
  std::vector<float> v = {-1.5f, 0.25f, 3.0f, NAN, 2.0f};
  RangeObserver o;
  o.observe_range(v);
  EXPECT_EQ(o.min(), -1.5f);
  EXPECT_EQ(o.max(), 3.0f);
  const ActivationQuant a = o.choose_minmax();
  EXPECT_NEAR(a.scale, 4.5f / 255.0f, 1e-7f);
  // -1.5 and 3.0 land on the ends of the int8 range (within the zero point's rounding).
  EXPECT_NEAR(-1.5f / a.scale + static_cast<float>(a.zero_point), -128.0f, 0.51f);
  EXPECT_NEAR(3.0f / a.scale + static_cast<float>(a.zero_point), 127.0f, 0.51f);
}

TEST(RangeObserver, PercentileClipsAnOutlier) {
  const RangeObserver o = observe(heavy_tailed(100000, 1));
  const ActivationQuant a = o.choose_percentile(99.9);
  EXPECT_LT(a.scale * 255.0f, 10.0f);  // far below the outlier's 40
  EXPECT_GT(a.scale * 255.0f, 1.0f);   // but above the body (99.9% of Exp(4) is ~1.7)
  EXPECT_EQ(a.zero_point, -128);       // non-negative data: 0 is the lowest code
}

TEST(RangeObserver, MseMinimizesTheExpectedError) {
  // A body with a thin tail of large values: clipping the tail trades a little clipping error for
  // a finer step over the body.
  std::vector<float> v = heavy_tailed(100000, 2);
  for (size_t i = 0; i < 30; ++i) v[i * 997] = 8.0f + static_cast<float>(i) * 0.5f;
  const RangeObserver o = observe(v);
  const ActivationQuant minmax = o.choose_minmax();
  const ActivationQuant pct = o.choose_percentile(99.9);
  const ActivationQuant mse = o.choose_mse();
  EXPECT_LT(mse.scale, minmax.scale);
  EXPECT_LT(o.expected_squared_error(mse), o.expected_squared_error(minmax));
  EXPECT_LE(o.expected_squared_error(mse), o.expected_squared_error(pct));
}

TEST(RangeObserver, ConstantDataGivesAUsableScale) {
  const RangeObserver o = observe(std::vector<float>(100, 0.0f));
  for (const ActivationQuant& a : {o.choose_minmax(), o.choose_percentile(99.99), o.choose_mse()}) {
    EXPECT_GT(a.scale, 0.0f);
    EXPECT_TRUE(std::isfinite(a.scale));
  }
}

}  // namespace
}  // namespace act
