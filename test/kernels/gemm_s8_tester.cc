#include "test/kernels/gemm_s8_tester.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "kernels/common/requant_ref.h"
#include "kernels/gemm_s8/gemm_s8_variants.h"

namespace act::kernels::test {

namespace {

// Elements after C's last row that must stay untouched.
constexpr size_t kGuard = 67;

struct AlignedFree {
  void operator()(void* p) const { std::free(p); }
};
using Packed = std::unique_ptr<uint8_t, AlignedFree>;

Packed pack_with(GemmS8PackFn pack, const GemmS8Kernels& v, int n, int k, const int8_t* w, const int32_t* bias,
                 int32_t za) {
  const size_t bytes = v.packed_size(n, k);
  EXPECT_EQ(bytes % kGemmS8PackedAlign, 0u);
  Packed p(static_cast<uint8_t*>(std::aligned_alloc(kGemmS8PackedAlign, bytes)));
  pack(n, k, w, static_cast<size_t>(k), bias, za, p.get());
  return p;
}

std::vector<int8_t> sign_flipped(const int8_t* x, size_t n) {
  std::vector<int8_t> out(x, x + n);
  for (int8_t& b : out) b = static_cast<int8_t>(b ^ 0x80);
  return out;
}

template <typename T>
T sentinel();
template <>
int8_t sentinel<int8_t>() { return static_cast<int8_t>(0x5A); }
template <>
int32_t sentinel<int32_t>() { return 0x5A5A5A5A; }
template <>
float sentinel<float>() {
  const uint32_t bits = 0x7FC0DEADu;  // a quiet NaN no kernel produces
  float f;
  std::memcpy(&f, &bits, 4);
  return f;
}

// Distance in units in the last place between two finite floats (0 for identical bits).
int64_t ulp_distance(float x, float y) {
  int32_t ix, iy;
  std::memcpy(&ix, &x, 4);
  std::memcpy(&iy, &y, 4);
  const int64_t ox = ix < 0 ? int64_t{INT32_MIN} - ix : ix;  // monotonic integer order
  const int64_t oy = iy < 0 ? int64_t{INT32_MIN} - iy : iy;
  return ox > oy ? ox - oy : oy - ox;
}

template <typename T>
bool same_bits(T x, T y) {
  return std::memcmp(&x, &y, sizeof(T)) == 0;
}

// Compares the [m x n] rectangle of `got` against `want` and checks that `got`'s gaps and guard
// still hold the sentinel. `max_ulp` < 0 means bit-exact.
template <typename T>
void expect_matrix(const char* what, const std::vector<T>& got, const std::vector<T>& want, int m, int n, size_t ld,
                   int64_t max_ulp) {
  size_t bad = 0, bad_sentinel = 0;
  std::ostringstream first;
  int64_t worst_ulp = 0;
  for (int i = 0; i < m; ++i) {
    for (int j = 0; j < n; ++j) {
      const size_t at = static_cast<size_t>(i) * ld + j;
      bool ok = same_bits(got[at], want[at]);
      if constexpr (std::is_same_v<T, float>) {
        if (!ok && max_ulp >= 0 && std::isfinite(got[at]) && std::isfinite(want[at])) {
          const int64_t d = ulp_distance(got[at], want[at]);
          worst_ulp = std::max(worst_ulp, d);
          ok = d <= max_ulp;
        }
      }
      if (!ok && bad++ == 0) {
        first << "first mismatch at [" << i << "][" << j << "]: got " << +got[at] << ", want " << +want[at];
      }
    }
  }
  for (size_t at = 0; at < got.size(); ++at) {
    const size_t row = at / ld, col = at % ld;
    const bool inside = row < static_cast<size_t>(m) && col < static_cast<size_t>(n);
    if (!inside && !same_bits(got[at], sentinel<T>()) && bad_sentinel++ == 0) {
      first << " first write outside C at element " << at << " (row " << row << ", col " << col << ")";
    }
  }
  EXPECT_EQ(bad, 0u) << what << ": " << bad << " of " << m * n << " elements differ; " << first.str();
  EXPECT_EQ(bad_sentinel, 0u) << what << ": " << bad_sentinel << " elements written outside C; " << first.str();
  if constexpr (std::is_same_v<T, float>) {
    if (worst_ulp > 0) ::testing::Test::RecordProperty("worst_ulp", static_cast<int>(worst_ulp));
  }
}

std::vector<std::pair<int, int>> tile_sizes(const GemmS8Kernels& v, int tm, int tn) {
  if (tm > 0 && tn > 0) return {{tm, tn}};
  // Unaligned to every tile on purpose, plus splits by rows only and by columns only.
  return {{1, 1 << 30}, {v.mr + 1, v.nr + 3}, {1 << 30, 5}, {7, 2 * v.nr - 1}};
}

}  // namespace

void GemmS8Tester::test(const GemmS8Kernels& v) const {
  SCOPED_TRACE(::testing::Message() << isa_name(v.isa) << " m=" << m_ << " n=" << n_ << " k=" << k_
                                    << " segment_k=" << segment_k_
                                    << " lda+=" << lda_pad_ << " ldc+=" << ldc_pad_ << " za=" << za_
                                    << " per_row=" << per_row_ << " out=" << static_cast<int>(out_)
                                    << " zo=" << zo_ << " q=[" << qmin_ << "," << qmax_ << "] res=" << residual_
                                    << " relu=" << relu_ << " seed=" << seed_);
  ASSERT_TRUE(segment_k_ == 0 || (segment_k_ % kGemmS8SegmentAlign == 0 && k_ % segment_k_ == 0)) << "bad test";
  ASSERT_TRUE(!unsigned_a_ || (v.pack_u8a != nullptr && !per_row_)) << "bad test: no unsigned activations here";
  ASSERT_TRUE(!residual_row_ || (residual_ && !in_place_)) << "bad test: a residual row needs a residual, not in place";
  const GemmS8Kernels* ref = gemm_s8_table_ref();
  std::mt19937 rng(seed_);
  auto uniform = [&](int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng); };
  auto log_uniform = [&](float lo, float hi) {
    if (lo == hi) return lo;
    return std::exp(std::uniform_real_distribution<float>(std::log(lo), std::log(hi))(rng));
  };

