// The INT8 GEMM family: every variant this CPU can run (built and detected) against the scalar
// reference, on the XNNPACK-style case lists (sizes around the tile, ragged K, strides, zero
// points, clamps, scales, saturating operands) with MLAS-style sentinels, plus the kernel naming
// grammar.
//
// ACT_ISA=<isa> restricts the variant tests to the variant an Engine at that level runs.
// ACT_TEST_REQUIRE_ISAS=avx2,avx512,avx512vnni (CI) makes the run fail unless those levels' variants
// are available and ran.
#include <limits>
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <memory>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "kernels/gemm_s8/gemm_s8.h"
#include "kernels/gemm_s8/gemm_s8_variants.h"
#include "test/kernels/kernel_test_util.h"
#include "test/kernels/gemm_s8_tester.h"

namespace act::kernels::test {
namespace {

std::vector<int> dedup_positive(std::vector<int> v) {
  std::set<int> s;
  for (int x : v) {
    if (x >= 1) s.insert(x);
  }
  return {s.begin(), s.end()};
}

class GemmS8Variant : public ::testing::TestWithParam<Isa> {
 protected:
  const GemmS8Kernels& variant() const { return test::table_of(GetParam(), &IsaTables::gemm_s8); }
  int mr() const { return variant().mr; }
  int nr() const { return variant().nr; }
  int kr() const { return variant().kr; }
  // The K step of the main loop (NEON SDOT consumes 16 bytes of A per step, an AMX tile 64).
  int kblock() const {
    if (GetParam() == Isa::kNeonDot) return 16;
    return GetParam() == Isa::kAmx ? 64 : kr();
  }
  std::vector<int> m_sizes() const { return dedup_positive({1, mr() - 1, mr(), mr() + 1, 2 * mr() + 1, 37}); }
  std::vector<int> n_sizes() const {
    return dedup_positive({1, nr() - 1, nr(), nr() + 1, 2 * nr() + 3, 3 * nr() - 5});
  }
  std::vector<int> k_sizes() const {
    const int kb = kblock();
    return dedup_positive({1, 2, kr() - 1, kr(), kr() + 1, kb - 1, kb, kb + 1, 2 * kb + kr() - 1, 2 * kb + 3, 67, 300});
  }
};

TEST_P(GemmS8Variant, ShapesAroundTheTile) {
  uint32_t seed = 1;
  for (int m : m_sizes()) {
    for (int n : n_sizes()) {
      for (int k : {kblock() + 1, 2 * kblock() + 3}) {
        for (GemmOut out : {GemmOut::kS32, GemmOut::kS8, GemmOut::kF32}) {
          const int za = static_cast<int>(seed % 7) - 3;
          GemmS8Tester().m(m).n(n).k(k).out(out).a_zero_point(za).seed(seed++).test(variant());
        }
      }
    }
  }
}

TEST_P(GemmS8Variant, RaggedK) {
  uint32_t seed = 100;
  for (int k : k_sizes()) {
    for (GemmOut out : {GemmOut::kS32, GemmOut::kS8, GemmOut::kF32}) {
      GemmS8Tester().m(mr() + 1).n(nr() + 1).k(k).out(out).a_zero_point(5).seed(seed++).test(variant());
      GemmS8Tester().m(1).n(2 * nr() - 1).k(k).out(out).a_zero_point(-7).seed(seed++).test(variant());
    }
  }
}

TEST_P(GemmS8Variant, LargeShapes) {
  GemmS8Tester().m(67).n(3 * nr() + 7).k(576).out(GemmOut::kS8).a_zero_point(-3).seed(7).test(variant());
  GemmS8Tester().m(29).n(2 * nr() + 1).k(1153).out(GemmOut::kF32).per_row(true).seed(8).test(variant());
  GemmS8Tester().m(2 * mr() + 3).n(4 * nr()).k(2304 + 7).out(GemmOut::kS32).a_zero_point(11).seed(9).test(variant());
  // Past 4608 bytes of K (ACT's largest, 3 x 3 x 512), AMX copies A chunk by chunk.
  GemmS8Tester().m(mr() + 5).n(nr() + 9).k(4800).segments(192).out(GemmOut::kF32).per_row(true).seed(10).test(variant());
  GemmS8Tester().m(2 * mr()).n(nr() + 61).k(4608 + 64 + 5).out(GemmOut::kS8).a_zero_point(-2).seed(11).test(variant());
}

// A in segments (a convolution's kernel rows read in place): segments of one and several k-steps,
// one to four per row, row tails, every epilogue, per-row zero points.
TEST_P(GemmS8Variant, SegmentedA) {
  uint32_t seed = 900;
  for (int segment_k : {8, 16, 24, 64, 192}) {
    for (int segments : {1, 2, 3, 4}) {
      for (int m : {1, mr() + 1, 2 * mr() + 3}) {
        for (GemmOut out : {GemmOut::kS32, GemmOut::kS8, GemmOut::kF32}) {
          const int za = static_cast<int>(seed % 9) - 4;
          GemmS8Tester()
              .m(m)
              .n(nr() + 5)
              .k(segment_k * segments)
              .segments(segment_k)
              .out(out)
              .a_zero_point(za)
              .per_row(out == GemmOut::kF32 && segments % 2 == 0)
              .residual(out != GemmOut::kS32 && m > 1)
              .seed(seed++)
              .test(variant());
        }
      }
    }
  }
  GemmS8Tester().m(37).n(3 * nr() + 1).k(576).segments(192).out(GemmOut::kS8).a_fill(GemmFill::kMin)
      .w_fill(GemmFill::kMax).seed(seed++).test(variant());
}

// A stored unsigned (pack_u8a, the static INT8 stem's image): the same results as the signed codes
// through the reference, on ragged shapes, K, segments, every zero point (0 and 255 stored), clamps
// and all-extreme operands. Only ISAs with an unsigned x signed product have it.
TEST_P(GemmS8Variant, UnsignedActivations) {
  if (variant().pack_u8a == nullptr) {
    EXPECT_NE(GetParam(), Isa::kAvx512Vnni) << "the VNNI variant reads unsigned activations";
    EXPECT_NE(GetParam(), Isa::kAvxVnni) << "the AVX-VNNI variant reads unsigned activations";
    return;
  }
  uint32_t seed = 1000;
  for (int m : m_sizes()) {
    for (int n : {1, nr() - 1, nr() + 1, 2 * nr() + 3}) {
      for (int k : {1, kr() + 1, 2 * kblock() + 3, 147}) {
        for (GemmOut out : {GemmOut::kS32, GemmOut::kS8, GemmOut::kF32}) {
          const int za = static_cast<int>(seed % 11) - 5;
          GemmS8Tester().m(m).n(n).k(k).out(out).a_zero_point(za).unsigned_a(true).seed(seed++).test(variant());
        }
      }
    }
  }
  for (int za : {-128, -1, 0, 127}) {
    GemmS8Tester().m(mr() + 1).n(nr() + 1).k(3 * kblock() + 1).a_zero_point(za).out_zero_point(-128).qmin(-128)
        .out(GemmOut::kS8).unsigned_a(true).seed(seed++).test(variant());
  }
  for (int segment_k : {8, 24}) {
    GemmS8Tester().m(2 * mr() + 3).n(nr() + 5).k(3 * segment_k).segments(segment_k).residual(true).out(GemmOut::kS8)
        .qmin(3).out_zero_point(3).unsigned_a(true).seed(seed++).test(variant());
  }
  GemmS8Tester().m(2 * mr() + 1).n(nr() + 3).k(2 * kblock() + 5).a_stride_pad(13).c_stride_pad(5).out(GemmOut::kS8)
      .unsigned_a(true).seed(seed++).test(variant());
  GemmS8Tester().m(37).n(2 * nr() + 1).k(1153).a_fill(GemmFill::kMax).w_fill(GemmFill::kMin).a_zero_point(-128)
      .out(GemmOut::kS32).unsigned_a(true).seed(seed++).test(variant());
  GemmS8Tester().m(37).n(2 * nr() + 1).k(1153).a_fill(GemmFill::kMin).w_fill(GemmFill::kMax).a_zero_point(127)
      .out(GemmOut::kS32).unsigned_a(true).seed(seed++).test(variant());
}

TEST_P(GemmS8Variant, StridedAAndC) {
  uint32_t seed = 200;
  for (GemmOut out : {GemmOut::kS32, GemmOut::kS8, GemmOut::kF32}) {
    for (size_t pad : {size_t{1}, size_t{13}, size_t{64}}) {
      GemmS8Tester()
          .m(2 * mr() + 1)
          .n(nr() + 3)
          .k(2 * kblock() + 5)
          .a_stride_pad(pad)
          .c_stride_pad(pad + 2)
          .residual(out != GemmOut::kS32)
          .out(out)
          .seed(seed++)
          .test(variant());
    }
  }
}

TEST_P(GemmS8Variant, ZeroPoints) {
  uint32_t seed = 300;
  for (int za : {-128, -1, 0, 127}) {
    for (int zo : {-128, -1, 0, 127}) {
      GemmS8Tester().m(mr() + 1).n(nr() + 1).k(3 * kblock() + 1).a_zero_point(za).out_zero_point(zo).out(GemmOut::kS8)
          .seed(seed++).test(variant());
    }
    GemmS8Tester().m(mr() + 1).n(nr() + 1).k(3 * kblock() + 1).a_zero_point(za).out(GemmOut::kS32).seed(seed++).test(
        variant());
    GemmS8Tester().m(mr() + 1).n(nr() + 1).k(3 * kblock() + 1).a_zero_point(za).out(GemmOut::kF32).seed(seed++).test(
        variant());
  }
}

TEST_P(GemmS8Variant, PerRowZeroPointsAndScales) {
  uint32_t seed = 400;
  for (int za : {-128, 0, 127}) {  // the packed zero point the rows override
    for (GemmOut out : {GemmOut::kS32, GemmOut::kS8, GemmOut::kF32}) {
      GemmS8Tester().m(3 * mr() + 2).n(2 * nr() + 5).k(77).per_row(true).a_zero_point(za).out(out).seed(seed++).test(
          variant());
    }
  }
  // s8 out with per-row scales and a float bias (a per-token input requantized to a per-tensor
  // output): with and without the bias, ReLU's clamp, a residual, ragged shapes and sub-rectangles.
  for (bool bias : {true, false}) {
    for (int m : {1, mr() + 1, 2 * mr() + 3}) {
      GemmS8Tester().m(m).n(2 * nr() + 5).k(71).per_row(true).bias(bias).out(GemmOut::kS8).out_zero_point(-128).qmin(-128)
          .seed(seed++).test(variant());
      GemmS8Tester().m(m).n(nr() + 3).k(2 * kblock() + 3).per_row(true).bias(bias).residual(true).out(GemmOut::kS8)
          .out_zero_point(9).qmin(9).seed(seed++).test(variant());
    }
  }
}

TEST_P(GemmS8Variant, TinyAndHugeScales) {
  uint32_t seed = 500;
  const std::pair<float, float> ranges[] = {{1e-12f, 1e-9f}, {1e-6f, 1e-4f}, {1e3f, 1e8f}, {1e20f, 1e30f}, {1e-9f, 1e9f}};
  for (const auto& [lo, hi] : ranges) {
    GemmS8Tester().m(mr() + 2).n(nr() + 2).k(61).scales(lo, hi).out(GemmOut::kS8).out_zero_point(3).seed(seed++).test(
        variant());
    GemmS8Tester().m(mr() + 2).n(nr() + 2).k(61).scales(lo, hi).residual(true).out(GemmOut::kS8).seed(seed++).test(
        variant());
    GemmS8Tester().m(mr() + 2).n(nr() + 2).k(61).scales(lo, hi).out(GemmOut::kF32).seed(seed++).test(variant());
  }
}

// A NaN scale makes every v NaN, which the rule clamps to qmin (requant_ref.h): the order of a
// kernel's min and max matters here, since x86's min/max return their second operand on a NaN.
TEST_P(GemmS8Variant, NaNBecomesQmin) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  uint32_t seed = 550;
  for (int qmin : {-128, -5}) {
    for (bool residual : {false, true}) {
      GemmS8Tester().m(mr() + 1).n(nr() + 5).k(19).scales(nan, nan).qmin(qmin).residual(residual).out(GemmOut::kS8)
          .seed(seed++).test(variant());
    }
  }
}

// Scales that are exact binary fractions with small accumulators make v land exactly on .5, so a
// round-half-away-from-zero kernel would fail here.
TEST_P(GemmS8Variant, RoundingTiesToEven) {
  uint32_t seed = 600;
  for (float s : {0.5f, 0.25f, 1.5f, 0.125f}) {
    for (int k : {1, 2, 3}) {
      GemmS8Tester().m(mr() + 1).n(nr() + 1).k(k).scales(s, s).bias(false).out(GemmOut::kS8).seed(seed++).test(
          variant());
      GemmS8Tester().m(mr() + 1).n(nr() + 1).k(k).scales(s, s).residual(true).out(GemmOut::kS8).seed(seed++).test(
          variant());
    }
  }
}

TEST_P(GemmS8Variant, ClampsResidualAndRelu) {
  uint32_t seed = 700;
  const std::pair<int, int> clamps[] = {{-128, 127}, {-20, 30}, {0, 127}, {5, 5}, {-128, -100}};
  for (const auto& [lo, hi] : clamps) {
    for (bool residual : {false, true}) {
      GemmS8Tester().m(mr() + 1).n(nr() + 5).k(40).scales(1e-3f, 1e-1f).qmin(lo).qmax(hi).out_zero_point(lo)
          .residual(residual).out(GemmOut::kS8).seed(seed++).test(variant());
    }
  }
  for (bool residual : {false, true}) {
    for (bool relu : {false, true}) {
      for (bool bias : {false, true}) {
        GemmS8Tester().m(mr() + 1).n(nr() + 5).k(40).residual(residual).relu(relu).bias(bias).out(GemmOut::kF32)
            .seed(seed++).test(variant());
      }
    }
  }
}

// One residual row added to every row (ldr 0), both epilogues, ragged shapes and sub-rectangles.
TEST_P(GemmS8Variant, OneResidualRowForAllRows) {
  uint32_t seed = 1100;
  for (int m : {1, mr() + 1, 2 * mr() + 3}) {
    for (GemmOut out : {GemmOut::kS8, GemmOut::kF32}) {
      GemmS8Tester().m(m).n(nr() + 5).k(kblock() + 3).residual(true).residual_row(true).out(out).seed(seed++)
          .test(variant());
    }
  }
}

TEST_P(GemmS8Variant, ResidualInPlace) {
  GemmS8Tester().m(2 * mr() + 1).n(2 * nr() + 3).k(50).c_stride_pad(3).residual(true).residual_in_place(true)
      .out(GemmOut::kS8).seed(800).test(variant());
}

// Fused multiply-add would round once where the rule rounds twice (requant_ref.h), and -mfma lets
// GCC contract _mm256_mul_ps + _mm256_add_ps unless -ffp-contract=off. These operands make the
// difference visible: 5 * 0.3f = 1.5 + 6e-8 exactly, which rounds to 1.5f, so the rule gives
// -1 + 1.5 = 0.5 (a tie, even -> 0) and 1.5 - 1 = 0.5f, while an FMA gives 0.5 + 1 ulp (-> 1).
TEST_P(GemmS8Variant, NoFusedMultiplyAdd) {
  const GemmS8Kernels& v = variant();
  const int m = v.mr + 1, n = v.nr + 1, k = 1;
  const float kTenths3 = 0.3f;
  std::vector<int8_t> w(static_cast<size_t>(n), -1), a(static_cast<size_t>(m) + kGemmS8ReadSlack, 1);
  std::unique_ptr<uint8_t, decltype(&std::free)> packed(
      static_cast<uint8_t*>(std::aligned_alloc(kGemmS8PackedAlign, v.packed_size(n, k))), &std::free);
  v.pack(n, k, w.data(), k, nullptr, 0, packed.get());
  GemmS8Args g;
  g.m = m;
  g.n = n;
  g.k = k;
  g.a = a.data();
  g.lda = k;
  g.packed_w = packed.get();
  // s8: acc = -1, scale 1, residual (5 - 0) * 0.3f.
  std::vector<float> ones(static_cast<size_t>(n), 1.0f);
  std::vector<int8_t> res(static_cast<size_t>(m) * n, 5), c(static_cast<size_t>(m) * n, 9);
  GemmS8OutS8 o8;
  o8.c = c.data();
  o8.ldc = n;
  o8.scale = ones.data();
  o8.residual = res.data();
  o8.ldr = n;
  o8.residual_scale = kTenths3;
  v.s8out(g, o8, 0, m, 0, n);
  for (int8_t x : c) ASSERT_EQ(x, 0) << "the s8 epilogue fused a multiply-add";
  // f32: acc = 5 (A = -5 against W = -1), s = 0.3f * 1, bias -1.
  std::fill(a.begin(), a.begin() + m, static_cast<int8_t>(-5));
  std::vector<float> bias(static_cast<size_t>(n), -1.0f), y(static_cast<size_t>(m) * n, 9.0f);
  GemmS8OutF32 of;
  of.c = y.data();
  of.ldc = n;
  of.w_scale = ones.data();
  of.a_scale = kTenths3;
  of.bias = bias.data();
  v.f32out(g, of, 0, m, 0, n);
  for (float x : y) ASSERT_EQ(x, 0.5f) << "the f32 epilogue fused a multiply-add";
}

// All 127 (or -128) activations against +-127 weights at the largest K: every int32 sum is at its
// extreme, 255 * 127 * K with the zero point. A kernel that adds u8 x s8 pairs in saturating int16
// (vpmaddubsw) fails this immediately; one with an int32 overflow fails at kGemmS8MaxK.
TEST_P(GemmS8Variant, SaturatingOperandsAtLargeK) {
  uint32_t seed = 900;
  struct Case {
    GemmFill a, w;
    int za;
  };
  const Case cases[] = {{GemmFill::kMax, GemmFill::kMax, -128}, {GemmFill::kMin, GemmFill::kMax, 127},
                        {GemmFill::kMax, GemmFill::kMin, -128}, {GemmFill::kMin, GemmFill::kMin, 127},
                        {GemmFill::kMax, GemmFill::kMax, 0},    {GemmFill::kMin, GemmFill::kMin, 0}};
  for (const Case& c : cases) {
    for (int k : {4608, kGemmS8MaxK}) {
      const int m = k == kGemmS8MaxK ? 3 : mr() + 1;
      GemmS8Tester().m(m).n(nr() + 1).k(k).a_fill(c.a).w_fill(c.w).a_zero_point(c.za).bias(false).out(GemmOut::kS32)
          .tile(m, nr()).seed(seed++).test(variant());
    }
    GemmS8Tester().m(mr() + 1).n(nr() + 1).k(4608).a_fill(c.a).w_fill(c.w).a_zero_point(c.za).scales(1e-7f, 1e-5f)
        .out(GemmOut::kS8).seed(seed++).test(variant());
  }
}

TEST_P(GemmS8Variant, EmptyRectangleWritesNothing) {
  const GemmS8Kernels& v = variant();
  const int n = 5, k = 9;
  std::vector<int8_t> w(static_cast<size_t>(n) * k, 1), a(k + kGemmS8ReadSlack, 1);
  std::unique_ptr<uint8_t, decltype(&std::free)> packed(
      static_cast<uint8_t*>(std::aligned_alloc(kGemmS8PackedAlign, v.packed_size(n, k))), &std::free);
  v.pack(n, k, w.data(), k, nullptr, 0, packed.get());
  GemmS8Args g;
  g.m = 1;
  g.n = n;
  g.k = k;
  g.a = a.data();
  g.lda = k;
  g.packed_w = packed.get();
  std::vector<int32_t> c(n, 77);
  v.s32out(g, GemmS8OutS32{c.data(), static_cast<size_t>(n)}, 0, 0, 0, n);
  v.s32out(g, GemmS8OutS32{c.data(), static_cast<size_t>(n)}, 0, 1, 3, 3);
  for (int32_t x : c) EXPECT_EQ(x, 77);
}

// A packed-weight buffer filled with `fill`: the packers under test must write every byte, so two
// buffers filled differently compare equal only where both were written in full.
using PackedBuffer = std::unique_ptr<uint8_t, decltype(&std::free)>;
PackedBuffer packed_buffer(size_t bytes, uint8_t fill) {
  PackedBuffer buffer(static_cast<uint8_t*>(std::aligned_alloc(kGemmS8PackedAlign, bytes)), &std::free);
  std::memset(buffer.get(), fill, bytes);
  return buffer;
}

// The portable packer of W (pack.cc) for each layout: the definition of that layout's bytes.
GemmS8PackFn portable_packer(GemmS8Layout layout) {
  switch (layout) {
    case GemmS8Layout::kRef1x1: return pack_w_s8_1x1_goi;
    case GemmS8Layout::kAvx2_8x8: return pack_w_s8_8x8_goi_pair4;
    case GemmS8Layout::kVnni64x4: return pack_w_s8_64x4_goi_x80;
    case GemmS8Layout::kNeon16x4: return pack_w_s8_16x4_goi;
    case GemmS8Layout::kVnni64x4U8A: return pack_w_s8_64x4_goi_u8a;
    case GemmS8Layout::kVnni16x4: return pack_w_s8_16x4_goi_x80;
    case GemmS8Layout::kAmx64x4: return pack_w_s8_64x4_goi_k64;
    case GemmS8Layout::kAmx64x4U8A: return pack_w_s8_64x4_goi_k64_u8a;
  }
  return nullptr;
}

// The transposed packers write, byte for byte, what their twins write for the explicit transpose:
// every layout (the packers are portable, so all of them run here), ragged n and k around each
// panel width and k-group, a row stride wider than n, both bias forms and a zero point.
TEST(GemmS8Pack, TransposedPackerMatchesPackOfTranspose) {
  struct Pair {
    GemmS8Layout layout;
    GemmS8PackFn pack, pack_transposed;
  };
  const Pair pairs[] = {{GemmS8Layout::kRef1x1, pack_w_s8_1x1_goi, pack_wt_s8_1x1_goi},
                        {GemmS8Layout::kAvx2_8x8, pack_w_s8_8x8_goi_pair4, pack_wt_s8_8x8_goi_pair4},
                        {GemmS8Layout::kVnni64x4, pack_w_s8_64x4_goi_x80, pack_wt_s8_64x4_goi_x80},
                        {GemmS8Layout::kNeon16x4, pack_w_s8_16x4_goi, pack_wt_s8_16x4_goi},
                        {GemmS8Layout::kVnni16x4, pack_w_s8_16x4_goi_x80, pack_wt_s8_16x4_goi_x80},
                        {GemmS8Layout::kAmx64x4, pack_w_s8_64x4_goi_k64, pack_wt_s8_64x4_goi_k64}};
  uint32_t seed = 1000;
  for (const Pair& p : pairs) {
    for (int n : {1, 7, 16, 17, 64, 65}) {
      for (int k : {1, 3, 4, 9, 64, 302}) {
        std::mt19937 rng(seed++);
        std::uniform_int_distribution<int> byte(-127, 127);
        const size_t ldt = static_cast<size_t>(n) + 3;  // wt [k x n], padded rows
        std::vector<int8_t> wt(static_cast<size_t>(k) * ldt), w(static_cast<size_t>(n) * k);
        for (auto& b : wt) b = static_cast<int8_t>(byte(rng));
        for (int j = 0; j < n; ++j) {
          for (int i = 0; i < k; ++i) w[static_cast<size_t>(j) * k + i] = wt[static_cast<size_t>(i) * ldt + j];
        }
        std::vector<int32_t> bias(static_cast<size_t>(n));
        for (auto& b : bias) b = byte(rng) * 1000;
        const size_t bytes = gemm_s8_packed_size(p.layout, n, k);
        for (const int32_t* b : {static_cast<const int32_t*>(nullptr), static_cast<const int32_t*>(bias.data())}) {
          const PackedBuffer want = packed_buffer(bytes, 0xa5), got = packed_buffer(bytes, 0x5a);
          p.pack(n, k, w.data(), static_cast<size_t>(k), b, -13, want.get());
          p.pack_transposed(n, k, wt.data(), ldt, b, -13, got.get());
          ASSERT_EQ(std::memcmp(got.get(), want.get(), bytes), 0)
              << "layout " << static_cast<int>(p.layout) << " n=" << n << " k=" << k << (b ? " with bias" : "");
        }
      }
    }
  }
}

// Each variant's table pairs its packer with the transposed twin of the same layout.
TEST_P(GemmS8Variant, TablePairsTransposedPacker) {
  const GemmS8Kernels& v = variant();
  const int n = v.nr + 1, k = 2 * v.kr + 1;
  std::vector<int8_t> w(static_cast<size_t>(n) * k);
  for (size_t i = 0; i < w.size(); ++i) w[i] = static_cast<int8_t>(static_cast<int>(i % 255) - 127);
  std::vector<int8_t> wt(w.size());
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < k; ++i) wt[static_cast<size_t>(i) * n + j] = w[static_cast<size_t>(j) * k + i];
  }
  const size_t bytes = v.packed_size(n, k);
  const PackedBuffer want = packed_buffer(bytes, 0xa5), got = packed_buffer(bytes, 0x5a);
  v.pack(n, k, w.data(), static_cast<size_t>(k), nullptr, 5, want.get());
  v.pack_transposed(n, k, wt.data(), static_cast<size_t>(n), nullptr, 5, got.get());
  EXPECT_EQ(std::memcmp(got.get(), want.get(), bytes), 0) << v.pack_name;
}

