// INT8 convolution (tiled im2col + gemm_s8) against a naive direct convolution defined here in
// integers: every geometry ResNet18 uses (7x7/2 stem with 3 input channels, 3x3/1, 3x3/2, 1x1/2
// downsample, 1x1/1 read in place), dilation, ragged tiles, residual + ReLU through qmin, s8 and f32
// outputs — with every gemm_s8 variant this CPU can run. s8 results must be bit-exact.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "kernels/common/requant_ref.h"
#include "kernels/conv_s8/conv_s8.h"
#include "kernels/common/im2col.h"
#include "test/kernels/kernel_test_util.h"

namespace act::kernels {
namespace {

struct ConvCase {
  const char* name;
  int h, w, cin, cout, kernel, stride, pad, dilation;
};

// ResNet18's convolutions at small spatial sizes (odd and even, so the last row/column of a
// stride-2 conv sees padding on one side only), plus edge geometries.
const ConvCase kCases[] = {
    {"stem_7x7s2", 13, 18, 3, 64, 7, 2, 3, 1},
    {"stem_7x7s2_odd", 9, 7, 3, 5, 7, 2, 3, 1},
    {"3x3s1", 9, 11, 64, 64, 3, 1, 1, 1},
    {"3x3s1_ragged_c", 6, 5, 13, 70, 3, 1, 1, 1},
    {"3x3s2", 10, 7, 64, 128, 3, 2, 1, 1},
    {"3x3s2_odd", 9, 9, 16, 33, 3, 2, 1, 1},
    {"1x1s2_downsample", 8, 9, 64, 128, 1, 2, 0, 1},
    {"1x1s1_in_place", 5, 7, 24, 17, 1, 1, 0, 1},
    {"3x3_dilated", 7, 6, 8, 9, 3, 1, 2, 2},
    {"single_pixel", 1, 1, 3, 2, 3, 1, 1, 1},
    {"layer4_like", 3, 4, 256, 512, 3, 1, 1, 1},
};

Conv2dShape shape_of(const ConvCase& c) {
  return Conv2dShape::square(c.h, c.w, c.cin, c.cout, c.kernel, c.stride, c.pad, c.dilation);
}

// acc[pixel][o] = sum over taps inside the image of (x - zp) * w + bias[o]: padding contributes 0.
std::vector<int32_t> conv_naive_acc(const Conv2dShape& s, const std::vector<int8_t>& x, int zp,
                                    const std::vector<int8_t>& w, const std::vector<int32_t>& bias) {
  std::vector<int32_t> acc(static_cast<size_t>(s.out_h) * s.out_w * s.out_c);
  for (int oy = 0; oy < s.out_h; ++oy)
    for (int ox = 0; ox < s.out_w; ++ox)
      for (int o = 0; o < s.out_c; ++o) {
        int32_t a = bias[o];
        for (int ky = 0; ky < s.kernel_h; ++ky)
          for (int kx = 0; kx < s.kernel_w; ++kx) {
            const int iy = oy * s.stride - s.pad + ky * s.dilation, ix = ox * s.stride - s.pad + kx * s.dilation;
            if (iy < 0 || iy >= s.in_h || ix < 0 || ix >= s.in_w) continue;
            for (int c = 0; c < s.in_c; ++c)
              a += (x[(static_cast<size_t>(iy) * s.in_w + ix) * s.in_c + c] - zp) *
                   w[((static_cast<size_t>(o) * s.kernel_h + ky) * s.kernel_w + kx) * s.in_c + c];
          }
        acc[(static_cast<size_t>(oy) * s.out_w + ox) * s.out_c + o] = a;
      }
  return acc;
}

struct FreeDeleter {
  void operator()(void* p) const { std::free(p); }
};

struct Problem {
  Conv2dShape s;
  int zp = 0;
  std::vector<int8_t> x, w, residual;
  std::vector<int32_t> bias;
  std::vector<float> scale, w_scale, fbias;
};

Problem make_problem(const ConvCase& c, int zp, std::mt19937& rng) {
  Problem p;
  p.s = shape_of(c);
  p.zp = zp;
  std::uniform_int_distribution<int> byte(-128, 127), weight(-127, 127), b(-5000, 5000);
  std::uniform_real_distribution<float> sc(0.5f, 2.0f);
  const size_t in = static_cast<size_t>(c.h) * c.w * c.cin;
  p.x.resize(in + kGemmS8ReadSlack);  // the kernels' documented read slack after the input
  for (auto& v : p.x) v = static_cast<int8_t>(byte(rng));
  p.w.resize(static_cast<size_t>(c.cout) * p.s.patch_size());
  for (auto& v : p.w) v = static_cast<int8_t>(weight(rng));
  p.bias.resize(c.cout);
  for (auto& v : p.bias) v = b(rng);
  p.residual.resize(static_cast<size_t>(p.s.out_h) * p.s.out_w * c.cout);
  for (auto& v : p.residual) v = static_cast<int8_t>(byte(rng));
  // Scales that put the outputs around the int8 range, so rounding and clamping both happen.
  const float base = 1.0f / (40.0f * std::sqrt(static_cast<float>(p.s.patch_size())));
  for (int o = 0; o < c.cout; ++o) {
    p.scale.push_back(base * sc(rng));
    p.w_scale.push_back(0.01f * sc(rng));
    p.fbias.push_back(sc(rng) - 1.25f);
  }
  return p;
}

// Runs conv_s8_s8out tile by tile (tiles of `tile` pixels, or the conv's own tile size when 0), and
// in blocks of `channel_block` output channels (all at once when 0); with unsigned_input, on the
// input stored unsigned (XOR 0x80) through weights packed by pack_u8a, as the INT8 stem runs.
std::vector<int8_t> run_s8(const GemmS8Kernels& v, const Problem& p, const GemmS8OutS8& out_template, int tile,
                           int channel_block = 0, bool unsigned_input = false) {
  const Conv2dShape& s = p.s;
  std::unique_ptr<uint8_t, FreeDeleter> packed(
      static_cast<uint8_t*>(std::aligned_alloc(kGemmS8PackedAlign, v.packed_size(s.out_c, s.patch_size()))));
  const GemmS8PackFn pack = unsigned_input ? v.pack_u8a : v.pack;
  pack(s.out_c, s.patch_size(), p.w.data(), static_cast<size_t>(s.patch_size()), p.bias.data(),
       p.zp + (unsigned_input ? 128 : 0), packed.get());
  std::vector<int8_t> x = p.x;
  if (unsigned_input) {
    for (int8_t& b : x) b = static_cast<int8_t>(b ^ 0x80);
  }
  ConvS8 conv;
  conv.shape = s;
  conv.kernels = &v;
  conv.packed_w = packed.get();
  conv.input_zero_point = static_cast<int8_t>(unsigned_input ? p.zp ^ 0x80 : p.zp);
  const int pixels = s.out_h * s.out_w;
  if (tile == 0) tile = conv_s8_tile_pixels(s);
  std::vector<int8_t> scratch(conv_s8_scratch_bytes(s, tile) + 1);
  std::vector<int8_t> y(static_cast<size_t>(pixels) * s.out_c, 99);
  GemmS8OutS8 out = out_template;
  out.c = y.data();
  out.ldc = static_cast<size_t>(s.out_c);
  const int block = channel_block == 0 ? s.out_c : channel_block;
  for (int p0 = 0; p0 < pixels; p0 += tile) {
    for (int c0 = 0; c0 < s.out_c; c0 += block) {
      conv_s8_s8out(conv, x.data(), out, p0, std::min(tile, pixels - p0), scratch.data(),
                    ConvChannels{c0, std::min(s.out_c, c0 + block)});
    }
  }
  return y;
}

std::string variant_names() {
  std::string s;
  for (Isa isa : test::isas_under_test(&IsaTables::gemm_s8)) s += std::string(isa_name(isa)) + " ";
  return s;
}

TEST(ConvS8, EqualsDirectIntegerConvolutionForEveryVariant) {
  std::mt19937 rng(11);
  SCOPED_TRACE("variants: " + variant_names());
  for (const ConvCase& c : kCases) {
    for (int zp : {-128, -3, 127}) {
      const Problem p = make_problem(c, zp, rng);
      const std::vector<int32_t> acc = conv_naive_acc(p.s, p.x, zp, p.w, p.bias);
      const int out_c = p.s.out_c;
      for (bool residual : {false, true}) {
        GemmS8OutS8 o;
        o.scale = p.scale.data();
        o.out_zero_point = -7;
        o.qmin = residual ? -7 : -128;  // residual + ReLU: the clamp at the output zero point
        if (residual) {
          o.residual = p.residual.data();
          o.ldr = static_cast<size_t>(out_c);
          o.residual_zero_point = 4;
          o.residual_scale = 0.75f;
        }
        std::vector<int8_t> want(acc.size());
        for (size_t i = 0; i < acc.size(); ++i) {
          const size_t n = i % out_c;
          want[i] = residual ? ref::requantize_s8_residual(acc[i], p.scale[n], p.residual[i], 4, 0.75f, -7, -7, 127)
                             : ref::requantize_s8(acc[i], p.scale[n], -7, -128, 127);
        }
        for (Isa isa : test::isas_under_test(&IsaTables::gemm_s8)) {
          const GemmS8Kernels& v = test::table_of(isa, &IsaTables::gemm_s8);
          // The conv's own tiles, and ragged ones (1 pixel; 7 = not a multiple of any MR).
          // Channel blocks of 16 (ragged against 64-wide panels) and 64, as threads split deep layers.
          // The input stored unsigned too, where the variant reads it so.
          for (bool unsigned_input : {false, true}) {
            if (unsigned_input && v.pack_u8a == nullptr) continue;
            for (const auto& [tile, block] : {std::pair{0, 0}, {1, 0}, {7, 0}, {0, 16}, {7, 64}}) {
              const std::vector<int8_t> y = run_s8(v, p, o, tile, block, unsigned_input);
              for (size_t i = 0; i < y.size(); ++i) {
                ASSERT_EQ(y[i], want[i]) << c.name << " zp=" << zp << " residual=" << residual << " " << isa_name(isa)
                                         << " unsigned input=" << unsigned_input << " tile=" << tile
                                         << " channel block=" << block << " pixel " << i / out_c << " channel " << i % out_c;
              }
            }
          }
        }
      }
    }
  }
}

TEST(ConvS8, F32OutEqualsDequantizedDirectConvolution) {
  std::mt19937 rng(12);
  for (const ConvCase& c : kCases) {
    const int zp = 9;
    const Problem p = make_problem(c, zp, rng);
    const Conv2dShape& s = p.s;
    const std::vector<int32_t> acc = conv_naive_acc(s, p.x, zp, p.w, p.bias);
    const int pixels = s.out_h * s.out_w;
    for (Isa isa : test::isas_under_test(&IsaTables::gemm_s8)) {
      const GemmS8Kernels& v = test::table_of(isa, &IsaTables::gemm_s8);
      std::unique_ptr<uint8_t, FreeDeleter> packed(
          static_cast<uint8_t*>(std::aligned_alloc(kGemmS8PackedAlign, v.packed_size(s.out_c, s.patch_size()))));
      v.pack(s.out_c, s.patch_size(), p.w.data(), static_cast<size_t>(s.patch_size()), p.bias.data(), zp, packed.get());
      const ConvS8 conv{s, &v, packed.get(), static_cast<int8_t>(zp)};
      const int tile = 5;
      std::vector<int8_t> scratch(conv_s8_scratch_bytes(s, tile));
      std::vector<float> y(static_cast<size_t>(pixels) * s.out_c, NAN);
      GemmS8OutF32 o;
      o.c = y.data();
      o.ldc = static_cast<size_t>(s.out_c);
      o.w_scale = p.w_scale.data();
      o.a_scale = 0.02f;
      o.bias = p.fbias.data();
      o.relu = true;
      for (int p0 = 0; p0 < pixels; p0 += tile) {
        conv_s8_f32out(conv, p.x.data(), o, p0, std::min(tile, pixels - p0), scratch.data());
      }
      for (size_t i = 0; i < y.size(); ++i) {
        const size_t n = i % s.out_c;
        const float want = ref::dequantize_f32(acc[i], 0.02f, p.w_scale[n], p.fbias[n], false, 0.0f, true);
        // The gemm_s8 contract: f32 outputs within 2 ulp of the reference rule.
        ASSERT_LE(test::ulp_distance(y[i], want), 2) << y[i] << " vs " << want << " " << c.name << " " << isa_name(isa) << " at " << i;
      }
    }
  }
}

// im2col against its definition: the stem on an image too narrow for any kernel row to be inside
// (every pixel tap by tap) and a wider one (the kernel-row loop for short runs), a 3x3 with 64
// channels (192-byte kernel rows: the pixel-by-pixel loop), a dilated one (always tap by tap); the
// pixels in ragged ranges that start mid-row, as tiles do.
TEST(ConvS8, Im2colPadsWithTheZeroPointAndKeepsTheRowGap) {
  const ConvCase cases[] = {
      {"stem_narrow", 5, 4, 3, 1, 7, 2, 3, 1},
      {"stem_wide", 9, 23, 3, 1, 7, 2, 3, 1},
      {"3x3_c64", 4, 9, 64, 1, 3, 1, 1, 1},
      {"3x3_dilated", 6, 7, 8, 1, 3, 1, 2, 2},
  };
  for (const ConvCase& c : cases) {
    const Conv2dShape s = shape_of(c);
    std::vector<int8_t> x(static_cast<size_t>(c.h) * c.w * c.cin);
    for (size_t i = 0; i < x.size(); ++i) x[i] = static_cast<int8_t>(i * 7 + 1);
    const size_t ld = static_cast<size_t>(s.patch_size()) + 3;
    const int pixels = s.out_h * s.out_w;
    for (int range : {pixels, 5}) {
      std::vector<int8_t> patches(pixels * ld, 99);
      for (int p0 = 0; p0 < pixels; p0 += range) {
        im2col_nhwc_s8(s, x.data(), -17, p0, std::min(range, pixels - p0), patches.data() + p0 * ld, ld);
      }
      for (int pix = 0; pix < pixels; ++pix) {
        const int oy = pix / s.out_w, ox = pix % s.out_w;
        for (int ky = 0; ky < s.kernel_h; ++ky)
          for (int kx = 0; kx < s.kernel_w; ++kx)
            for (int ch = 0; ch < s.in_c; ++ch) {
              const int iy = oy * s.stride - s.pad + ky * s.dilation, ix = ox * s.stride - s.pad + kx * s.dilation;
              const bool inside = iy >= 0 && iy < c.h && ix >= 0 && ix < c.w;
              const int8_t want = inside ? x[(static_cast<size_t>(iy) * c.w + ix) * s.in_c + ch] : int8_t{-17};
              ASSERT_EQ(patches[pix * ld + (ky * s.kernel_w + kx) * s.in_c + ch], want)
                  << c.name << " range " << range << " pixel " << pix << " tap " << ky << "," << kx << " channel " << ch;
            }
        for (size_t g = s.patch_size(); g < ld; ++g) ASSERT_EQ(patches[pix * ld + g], 99) << c.name << ": wrote into the row gap";
      }
    }
  }
}

}  // namespace
}  // namespace act::kernels
