// The fuzz targets' bridge to parsers that read files: the input is written to an anonymous
// in-memory file (memfd) and handed over by its /proc path, so the fuzzed code path is exactly the
// one real files take (open, fstat, mmap).
#pragma once

#include <sys/mman.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace act::fuzz {

class InputFile {
 public:
  InputFile() : fd_(memfd_create("fuzz-input", 0)) {
    if (fd_ < 0) {
      std::perror("memfd_create");
      std::abort();
    }
    path_ = "/proc/self/fd/" + std::to_string(fd_);
  }
  InputFile(const InputFile&) = delete;
  InputFile& operator=(const InputFile&) = delete;
  ~InputFile() { close(fd_); }

  /// Replaces the file's content with `data` and returns its path.
  const std::string& write(const uint8_t* data, size_t size) {
    if (ftruncate(fd_, 0) != 0 || pwrite(fd_, data, size, 0) != static_cast<ssize_t>(size)) {
      std::perror("memfd write");
      std::abort();
    }
    return path_;
  }

 private:
  int fd_;
  std::string path_;
};

/// Reads every byte of a view the parser returned, so ASan sees any pointer outside the input.
inline uint8_t touch(const uint8_t* data, size_t size) {
  uint8_t sum = 0;
  for (size_t i = 0; i < size; ++i) sum = static_cast<uint8_t>(sum + data[i]);
  return sum;
}

}  // namespace act::fuzz
