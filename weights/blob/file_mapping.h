// A whole file in read-only memory (RAII, movable): mapped from the file, or a private copy.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace act {

class FileMapping {
 public:
  /// kMap shares the file's pages (no copy): a later write to the file shows through, and a
  /// truncation makes reading the lost pages raise SIGBUS. kPrivateCopy reads the file into memory
  /// of its own at open: what was read never changes, whatever happens to the file.
  enum class Mode { kMap, kPrivateCopy };

  FileMapping() = default;
  /// Maps `path` read-only. Throws act::Error: kNotFound if missing, kIoError if it cannot be opened
  /// or mapped or is not a regular file (a FIFO is refused at once, never waited on). An empty file
  /// maps to size() == 0, data() == nullptr.
  static FileMapping open(const std::string& path, Mode mode = Mode::kMap);
  ~FileMapping();
  FileMapping(FileMapping&& other) noexcept;
  FileMapping& operator=(FileMapping&& other) noexcept;
  FileMapping(const FileMapping&) = delete;
  FileMapping& operator=(const FileMapping&) = delete;

  /// Gives the whole pages inside [begin, begin + bytes) of the mapping back to the system: a mapped
  /// file's pages are read from the file again if touched, a private copy's then read as zeros.
  /// For data the caller keeps in another form (a layer's packed weights).
  void release_pages(const uint8_t* begin, size_t bytes);

  const uint8_t* data() const { return data_; }
  size_t size() const { return size_; }
  const std::string& path() const { return path_; }

 private:
  const uint8_t* data_ = nullptr;
  size_t size_ = 0;
  std::string path_;
};

}  // namespace act