  const size_t lda = static_cast<size_t>(k_) + lda_pad_;
  const size_t ldc = static_cast<size_t>(n_) + ldc_pad_;
  const size_t ldr = residual_row_ ? 0 : ldc;

  // A: garbage everywhere (row gaps and the read slack too: their values must not matter), then rows.
  std::vector<int8_t> a((static_cast<size_t>(m_) - 1) * lda + static_cast<size_t>(k_) + kGemmS8ReadSlack);
  for (auto& x : a) x = static_cast<int8_t>(uniform(-128, 127));
  for (int i = 0; i < m_; ++i) {
    for (int kk = 0; kk < k_; ++kk) {
      int8_t& x = a[static_cast<size_t>(i) * lda + kk];
      if (a_fill_ == GemmFill::kMax) x = 127;
      if (a_fill_ == GemmFill::kMin) x = -128;
    }
  }
  // Segments: a pool of separately allocated kernel-row-like pieces, each row's segments picked from
  // it (rows share them), and the dense A above rewritten to the bytes the segments hold.
  std::vector<std::unique_ptr<int8_t[]>> segment_pool;
  std::vector<const int8_t*> a_segments;
  if (segment_k_ > 0) {
    const int per_row = k_ / segment_k_;
    const int pool_size = std::max(1, m_ * per_row / 2 + 1);
    for (int p = 0; p < pool_size; ++p) {
      segment_pool.emplace_back(new int8_t[static_cast<size_t>(segment_k_)]);
      for (int t = 0; t < segment_k_; ++t) {
        segment_pool.back()[t] = static_cast<int8_t>(a_fill_ == GemmFill::kMax   ? 127
                                                     : a_fill_ == GemmFill::kMin ? -128
                                                                                 : uniform(-128, 127));
      }
    }
    for (int i = 0; i < m_; ++i) {
      for (int s = 0; s < per_row; ++s) {
        const int8_t* seg = segment_pool[static_cast<size_t>(uniform(0, pool_size - 1))].get();
        a_segments.push_back(seg);
        std::memcpy(&a[static_cast<size_t>(i) * lda + static_cast<size_t>(s) * segment_k_], seg, static_cast<size_t>(segment_k_));
      }
    }
  }
  std::vector<int8_t> w(static_cast<size_t>(n_) * k_);
  for (auto& x : w) {
    x = static_cast<int8_t>(w_fill_ == GemmFill::kMax   ? 127
                            : w_fill_ == GemmFill::kMin ? -127
                                                        : uniform(-127, 127));
  }
  std::vector<int32_t> bias_i32(static_cast<size_t>(n_));
  std::vector<float> bias_f32(static_cast<size_t>(n_));
  for (int j = 0; j < n_; ++j) {
    bias_i32[j] = uniform(-(1 << 18), 1 << 18);
    bias_f32[j] = std::uniform_real_distribution<float>(-5.0f, 5.0f)(rng);
  }
  // s8 out with per-row scales takes its bias in float (output units), as f32 out does.
  const bool float_bias = bias_ && (out_ == GemmOut::kF32 || (out_ == GemmOut::kS8 && per_row_));
  const bool int_bias = bias_ && !float_bias;
  std::vector<int32_t> row_zp(static_cast<size_t>(m_));
  std::vector<float> row_scale(static_cast<size_t>(m_));
  for (int i = 0; i < m_; ++i) {
    const int pick = uniform(0, 5);  // the extremes often, like real per-token zero points
    row_zp[i] = pick == 0 ? -128 : pick == 1 ? 127 : uniform(-128, 127);
    row_scale[i] = log_uniform(1e-3f, 1e-1f);
  }
  std::vector<float> scale(static_cast<size_t>(n_));
  for (auto& s : scale) s = log_uniform(scale_lo_, scale_hi_);
  const float a_scale = 0.02f;
  const int32_t rzp = uniform(-128, 127);
  const float rscale = log_uniform(0.05f, 2.0f);
  const size_t residual_elements = residual_row_ ? static_cast<size_t>(n_) : static_cast<size_t>(m_) * ldr;
  std::vector<int8_t> res_s8(residual_elements);
  std::vector<float> res_f32(residual_elements);
  for (auto& x : res_s8) x = static_cast<int8_t>(uniform(-128, 127));
  for (auto& x : res_f32) x = std::uniform_real_distribution<float>(-50.0f, 50.0f)(rng);

