#include "weights/blob/tensor_header.h"

#include "actengine/status.h"
#include "weights/blob/file_util.h"

namespace act::detail {

void fail_corrupt(const std::string& path, const std::string& what) { fail(StatusCode::kDataLoss, "'" + path + "': " + what); }

nlohmann::json parse_json_object_header(const std::string& path, const uint8_t* data, size_t size) {
  nlohmann::json header = parse_json_header(path, data, size);
  if (!header.is_object()) fail_corrupt(path, std::string("JSON header must be an object, got ") + header.type_name());
  return header;
}

TensorEntryType parse_tensor_entry_type(const std::string& path, const std::string& where, const nlohmann::json& entry) {
  TensorEntryType t;
  const auto dtype = entry.find("dtype");
  if (dtype == entry.end()) fail_corrupt(path, where + "missing 'dtype'");
  if (!dtype->is_string()) fail_corrupt(path, where + "'dtype' must be a string, got " + dtype->type_name());
  const auto& dtype_name_text = dtype->get_ref<const std::string&>();
  if (!parse_dtype(dtype_name_text, &t.dtype)) fail_corrupt(path, where + "unknown dtype '" + dtype_name_text.substr(0, 32) + "'");

  const auto shape = entry.find("shape");
  if (shape == entry.end()) fail_corrupt(path, where + "missing 'shape'");
  std::string why;
  if (!json_to_shape(*shape, &t.shape, &why)) fail_corrupt(path, where + why);
  uint64_t elements = 0;
  try {
    elements = shape_elements(t.shape);
  } catch (const Error& e) {
    fail_corrupt(path, where + e.what());
  }
  if (!checked_mul(elements, dtype_size(t.dtype), &t.nbytes)) {
    fail_corrupt(path, where + "shape " + shape_string(t.shape) + " with dtype " + dtype_name(t.dtype) + " is too large");
  }
  return t;
}

}  // namespace act::detail
