// The calibration range choices (minmax, percentile, mse) of weights/quantize/activation_ranges.h.
#include <gtest/gtest.h>

#include <algorithm>
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
  o.observe(v);
  return o;
}

// The histogram's count of values in [lo, hi) (both on its bin edges).
double count_between(const RangeObserver::Histogram& h, double lo, double hi) {
  double n = 0.0;
  for (size_t b = 0; b < h.counts.size(); ++b) {
    const double edge = h.first_edge + static_cast<double>(b) * h.width;
    if (edge >= lo && edge + h.width <= hi) n += h.counts[b];
  }
  return n;
}

TEST(RangeObserver, MinMaxCoversTheWholeRange) {
  std::vector<float> v = {-1.5f, 0.25f, 3.0f, NAN, 2.0f};
  RangeObserver o;
  o.observe(v);
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

TEST(RangeObserver, OnePassCountsEveryValueInTheBinThatHoldsIt) {
  // The first frame spans [0, kMaxGridBins - 1], so the grid's edges are integers (and stay on
  // multiples of its power-of-two width as it grows): values at half-integers are never on an edge,
  // and the bin that holds each one is known exactly. Later frames widen the range both ways, by
  // little and by a lot: bins are added at the ends and pairs merged, no count crossing an edge.
  std::mt19937 rng(3);
  RangeObserver o;
  std::vector<float> all;
  const int top = RangeObserver::kMaxGridBins - 1;
  for (int frame = 0; frame < 12; ++frame) {
    const int lo = frame == 0 ? 0 : -100 * frame * frame, hi = frame == 0 ? top : top + 50 * frame * frame * frame;
    std::uniform_int_distribution<int> d(lo, hi - 1);
    std::vector<float> v(5000);
    for (float& x : v) x = static_cast<float>(d(rng)) + 0.5f;
    if (frame == 0) {
      v[0] = 0.0f;
      v[1] = static_cast<float>(top);
    }
    if (frame == 4) v[7] = NAN;
    o.observe(v);
    for (float x : v) {
      if (std::isfinite(x)) all.push_back(x);
    }
    const RangeObserver::Histogram h = o.histogram();
    ASSERT_GT(h.width, 0.0);
    // The bins cover [min, max], kMaxGridBins / 2 to kMaxGridBins of them.
    EXPECT_LE(h.first_edge, o.min());
    EXPECT_GT(h.first_edge + static_cast<double>(h.counts.size()) * h.width, o.max());
    EXPECT_LE(h.counts.size(), static_cast<size_t>(RangeObserver::kMaxGridBins));
    EXPECT_GE(static_cast<double>(o.max()) - o.min(), (RangeObserver::kMaxGridBins / 2 - 2) * h.width);
  }
  const RangeObserver::Histogram h = o.histogram();
  EXPECT_GT(h.width, 4.0);  // the test did merge bins
  double total = 0.0;
  for (double c : h.counts) total += c;
  EXPECT_EQ(total, static_cast<double>(all.size()));
  // Counts between any two bin edges equal the values there.
  for (size_t from : {size_t{0}, h.counts.size() / 3, h.counts.size() / 2, h.counts.size() - 40}) {
    const double lo = h.first_edge + static_cast<double>(from) * h.width, hi = lo + 37.0 * h.width;
    const auto inside = std::count_if(all.begin(), all.end(), [&](float x) { return x >= lo && x < hi; });
    EXPECT_EQ(count_between(h, lo, hi), static_cast<double>(inside)) << "bins from " << from;
  }
}

TEST(RangeObserver, FramesObservedOneByOneChooseAsAllAtOnce) {
  // Heavy-tailed frames whose range grows: the methods' bins taken from the grid give the scales
  // that the values seen in one call (the grid spanning exactly [min, max]) give.
  RangeObserver by_frame, at_once;
  std::vector<float> all;
  for (uint32_t frame = 0; frame < 10; ++frame) {
    std::vector<float> v = heavy_tailed(20000, 10 + frame);
    for (float& x : v) x = x * (1.0f + 0.3f * static_cast<float>(frame)) - 0.05f * static_cast<float>(frame);
    by_frame.observe(v);
    all.insert(all.end(), v.begin(), v.end());
  }
  at_once.observe(all);
  EXPECT_EQ(by_frame.min(), at_once.min());
  EXPECT_EQ(by_frame.max(), at_once.max());
  for (const auto& [a, b] : {std::pair{by_frame.choose_mse(), at_once.choose_mse()},
                             std::pair{by_frame.choose_percentile(99.9), at_once.choose_percentile(99.9)}}) {
    EXPECT_NEAR(a.scale, b.scale, 0.01f * b.scale);
    EXPECT_NEAR(a.zero_point, b.zero_point, 1);
  }
  EXPECT_LT(by_frame.choose_mse().scale, by_frame.choose_minmax().scale);  // the outliers are clipped
}

TEST(RangeObserver, ValuesSeenWhileConstantAreCountedOnceARangeAppears) {
  RangeObserver o;
  o.observe(std::vector<float>(100, 2.0f));
  EXPECT_FALSE(o.has_histogram());
  o.observe(std::vector<float>{0.0f, 4.0f});
  const RangeObserver::Histogram h = o.histogram();
  EXPECT_EQ(count_between(h, 1.5, 2.5), 100.0);
  EXPECT_EQ(count_between(h, h.first_edge, h.first_edge + static_cast<double>(h.counts.size()) * h.width), 102.0);
}

}  // namespace
}  // namespace act