  // The naive definition, from the unpacked operands.
  std::vector<int32_t> acc(static_cast<size_t>(m_) * n_);
  for (int i = 0; i < m_; ++i) {
    const int32_t zr = per_row_ ? row_zp[i] : za_;
    for (int j = 0; j < n_; ++j) {
      int64_t s = int_bias ? bias_i32[j] : 0;
      for (int kk = 0; kk < k_; ++kk) {
        s += (int64_t{a[static_cast<size_t>(i) * lda + kk]} - zr) * w[static_cast<size_t>(j) * k_ + kk];
      }
      acc[static_cast<size_t>(i) * n_ + j] = static_cast<int32_t>(s);
    }
  }

  const Packed ref_w = pack_with(ref->pack, *ref, n_, k_, w.data(), int_bias ? bias_i32.data() : nullptr, za_);
  const Packed var_w = unsigned_a_ ? pack_with(v.pack_u8a, v, n_, k_, w.data(), int_bias ? bias_i32.data() : nullptr, za_ + 128)
                                   : pack_with(v.pack, v, n_, k_, w.data(), int_bias ? bias_i32.data() : nullptr, za_);
  // The variant's A: the same codes, or their unsigned bytes (segments too, each its own copy).
  const std::vector<int8_t> a_unsigned = sign_flipped(a.data(), a.size());
  std::vector<std::vector<int8_t>> segment_pool_unsigned;
  std::vector<const int8_t*> a_segments_unsigned;
  for (const auto& seg : segment_pool) segment_pool_unsigned.push_back(sign_flipped(seg.get(), static_cast<size_t>(segment_k_)));
  for (const int8_t* seg : a_segments) {
    for (size_t p = 0; p < segment_pool.size(); ++p) {
      if (segment_pool[p].get() == seg) a_segments_unsigned.push_back(segment_pool_unsigned[p].data());
    }
  }
  auto args_for = [&](const Packed& p, CoveredPaths* covered) {
    const bool stored_unsigned = unsigned_a_ && &p == &var_w;
    GemmS8Args g;
    g.m = m_;
    g.n = n_;
    g.k = k_;
    if (segment_k_ > 0) {
      g.a_segments = stored_unsigned ? a_segments_unsigned.data() : a_segments.data();
      g.segment_k = segment_k_;
    } else {
      g.a = stored_unsigned ? a_unsigned.data() : a.data();
      g.lda = lda;
    }
    g.packed_w = p.get();
    g.a_row_zero_point = per_row_ ? row_zp.data() : nullptr;
    g.covered = covered;
    return g;
  };

