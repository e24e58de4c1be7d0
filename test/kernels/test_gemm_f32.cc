// The packed FP32 GEMM (gemm_f32.h): every variant this CPU runs, the scalar reference included,
// against a double-precision product with the epilogue, on exact tile multiples, ragged edges, k
// across the kernels' k blocks, column blocks wider than one cache block, and sub-rectangles of a
// larger layer (col0, row offsets, strides, sentinels around C); the SIMD variants record which
// tiles ran. Tolerance (gemm_f32.h): 4 k eps sum |a b| per output, plus GELU's own (4 ulp or 1e-7);
// the SIMD variants, whatever their tile and blocking, give exactly one fused multiply-add chain in k
// order per output (so they agree bit for bit with each other).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <optional>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "kernels/fp32/gemm_f32.h"
#include "test/kernels/kernel_test_util.h"

namespace act::kernels {
namespace {

constexpr float kSentinel = 12345.0f;

struct Case {
  int rows, cols, k;     // the layer: B is [cols x k], A [rows x k]
  int m0, m, col_panel;  // the call: rows [m0, m0 + m), columns from col_panel * nr
  int n;                 // columns computed (to the layer's edge at most)
  int bias;              // 0 none, 1 vector, 2 per-row table
  int residual;          // 0 none, 1 full, 2 broadcast row
  GemmF32Activation activation;
  int segment_k = 0;     // > 0: A given as segments (a_segments), each stored apart from its row
};

std::string describe(const Case& c) {
  return "layer " + std::to_string(c.rows) + "x" + std::to_string(c.cols) + "x" + std::to_string(c.k) + " call rows " +
         std::to_string(c.m0) + "+" + std::to_string(c.m) + " panel " + std::to_string(c.col_panel) + " n " +
         std::to_string(c.n) + " bias " + std::to_string(c.bias) + " residual " + std::to_string(c.residual) + " act " +
         std::to_string(static_cast<int>(c.activation)) + " segments of " + std::to_string(c.segment_k);
}

// Runs one case on `g` and checks every output against the double product; returns the paths recorded.
uint32_t check_case(const GemmF32Kernels& g, const Case& c, std::mt19937& rng) {
  std::uniform_real_distribution<float> d(-1.0f, 1.0f);
  const size_t lda = static_cast<size_t>(c.k) + 3, ldc = static_cast<size_t>(c.cols) + 5;
  std::vector<float> a(static_cast<size_t>(c.rows) * lda), b(static_cast<size_t>(c.cols) * c.k);
  std::vector<float> bias(static_cast<size_t>(c.rows) * c.cols), residual(bias.size());
  for (auto* v : {&a, &b, &bias, &residual}) {
    for (float& x : *v) x = d(rng);
  }
  std::vector<float> packed(gemm_f32_packed_floats(g.nr, c.cols, c.k));
  gemm_f32_pack(g.nr, c.cols, c.k, b.data(), static_cast<size_t>(c.k), packed.data());
  std::vector<float> out(static_cast<size_t>(c.rows + 1) * ldc, kSentinel);
  const int col0 = c.col_panel * g.nr;
  GemmF32PackedArgs args;
  args.m = c.m;
  args.n = c.n;
  args.k = c.k;
  args.a = a.data() + static_cast<size_t>(c.m0) * lda;
  args.lda = lda;
  // Segmented A: each segment copied to its own place, last row's first, the row pointers from m0.
  const size_t segments = c.segment_k > 0 ? static_cast<size_t>(c.k / c.segment_k) : 0;
  std::vector<float> segment_store(static_cast<size_t>(c.rows) * static_cast<size_t>(c.k));
  std::vector<const float*> segment_rows(static_cast<size_t>(c.rows) * segments);
  for (size_t i = 0; i < segment_rows.size(); ++i) {
    const size_t r = i / segments, s = i % segments, seg = static_cast<size_t>(c.segment_k);
    float* dst = segment_store.data() + (segment_rows.size() - 1 - i) * seg;
    std::copy_n(a.data() + r * lda + s * seg, seg, dst);
    segment_rows[i] = dst;
  }
  if (c.segment_k > 0) {
    args.a = nullptr;
    args.a_segments = segment_rows.data() + static_cast<size_t>(c.m0) * segments;
    args.segment_k = c.segment_k;
  }
  args.packed_b = packed.data();
  args.col0 = col0;
  args.c = out.data() + static_cast<size_t>(c.m0) * ldc + static_cast<size_t>(col0);
  args.ldc = ldc;
  const size_t at = static_cast<size_t>(c.m0) * c.cols + static_cast<size_t>(col0);
  if (c.bias) args.epilogue = {bias.data() + (c.bias == 1 ? static_cast<size_t>(col0) : at), c.bias == 1 ? 0u : static_cast<size_t>(c.cols)};
  if (c.residual) {
    args.epilogue.residual = residual.data() + (c.residual == 2 ? static_cast<size_t>(col0) : at);
    args.epilogue.residual_ld = c.residual == 2 ? 0 : static_cast<size_t>(c.cols);
  }
  args.epilogue.activation = c.activation;
  CoveredPaths covered;
  args.covered = &covered;
  g.packed(args);

  const double eps = std::ldexp(1.0, -23);
  int failures = 0;
  for (int r = 0; r < c.rows + 1; ++r) {
    for (size_t col = 0; col < ldc; ++col) {
      const float got = out[static_cast<size_t>(r) * ldc + col];
      const bool written = r >= c.m0 && r < c.m0 + c.m && col >= static_cast<size_t>(col0) && col < static_cast<size_t>(col0 + c.n);
      if (!written) {
        if (got != kSentinel && ++failures <= 3) ADD_FAILURE() << describe(c) << ": wrote outside C at " << r << "," << col;
        continue;
      }
      double sum = 0.0, mag = 0.0;
      for (int p = 0; p < c.k; ++p) {
        const double t = static_cast<double>(a[static_cast<size_t>(r) * lda + p]) * b[col * static_cast<size_t>(c.k) + p];
        sum += t;
        mag += std::fabs(t);
      }
      if (c.bias) sum += bias[(c.bias == 1 ? 0 : static_cast<size_t>(r) * c.cols) + col];
      if (c.residual) sum += residual[(c.residual == 2 ? 0 : static_cast<size_t>(r) * c.cols) + col];
      double tol = 4.0 * c.k * eps * mag + 4.0 * eps * (std::fabs(sum) + 2.0);
      double want = sum;
      if (c.activation == GemmF32Activation::kRelu) want = std::max(sum, 0.0);
      if (c.activation == GemmF32Activation::kGelu) {
        want = 0.5 * sum * (1.0 + std::erf(sum / std::sqrt(2.0)));
        tol = 1.2 * tol + 4.0 * eps * std::fabs(want) + 1e-7;
      }
      if (g.isa != Isa::kRef && c.activation != GemmF32Activation::kGelu) {
        // The SIMD variants: one fused multiply-add chain in k order per output, then the epilogue.
        float chain = 0.0f;
        for (int p = 0; p < c.k; ++p) chain = std::fmaf(a[static_cast<size_t>(r) * lda + p], b[col * static_cast<size_t>(c.k) + p], chain);
        if (c.bias) chain += bias[(c.bias == 1 ? 0 : static_cast<size_t>(r) * c.cols) + col];
        if (c.residual) chain += residual[(c.residual == 2 ? 0 : static_cast<size_t>(r) * c.cols) + col];
        if (c.activation == GemmF32Activation::kRelu) chain = chain < 0.0f ? 0.0f : chain;
        if (got != chain && ++failures <= 3) {
          ADD_FAILURE() << g.name << " " << describe(c) << ": C(" << r << "," << col << ") = " << got
                        << ", not the k-order fused multiply-add chain " << chain;
        }
      }
      if (!(std::fabs(got - want) <= tol) && ++failures <= 3) {
        ADD_FAILURE() << g.name << " " << describe(c) << ": C(" << r << "," << col << ") = " << got << ", want "
                      << want << " within " << tol;
      }
    }
  }
  return covered.paths(g.isa);
}

TEST(GemmF32Packed, EveryVariantMatchesTheDoubleProduct) {
  std::mt19937 rng(15);
  const auto isas = test::isas_under_test(&IsaTables::gemm_f32);
  ASSERT_FALSE(isas.empty());
  // Every level's variant for this CPU, and at avx512 the other B-prefetch choice too.
  std::vector<const GemmF32Kernels*> variants;
  for (Isa isa : isas) {
    variants.push_back(&test::table_of(isa, &IsaTables::gemm_f32));
    if (isa == Isa::kAvx512) {
      const GemmF32Kernels* other = gemm_f32_table_avx512(variants.back() != gemm_f32_table_avx512(true));
      variants.push_back(other);
    }
  }
  for (const GemmF32Kernels* variant : variants) {
    const GemmF32Kernels& g = *variant;
    const Isa isa = g.isa;
    const int mr = g.mr, nr = g.nr;
    const Case cases[] = {
        // Exact tile multiples, one k block and several (the kernels block k by 256).
        {3 * mr, 2 * nr, 64, 0, 3 * mr, 0, 2 * nr, 1, 0, GemmF32Activation::kNone},
        {2 * mr, nr, 577, 0, 2 * mr, 0, nr, 1, 1, GemmF32Activation::kRelu},
        // Ragged rows and columns, k = 1 and odd k.
        {2 * mr + 1, nr + 3, 1, 0, 2 * mr + 1, 0, nr + 3, 2, 0, GemmF32Activation::kNone},
        {mr - 1 > 0 ? mr - 1 : 1, 2 * nr - 1, 147, 0, mr - 1 > 0 ? mr - 1 : 1, 0, 2 * nr - 1, 1, 2, GemmF32Activation::kGelu},
        {2 * mr + 3, 3 * nr + 5, 300, 0, 2 * mr + 3, 0, 3 * nr + 5, 2, 1, GemmF32Activation::kRelu},
        // Edge panels of every width in vectors (a narrow one computes only the vectors it needs):
        // a quarter, a half and three quarters of a panel, plus one column.
        {mr + 1, nr / 4 + 1, 64, 0, mr + 1, 0, nr / 4 + 1, 1, 1, GemmF32Activation::kRelu},
        {2 * mr, nr + nr / 2 + 1, 130, 0, 2 * mr, 0, nr + nr / 2 + 1, 2, 0, GemmF32Activation::kNone},
        {mr, 2 * nr + 3 * nr / 4 + 1, 147, 0, mr, 0, 2 * nr + 3 * nr / 4 + 1, 1, 2, GemmF32Activation::kGelu, 21},
        // More columns than one cache block (at most 512 columns) with a k tail.
        {mr + 2, 17 * nr + 7, 260, 0, mr + 2, 0, 17 * nr + 7, 1, 1, GemmF32Activation::kGelu},
        // Sub-rectangles of a layer: rows from the middle, columns from the second panel, to the edge or not.
        {3 * mr + 2, 4 * nr + 3, 70, mr + 1, mr + 1, 1, 2 * nr, 2, 1, GemmF32Activation::kRelu},
        {3 * mr + 2, 4 * nr + 3, 70, 1, 2 * mr, 2, 2 * nr + 3, 1, 2, GemmF32Activation::kNone},
        {5, 3 * nr, 33, 2, 3, 1, nr - 1, 0, 1, GemmF32Activation::kGelu},
        // A in segments (a convolution's kernel rows): one k block of 7 (the stem's 7 x 21); segments
        // longer than 256 cut into k blocks of their largest divisor up to 256 (300 in halves, 768 in
        // thirds as layer3's, a prime 263 value by value); blocks of 10 segments with a shorter last one.
        {2 * mr + 1, nr + 3, 147, 0, 2 * mr + 1, 0, nr + 3, 1, 1, GemmF32Activation::kRelu, 21},
        {mr + 2, 2 * nr, 3 * 300, 1, mr, 0, 2 * nr, 2, 0, GemmF32Activation::kNone, 300},
        {mr + 1, nr + 1, 2 * 768, 0, mr + 1, 0, nr + 1, 1, 1, GemmF32Activation::kRelu, 768},
        {mr - 1 > 0 ? mr - 1 : 1, nr, 2 * 263, 0, mr - 1 > 0 ? mr - 1 : 1, 0, nr, 0, 2, GemmF32Activation::kGelu, 263},
        {3 * mr, 2 * nr + 1, 600, 0, 3 * mr, 0, 2 * nr + 1, 0, 2, GemmF32Activation::kGelu, 24},
    };
    uint32_t paths = 0;
    for (const Case& c : cases) paths |= check_case(g, c, rng);
    if (isa != Isa::kRef) {
      EXPECT_EQ(paths, kPathFullTile | kPathRowTail | kPathPartialCols) << g.name << " did not run every tile kind";
    }
  }
}

// At every level CI requires (ACT_TEST_REQUIRE_ISAS), an Engine runs a SIMD packed GEMM, not the
// scalar reference, and it is among the variants tested above.
TEST(GemmF32Packed, RequiredLevelsRunSimdVariants) {
  const std::vector<Isa> tested = test::isas_under_test(&IsaTables::gemm_f32);
  for (const std::optional<Isa>& isa : test::required_isas()) {
    ASSERT_TRUE(isa.has_value()) << "ACT_TEST_REQUIRE_ISAS names an unknown ISA";
    ASSERT_TRUE(cpu_supports(*isa)) << isa_name(*isa) << " is required but this CPU does not run it";
    const GemmF32Kernels& v = variant_for(*isa, &IsaTables::gemm_f32);
    EXPECT_NE(v.packed, gemm_f32_table_ref()->packed) << "no SIMD packed GEMM at " << isa_name(*isa);
    if (std::getenv("ACT_ISA") == nullptr) {
      EXPECT_NE(std::find(tested.begin(), tested.end(), v.isa), tested.end()) << isa_name(v.isa) << " was not tested";
    }
  }
}

// A call may run past B's last column to its panel's end (attention's scores in rows of whole
// panels): those columns are exactly zero, the others the same bits as a call that stops at N.
TEST(GemmF32Packed, ColumnsPastTheLastReachThePanelsZeroPadding) {
  std::mt19937 rng(16);
  std::uniform_real_distribution<float> d(-1.0f, 1.0f);
  for (Isa isa : test::isas_under_test(&IsaTables::gemm_f32)) {
    const GemmF32Kernels& g = test::table_of(isa, &IsaTables::gemm_f32);
    for (const int n : {g.nr + 3, 2 * g.nr - 1, 4 * g.nr + g.nr / 2 + 1}) {
      const int m = 2 * g.mr + 1, k = 64, padded = (n + g.nr - 1) / g.nr * g.nr;
      std::vector<float> a(static_cast<size_t>(m) * k), b(static_cast<size_t>(n) * k);
      for (auto* v : {&a, &b}) {
        for (float& x : *v) x = d(rng);
      }
      std::vector<float> packed(gemm_f32_packed_floats(g.nr, n, k));
      gemm_f32_pack(g.nr, n, k, b.data(), static_cast<size_t>(k), packed.data());
      std::vector<float> to_n(static_cast<size_t>(m) * padded, kSentinel), to_panel_end(to_n.size(), kSentinel);
      for (auto [cols, c] : {std::pair{n, &to_n}, std::pair{padded, &to_panel_end}}) {
        g.packed({.m = m, .n = cols, .k = k, .a = a.data(), .lda = static_cast<size_t>(k), .packed_b = packed.data(),
                  .c = c->data(), .ldc = static_cast<size_t>(padded), .epilogue = {}});
      }
      for (int r = 0; r < m; ++r) {
        for (int col = 0; col < padded; ++col) {
          const size_t i = static_cast<size_t>(r) * padded + static_cast<size_t>(col);
          const float want = col < n ? to_n[i] : 0.0f;
          ASSERT_EQ(to_panel_end[i], want) << g.name << " n " << n << " C(" << r << "," << col << ")";
        }
      }
    }
  }
}

TEST(GemmF32Packed, PackingFromTheTransposeGivesTheSamePanels) {
  const int n = 13, k = 7, nr = 8;
  std::vector<float> b(static_cast<size_t>(n) * k), bt(static_cast<size_t>(k) * (n + 2));
  for (int c = 0; c < n; ++c) {
    for (int p = 0; p < k; ++p) {
      b[static_cast<size_t>(c) * k + p] = static_cast<float>(c * 100 + p);
      bt[static_cast<size_t>(p) * (n + 2) + c] = static_cast<float>(c * 100 + p);
    }
  }
  std::vector<float> from_b(gemm_f32_packed_floats(nr, n, k), -1.0f), from_bt(from_b.size(), -2.0f);
  gemm_f32_pack(nr, n, k, b.data(), static_cast<size_t>(k), from_b.data());
  gemm_f32_pack_transposed(nr, n, k, bt.data(), static_cast<size_t>(n + 2), from_bt.data());
  EXPECT_EQ(from_b, from_bt);
}

TEST(GemmF32Packed, UnpackingGivesBackTheMatrix) {
  const int n = 37, k = 5;
  std::vector<float> b(static_cast<size_t>(n) * k);
  for (size_t i = 0; i < b.size(); ++i) b[i] = static_cast<float>(i) * 0.25f - 3.0f;
  for (int nr : {12, 16, 32}) {
    std::vector<float> packed(gemm_f32_packed_floats(nr, n, k), -1.0f), back(b.size(), -2.0f);
    gemm_f32_pack(nr, n, k, b.data(), static_cast<size_t>(k), packed.data());
    gemm_f32_unpack(nr, n, k, packed.data(), back.data());
    EXPECT_EQ(back, b) << "nr " << nr;
  }
}

TEST(GemmF32Packed, PackingPadsPanelsWithZeros) {
  const int n = 5, k = 3, nr = 4;
  std::vector<float> b(static_cast<size_t>(n) * k);
  for (size_t i = 0; i < b.size(); ++i) b[i] = static_cast<float>(i + 1);
  std::vector<float> packed(gemm_f32_packed_floats(nr, n, k), -1.0f);
  ASSERT_EQ(packed.size(), 24u);
  gemm_f32_pack(nr, n, k, b.data(), static_cast<size_t>(k), packed.data());
  // Panel 0: row p holds B(0..3, p); panel 1: B(4, p) then three zeros.
  EXPECT_EQ(packed[0], 1.0f);
  EXPECT_EQ(packed[1], 4.0f);
  EXPECT_EQ(packed[4], 2.0f);
  EXPECT_EQ(packed[12], 13.0f);
  EXPECT_EQ(packed[13], 0.0f);
  EXPECT_EQ(packed[23], 0.0f);
  EXPECT_EQ(packed[20], 15.0f);
}

}  // namespace
}  // namespace act::kernels
