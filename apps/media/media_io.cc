#include "apps/media/media_io.h"

#include <dlfcn.h>

#include <filesystem>
#include <limits>

#include "actengine/status.h"
#include "apps/executable_dir.h"
#include "weights/blob/file_util.h"

namespace act::media {
namespace {

// Loads the module once, on the first call from any thread (a function-local static); a failure
// is thrown again by every later call.
const MediaIo& module() {
  static const std::pair<const MediaIo*, std::string> loaded = []() -> std::pair<const MediaIo*, std::string> {
    std::string path;
    try {
      // ACT_MEDIA_IO_FROM_BINDIR: the module's path relative to the programs' folder (apps/CMakeLists.txt).
      path = (executable_dir() / ACT_MEDIA_IO_FROM_BINDIR).lexically_normal().string();
    } catch (const Error& e) {
      return {nullptr, e.what()};
    }
    void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    const char* why = handle ? nullptr : dlerror();
    auto entry = handle ? reinterpret_cast<MediaIoEntryPoint>(dlsym(handle, kMediaIoEntryPoint)) : nullptr;
    if (handle && !entry) why = dlerror();
    if (!entry) {
      return {nullptr, "cannot load the image and video support (OpenCV imgcodecs and videoio) from " + path + ": " +
                           (why ? why : "unknown error") + " (reinstall actengine-tools, or rebuild)"};
    }
    return {&entry(), ""};  // never unloaded: OpenCV's libraries stay until the process ends
  }();
  if (!loaded.first) fail(StatusCode::kNotFound, loaded.second);
  return *loaded.first;
}

}  // namespace

cv::Mat read_image(const std::string& path, int flags, std::string* why) {
  std::string bytes;
  try {
    bytes = detail::read_regular_file(path);
  } catch (const Error& e) {
    if (why) *why = e.what();
    return {};
  }
  if (bytes.size() > static_cast<size_t>(std::numeric_limits<int>::max())) {
    if (why) *why = "'" + path + "' is too large for an image (" + std::to_string(bytes.size()) + " bytes)";
    return {};
  }
  cv::Mat image = module().decode_image(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size(), flags);
  if (image.empty() && why) *why = "cannot decode '" + path + "' as an image (" + std::to_string(bytes.size()) + " bytes)";
  return image;
}
bool write_image(const std::string& path, const cv::Mat& image) { return module().write_image(path, image); }
bool encode_image(const std::string& extension, const cv::Mat& image, std::vector<uchar>& encoded) {
  return module().encode_image(extension, image, encoded);
}
std::unique_ptr<VideoReader> open_video(const std::string& source, int backend, const std::vector<int>& parameters) {
  return module().open_video(source, backend, parameters);
}
std::unique_ptr<VideoReader> open_camera(int index, int backend) { return module().open_camera(index, backend); }
std::unique_ptr<VideoWriter> create_video(const std::string& path, const std::string& fourcc, double fps, cv::Size size) {
  return module().create_video(path, fourcc, fps, size);
}

}  // namespace act::media
