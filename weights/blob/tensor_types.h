// Element types and tensor descriptions shared by the safetensors reader and the .actb blob.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace act {

enum class DType : uint8_t { kF32, kF16, kBF16, kI8, kU8, kI32, kF64, kI64 };

/// Bytes per element.
size_t dtype_size(DType dtype);
/// Name as used by safetensors ("F32", "F16", "BF16", "I8", "U8", "I32", "F64", "I64").
const char* dtype_name(DType dtype);
/// Parses a safetensors dtype name; returns false for names this project does not handle.
bool parse_dtype(std::string_view name, DType* dtype);

/// Number of elements of a shape; throws act::Error(kInvalidArgument) on negative dims or overflow.
uint64_t shape_elements(const std::vector<int64_t>& shape);
/// "[2, 3, 4]"
std::string shape_string(const std::vector<int64_t>& shape);

/// Converts `count` elements of `src` (F32, F16 or BF16) to float32. Throws for other dtypes.
void convert_to_f32(DType dtype, const void* src, size_t count, float* dst);

}  // namespace act
