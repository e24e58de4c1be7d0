// What the .actb and safetensors readers check alike: a JSON header that is one bounded object, and
// tensor entries whose "dtype" and "shape" give a byte size without overflow. Messages start with
// "'<path>': " and the error code is kDataLoss (a damaged or hostile file).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "weights/blob/tensor_types.h"

namespace act::detail {

/// The largest JSON header either reader accepts: a real one is a few hundred KB; anything near this
/// is corrupt or hostile, and parsing it would cost far more memory than the text itself.
inline constexpr uint64_t kMaxJsonHeaderSize = 100'000'000;

/// Throws act::Error(kDataLoss, "'<path>': <what>").
[[noreturn]] void fail_corrupt(const std::string& path, const std::string& what);

inline uint64_t read_le64(const uint8_t* p) {
  uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}

inline void put_le64(uint64_t v, uint8_t* p) {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}

/// parse_json_header (file_util.h), and the header must be a JSON object.
nlohmann::json parse_json_object_header(const std::string& path, const uint8_t* data, size_t size);

struct TensorEntryType {
  DType dtype = DType::kF32;
  std::vector<int64_t> shape;
  uint64_t nbytes = 0;  ///< elements x dtype size
};

/// The entry's "dtype" (a known dtype name) and "shape" (dimensions >= 0) and the bytes they imply.
/// `where` prefixes every message, e.g. "tensor 'a': ".
TensorEntryType parse_tensor_entry_type(const std::string& path, const std::string& where, const nlohmann::json& entry);

}  // namespace act::detail
