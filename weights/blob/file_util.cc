#include "weights/blob/file_util.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <set>
#include <system_error>
#include <utility>

#include "actengine/status.h"
#include "weights/blob/file_mapping.h"

namespace act::detail {

namespace {

std::string errno_text(int err) { return std::error_code(err, std::generic_category()).message(); }

// Keeps error messages readable when untrusted input contains huge strings.
std::string clip(std::string s, size_t max_len = 300) {
  if (s.size() > max_len) {
    s.resize(max_len);
    s += "...";
  }
  return s;
}

}  // namespace

AtomicFileWriter::AtomicFileWriter(std::string path) : path_(std::move(path)) {
  std::string dir = std::filesystem::path(path_).parent_path().string();
  if (dir.empty()) dir = ".";
  // An unnamed file in the target's folder: until commit() gives it a name, a crash, a signal or
  // SIGKILL leaves nothing behind, with no handler to install.
  do {
    fd_ = ::open(dir.c_str(), O_TMPFILE | O_WRONLY | O_CLOEXEC, 0644);
  } while (fd_ < 0 && errno == EINTR);
  if (fd_ >= 0) return;
  const int tmpfile_err = errno;
  if (tmpfile_err != EOPNOTSUPP && tmpfile_err != EISDIR && tmpfile_err != EINVAL) {
    fail(StatusCode::kIoError, "cannot write '" + path_ + "': cannot create a file in '" + dir + "': " +
                                    errno_text(tmpfile_err));
  }
  // A file system without O_TMPFILE: a named temporary file, removed by the destructor. O_TRUNC
  // rather than O_EXCL: a stale one left by a crashed process with the same pid (common in
  // containers) must not block writing forever. O_NOFOLLOW: never write through a planted symlink.
  temp_path_ = path_ + ".tmp." + std::to_string(::getpid());
  do {
    fd_ = ::open(temp_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC | O_NOFOLLOW, 0644);
  } while (fd_ < 0 && errno == EINTR);
  if (fd_ < 0) {
    const int err = errno;
    fail(StatusCode::kIoError,
         "cannot write '" + path_ + "': cannot create '" + temp_path_ + "': " + errno_text(err));
  }
}

AtomicFileWriter::~AtomicFileWriter() {
  if (fd_ >= 0) ::close(fd_);
  if (!committed_ && !temp_path_.empty()) ::unlink(temp_path_.c_str());
}

std::string AtomicFileWriter::describe_target() const {
  return "'" + path_ + "'" + (temp_path_.empty() ? std::string() : " (via '" + temp_path_ + "')");
}

std::string AtomicFileWriter::readable_path() const {
  return temp_path_.empty() ? "/proc/self/fd/" + std::to_string(fd_) : temp_path_;
}

void AtomicFileWriter::write(const void* data, size_t size) {
  write_all(data, size, -1);
  written_ += size;
}

void AtomicFileWriter::write_at(size_t offset, const void* data, size_t size) {
  if (offset + size > written_) {
    fail(StatusCode::kInvalidArgument, "cannot overwrite bytes " + std::to_string(offset) + " to " +
                                           std::to_string(offset + size) + " of " + describe_target() + ": " +
                                          std::to_string(written_) + " bytes are written");
  }
  write_all(data, size, static_cast<off_t>(offset));
}

void AtomicFileWriter::write_all(const void* data, size_t size, off_t offset) {
  const auto* p = static_cast<const uint8_t*>(data);
  while (size > 0) {
    // Linux writes at most ~2 GiB per call; loop on partial writes and EINTR.
    const size_t chunk = std::min<size_t>(size, size_t{1} << 30);
    const ssize_t n = offset < 0 ? ::write(fd_, p, chunk) : ::pwrite(fd_, p, chunk, offset);
    if (n < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      fail(StatusCode::kIoError, "cannot write " + describe_target() + ": " + errno_text(err));
    }
    if (n == 0) fail(StatusCode::kIoError, "cannot write " + describe_target() + ": write returned 0");
    p += n;
    size -= static_cast<size_t>(n);
    if (offset >= 0) offset += n;
  }
}

void AtomicFileWriter::write_zeros(size_t size) {
  static constexpr uint8_t kZeros[256] = {};
  while (size > 0) {
    const size_t n = std::min(size, sizeof kZeros);
    write(kZeros, n);
    size -= n;
  }
}

void AtomicFileWriter::name_unnamed_file() {
  // linkat cannot replace an existing name, so the unnamed file gets a fresh temporary name first and
  // is then renamed over the target: the name exists only between these two calls.
  temp_path_ = path_ + ".tmp." + std::to_string(::getpid());
  const std::string fd_link = "/proc/self/fd/" + std::to_string(fd_);
  for (int attempt = 0; attempt < 2; ++attempt) {
    if (::linkat(AT_FDCWD, fd_link.c_str(), AT_FDCWD, temp_path_.c_str(), AT_SYMLINK_FOLLOW) == 0) return;
    if (errno == EEXIST && attempt == 0) {  // a stale one from a crashed process with our pid
      ::unlink(temp_path_.c_str());
      continue;
    }
    break;
  }
  const int err = errno;
  temp_path_.clear();
  fail(StatusCode::kIoError, "cannot write '" + path_ + "': cannot give the new file a name: " + errno_text(err));
}

void AtomicFileWriter::commit() {
  // fsync before rename: otherwise a crash can leave the new name pointing at unwritten blocks.
  if (::fsync(fd_) != 0) {
    const int err = errno;
    fail(StatusCode::kIoError, "cannot write " + describe_target() + ": fsync failed: " + errno_text(err));
  }
  if (temp_path_.empty()) name_unnamed_file();
  const int fd = std::exchange(fd_, -1);
  if (::close(fd) != 0) {
    const int err = errno;
    fail(StatusCode::kIoError, "cannot write " + describe_target() + ": close failed: " + errno_text(err));
  }
  if (::rename(temp_path_.c_str(), path_.c_str()) != 0) {
    const int err = errno;
    fail(StatusCode::kIoError,
         "cannot write '" + path_ + "': rename from '" + temp_path_ + "' failed: " + errno_text(err));
  }
  committed_ = true;
  // Best effort: persist the directory entry. Some file systems refuse fsync on directories.
  std::string dir = std::filesystem::path(path_).parent_path().string();
  if (dir.empty()) dir = ".";
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    (void)::fsync(dfd);
    ::close(dfd);
  }
}