// Each variant's packers, of W and of W^T, write what the portable packer of its layout writes for
// W (pack.cc; AVX-512 VNNI and AVX-VNNI have SIMD ones): ragged n and k around the 16-column blocks, the panels,
// the 64-byte k chunks and the 4-byte k-groups, row strides wider than a row, both bias forms, a
// zero point, every byte written.
TEST_P(GemmS8Variant, PackerWritesThePortablePackersBytes) {
  const GemmS8Kernels& v = variant();
  const GemmS8PackFn portable = portable_packer(v.layout);
  ASSERT_NE(portable, nullptr) << v.pack_name;
  uint32_t seed = 2000;
  for (int n : {1, 15, 16, 17, 63, 64, 65, 130, 302}) {
    for (int k : {1, 3, 4, 5, 63, 64, 65, 127, 128, 129, 302}) {
      std::mt19937 rng(seed++);
      std::uniform_int_distribution<int> byte(-127, 127);
      const size_t ldw = static_cast<size_t>(k) + 5;
      std::vector<int8_t> w(static_cast<size_t>(n) * ldw);
      for (auto& b : w) b = static_cast<int8_t>(byte(rng));
      const size_t ldt = static_cast<size_t>(n) + 3;  // W^T [k x n]
      std::vector<int8_t> wt(static_cast<size_t>(k) * ldt);
      for (int j = 0; j < n; ++j) {
        for (int i = 0; i < k; ++i) wt[static_cast<size_t>(i) * ldt + j] = w[static_cast<size_t>(j) * ldw + i];
      }
      std::vector<int32_t> bias(static_cast<size_t>(n));
      for (auto& b : bias) b = byte(rng) * 100000;
      const size_t bytes = v.packed_size(n, k);
      for (const int32_t* b : {static_cast<const int32_t*>(nullptr), static_cast<const int32_t*>(bias.data())}) {
        const PackedBuffer want = packed_buffer(bytes, 0xa5), got = packed_buffer(bytes, 0x5a);
        portable(n, k, w.data(), ldw, b, -13, want.get());
        v.pack(n, k, w.data(), ldw, b, -13, got.get());
        ASSERT_EQ(std::memcmp(got.get(), want.get(), bytes), 0) << v.pack_name << " n=" << n << " k=" << k << (b ? " with bias" : "");
        std::memset(got.get(), 0x5a, bytes);
        v.pack_transposed(n, k, wt.data(), ldt, b, -13, got.get());
        ASSERT_EQ(std::memcmp(got.get(), want.get(), bytes), 0)
            << v.pack_name << " transposed, n=" << n << " k=" << k << (b ? " with bias" : "");
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Available, GemmS8Variant, ::testing::ValuesIn(test::isas_under_test(&IsaTables::gemm_s8)), test::isa_param_name);
GTEST_ALLOW_UNINSTANTIATED_PARAMETERIZED_TEST(GemmS8Variant);

// ---- dispatch, detection, override, naming -----------------------------------------------------

TEST(GemmS8Dispatch, DetectedVariantsAreBuiltAndRun) {
  const CpuFeatures& f = cpu_features();
  std::cout << "cpu features (" << f.source << "): avx2=" << f.avx2 << " fma=" << f.fma << " avx512f=" << f.avx512f
            << " avx512bw=" << f.avx512bw << " avx512vl=" << f.avx512vl << " avx512vnni=" << f.avx512vnni
            << " avxvnni=" << f.avxvnni << " amx=" << f.amx << (f.amx_refused ? " (" : "")
            << (f.amx_refused ? f.amx_refused : "") << (f.amx_refused ? ")" : "") << " neon=" << f.neon
            << " dotprod=" << f.dotprod << "; runs " << isa_mask_names(cpu_isa_mask()) << "\n";
#if defined(__x86_64__)
  const Isa simd[] = {Isa::kAvx2, Isa::kAvxVnni, Isa::kAvx512Vnni, Isa::kAmx};
#elif defined(__aarch64__)
  const Isa simd[] = {Isa::kNeonDot};
#else
  const Isa simd[] = {Isa::kRef};
#endif
  // Every SIMD variant of this architecture must be compiled in, and must run when the CPU has it.
  bool any_simd = false;
  for (Isa isa : simd) {
    const GemmS8Kernels* v = isa_tables(isa).gemm_s8;
    ASSERT_NE(v, nullptr) << isa_name(isa) << " kernels are not compiled in";
    if (!cpu_supports(isa)) continue;
    any_simd = any_simd || isa != Isa::kRef;
    GemmS8Tester().m(v->mr + 1).n(v->nr + 1).k(33).out(GemmOut::kS8).test(*v);  // asserts it ran
  }
#if defined(__x86_64__)
  if (cpu_features().avx2) {
    EXPECT_TRUE(any_simd) << "an AVX2 CPU ran no SIMD gemm_s8 variant";
  }
#endif
  EXPECT_NE(isa_tables(Isa::kRef).gemm_s8, nullptr);
}

// CI sets ACT_TEST_REQUIRE_ISAS (comma-separated) to the ISA levels its machine must run: the
// gemm_s8 variant an Engine runs at each of them must run here (the tester checks what ran).
TEST(GemmS8Dispatch, RequiredVariantsRun) {
  const std::vector<std::optional<Isa>> required = test::required_isas();
  if (required.empty()) GTEST_SKIP() << "ACT_TEST_REQUIRE_ISAS is not set";
  for (const std::optional<Isa>& isa : required) {
    ASSERT_TRUE(isa.has_value()) << "ACT_TEST_REQUIRE_ISAS names an unknown ISA";
    ASSERT_TRUE(cpu_supports(*isa)) << isa_name(*isa) << " is required but this CPU runs only "
                                    << isa_mask_names(cpu_isa_mask());
    const GemmS8Kernels& v = variant_for(*isa, &IsaTables::gemm_s8);
    GemmS8Tester().m(v.mr + 1).n(v.nr + 1).k(19).out(GemmOut::kS32).test(v);
  }
}

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out(1);
  for (char c : s) {
    if (c == sep) {
      out.emplace_back();
    } else {
      out.back() += c;
    }
  }
  return out;
}

// "<a>x<b>" or "<a>x<b>c<c>" with nothing else; false otherwise.
bool parse_tile(const std::string& s, bool with_kr, int* a, int* b, int* c) {
  int used = 0;
  const int got = with_kr ? std::sscanf(s.c_str(), "%dx%dc%d%n", a, b, c, &used)
                          : std::sscanf(s.c_str(), "%dx%d%n", a, b, &used);
  return got == (with_kr ? 3 : 2) && used == static_cast<int>(s.size());
}

// <family>_<dtypes>_<tile>_<isa> (kernels/README.md, "Adding a variant"), tile matching the table.
// (A hand parser: std::regex trips GCC 12's -Wmaybe-uninitialized under ASan.)
TEST(GemmS8Dispatch, KernelNamesFollowTheGrammar) {
  const std::set<std::string> isa_suffixes = {"ref",    "neon",   "neondot",    "neoni8mm", "avx2",
                                              "avxvnni", "avx512", "avx512vnni", "amx"};
  const GemmS8Kernels* tables[] = {gemm_s8_table_ref(), gemm_s8_table_avx2(), gemm_s8_table_avxvnni(), gemm_s8_table_avx512vnni(),
                                   gemm_s8_table_amx(), gemm_s8_table_neondot()};
  int checked = 0;
  for (const GemmS8Kernels* t : tables) {
    if (t == nullptr) continue;
    ++checked;
    const char* kinds[] = {"s8out", "f32out", "s32out"};
    const char* names[] = {t->s8out_name, t->f32out_name, t->s32out_name};
    for (int i = 0; i < 3; ++i) {
      const std::vector<std::string> part = split(names[i], '_');
      ASSERT_EQ(part.size(), 5u) << names[i];
      EXPECT_EQ(part[0], "gemm") << names[i];
      EXPECT_EQ(part[1], "s8s8") << names[i];
      EXPECT_EQ(part[2], kinds[i]) << names[i];
      int mr = 0, nr = 0, kr = 0;
      ASSERT_TRUE(parse_tile(part[3], true, &mr, &nr, &kr)) << names[i];
      EXPECT_EQ(mr, t->mr) << names[i];
      EXPECT_EQ(nr, t->nr) << names[i];
      EXPECT_EQ(kr, t->kr) << names[i];
      EXPECT_TRUE(isa_suffixes.count(part[4]) == 1) << names[i];
      EXPECT_EQ(part[4], isa_name(t->isa)) << names[i];
    }
    // pack_w_s8_<nr>x<kr>_goi[_<variant>]
    const std::vector<std::string> part = split(t->pack_name, '_');
    ASSERT_TRUE(part.size() == 5u || part.size() == 6u) << t->pack_name;
    EXPECT_EQ(part[0] + "_" + part[1] + "_" + part[2], "pack_w_s8") << t->pack_name;
    int nr = 0, kr = 0;
    ASSERT_TRUE(parse_tile(part[3], false, &nr, &kr, nullptr)) << t->pack_name;
    EXPECT_EQ(nr, t->nr) << t->pack_name;
    EXPECT_EQ(kr, t->kr) << t->pack_name;
    EXPECT_EQ(part[4], "goi") << t->pack_name;
  }
  EXPECT_GE(checked, 2) << "expected the reference and at least one SIMD table in this build";
}

// The packed header and the column sums / folded bias, checked by hand for one small weight.
TEST(GemmS8Pack, HeaderAndFoldedBias) {
  const int n = 3, k = 5;
  const int8_t w[n * k] = {1, 2, 3, 4, 5, -1, -1, -1, -1, -1, 127, -127, 0, 0, 127};
  const int32_t bias[n] = {10, 20, 30};
  for (GemmS8Layout layout : {GemmS8Layout::kRef1x1, GemmS8Layout::kAvx2_8x8, GemmS8Layout::kVnni64x4,
                              GemmS8Layout::kNeon16x4, GemmS8Layout::kVnni64x4U8A, GemmS8Layout::kVnni16x4,
                              GemmS8Layout::kAmx64x4, GemmS8Layout::kAmx64x4U8A}) {
    const size_t bytes = gemm_s8_packed_size(layout, n, k);
    const PackedBuffer p = packed_buffer(bytes, 0);
    const int za = -3;
    portable_packer(layout)(n, k, w, k, bias, za, p.get());
    GemmS8PackedHeader h;
    std::memcpy(&h, p.get(), sizeof h);
    EXPECT_EQ(h.magic, kGemmS8PackedMagic);
    EXPECT_EQ(h.layout, layout);
    EXPECT_EQ(h.n, n);
    EXPECT_EQ(h.k, k);
    EXPECT_EQ(h.kp % h.kr, 0);
    EXPECT_EQ(h.panel_bytes % 64, 0u);
    EXPECT_EQ(bytes, sizeof h + static_cast<size_t>((n + h.nr - 1) / h.nr) * h.panel_bytes);
    const int32_t sums[n] = {15, -5, 127};
    for (int c = 0; c < n; ++c) {
      const uint8_t* panel = p.get() + sizeof h + static_cast<size_t>(c / h.nr) * h.panel_bytes;
      int32_t kbias, ksum;
      std::memcpy(&kbias, panel + 4 * (c % h.nr), 4);
      std::memcpy(&ksum, panel + 4 * (h.nr + c % h.nr), 4);
      EXPECT_EQ(ksum, sums[c]);
      EXPECT_EQ(kbias, bias[c] - za * sums[c]);
    }
    // Weight bytes of the 4-byte k-group layouts: W XOR 0x80 (W + 128 as u8) for the
    // signed-activation VNNI layouts, W itself for the others; k-padding 0.
    if (h.kr == 4) {
      const int flip = layout == GemmS8Layout::kVnni64x4 || layout == GemmS8Layout::kVnni16x4 ? 0x80 : 0;
      const int8_t* wp = reinterpret_cast<const int8_t*>(p.get() + sizeof h + 8 * h.nr);
      for (int c = 0; c < n; ++c) {
        for (int kk = 0; kk < h.kp; ++kk) {
          const int8_t want = kk < k ? static_cast<int8_t>(w[c * k + kk] ^ flip) : int8_t{0};
          EXPECT_EQ(wp[(kk / 4 * h.nr + c) * 4 + kk % 4], want) << "column " << c << " k " << kk;
        }
      }
    }
  }
}

}  // namespace
}  // namespace act::kernels::test
