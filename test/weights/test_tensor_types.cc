#include "weights/blob/tensor_types.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "actengine/status.h"
#include "support/file_test_util.h"

namespace act {
namespace {

using test::throws_error;

constexpr DType kAllDtypes[] = {DType::kF32, DType::kF16, DType::kBF16, DType::kI8,
                                DType::kU8,  DType::kI32, DType::kF64,  DType::kI64};

TEST(TensorTypes, DtypeSizes) {
  EXPECT_EQ(dtype_size(DType::kF32), 4u);
  EXPECT_EQ(dtype_size(DType::kF16), 2u);
  EXPECT_EQ(dtype_size(DType::kBF16), 2u);
  EXPECT_EQ(dtype_size(DType::kI8), 1u);
  EXPECT_EQ(dtype_size(DType::kU8), 1u);
  EXPECT_EQ(dtype_size(DType::kI32), 4u);
  EXPECT_EQ(dtype_size(DType::kF64), 8u);
  EXPECT_EQ(dtype_size(DType::kI64), 8u);
}

TEST(TensorTypes, DtypeNamesRoundTrip) {
  EXPECT_STREQ(dtype_name(DType::kF32), "F32");
  EXPECT_STREQ(dtype_name(DType::kF16), "F16");
  EXPECT_STREQ(dtype_name(DType::kBF16), "BF16");
  EXPECT_STREQ(dtype_name(DType::kI8), "I8");
  EXPECT_STREQ(dtype_name(DType::kU8), "U8");
  EXPECT_STREQ(dtype_name(DType::kI32), "I32");
  EXPECT_STREQ(dtype_name(DType::kF64), "F64");
  EXPECT_STREQ(dtype_name(DType::kI64), "I64");
  for (DType d : kAllDtypes) {
    DType parsed = DType::kF32;
    EXPECT_TRUE(parse_dtype(dtype_name(d), &parsed)) << dtype_name(d);
    EXPECT_EQ(parsed, d);
  }
}

TEST(TensorTypes, ParseDtypeRejectsUnknownNames) {
  for (const char* name : {"", "f32", "F8_E4M3", "BOOL", "U16", "I16", "F32 ", "FLOAT", "BF"}) {
    DType d = DType::kI64;
    EXPECT_FALSE(parse_dtype(name, &d)) << "'" << name << "'";
    EXPECT_EQ(d, DType::kI64) << "output must be untouched on failure";
  }
  // A string_view that is a prefix of a longer buffer must not match by accident.
  const std::string longer = "F32X";
  EXPECT_TRUE(parse_dtype(std::string_view(longer).substr(0, 3), nullptr));
  EXPECT_FALSE(parse_dtype(longer, nullptr));
}

TEST(TensorTypes, ShapeElements) {
  EXPECT_EQ(shape_elements({}), 1u);  // a scalar
  EXPECT_EQ(shape_elements({7}), 7u);
  EXPECT_EQ(shape_elements({2, 3, 4}), 24u);
  EXPECT_EQ(shape_elements({0}), 0u);
  EXPECT_EQ(shape_elements({5, 0, 3}), 0u);
  // Empty tensors have 0 elements even when the other dims would overflow when multiplied.
  constexpr int64_t kMax = std::numeric_limits<int64_t>::max();
  EXPECT_EQ(shape_elements({kMax, kMax, 0}), 0u);
  EXPECT_EQ(shape_elements({kMax, 2}), static_cast<uint64_t>(kMax) * 2);
  EXPECT_EQ(shape_elements({int64_t{1} << 32, int64_t{1} << 31}), uint64_t{1} << 63);
}

TEST(TensorTypes, ShapeElementsRejectsNegativeDims) {
  EXPECT_TRUE(throws_error([] { shape_elements({2, -1, 3}); }, StatusCode::kInvalidArgument,
                           {"negative dimension -1", "[2, -1, 3]"}));
  // A negative dim is reported even next to a zero dim.
  EXPECT_TRUE(throws_error([] { shape_elements({0, -5}); }, StatusCode::kInvalidArgument, {"negative"}));
  EXPECT_TRUE(throws_error([] { shape_elements({std::numeric_limits<int64_t>::min()}); },
                           StatusCode::kInvalidArgument, {"negative"}));
}

TEST(TensorTypes, ShapeElementsRejectsOverflow) {
  EXPECT_TRUE(throws_error([] { shape_elements({int64_t{1} << 32, int64_t{1} << 32}); },
                           StatusCode::kInvalidArgument, {"overflows", "[4294967296, 4294967296]"}));
  EXPECT_TRUE(throws_error([] { shape_elements({std::numeric_limits<int64_t>::max(), 3}); },
                           StatusCode::kInvalidArgument, {"overflows"}));
  EXPECT_TRUE(throws_error([] { shape_elements({1 << 16, 1 << 16, 1 << 16, 1 << 16, 2}); },
                           StatusCode::kInvalidArgument, {"overflows"}));
}

TEST(TensorTypes, ShapeString) {
  EXPECT_EQ(shape_string({}), "[]");
  EXPECT_EQ(shape_string({5}), "[5]");
  EXPECT_EQ(shape_string({2, 3, 4}), "[2, 3, 4]");
  EXPECT_EQ(shape_string({-1, 0}), "[-1, 0]");
}

uint32_t bits_of(float f) { return std::bit_cast<uint32_t>(f); }

float f16(uint16_t h) {
  float out = 0;
  convert_to_f32(DType::kF16, &h, 1, &out);
  return out;
}

float bf16(uint16_t b) {
  float out = 0;
  convert_to_f32(DType::kBF16, &b, 1, &out);
  return out;
}

TEST(TensorTypes, F16KnownValues) {
  EXPECT_EQ(bits_of(f16(0x0000)), 0x00000000u);  // +0
  EXPECT_EQ(bits_of(f16(0x8000)), 0x80000000u);  // -0 keeps its sign
  EXPECT_EQ(f16(0x3C00), 1.0f);
  EXPECT_EQ(f16(0xBC00), -1.0f);
  EXPECT_EQ(f16(0x4000), 2.0f);
  EXPECT_EQ(f16(0xC000), -2.0f);
  EXPECT_EQ(f16(0x3800), 0.5f);
  EXPECT_EQ(f16(0x3555), 0.333251953125f);
  EXPECT_EQ(f16(0x4248), 3.140625f);
  EXPECT_EQ(f16(0x7BFF), 65504.0f);   // largest finite half
  EXPECT_EQ(f16(0xFBFF), -65504.0f);
  EXPECT_EQ(f16(0x3BFF), 0.99951171875f);  // largest below 1
  EXPECT_EQ(f16(0x3C01), 1.0009765625f);   // smallest above 1
  EXPECT_EQ(f16(0x0400), std::ldexp(1.0f, -14));  // smallest normal
}

TEST(TensorTypes, F16Subnormals) {
  EXPECT_EQ(f16(0x0001), std::ldexp(1.0f, -24));  // smallest subnormal
  EXPECT_EQ(bits_of(f16(0x0001)), 0x33800000u);
  EXPECT_EQ(f16(0x8001), -std::ldexp(1.0f, -24));
  EXPECT_EQ(f16(0x0002), std::ldexp(1.0f, -23));
  EXPECT_EQ(f16(0x0200), std::ldexp(1.0f, -15));
  EXPECT_EQ(f16(0x03FF), 1023.0f * std::ldexp(1.0f, -24));  // largest subnormal
  EXPECT_EQ(bits_of(f16(0x03FF)), 0x387FC000u);
  EXPECT_EQ(f16(0x0155), 341.0f * std::ldexp(1.0f, -24));
}

TEST(TensorTypes, F16InfAndNan) {
  EXPECT_EQ(bits_of(f16(0x7C00)), 0x7F800000u);
  EXPECT_TRUE(std::isinf(f16(0x7C00)) && f16(0x7C00) > 0);
  EXPECT_EQ(bits_of(f16(0xFC00)), 0xFF800000u);
  EXPECT_TRUE(std::isinf(f16(0xFC00)) && f16(0xFC00) < 0);
  EXPECT_TRUE(std::isnan(f16(0x7E00)));
  EXPECT_EQ(bits_of(f16(0x7E00)), 0x7FC00000u);  // canonical quiet NaN
  EXPECT_EQ(bits_of(f16(0xFE00)), 0xFFC00000u);
  // Signalling NaN and payloads survive: the mantissa moves up by 13 bits, never becomes an infinity.
  EXPECT_TRUE(std::isnan(f16(0x7C01)));
  EXPECT_EQ(bits_of(f16(0x7C01)), 0x7F802000u);
  EXPECT_EQ(bits_of(f16(0x7FFF)), 0x7FFFE000u);
}

// Every one of the 65536 half values against an independent, arithmetic definition of binary16.
TEST(TensorTypes, F16ExhaustiveAgainstReference) {
  std::vector<uint16_t> all(65536);
  for (uint32_t i = 0; i < 65536; ++i) all[i] = static_cast<uint16_t>(i);
  std::vector<float> out(all.size());
  convert_to_f32(DType::kF16, all.data(), all.size(), out.data());
  int mismatches = 0;
  for (uint32_t h = 0; h < 65536; ++h) {
    const int sign = (h & 0x8000) ? -1 : 1;
    const int exp = static_cast<int>((h >> 10) & 0x1f);
    const int mant = static_cast<int>(h & 0x3ff);
    const float got = out[h];
    bool ok;
    if (exp == 31) {
      ok = mant == 0 ? (std::isinf(got) && (got < 0) == (sign < 0)) : std::isnan(got);
    } else {
      const double mag = exp == 0 ? std::ldexp(mant, -24) : std::ldexp(1024 + mant, exp - 25);
      const double want = sign * mag;
      ok = static_cast<double>(got) == want && std::signbit(got) == (sign < 0);
    }
    if (!ok && ++mismatches <= 5) ADD_FAILURE() << "half 0x" << std::hex << h << " -> " << got;
  }
  EXPECT_EQ(mismatches, 0);
}

TEST(TensorTypes, Bf16KnownValues) {
  EXPECT_EQ(bf16(0x3F80), 1.0f);
  EXPECT_EQ(bf16(0xBF80), -1.0f);
  EXPECT_EQ(bf16(0x4000), 2.0f);
  EXPECT_EQ(bf16(0xC000), -2.0f);
  EXPECT_EQ(bf16(0x3F00), 0.5f);
  EXPECT_EQ(bf16(0x4049), 3.140625f);
  EXPECT_EQ(bf16(0x3EAB), 0.333984375f);
  EXPECT_EQ(bits_of(bf16(0x0000)), 0x00000000u);
  EXPECT_EQ(bits_of(bf16(0x8000)), 0x80000000u);
  EXPECT_EQ(bf16(0x7F7F), 3.3895313892515355e38f);  // largest finite
  EXPECT_EQ(bf16(0x0080), std::numeric_limits<float>::min());  // smallest normal
  // Subnormals are float subnormals: 0x0001 is 2^-133.
  EXPECT_EQ(bf16(0x0001), std::ldexp(1.0f, -133));
  EXPECT_EQ(bits_of(bf16(0x0001)), 0x00010000u);
  EXPECT_EQ(bf16(0x007F), 127.0f * std::ldexp(1.0f, -133));
  EXPECT_EQ(bits_of(bf16(0x7F80)), 0x7F800000u);
  EXPECT_TRUE(std::isinf(bf16(0xFF80)) && bf16(0xFF80) < 0);
  EXPECT_TRUE(std::isnan(bf16(0x7FC0)));
  EXPECT_TRUE(std::isnan(bf16(0x7F81)));  // signalling NaN stays NaN
  EXPECT_EQ(bits_of(bf16(0xFFC1)), 0xFFC10000u);
}

TEST(TensorTypes, Bf16IsUpperHalfOfF32) {
  for (float f : {1.0f, -3.5f, 1e-30f, 6.02e23f, -0.0f, 0.15625f}) {
    const uint32_t b = bits_of(f);
    if ((b & 0xFFFFu) != 0) continue;  // only values exactly representable in bf16
    EXPECT_EQ(bits_of(bf16(static_cast<uint16_t>(b >> 16))), b) << f;
  }
}

TEST(TensorTypes, ConvertF32CopiesExactly) {
  const std::vector<float> src = {1.5f, -0.0f, std::numeric_limits<float>::infinity(),
                                  std::numeric_limits<float>::denorm_min(), 123456.789f};
  std::vector<float> dst(src.size(), 7.0f);
  convert_to_f32(DType::kF32, src.data(), src.size(), dst.data());
  for (size_t i = 0; i < src.size(); ++i) EXPECT_EQ(bits_of(dst[i]), bits_of(src[i])) << i;
}

TEST(TensorTypes, ConvertHandlesUnalignedSources) {
  // safetensors data offsets need not be aligned; the conversion must not assume they are.
  const uint16_t halves[3] = {0x3C00, 0xC000, 0x7BFF};
  const uint16_t bfs[3] = {0x3F80, 0xC000, 0x4049};
  const float floats[3] = {1.25f, -8.0f, 0.1f};
  std::vector<uint8_t> buf(64);
  std::vector<float> out(3);

  std::memcpy(buf.data() + 1, halves, sizeof halves);
  convert_to_f32(DType::kF16, buf.data() + 1, 3, out.data());
  EXPECT_EQ(out, (std::vector<float>{1.0f, -2.0f, 65504.0f}));

  std::memcpy(buf.data() + 3, bfs, sizeof bfs);
  convert_to_f32(DType::kBF16, buf.data() + 3, 3, out.data());
  EXPECT_EQ(out, (std::vector<float>{1.0f, -2.0f, 3.140625f}));

  std::memcpy(buf.data() + 5, floats, sizeof floats);
  convert_to_f32(DType::kF32, buf.data() + 5, 3, out.data());
  EXPECT_EQ(out, (std::vector<float>{1.25f, -8.0f, 0.1f}));
}

TEST(TensorTypes, ConvertZeroCountTouchesNothing) {
  convert_to_f32(DType::kF16, nullptr, 0, nullptr);
  convert_to_f32(DType::kF32, nullptr, 0, nullptr);
  convert_to_f32(DType::kBF16, nullptr, 0, nullptr);
}

TEST(TensorTypes, ConvertRejectsNonFloatDtypes) {
  const uint8_t src[8] = {};
  float dst[8];
  for (DType d : {DType::kI8, DType::kU8, DType::kI32, DType::kF64, DType::kI64}) {
    EXPECT_TRUE(throws_error([&] { convert_to_f32(d, src, 1, dst); }, StatusCode::kInvalidArgument,
                             {dtype_name(d), "F32"}))
        << dtype_name(d);
  }
}

}  // namespace
}  // namespace act
