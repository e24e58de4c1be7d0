// The .actb weight blob: one file, loaded by a single mmap with no copy.
//
// Layout (all integers little-endian):
//   offset 0   char[8]  magic "ACTBLOB\0"
//          8   u32      format version (kActbFormatVersion)
//         12   u32      reserved, 0
//         16   u64      header_size: bytes of the JSON header that follows at offset 64
//         24   u64      data_offset: start of the data area (64-byte aligned, >= 64 + header_size)
//         32   u64      data_size: bytes of the data area (the file is exactly data_offset + data_size)
//         40   u64      checksum: CRC-32 (zlib) of bytes [64, data_offset + data_size), zero-extended
//         48   u8[16]   reserved, 0
//         64   JSON header: {"producer": str, "config": {...}, "tensors": [{"name", "dtype", "shape",
//                            "offset", "nbytes", "quant": {...}?}, ...]}   (offset is relative to data_offset)
//   data_offset  tensor data; every tensor starts at a 64-byte aligned offset.
//
// Errors name the problem: wrong magic ("not an .actb file"), a newer/older format version ("format
// version 7, this build reads 1"), truncation ("file has 100 bytes, header says 4096"), checksum
// mismatch, malformed JSON, tensors out of bounds or overlapping, unknown dtypes.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "weights/blob/file_mapping.h"
#include "weights/blob/tensor_types.h"

namespace act::detail {
class AtomicFileWriter;
}

namespace act {

inline constexpr uint32_t kActbFormatVersion = 1;
inline constexpr size_t kActbAlignment = 64;

/// Quantization parameters of a tensor (empty for float tensors). Per-channel when scales.size() > 1,
/// along `axis`.
struct QuantParams {
  std::vector<float> scales;
  std::vector<int32_t> zero_points;
  int32_t axis = 0;
  bool empty() const { return scales.empty(); }
};

struct ActbTensor {
  std::string name;
  DType dtype = DType::kF32;
  std::vector<int64_t> shape;
  const uint8_t* data = nullptr;  ///< into the mapping, 64-byte aligned
  size_t nbytes = 0;
  QuantParams quant;

  uint64_t elements() const { return shape_elements(shape); }
  const float* f32() const;  ///< throws kInvalidArgument unless dtype is F32
};

class ActbWriter {
 public:
  void set_producer(std::string producer) { producer_ = std::move(producer); }
  void set_config(nlohmann::json config) { config_ = std::move(config); }
  /// Copies the data. Throws kInvalidArgument on a duplicate name or nbytes != elements * dtype size.
  void add_tensor(const std::string& name, DType dtype, std::vector<int64_t> shape, const void* data,
                  size_t nbytes, QuantParams quant = {});
  void add_f32(const std::string& name, std::vector<int64_t> shape, const std::vector<float>& values);
  /// As add_f32, but refers to `values` instead of copying them: they must stay alive and unchanged
  /// until the writer's last write. For whole models written from their own tensors (fp32_blob,
  /// int8_blob), where copying every weight was most of a conversion's time.
  void add_f32_ref(const std::string& name, std::vector<int64_t> shape, const std::vector<float>& values);
  /// Writes atomically: a temporary file next to `path`, fsync, rename. On any failure the temporary
  /// file is removed and no file appears at `path`. Returns the number of bytes written.
  size_t write(const std::string& path) const;
  /// Writes the whole blob into `file` without committing it (the caller decides whether it gets
  /// its name; the converter opens uncommitted blobs through AtomicFileWriter::readable_path).
  /// Checksum::kLater leaves the checksum field 0, for a blob that may never be kept: whoever keeps
  /// it calls seal_actb_checksum() before committing.
  enum class Checksum { kNow, kLater };
  void write_to(detail::AtomicFileWriter& file, Checksum checksum = Checksum::kNow) const;

 private:
  struct Pending {
    std::string name;
    DType dtype;
    std::vector<int64_t> shape;
    std::vector<uint8_t> copy;    // the bytes when the writer holds them
    const uint8_t* referenced;    // else the caller's (add_f32_ref)
    size_t nbytes;
    QuantParams quant;
    const uint8_t* data() const { return referenced != nullptr ? referenced : copy.data(); }
  };
  void add(const std::string& name, DType dtype, std::vector<int64_t> shape, const void* data, size_t nbytes,
           QuantParams quant, bool copy);
  std::string producer_ = "actengine";
  nlohmann::json config_ = nlohmann::json::object();
  std::vector<Pending> tensors_;
  std::map<std::string, size_t> index_;
};

/// Computes the checksum of the blob written so far into `file` (by write_to(file, Checksum::kLater))
/// and writes it into the fixed header. Throws act::Error naming the file: kInvalidArgument when no
/// blob was written, kIoError when the file cannot be read back or written.
void seal_actb_checksum(detail::AtomicFileWriter& file);

class ActbFile {
 public:
  /// Opens, validates every header field and the tensor directory, and (when verify_checksum) the
  /// checksum. `mode`: share the file's pages, or read a private copy that no later change of the
  /// file can touch (file_mapping.h). Throws act::Error with kNotFound / kIoError / kDataLoss /
  /// kUnimplemented (version).
  static ActbFile open(const std::string& path, bool verify_checksum = true,
                       FileMapping::Mode mode = FileMapping::Mode::kMap);

  const std::string& path() const { return mapping_.path(); }
  uint32_t format_version() const { return version_; }
  const std::string& producer() const { return producer_; }
  const nlohmann::json& config() const { return config_; }
  const ActbTensor* find(const std::string& name) const;
  /// Throws kNotFound naming the tensor and the file.
  const ActbTensor& get(const std::string& name) const;
  const std::vector<ActbTensor>& tensors() const { return tensors_; }
  size_t file_size() const { return mapping_.size(); }
  /// Gives `tensor`'s memory back (FileMapping::release_pages): read it no more afterwards.
  void release_pages(const ActbTensor& tensor) { mapping_.release_pages(tensor.data, tensor.nbytes); }

 private:
  FileMapping mapping_;
  uint32_t version_ = 0;
  std::string producer_;
  nlohmann::json config_;
  std::vector<ActbTensor> tensors_;
  std::map<std::string, size_t> index_;
};

}  // namespace act
