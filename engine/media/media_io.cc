#include "engine/media/media_io.h"

#include <dlfcn.h>

#include <filesystem>
#include <limits>
#include <string>
#include <system_error>
#include <vector>

#include "actengine/status.h"
#include "weights/blob/file_util.h"

namespace act::media {
namespace {

constexpr const char* kModuleFile = "libact_media_io.so";

// Where the module may be: beside the shared object holding this code (the Python package:
// actengine/_media*.so and libact_media_io.so in one folder), then at ACT_MEDIA_IO_FROM_BINDIR from the
// program's own folder (the apps: <bindir>/../<libdir>/actengine, and build/apps, build/test alike).
std::vector<std::string> module_candidates() {
  std::vector<std::string> paths;
  Dl_info self{};
  if (dladdr(reinterpret_cast<const void*>(&module_candidates), &self) != 0 && self.dli_fname != nullptr) {
    const std::filesystem::path object(self.dli_fname);
    // The main program's own entry is its argv[0] (maybe relative): /proc/self/exe below says it better.
    if (object.is_absolute() && object.extension() == ".so") paths.push_back((object.parent_path() / kModuleFile).string());
  }
  std::error_code error;
  const std::filesystem::path self_exe = std::filesystem::read_symlink("/proc/self/exe", error);
  if (!error) paths.push_back((self_exe.parent_path() / ACT_MEDIA_IO_FROM_BINDIR).lexically_normal().string());
  return paths;
}

// Loads the module once, on the first call from any thread (a function-local static); a failure
// is thrown again by every later call.
const MediaIo& module() {
  static const std::pair<const MediaIo*, std::string> loaded = []() -> std::pair<const MediaIo*, std::string> {
    const std::vector<std::string> candidates = module_candidates();
    std::string tried;
    for (const std::string& path : candidates) {
      if (!std::filesystem::exists(path)) {
        tried += (tried.empty() ? "" : "; ") + path + ": no such file";
        continue;
      }
      void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
      const char* why = handle ? nullptr : dlerror();
      auto entry = handle ? reinterpret_cast<MediaIoEntryPoint>(dlsym(handle, kMediaIoEntryPoint)) : nullptr;
      if (handle && !entry) why = dlerror();
      if (entry) return {&entry(), ""};  // never unloaded: OpenCV's libraries stay until the process ends
      tried += (tried.empty() ? "" : "; ") + path + ": " + (why ? why : "unknown error");
    }
    return {nullptr, "cannot load the image and video support (OpenCV imgcodecs and videoio, " + std::string(kModuleFile) +
                         "): " + (tried.empty() ? "the program's own folder is unknown" : tried) +
                         " (reinstall actengine-tools or the actengine wheel, or rebuild)"};
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
