// Internal helpers shared by the safetensors and .actb code: atomic file writes, checked integer
// arithmetic, and JSON header handling that never lets an nlohmann exception escape.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <sys/types.h>  // off_t

#include <nlohmann/json.hpp>

namespace act::detail {

/// Writes a file atomically: data goes to an unnamed file (O_TMPFILE) in the same folder, and commit()
/// fsyncs it, names it "<path>.tmp.<pid>" and renames that over `path`. Until commit() nothing is
/// visible, so a crash or a kill (even SIGKILL) leaves `path` with its old content and no leftover.
/// (On a file system without O_TMPFILE the data goes to the named temporary file from the start, and
/// the destructor removes it when commit() is never reached.)
class AtomicFileWriter {
 public:
  /// Creates the unnamed file. Throws act::Error(kIoError) naming the path.
  explicit AtomicFileWriter(std::string path);
  ~AtomicFileWriter();
  AtomicFileWriter(const AtomicFileWriter&) = delete;
  AtomicFileWriter& operator=(const AtomicFileWriter&) = delete;

  void write(const void* data, size_t size);
  void write(const std::string& text) { write(text.data(), text.size()); }
  void write_zeros(size_t size);
  /// Overwrites bytes already written, at `offset` from the start (the file position stays at the end).
  void write_at(size_t offset, const void* data, size_t size);
  /// fsync, close, rename into place, then (best effort) fsync the folder so the rename is durable.
  void commit();

  size_t bytes_written() const { return written_; }
  /// The path being written (the target, not the temporary file).
  const std::string& path() const { return path_; }
  /// A path that opens the data written so far, before commit(): "/proc/self/fd/N" for the unnamed
  /// file (or the named temporary file on a file system without O_TMPFILE).
  std::string readable_path() const;

 private:
  // All `size` bytes at `offset`, or at the file position when offset < 0.
  void write_all(const void* data, size_t size, off_t offset);
  void name_unnamed_file();
  std::string describe_target() const;

  std::string path_;
  std::string temp_path_;  // empty while the file has no name
  int fd_ = -1;
  size_t written_ = 0;
  bool committed_ = false;
};

/// The whole content of a regular file (FileMapping's rules: a missing file is kNotFound; a folder,
/// FIFO or device is refused at once, never waited on).
std::string read_regular_file(const std::string& path);

/// a + b / a * b, false on uint64 overflow.
inline bool checked_add(uint64_t a, uint64_t b, uint64_t* out) { return !__builtin_add_overflow(a, b, out); }
inline bool checked_mul(uint64_t a, uint64_t b, uint64_t* out) { return !__builtin_mul_overflow(a, b, out); }

/// Deepest nesting of arrays/objects accepted in a file header (real headers use fewer than 10).
inline constexpr size_t kMaxJsonDepth = 256;

/// Parses `size` bytes of untrusted JSON (Json: nlohmann::json or nlohmann::ordered_json). Throws
/// act::Error(kDataLoss, "'<path>': <failure>: <why>") on a syntax error, a NUL byte, nesting deeper
/// than kMaxJsonDepth, or a key that appears twice in one object (nlohmann would keep the last).
template <class Json>
Json parse_untrusted_json(const std::string& path, const char* data, size_t size, const std::string& failure);
/// parse_untrusted_json of a file header ("malformed JSON header: ...").
nlohmann::json parse_json_header(const std::string& path, const uint8_t* data, size_t size);
/// A JSON file from outside, in key order (read_regular_file + parse_untrusted_json: "not valid JSON: ...").
nlohmann::ordered_json read_json_file(const std::string& path);

[[noreturn]] void throw_dump_error(const std::string& what, const char* reason);

/// Serialises `j`; converts nlohmann's errors (e.g. a string that is not valid UTF-8) into
/// act::Error(kInvalidArgument) mentioning `what`.
template <typename Json>
std::string dump_json(const Json& j, const std::string& what) {
  try {
    return j.dump();
  } catch (const nlohmann::json::exception& e) {
    throw_dump_error(what, e.what());
  }
}

/// JSON integer (signed or unsigned storage) -> int64 / uint64; false for non-integers or out of range.
/// Floats are rejected even when integral (2.0): the writers never produce them.
bool json_to_i64(const nlohmann::json& j, int64_t* out);
bool json_to_u64(const nlohmann::json& j, uint64_t* out);
/// JSON integer within int32's range -> int32; false otherwise (narrowing a float or a larger integer
/// is undefined or silently wraps, so outside data is range-checked here first).
bool json_to_i32(const nlohmann::json& j, int32_t* out);
/// JSON number within float's range -> float; false otherwise.
bool json_to_f32(const nlohmann::json& j, float* out);

/// A shape: array of integers >= 0. On failure returns false and sets *why.
bool json_to_shape(const nlohmann::json& j, std::vector<int64_t>* shape, std::string* why);

}  // namespace act::detail