std::string read_regular_file(const std::string& path) {
  // A private copy: a file truncated meanwhile is an error, never a SIGBUS.
  const FileMapping file = FileMapping::open(path, FileMapping::Mode::kPrivateCopy);
  return std::string(reinterpret_cast<const char*>(file.data()), file.size());
}

template <class Json>
Json parse_untrusted_json(const std::string& path, const char* begin, size_t size, const std::string& failure) {
  const auto bad = [&](const std::string& why) { fail(StatusCode::kDataLoss, "'" + path + "': " + failure + ": " + why); };
  // The key sets of the objects currently open, innermost last; keys only occur in the innermost one.
  std::vector<std::set<std::string>> open_objects;
  std::string duplicate;
  bool has_duplicate = false;
  size_t depth = 0;
  size_t max_depth = 0;
  auto callback = [&](int /*depth*/, typename Json::parse_event_t event, Json& parsed) {
    using Event = typename Json::parse_event_t;
    if (event == Event::object_start || event == Event::array_start) {
      max_depth = std::max(max_depth, ++depth);
    } else if ((event == Event::object_end || event == Event::array_end) && depth > 0) {
      --depth;
    }
    if (event == Event::object_start) {
      open_objects.emplace_back();
    } else if (event == Event::object_end) {
      if (!open_objects.empty()) open_objects.pop_back();
    } else if (event == Event::key && !open_objects.empty() && parsed.is_string()) {
      const auto& key = parsed.template get_ref<const std::string&>();
      if (!open_objects.back().insert(key).second && !has_duplicate) {
        has_duplicate = true;
        duplicate = key;
      }
    }
    return true;
  };

  // nlohmann stops at a NUL byte as if the input ended there, which would let anything after it pass
  // unchecked. Valid JSON text never contains a raw NUL, so reject it up front.
  if (const void* nul = size == 0 ? nullptr : std::memchr(begin, 0, size); nul != nullptr) {
    bad("NUL byte at offset " + std::to_string(static_cast<const char*>(nul) - begin));
  }
  Json j;
  try {
    j = Json::parse(begin, begin + size, callback);
  } catch (const nlohmann::json::exception& e) {
    bad(clip(e.what()));
  }
  // Parsing and destroying are iterative in nlohmann, but copying, comparing and dumping recurse: bound
  // the depth so no later use of the value can overflow the stack.
  if (max_depth > kMaxJsonDepth) bad("nested deeper than " + std::to_string(kMaxJsonDepth) + " levels");
  // nlohmann would silently keep the last of two equal keys.
  if (has_duplicate) bad("duplicate key '" + clip(duplicate) + "'");
  return j;
}

