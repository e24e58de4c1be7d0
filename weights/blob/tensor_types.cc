#include "weights/blob/tensor_types.h"

#include <bit>
#include <cstring>
#include <limits>

#include "actengine/status.h"

namespace act {

// Tensor data in both formats is little-endian and read in place; a big-endian host would need
// byte swapping everywhere, which this project does not do.
static_assert(std::endian::native == std::endian::little, "actengine assumes a little-endian host");

size_t dtype_size(DType dtype) {
  switch (dtype) {
    case DType::kF32: return 4;
    case DType::kF16: return 2;
    case DType::kBF16: return 2;
    case DType::kI8: return 1;
    case DType::kU8: return 1;
    case DType::kI32: return 4;
    case DType::kF64: return 8;
    case DType::kI64: return 8;
  }
  fail(StatusCode::kInternal, "dtype_size: invalid DType value " + std::to_string(static_cast<int>(dtype)));
}

const char* dtype_name(DType dtype) {
  switch (dtype) {
    case DType::kF32: return "F32";
    case DType::kF16: return "F16";
    case DType::kBF16: return "BF16";
    case DType::kI8: return "I8";
    case DType::kU8: return "U8";
    case DType::kI32: return "I32";
    case DType::kF64: return "F64";
    case DType::kI64: return "I64";
  }
  return "invalid";
}

bool parse_dtype(std::string_view name, DType* dtype) {
  static constexpr DType kAll[] = {DType::kF32, DType::kF16, DType::kBF16, DType::kI8,
                                   DType::kU8,  DType::kI32, DType::kF64,  DType::kI64};
  for (DType d : kAll) {
    if (name == dtype_name(d)) {
      if (dtype != nullptr) *dtype = d;
      return true;
    }
  }
  return false;
}

uint64_t shape_elements(const std::vector<int64_t>& shape) {
  bool has_zero = false;
  for (int64_t d : shape) {
    if (d < 0) {
      fail(StatusCode::kInvalidArgument,
           "negative dimension " + std::to_string(d) + " in shape " + shape_string(shape));
    }
    has_zero = has_zero || d == 0;
  }
  // An empty tensor has 0 elements however large its other dimensions are.
  if (has_zero) return 0;
  uint64_t n = 1;
  for (int64_t d : shape) {
    const auto u = static_cast<uint64_t>(d);
    if (n > std::numeric_limits<uint64_t>::max() / u) {
      fail(StatusCode::kInvalidArgument, "element count of shape " + shape_string(shape) + " overflows");
    }
    n *= u;
  }
  return n;
}

std::string shape_string(const std::vector<int64_t>& shape) {
  std::string s = "[";
  for (size_t i = 0; i < shape.size(); ++i) {
    if (i != 0) s += ", ";
    s += std::to_string(shape[i]);
  }
  s += "]";
  return s;
}

namespace {

// IEEE binary16 -> binary32. Every half value is exactly representable as a float, so this is exact.
float half_to_float(uint16_t h) {
  const uint32_t sign = static_cast<uint32_t>(h & 0x8000u) << 16;
  uint32_t exp = (h >> 10) & 0x1fu;
  uint32_t mant = h & 0x3ffu;
  uint32_t bits = 0;
  if (exp == 0x1f) {
    // Inf or NaN; the mantissa shift keeps the NaN payload and its quiet bit.
    bits = sign | 0x7f800000u | (mant << 13);
  } else if (exp != 0) {
    bits = sign | ((exp + (127 - 15)) << 23) | (mant << 13);
  } else if (mant == 0) {
    bits = sign;  // signed zero
  } else {
    // Subnormal half: value = mant * 2^-24. Normalise so the leading 1 sits at bit 10.
    int e = 1;
    while ((mant & 0x400u) == 0) {
      mant <<= 1;
      --e;
    }
    mant &= 0x3ffu;
    exp = static_cast<uint32_t>(e + (127 - 15));
    bits = sign | (exp << 23) | (mant << 13);
  }
  return std::bit_cast<float>(bits);
}

// bfloat16 is the upper half of a float32, so widening is a shift (NaN and subnormals included).
float bf16_to_float(uint16_t b) { return std::bit_cast<float>(static_cast<uint32_t>(b) << 16); }

template <float (*Convert)(uint16_t)>
void convert_16(const void* src, size_t count, float* dst) {
  const auto* bytes = static_cast<const uint8_t*>(src);
  for (size_t i = 0; i < count; ++i) {
    uint16_t v;
    std::memcpy(&v, bytes + 2 * i, sizeof v);  // the source may be unaligned (safetensors)
    dst[i] = Convert(v);
  }
}

}  // namespace

void convert_to_f32(DType dtype, const void* src, size_t count, float* dst) {
  if (count == 0) return;
  switch (dtype) {
    case DType::kF32:
      std::memcpy(dst, src, count * sizeof(float));
      return;
    case DType::kF16:
      convert_16<half_to_float>(src, count, dst);
      return;
    case DType::kBF16:
      convert_16<bf16_to_float>(src, count, dst);
      return;
    default:
      fail(StatusCode::kInvalidArgument,
           std::string("cannot convert dtype ") + dtype_name(dtype) + " to F32 (only F32, F16, BF16)");
  }
}

}  // namespace act
