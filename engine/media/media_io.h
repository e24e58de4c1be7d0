// Image files and video (OpenCV's imgcodecs and videoio) for the apps, their tests and the calibration
// readers (actengine/calibration_files.h), loaded on first use from a module of their own,
// libact_media_io.so. Debian's builds of those two OpenCV modules pull in about 250 shared libraries
// (GDAL, FFmpeg, GStreamer): linked into every app, they took 0.35 s of each start (act_bench --help
// included) and 0.55 s under ASan. Through this module only a program that reads or writes an image
// or a video pays, once, when it first does.
//
// The module is found beside the shared object that holds this code (the Python package's
// actengine/ folder), else in <libdir>/actengine/ from the program's own folder (<bindir>, or
// build/apps and build/test in the build tree: build/<libdir>/actengine/). When it cannot be loaded
// (moved, or an OpenCV library missing), the first call throws act::Error naming the paths tried and why.
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
// The flags below are OpenCV's (cv::IMREAD_*, cv::CAP_*, cv::CAP_PROP_*): enums, no code.
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

namespace act {

/// Image files (png, jpg, jpeg, bmp) and videos (mp4, avi, mkv, mov, webm), by extension in any case:
/// what act_convert and act_eval read.
bool is_image_file(const std::filesystem::path& p);
bool is_video_file(const std::filesystem::path& p);
/// The files of a folder and its subfolders that `pick` accepts, sorted by path.
std::vector<std::filesystem::path> files_in(const std::filesystem::path& dir, bool (*pick)(const std::filesystem::path&));

}  // namespace act

namespace act::media {

/// A video read frame by frame (cv::VideoCapture): a file, a camera, a URL, an image sequence or a
/// GStreamer pipeline. Used by one thread at a time.
class VideoReader {
 public:
  virtual ~VideoReader() = default;
  /// The next frame (BGR as decoded); false at the end or on an error.
  virtual bool read(cv::Mat& frame) = 0;
  /// cv::CAP_PROP_* (0 when the backend does not say).
  virtual double get(int property) const = 0;
  virtual bool set(int property, double value) = 0;
};

/// A video file being written (cv::VideoWriter); closed when destroyed.
class VideoWriter {
 public:
  virtual ~VideoWriter() = default;
  virtual void write(const cv::Mat& bgr) = 0;
};

/// An image file decoded (cv::imdecode of its bytes): an empty Mat when the file cannot be read or
/// decoded, with the reason in `why` when given. The bytes are read by act::detail::read_regular_file,
/// so a FIFO, a folder or a device is refused at once ("not a regular file (a FIFO)"), never waited on.
/// `flags`: cv::IMREAD_*.
cv::Mat read_image(const std::string& path, int flags = cv::IMREAD_COLOR, std::string* why = nullptr);
/// cv::imwrite (the extension picks the format): false when it could not.
bool write_image(const std::string& path, const cv::Mat& image);
/// cv::imencode, e.g. ".jpg": false when it could not.
bool encode_image(const std::string& extension, const cv::Mat& image, std::vector<uchar>& encoded);

/// A video, a URL, an image sequence or a pipeline through one backend (cv::CAP_*) with its open
/// parameters (cv::CAP_PROP_* pairs); null when it does not open.
std::unique_ptr<VideoReader> open_video(const std::string& source, int backend, const std::vector<int>& parameters = {});
/// A camera by index; null when it does not open.
std::unique_ptr<VideoReader> open_camera(int index, int backend);
/// A video file of `fps` frames of `size` with a four-character codec ("mp4v", "MJPG"); null when it
/// cannot be written.
std::unique_ptr<VideoWriter> create_video(const std::string& path, const std::string& fourcc, double fps, cv::Size size);

/// What the module exports (media_io_module.cc); the functions above load it and call it.
class MediaIo {
 public:
  virtual cv::Mat decode_image(const uint8_t* data, size_t size, int flags) const = 0;
  virtual bool write_image(const std::string& path, const cv::Mat& image) const = 0;
  virtual bool encode_image(const std::string& extension, const cv::Mat& image, std::vector<uchar>& encoded) const = 0;
  virtual std::unique_ptr<VideoReader> open_video(const std::string& source, int backend,
                                                  const std::vector<int>& parameters) const = 0;
  virtual std::unique_ptr<VideoReader> open_camera(int index, int backend) const = 0;
  virtual std::unique_ptr<VideoWriter> create_video(const std::string& path, const std::string& fourcc, double fps,
                                                    cv::Size size) const = 0;

 protected:
  ~MediaIo() = default;  // one static instance in the module, never deleted through this
};

/// The module's one exported symbol, returning its MediaIo.
inline constexpr const char* kMediaIoEntryPoint = "act_media_io";
using MediaIoEntryPoint = const MediaIo& (*)();

}  // namespace act::media
