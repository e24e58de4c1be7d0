// A read-only memory mapping of a whole file (RAII, movable).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace act {

class FileMapping {
 public:
  FileMapping() = default;
  /// Maps `path` read-only. Throws act::Error: kNotFound if missing, kIoError if it cannot be opened
  /// or mapped or is not a regular file (a FIFO is refused at once, never waited on). An empty file
  /// maps to size() == 0, data() == nullptr.
  static FileMapping open(const std::string& path);
  ~FileMapping();
  FileMapping(FileMapping&& other) noexcept;
  FileMapping& operator=(FileMapping&& other) noexcept;
  FileMapping(const FileMapping&) = delete;
  FileMapping& operator=(const FileMapping&) = delete;

  const uint8_t* data() const { return data_; }
  size_t size() const { return size_; }
  const std::string& path() const { return path_; }

 private:
  const uint8_t* data_ = nullptr;
  size_t size_ = 0;
  std::string path_;
};

}  // namespace act
