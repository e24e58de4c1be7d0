#include "weights/import/safetensors.h"

#include <algorithm>
#include <set>
#include <utility>

#include <nlohmann/json.hpp>

#include "actengine/status.h"
#include "weights/blob/file_util.h"
#include "weights/blob/tensor_header.h"

namespace act {

namespace {

using detail::fail_corrupt;
// The same bound as the reference implementation.
constexpr uint64_t kMaxHeaderSize = detail::kMaxJsonHeaderSize;

std::string range_string(uint64_t begin, uint64_t end) {
  // Appending (rather than "[" + to_string(...)) avoids a GCC 12 -Wrestrict false positive.
  std::string s = "[";
  s += std::to_string(begin);
  s += ", ";
  s += std::to_string(end);
  s += "]";
  return s;
}

struct Range {
  uint64_t begin;
  uint64_t end;
  const std::string* name;
};

// Validates one tensor entry of the header and returns its tensor (data pointer not yet set) and range.
SafetensorsTensor parse_entry(const std::string& path, const std::string& name, const nlohmann::json& entry,
                              uint64_t data_size, Range* range) {
  const std::string where = "tensor '" + name + "': ";
  if (!entry.is_object()) fail_corrupt(path, where + "entry must be an object, got " + entry.type_name());

  SafetensorsTensor t;
  t.name = name;
  detail::TensorEntryType type = detail::parse_tensor_entry_type(path, where, entry);
  t.dtype = type.dtype;
  t.shape = std::move(type.shape);
  const uint64_t expected_bytes = type.nbytes;

  const auto offsets_it = entry.find("data_offsets");
  if (offsets_it == entry.end()) fail_corrupt(path, where + "missing 'data_offsets'");
  uint64_t begin = 0;
  uint64_t end = 0;
  if (!offsets_it->is_array() || offsets_it->size() != 2 || !detail::json_to_u64((*offsets_it)[0], &begin) ||
      !detail::json_to_u64((*offsets_it)[1], &end)) {
    fail_corrupt(path, where + "'data_offsets' must be an array of 2 non-negative integers");
  }
  if (begin > end) fail_corrupt(path, where + "data_offsets " + range_string(begin, end) + " are reversed");
  if (end > data_size) {
    fail_corrupt(path, where + "data_offsets " + range_string(begin, end) + " are out of bounds of the data area of " +
                      std::to_string(data_size) + " bytes (file truncated?)");
  }
  if (end - begin != expected_bytes) {
    fail_corrupt(path, where + "shape " + shape_string(t.shape) + " with dtype " + dtype_name(t.dtype) + " needs " +
                      std::to_string(expected_bytes) + " bytes, data_offsets " + range_string(begin, end) +
                      " hold " + std::to_string(end - begin));
  }
  t.nbytes = static_cast<size_t>(end - begin);
  *range = {begin, end, nullptr};
  return t;
}

}  // namespace

std::vector<float> SafetensorsTensor::to_f32() const {
  if (dtype != DType::kF32 && dtype != DType::kF16 && dtype != DType::kBF16) {
    fail(StatusCode::kInvalidArgument,
         "tensor '" + name + "' has dtype " + dtype_name(dtype) + ", cannot convert to F32");
  }
  const uint64_t count = elements();
  // Guards hand-built tensors; tensors from open() always pass.
  if (count > nbytes / dtype_size(dtype) || count * dtype_size(dtype) != nbytes) {
    fail(StatusCode::kInvalidArgument, "tensor '" + name + "': shape " + shape_string(shape) + " does not match " +
                                            std::to_string(nbytes) + " bytes");
  }
  std::vector<float> out(static_cast<size_t>(count));
  convert_to_f32(dtype, data, out.size(), out.data());
  return out;
}

SafetensorsFile SafetensorsFile::open(const std::string& path) {
  SafetensorsFile f;
  f.mapping_ = FileMapping::open(path);
  f.origin_ = path;
  const uint8_t* base = f.mapping_.data();
  const size_t size = f.mapping_.size();

  if (size == 0) fail_corrupt(path, "file is empty, not a safetensors file");
  if (size < 8) {
    fail_corrupt(path, "file has " + std::to_string(size) + " bytes, too short for the 8-byte header length");
  }
  const uint64_t header_size = detail::read_le64(base);
  if (header_size > kMaxHeaderSize) {
    fail_corrupt(path, "header length " + std::to_string(header_size) + " exceeds the limit of " +
                      std::to_string(kMaxHeaderSize) + " bytes");
  }
  if (header_size > size - 8) {
    fail_corrupt(path, "header length " + std::to_string(header_size) + " exceeds file size " + std::to_string(size));
  }

  const nlohmann::json header = detail::parse_json_object_header(path, base + 8, static_cast<size_t>(header_size));

  const uint8_t* data_area = base + 8 + header_size;
  const uint64_t data_size = size - 8 - header_size;
  std::vector<Range> ranges;
  ranges.reserve(header.size());
  for (const auto& [key, value] : header.items()) {
    if (key == "__metadata__") {
      if (!value.is_object()) {
        fail_corrupt(path, std::string("__metadata__ must be an object of strings, got ") + value.type_name());
      }
      for (const auto& [mkey, mvalue] : value.items()) {
        if (!mvalue.is_string()) {
          fail_corrupt(path, "__metadata__ value of '" + mkey + "' must be a string, got " + mvalue.type_name());
        }
        f.metadata_.emplace(mkey, mvalue.get<std::string>());
      }
      continue;
    }
    if (key.empty()) fail_corrupt(path, "tensor with an empty name");
    Range range{};
    SafetensorsTensor t = parse_entry(path, key, value, data_size, &range);
    t.data = data_area + range.begin;
    auto [it, inserted] = f.index_.emplace(key, std::move(t));
    (void)inserted;  // keys of a JSON object are unique (parse_json_header rejects duplicates)
    range.name = &it->first;
    ranges.push_back(range);
  }

  // Empty tensors occupy no bytes and cannot overlap anything.
  std::sort(ranges.begin(), ranges.end(), [](const Range& a, const Range& b) {
    return a.begin != b.begin ? a.begin < b.begin : a.end < b.end;
  });
  const Range* furthest = nullptr;
  for (const Range& r : ranges) {
    if (r.begin == r.end) continue;
    if (furthest != nullptr && r.begin < furthest->end) {
      fail_corrupt(path, "tensors '" + *furthest->name + "' " + range_string(furthest->begin, furthest->end) + " and '" +
                        *r.name + "' " + range_string(r.begin, r.end) + " overlap");
    }
    if (furthest == nullptr || r.end > furthest->end) furthest = &r;
  }
  return f;
}

const SafetensorsTensor* TensorSet::find(const std::string& name) const {
  const auto it = index_.find(name);
  return it == index_.end() ? nullptr : &it->second;
}

const SafetensorsTensor& TensorSet::get(const std::string& name) const {
  const SafetensorsTensor* t = find(name);
  if (t == nullptr) fail(StatusCode::kNotFound, "tensor '" + name + "' not found in '" + origin_ + "'");
  return *t;
}

std::vector<std::string> TensorSet::names() const {
  std::vector<std::string> out;
  out.reserve(index_.size());
  for (const auto& [name, t] : index_) out.push_back(name);
  return out;
}

void OwnedTensorSet::add_f32(const std::string& name, std::vector<int64_t> shape, std::vector<float> values) {
  if (index_.count(name)) fail(StatusCode::kInvalidArgument, origin_ + ": duplicate tensor '" + name + "'");
  if (shape_elements(shape) != values.size()) {
    fail(StatusCode::kInvalidArgument, origin_ + ": tensor '" + name + "' has " + std::to_string(values.size()) +
         " values for shape " + shape_string(shape));
  }
  std::vector<float>& stored = storage_[name] = std::move(values);
  SafetensorsTensor t;
  t.name = name;
  t.dtype = DType::kF32;
  t.shape = std::move(shape);
  t.data = reinterpret_cast<const uint8_t*>(stored.data());
  t.nbytes = stored.size() * sizeof(float);
  index_.emplace(name, std::move(t));
}

void OwnedTensorSet::add(const std::string& name, DType dtype, std::vector<int64_t> shape, std::vector<uint8_t> bytes) {
  if (index_.count(name)) fail(StatusCode::kInvalidArgument, origin_ + ": duplicate tensor '" + name + "'");
  uint64_t expected = 0;
  if (!detail::checked_mul(shape_elements(shape), dtype_size(dtype), &expected) || expected != bytes.size()) {
    fail(StatusCode::kInvalidArgument, origin_ + ": tensor '" + name + "' has " + std::to_string(bytes.size()) +
         " bytes for " + dtype_name(dtype) + " shape " + shape_string(shape));
  }
  std::vector<uint8_t>& stored = byte_storage_[name] = std::move(bytes);
  SafetensorsTensor t;
  t.name = name;
  t.dtype = dtype;
  t.shape = std::move(shape);
  t.data = stored.data();
  t.nbytes = stored.size();
  index_.emplace(name, std::move(t));
}

void OwnedTensorSet::rename(const std::function<std::string(const std::string&)>& new_name) {
  // Moving a vector keeps its buffer, so the views stay valid.
  std::map<std::string, SafetensorsTensor> index;
  std::map<std::string, std::vector<float>> storage;
  std::map<std::string, std::vector<uint8_t>> byte_storage;
  for (auto& [old_name, t] : index_) {
    std::string name = new_name(old_name);
    if (index.count(name)) {
      fail(StatusCode::kInvalidArgument, origin_ + ": renaming '" + old_name + "' to '" + name + "' collides with another tensor");
    }
    if (auto it = storage_.find(old_name); it != storage_.end()) storage[name] = std::move(it->second);
    if (auto it = byte_storage_.find(old_name); it != byte_storage_.end()) byte_storage[name] = std::move(it->second);
    t.name = name;
    index.emplace(std::move(name), std::move(t));
  }
  index_ = std::move(index);
  storage_ = std::move(storage);
  byte_storage_ = std::move(byte_storage);
}

void write_safetensors(const std::string& path, const std::vector<SafetensorsWriteTensor>& tensors,
                       const std::map<std::string, std::string>& metadata) {
  // ordered_json keeps the header in data order, which makes files easy to inspect.
  nlohmann::ordered_json header = nlohmann::ordered_json::object();
  if (!metadata.empty()) {
    nlohmann::ordered_json m = nlohmann::ordered_json::object();
    for (const auto& [k, v] : metadata) m[k] = v;
    header["__metadata__"] = std::move(m);
  }
  std::set<std::string> seen;
  uint64_t offset = 0;
  for (const SafetensorsWriteTensor& t : tensors) {
    const std::string where = "write_safetensors '" + path + "': tensor '" + t.name + "': ";
    if (t.name.empty()) fail(StatusCode::kInvalidArgument, where + "empty name");
    if (t.name == "__metadata__") fail(StatusCode::kInvalidArgument, where + "name is reserved");
    if (!seen.insert(t.name).second) fail(StatusCode::kInvalidArgument, where + "duplicate name");
    uint64_t elements = 0;
    try {
      elements = shape_elements(t.shape);
    } catch (const Error& e) {
      fail(StatusCode::kInvalidArgument, where + e.what());
    }
    uint64_t expected = 0;
    if (!detail::checked_mul(elements, dtype_size(t.dtype), &expected) || expected != t.nbytes) {
      fail(StatusCode::kInvalidArgument, where + "shape " + shape_string(t.shape) + " with dtype " +
                                              dtype_name(t.dtype) + " does not match " + std::to_string(t.nbytes) +
                                             " bytes");
    }
    if (t.data == nullptr && t.nbytes != 0) fail(StatusCode::kInvalidArgument, where + "data is null");
    nlohmann::ordered_json entry = nlohmann::ordered_json::object();
    entry["dtype"] = dtype_name(t.dtype);
    entry["shape"] = t.shape;
    entry["data_offsets"] = nlohmann::ordered_json::array({offset, offset + t.nbytes});
    header[t.name] = std::move(entry);
    offset += t.nbytes;
  }

  std::string text = detail::dump_json(header, "the safetensors header of '" + path + "'");
  // Pad with spaces so the data area starts 8-byte aligned (JSON allows trailing whitespace).
  text.append((8 - text.size() % 8) % 8, ' ');
  if (text.size() > kMaxHeaderSize) {
    fail(StatusCode::kInvalidArgument, "write_safetensors '" + path + "': header of " + std::to_string(text.size()) +
                                            " bytes exceeds the limit of " + std::to_string(kMaxHeaderSize));
  }

  detail::AtomicFileWriter out(path);
  uint8_t len[8];
  detail::put_le64(text.size(), len);
  out.write(len, sizeof len);
  out.write(text.data(), text.size());
  for (const SafetensorsWriteTensor& t : tensors) {
    if (t.nbytes != 0) out.write(t.data, t.nbytes);
  }
  out.commit();
}

}  // namespace act
