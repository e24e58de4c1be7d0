// INT8 NHWC max-pool against a naive definition: ResNet's 3x3/2 pad 1 on odd and even sizes,
// channel counts around every vector width, padding never winning, row ranges split anywhere.
#include <gtest/gtest.h>

#include <algorithm>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "kernels/fp32/fp32_kernels.h"  // Conv2dShape::out_dim
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

// The public function runs the chosen variant; _with runs each one. 7x7 windows (49 taps) cross the
// driver's 32-tap batches.
TEST_P(MaxPoolS8Variant, MatchesNaiveDefinition) {
  const MaxPoolS8Kernels& k = *maxpool_s8_kernels(GetParam());
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
          maxpool_nhwc_s8_with(k, pc.h, pc.w, c, pc.kernel, pc.stride, pc.pad, ow, x.data(), y.data(), splits[i],
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

std::string isa_param_name(const ::testing::TestParamInfo<Isa>& info) { return isa_name(info.param); }

INSTANTIATE_TEST_SUITE_P(Available, MaxPoolS8Variant,
                         ::testing::ValuesIn(test::isas_under_test(maxpool_s8_available_isas(),
                                                                   maxpool_s8_built_isas())),
                         isa_param_name);
GTEST_ALLOW_UNINSTANTIATED_PARAMETERIZED_TEST(MaxPoolS8Variant);

TEST(MaxPoolS8, PublicFunctionRunsTheChosenVariant) {
  const IsaChoice choice = choose_isa_from_env(maxpool_s8_built_isas());
  if (choice.ok()) {
    EXPECT_EQ(maxpool_s8_active().isa, choice.isa);
  }
  const int h = 5, w = 6, c = 67;
  std::vector<int8_t> x(static_cast<size_t>(h) * w * c);
  for (size_t i = 0; i < x.size(); ++i) x[i] = static_cast<int8_t>(i * 37);
  std::vector<int8_t> y(static_cast<size_t>(3) * 3 * c);
  maxpool_nhwc_s8(h, w, c, 3, 2, 1, 3, x.data(), y.data(), 0, 3);
  EXPECT_EQ(y, maxpool_naive(h, w, c, 3, 2, 1, 3, 3, x));
}

TEST(MaxPoolS8, RequiredVariantsAreTheirOwn) {
  for (const std::optional<Isa>& isa : test::required_isas()) {
    ASSERT_TRUE(isa.has_value()) << "ACT_TEST_REQUIRE_ISAS names an unknown ISA";
    const MaxPoolS8Kernels* v = maxpool_s8_kernels(*isa);
    ASSERT_NE(v, nullptr) << isa_name(*isa) << " max-pool kernels are required but not available";
    EXPECT_EQ(v->isa, *isa);
    EXPECT_NE(v->max_taps, maxpool_s8_table_ref()->max_taps);
  }
}

}  // namespace
}  // namespace act::kernels
