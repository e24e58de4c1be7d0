// INT8 NHWC max-pool against a naive definition: ResNet's 3x3/2 pad 1 on odd and even sizes,
// channel counts around every vector width, padding never winning, row ranges split anywhere.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "kernels/common/conv2d_shape.h"  // Conv2dShape::out_dim
#include "kernels/pool_s8/maxpool_s8.h"
#include "kernels/pool_s8/maxpool_s8_variants.h"
#include "test/kernels/kernel_test_util.h"

namespace act::kernels {
namespace {

std::vector<int8_t> maxpool_naive(int h, int w, int c, int kernel, int stride, int pad, int oh, int ow,
                                  const std::vector<int8_t>& x) {
  std::vector<int8_t> y(static_cast<size_t>(oh) * ow * c);
  for (int oy = 0; oy < oh; ++oy)
    for (int ox = 0; ox < ow; ++ox)
      for (int ch = 0; ch < c; ++ch) {
        int best = -128;
        for (int ky = 0; ky < kernel; ++ky)
          for (int kx = 0; kx < kernel; ++kx) {
            const int iy = oy * stride - pad + ky, ix = ox * stride - pad + kx;
            if (iy < 0 || iy >= h || ix < 0 || ix >= w) continue;
            best = std::max(best, int{x[(static_cast<size_t>(iy) * w + ix) * c + ch]});
          }
        y[(static_cast<size_t>(oy) * ow + ox) * c + ch] = static_cast<int8_t>(best);
      }
  return y;
}

struct PoolCase {
  int h, w, kernel, stride, pad;
};

class MaxPoolS8Variant : public ::testing::TestWithParam<Isa> {};

// Each variant against the naive definition. 7x7 windows (49 taps) cross the driver's 32-tap
// batches.
TEST_P(MaxPoolS8Variant, MatchesNaiveDefinition) {
  const MaxPoolS8Kernels& k = test::table_of(GetParam(), &IsaTables::maxpool_s8);
  std::mt19937 rng(21);
  const PoolCase cases[] = {{12, 16, 3, 2, 1}, {11, 9, 3, 2, 1}, {1, 1, 3, 2, 1}, {2, 3, 3, 2, 1},
                            {7, 7, 2, 2, 0},   {6, 5, 3, 1, 1},  {9, 8, 5, 3, 2}, {9, 10, 7, 1, 3}};
  for (const PoolCase& pc : cases) {
    for (int c : {1, 3, 15, 16, 17, 31, 32, 33, 63, 64, 65, 100, 128}) {
      for (int fill : {0, 1, 2}) {  // random, all -128 (the initial value), all negative
        std::uniform_int_distribution<int> d(fill == 2 ? -128 : -128, fill == 2 ? -1 : 127);
        std::vector<int8_t> x(static_cast<size_t>(pc.h) * pc.w * c);
        for (auto& v : x) v = fill == 1 ? int8_t{-128} : static_cast<int8_t>(d(rng));
        const int oh = Conv2dShape::out_dim(pc.h, pc.kernel, pc.stride, pc.pad, 1);
        const int ow = Conv2dShape::out_dim(pc.w, pc.kernel, pc.stride, pc.pad, 1);
        const std::vector<int8_t> want = maxpool_naive(pc.h, pc.w, c, pc.kernel, pc.stride, pc.pad, oh, ow, x);
        std::vector<int8_t> y(want.size() + 16, 99);
        // Rows in uneven ranges: [0, 1), [1, oh/2), [oh/2, oh).
        const int splits[] = {0, std::min(1, oh), std::max(std::min(1, oh), oh / 2), oh};
        for (int i = 0; i < 3; ++i) {
          maxpool_nhwc_s8(k, pc.h, pc.w, c, pc.kernel, pc.stride, pc.pad, ow, x.data(), y.data(), splits[i],
                          splits[i + 1]);
        }
        for (size_t i = 0; i < want.size(); ++i) {
          ASSERT_EQ(y[i], want[i]) << k.max_taps_name << " " << pc.h << "x" << pc.w << " k" << pc.kernel << "/" << pc.stride << " c=" << c
                                   << " fill " << fill << " at " << i;
        }
        for (size_t i = want.size(); i < y.size(); ++i) ASSERT_EQ(y[i], 99) << "wrote past the output";
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Available, MaxPoolS8Variant,
                         ::testing::ValuesIn(test::isas_under_test(&IsaTables::maxpool_s8)),
                         test::isa_param_name);
GTEST_ALLOW_UNINSTANTIATED_PARAMETERIZED_TEST(MaxPoolS8Variant);

// At every level CI requires, an Engine runs a SIMD channel-max (its own, not the reference's),
// and it is among the variants tested above.
TEST(MaxPoolS8Variants, RequiredLevelsRunSimdVariants) {
  const std::vector<Isa> tested = test::isas_under_test(&IsaTables::maxpool_s8);
  for (const std::optional<Isa>& isa : test::required_isas()) {
    ASSERT_TRUE(isa.has_value()) << "ACT_TEST_REQUIRE_ISAS names an unknown ISA";
    ASSERT_TRUE(cpu_supports(*isa)) << isa_name(*isa) << " is required but this CPU does not run it";
    const MaxPoolS8Kernels& v = variant_for(*isa, &IsaTables::maxpool_s8);
    EXPECT_NE(v.isa, Isa::kRef) << "no SIMD max-pool variant at " << isa_name(*isa);
    EXPECT_NE(v.max_taps, maxpool_s8_table_ref()->max_taps);
    if (std::getenv("ACT_ISA") == nullptr) {
      EXPECT_NE(std::find(tested.begin(), tested.end(), v.isa), tested.end()) << isa_name(v.isa) << " was not tested";
    }
  }
}

}  // namespace
}  // namespace act::kernels
