// DiffStats, the apps' --compare arithmetic: NaN and infinity fail every check.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "apps/diff_stats.h"

namespace act {
namespace {

TEST(DiffStats, FiniteDifferences) {
  DiffStats d;
  d.add(1.0, 1.0);
  d.add(2.5, 2.0);
  d.add(-1.0, 0.0);
  EXPECT_EQ(d.count, 3u);
  EXPECT_EQ(d.non_finite, 0u);
  EXPECT_DOUBLE_EQ(d.max_abs, 1.0);
  EXPECT_DOUBLE_EQ(d.max_ratio, 1.0 / 1.0);  // |-1 - 0| / (1 + 0)
  EXPECT_DOUBLE_EQ(d.mse(), (0.0 + 0.25 + 1.0) / 3.0);
  EXPECT_TRUE(d.within(1.0));
  EXPECT_FALSE(d.within(0.5));
}

TEST(DiffStats, NonFiniteOnEitherSideFailsEveryCheck) {
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  for (const auto& [ours, ref] : {std::pair{nan, 1.0}, std::pair{1.0, nan}, std::pair{inf, 1.0}, std::pair{1.0, -inf}}) {
    DiffStats d;
    d.add(1.0, 1.0);
    d.add(ours, ref);
    EXPECT_EQ(d.non_finite, 1u);
    EXPECT_FALSE(d.within(1e30)) << ours << " vs " << ref;
    EXPECT_TRUE(std::isnan(d.mse()));
  }
}

TEST(DiffStats, NothingComparedIsNoPass) {
  const DiffStats d;
  EXPECT_FALSE(d.within(1.0));
  EXPECT_TRUE(std::isnan(d.mse()));
}

}  // namespace
}  // namespace act