  // Runs `kernel` over every tile of a (tm x tn) split (one call when tm, tn cover C) into a fresh
  // sentinel-filled buffer; returns the buffer.
  auto run_tiled = [&](auto kernel, const Packed& p, CoveredPaths* covered, auto make_out, auto* type_tag, int tm,
                       int tn) {
    using T = std::remove_pointer_t<decltype(type_tag)>;
    std::vector<T> c(static_cast<size_t>(m_) * ldc + kGuard, sentinel<T>());
    if (in_place_) {
      for (int i = 0; i < m_; ++i) {
        for (int j = 0; j < n_; ++j) {
          if constexpr (std::is_same_v<T, int8_t>) c[static_cast<size_t>(i) * ldc + j] = res_s8[i * ldr + j];
        }
      }
    }
    const auto out = make_out(c.data());
    const GemmS8Args g = args_for(p, covered);
    for (int m0 = 0; m0 < m_; m0 += std::min(tm, m_)) {
      for (int n0 = 0; n0 < n_; n0 += std::min(tn, n_)) {
        kernel(g, out, m0, std::min(m_, m0 + tm), n0, std::min(n_, n0 + tn));
      }
    }
    return c;
  };

  auto check_kind = [&](auto ref_kernel, auto var_kernel, auto make_out, auto* type_tag, const auto& expect_at,
                        int64_t max_ulp) {
    using T = std::remove_pointer_t<decltype(type_tag)>;
    std::vector<T> want(static_cast<size_t>(m_) * ldc + kGuard, sentinel<T>());
    for (int i = 0; i < m_; ++i) {
      for (int j = 0; j < n_; ++j) want[static_cast<size_t>(i) * ldc + j] = expect_at(i, j);
    }
    const std::vector<T> c_ref = run_tiled(ref_kernel, ref_w, nullptr, make_out, type_tag, 1 << 30, 1 << 30);
    expect_matrix("reference vs naive definition", c_ref, want, m_, n_, ldc, -1);

    CoveredPaths covered;
    const std::vector<T> c_var = run_tiled(var_kernel, var_w, &covered, make_out, type_tag, 1 << 30, 1 << 30);
    expect_matrix("variant vs reference", c_var, c_ref, m_, n_, ldc, max_ulp);
    EXPECT_EQ(covered.ran_mask(), isa_bit(v.isa))
        << "asked for " << isa_name(v.isa) << " but ran: " << isa_mask_names(covered.ran_mask());
    const uint32_t paths = covered.paths(v.isa);
    if (per_row_) {
      EXPECT_NE(paths & kPathRowZeroPoint, 0u) << "per-row zero points were not applied";
    }
    EXPECT_EQ((paths & kPathSegmentedA) != 0, segment_k_ > 0) << "A was not read the way it was given";
    EXPECT_EQ((paths & kPathUnsignedA) != 0, unsigned_a_) << "A was not read as signed or unsigned as it was stored";
    if (m_ % v.mr != 0) {
      EXPECT_NE(paths & kPathRowTail, 0u) << "row tail kernel did not run";
    }
    if (m_ >= v.mr) {
      EXPECT_NE(paths & kPathFullTile, 0u) << "full tile kernel did not run";
    }
    if (n_ % v.nr != 0) {
      EXPECT_NE(paths & kPathPartialCols, 0u) << "partial columns did not run";
    }
    // The VNNI kernel prefetches weights that span several panels (or one too large for L1) and
    // only those: both loops, with and without the prefetches, must have run where expected.
    if (v.isa == Isa::kAvx512Vnni && (k_ <= 256 || k_ > 512)) {  // panels of at most 16.5 KB, or over 32 KB
      EXPECT_EQ((paths & kPathStreamedWeights) != 0, n_ > v.nr || k_ > 512) << "weight prefetching ran where it should not, or did not";
    }

    for (const auto& [tm, tn] : tile_sizes(v, tile_m_, tile_n_)) {
      SCOPED_TRACE(::testing::Message() << "sub-rectangles " << tm << "x" << tn);
      CoveredPaths covered_tiles;
      const std::vector<T> c_tiles = run_tiled(var_kernel, var_w, &covered_tiles, make_out, type_tag, tm, tn);
      expect_matrix("sub-rectangles vs one call", c_tiles, c_var, m_, n_, ldc, -1);
      EXPECT_EQ(covered_tiles.ran_mask(), isa_bit(v.isa));
      if (in_place_) continue;
      // Each call alone, on a fresh sentinel buffer: it writes its rectangle and nothing else (a
      // kernel that also wrote a neighbour's columns with correct values would pass the check above).
      const GemmS8Args g = args_for(var_w, nullptr);
      int checked = 0;
      for (int m0 = 0; m0 < m_ && checked < 48; m0 += std::min(tm, m_)) {
        for (int n0 = 0; n0 < n_ && checked < 48; n0 += std::min(tn, n_), ++checked) {
          const int m1 = std::min(m_, m0 + tm), n1 = std::min(n_, n0 + tn);
          std::vector<T> c(static_cast<size_t>(m_) * ldc + kGuard, sentinel<T>());
          var_kernel(g, make_out(c.data()), m0, m1, n0, n1);
          size_t wrong = 0;
          for (size_t at = 0; at < c.size(); ++at) {
            const size_t row = at / ldc, col = at % ldc;
            const bool inside = row >= static_cast<size_t>(m0) && row < static_cast<size_t>(m1) &&
                                col >= static_cast<size_t>(n0) && col < static_cast<size_t>(n1);
            wrong += inside ? !same_bits(c[at], c_var[at]) : !same_bits(c[at], sentinel<T>());
          }
          EXPECT_EQ(wrong, 0u) << "the call for [" << m0 << "," << m1 << ")x[" << n0 << "," << n1
                               << ") wrote outside its rectangle or not all of it";
        }
      }
    }
  };

