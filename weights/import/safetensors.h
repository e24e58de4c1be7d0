// Reader for the safetensors format (8-byte LE header length, JSON header, raw LE C-order data).
// The file is mmapped; tensors are views into it. Everything in the header is validated at open:
// header length within the file, JSON well formed, dtype known, shape non-negative, offsets inside the
// data area, ordered, non-overlapping, and end - begin == elements * dtype size.
#pragma once

#include <functional>
#include <map>
#include <string>
#include <vector>

#include "weights/blob/file_mapping.h"
#include "weights/blob/tensor_types.h"

namespace act {

struct SafetensorsTensor {
  std::string name;
  DType dtype = DType::kF32;
  std::vector<int64_t> shape;
  const uint8_t* data = nullptr;  ///< points into the mapping
  size_t nbytes = 0;

  uint64_t elements() const { return shape_elements(shape); }
  /// The tensor converted to float32 (from F32, F16 or BF16); throws kInvalidArgument otherwise.
  std::vector<float> to_f32() const;
};

/// Named tensor views, sorted by name: a safetensors file, or tensors built in memory.
class TensorSet {
 public:
  /// Where the tensors come from, for error messages (a file path, or a description).
  const std::string& origin() const { return origin_; }
  bool contains(const std::string& name) const { return index_.count(name) != 0; }
  /// Throws kNotFound naming the tensor and the origin.
  const SafetensorsTensor& get(const std::string& name) const;
  const SafetensorsTensor* find(const std::string& name) const;
  /// Tensor names in sorted order.
  std::vector<std::string> names() const;

 protected:
  std::string origin_;
  std::map<std::string, SafetensorsTensor> index_;
};

class SafetensorsFile : public TensorSet {
 public:
  /// Opens and validates `path`. Throws act::Error (kNotFound, kIoError, kDataLoss with the file name
  /// and what is wrong, e.g. "header length 9999 exceeds file size 100").
  static SafetensorsFile open(const std::string& path);

  const std::string& path() const { return mapping_.path(); }
  const std::map<std::string, std::string>& metadata() const { return metadata_; }

 private:
  FileMapping mapping_;
  std::map<std::string, std::string> metadata_;
};

/// Tensors owned in memory (e.g. a synthetic model's state dict, or one read from a PyTorch .pth).
/// Movable (the storage moves with its buffers, so the views stay valid) but not copyable.
class OwnedTensorSet : public TensorSet {
 public:
  explicit OwnedTensorSet(std::string origin) { origin_ = std::move(origin); }
  OwnedTensorSet(const OwnedTensorSet&) = delete;
  OwnedTensorSet& operator=(const OwnedTensorSet&) = delete;
  OwnedTensorSet(OwnedTensorSet&&) = default;
  OwnedTensorSet& operator=(OwnedTensorSet&&) = default;
  /// Throws kInvalidArgument on a duplicate name or a size that does not match the shape.
  void add_f32(const std::string& name, std::vector<int64_t> shape, std::vector<float> values);
  /// Any dtype: `bytes` holds the elements, little-endian, C order. Same checks as add_f32.
  void add(const std::string& name, DType dtype, std::vector<int64_t> shape, std::vector<uint8_t> bytes);
  /// Renames every tensor to new_name(old name); throws kInvalidArgument if two names collide.
  void rename(const std::function<std::string(const std::string&)>& new_name);

 private:
  std::map<std::string, std::vector<float>> storage_;
  std::map<std::string, std::vector<uint8_t>> byte_storage_;
};

/// A tensor to write (used by tests and by act_eval --output).
struct SafetensorsWriteTensor {
  std::string name;
  DType dtype = DType::kF32;
  std::vector<int64_t> shape;
  const void* data = nullptr;
  size_t nbytes = 0;
};

/// Writes a safetensors file atomically (temporary file in the same folder, then rename).
/// Throws act::Error on I/O failure or inconsistent sizes; leaves no partial file behind.
void write_safetensors(const std::string& path, const std::vector<SafetensorsWriteTensor>& tensors,
                       const std::map<std::string, std::string>& metadata = {});

}  // namespace act
