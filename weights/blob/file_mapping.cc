#include "weights/blob/file_mapping.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <limits>
#include <system_error>
#include <utility>

#include "actengine/status.h"

namespace act {

namespace {

// std::error_code gives strerror text without strerror()'s shared static buffer.
std::string errno_text(int err) { return std::error_code(err, std::generic_category()).message(); }

// Closes the descriptor on every path out of open().
class FdGuard {
 public:
  explicit FdGuard(int fd) : fd_(fd) {}
  ~FdGuard() { ::close(fd_); }
  FdGuard(const FdGuard&) = delete;
  FdGuard& operator=(const FdGuard&) = delete;
  int get() const { return fd_; }

 private:
  int fd_;
};

const char* file_kind(mode_t mode) {
  if (S_ISDIR(mode)) return "a folder";
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISSOCK(mode)) return "a socket";
  if (S_ISCHR(mode) || S_ISBLK(mode)) return "a device";
  return "not a plain file";
}

// Reads `size` bytes of the file into anonymous memory (page-aligned, read-only afterwards), so that
// it is released with munmap like a mapping. A file that shrinks or grows meanwhile is an error.
const uint8_t* read_private_copy(int fd, const std::string& path, size_t size) {
  void* p = ::mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) {
    fail(StatusCode::kIoError, "cannot allocate " + std::to_string(size) + " bytes to read '" + path + "': " +
                                    errno_text(errno));
  }
  auto* bytes = static_cast<uint8_t*>(p);
  size_t done = 0;
  while (done < size) {
    const ssize_t n = ::pread(fd, bytes + done, std::min<size_t>(size - done, size_t{1} << 30), static_cast<off_t>(done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int err = n < 0 ? errno : 0;
      ::munmap(p, size);
      fail(StatusCode::kIoError, "cannot read '" + path + "': " +
                                     (err != 0 ? errno_text(err) : "the file became shorter while it was read"));
    }
    done += static_cast<size_t>(n);
  }
  char extra = 0;
  if (::pread(fd, &extra, 1, static_cast<off_t>(size)) > 0) {
    ::munmap(p, size);
    fail(StatusCode::kIoError, "cannot read '" + path + "': the file grew while it was read");
  }
  ::mprotect(p, size, PROT_READ);
  return bytes;
}

}  // namespace

FileMapping FileMapping::open(const std::string& path, Mode mode) {
  int fd;
  do {
    // O_NONBLOCK: opening a FIFO for reading would otherwise wait, signals and all, for a writer
    // that may never come; a regular file ignores it.
    fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  } while (fd < 0 && errno == EINTR);
  if (fd < 0) {
    const int err = errno;
    const StatusCode code = (err == ENOENT || err == ENOTDIR) ? StatusCode::kNotFound : StatusCode::kIoError;
    fail(code, "cannot open '" + path + "': " + errno_text(err));
  }
  FdGuard guard(fd);

  struct stat st{};
  if (::fstat(fd, &st) != 0) {
    fail(StatusCode::kIoError, "cannot stat '" + path + "': " + errno_text(errno));
  }
  // Directories, FIFOs and devices open fine with O_RDONLY but cannot be mapped as weights.
  if (!S_ISREG(st.st_mode)) {
    fail(StatusCode::kIoError, std::string(mode == Mode::kMap ? "cannot map '" : "cannot read '") + path +
                                  "': not a regular file (" + file_kind(st.st_mode) + ")");
  }
  if (st.st_size < 0 || static_cast<uint64_t>(st.st_size) > std::numeric_limits<size_t>::max()) {
    fail(StatusCode::kIoError, "cannot map '" + path + "': file size " + std::to_string(st.st_size) +
                                    " does not fit in the address space");
  }

  FileMapping m;
  m.path_ = path;
  m.size_ = static_cast<size_t>(st.st_size);
  if (m.size_ == 0) return m;  // mmap rejects length 0

  if (mode == Mode::kPrivateCopy) {
    m.data_ = read_private_copy(fd, path, m.size_);
    return m;
  }
  void* p = ::mmap(nullptr, m.size_, PROT_READ, MAP_PRIVATE, fd, 0);
  if (p == MAP_FAILED) {
    fail(StatusCode::kIoError, "cannot mmap '" + path + "' (" + std::to_string(m.size_) +
                                    " bytes): " + errno_text(errno));
  }
  m.data_ = static_cast<const uint8_t*>(p);
  return m;
}

void FileMapping::release_pages(const uint8_t* begin, size_t bytes) {
  if (bytes == 0) return;
  check(begin >= data_ && bytes <= size_ - static_cast<size_t>(begin - data_), StatusCode::kInternal,
        "releasing pages outside the mapping of '" + path_ + "'");
  const auto page = static_cast<uintptr_t>(::sysconf(_SC_PAGESIZE));
  const uintptr_t first = (reinterpret_cast<uintptr_t>(begin) + page - 1) / page * page;
  const uintptr_t last = (reinterpret_cast<uintptr_t>(begin) + bytes) / page * page;
  // Advice only: pages that stay (a refusal, or a kernel without it) cost memory, never correctness.
  if (first < last) ::madvise(reinterpret_cast<void*>(first), last - first, MADV_DONTNEED);
}

FileMapping::~FileMapping() {
  if (data_ != nullptr) ::munmap(const_cast<uint8_t*>(data_), size_);
}

FileMapping::FileMapping(FileMapping&& other) noexcept
    : data_(std::exchange(other.data_, nullptr)),
      size_(std::exchange(other.size_, 0)),
      path_(std::exchange(other.path_, std::string())) {}

FileMapping& FileMapping::operator=(FileMapping&& other) noexcept {
  if (this != &other) {
    if (data_ != nullptr) ::munmap(const_cast<uint8_t*>(data_), size_);
    data_ = std::exchange(other.data_, nullptr);
    size_ = std::exchange(other.size_, 0);
    path_ = std::exchange(other.path_, std::string());
  }
  return *this;
}

}  // namespace act