  switch (out_) {
    case GemmOut::kS32: {
      auto make_out = [&](int32_t* c) { return GemmS8OutS32{c, ldc}; };
      auto expect_at = [&](int i, int j) { return acc[static_cast<size_t>(i) * n_ + j]; };
      check_kind(ref->s32out, v.s32out, make_out, static_cast<int32_t*>(nullptr), expect_at, -1);
      break;
    }
    case GemmOut::kS8: {
      auto make_out = [&](int8_t* c) {
        GemmS8OutS8 o;
        o.c = c;
        o.ldc = ldc;
        o.scale = scale.data();
        o.out_zero_point = zo_;
        o.qmin = qmin_;
        o.qmax = qmax_;
        if (per_row_) o.a_row_scale = row_scale.data();
        if (float_bias) o.bias = bias_f32.data();
        if (residual_) {
          o.residual = in_place_ ? c : res_s8.data();
          o.ldr = ldr;
          o.residual_zero_point = rzp;
          o.residual_scale = rscale;
        }
        return o;
      };
      auto expect_at = [&](int i, int j) {
        const int32_t x = acc[static_cast<size_t>(i) * n_ + j];
        if (per_row_) {
          float y = ref::scale_acc_row(x, row_scale[i], scale[j], float_bias ? bias_f32[j] : 0.0f);
          if (residual_) y = ref::fp_barrier(y + ref::residual_term(res_s8[i * ldr + j], rzp, rscale));
          return ref::finish_s8(y, zo_, qmin_, qmax_);
        }
        return residual_ ? ref::requantize_s8_residual(x, scale[j], res_s8[i * ldr + j], rzp, rscale, zo_, qmin_, qmax_)
                         : ref::requantize_s8(x, scale[j], zo_, qmin_, qmax_);
      };
      check_kind(ref->s8out, v.s8out, make_out, static_cast<int8_t*>(nullptr), expect_at, -1);
      break;
    }
    case GemmOut::kF32: {
      auto make_out = [&](float* c) {
        GemmS8OutF32 o;
        o.c = c;
        o.ldc = ldc;
        o.w_scale = scale.data();
        o.a_scale = a_scale;
        o.a_row_scale = per_row_ ? row_scale.data() : nullptr;
        o.bias = bias_ ? bias_f32.data() : nullptr;
        o.residual = residual_ ? res_f32.data() : nullptr;
        o.ldr = ldr;
        o.relu = relu_;
        return o;
      };
      auto expect_at = [&](int i, int j) {
        return ref::dequantize_f32(acc[static_cast<size_t>(i) * n_ + j], per_row_ ? row_scale[i] : a_scale, scale[j],
                                   bias_ ? bias_f32[j] : 0.0f, residual_, residual_ ? res_f32[i * ldr + j] : 0.0f,
                                   relu_);
      };
      check_kind(ref->f32out, v.f32out, make_out, static_cast<float*>(nullptr), expect_at, 2);
      break;
    }
  }
}

}  // namespace act::kernels::test