template nlohmann::json parse_untrusted_json(const std::string&, const char*, size_t, const std::string&);
template nlohmann::ordered_json parse_untrusted_json(const std::string&, const char*, size_t, const std::string&);

nlohmann::json parse_json_header(const std::string& path, const uint8_t* data, size_t size) {
  return parse_untrusted_json<nlohmann::json>(path, reinterpret_cast<const char*>(data), size, "malformed JSON header");
}

nlohmann::ordered_json read_json_file(const std::string& path) {
  const std::string text = read_regular_file(path);
  return parse_untrusted_json<nlohmann::ordered_json>(path, text.data(), text.size(), "not valid JSON");
}

void throw_dump_error(const std::string& what, const char* reason) {
  fail(StatusCode::kInvalidArgument, "cannot serialise " + what + " as JSON: " + clip(reason));
}

bool json_to_i64(const nlohmann::json& j, int64_t* out) {
  if (j.is_number_unsigned()) {
    const auto v = j.get<uint64_t>();
    if (v > static_cast<uint64_t>(std::numeric_limits<int64_t>::max())) return false;
    *out = static_cast<int64_t>(v);
    return true;
  }
  if (j.is_number_integer()) {
    *out = j.get<int64_t>();
    return true;
  }
  return false;
}

bool json_to_u64(const nlohmann::json& j, uint64_t* out) {
  if (j.is_number_unsigned()) {
    *out = j.get<uint64_t>();
    return true;
  }
  if (j.is_number_integer()) {
    const auto v = j.get<int64_t>();
    if (v < 0) return false;
    *out = static_cast<uint64_t>(v);
    return true;
  }
  return false;
}

bool json_to_i32(const nlohmann::json& j, int32_t* out) {
  int64_t v = 0;
  if (!json_to_i64(j, &v) || v < std::numeric_limits<int32_t>::min() || v > std::numeric_limits<int32_t>::max()) {
    return false;
  }
  *out = static_cast<int32_t>(v);
  return true;
}

bool json_to_f32(const nlohmann::json& j, float* out) {
  if (!j.is_number()) return false;
  const auto d = j.get<double>();
  if (!(std::fabs(d) <= static_cast<double>(std::numeric_limits<float>::max()))) return false;
  *out = static_cast<float>(d);
  return true;
}

bool json_to_shape(const nlohmann::json& j, std::vector<int64_t>* shape, std::string* why) {
  if (!j.is_array()) {
    *why = std::string("shape must be an array, got ") + j.type_name();
    return false;
  }
  shape->clear();
  shape->reserve(j.size());
  for (const auto& d : j) {
    int64_t v = 0;
    if (!json_to_i64(d, &v)) {
      if (d.is_number_unsigned()) {
        *why = "dimension " + std::to_string(d.get<uint64_t>()) + " is too large";
      } else if (d.is_number_float()) {
        *why = "shape has a non-integer dimension";
      } else {
        *why = std::string("shape dimensions must be integers, got ") + d.type_name();
      }
      return false;
    }
    if (v < 0) {
      *why = "negative dimension " + std::to_string(v) + " in shape";
      return false;
    }
    shape->push_back(v);
  }
  return true;
}

}  // namespace act::detail
