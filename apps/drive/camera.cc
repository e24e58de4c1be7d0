#include "apps/drive/camera.h"

#include <algorithm>
#include <cctype>
#include <filesystem>

#include <opencv2/videoio.hpp>

#include "weights/blob/error.h"

namespace act::drive {

struct Camera::Capture {
  cv::VideoCapture video;
};

namespace {

bool is_index(const std::string& s) {
  return !s.empty() && s.size() < 4 && std::all_of(s.begin(), s.end(), [](unsigned char c) { return std::isdigit(c); });
}

// What a --camera string names; each kind opens through one OpenCV backend (open_capture).
enum class SourceKind {
  kIndex,              // "0"
  kDevice,             // /dev/video0
  kFile,               // a video file
  kGstreamerPipeline,  // e.g. a Pi camera: "libcamerasrc ! video/x-raw,width=640,height=480 ! videoconvert !
                       //   video/x-raw,format=BGR ! appsink"
  kUrl,                // rtsp://, http://... (may hold %-escapes, so before image sequences)
  kImageSequence,      // frames/%06d.png, read like a camera
  kUnknown,            // none of these: a path that does not exist, or a folder
};

SourceKind source_kind(const std::string& s) {
  if (is_index(s)) return SourceKind::kIndex;
  if (s.rfind("/dev/", 0) == 0) return SourceKind::kDevice;
  if (std::filesystem::is_regular_file(s)) return SourceKind::kFile;
  if (s.find(" ! ") != std::string::npos) return SourceKind::kGstreamerPipeline;
  if (s.find("://") != std::string::npos) return SourceKind::kUrl;
  if (s.find('%') != std::string::npos) return SourceKind::kImageSequence;
  return SourceKind::kUnknown;
}

// Files go through FFmpeg only, as act_convert's calibration reads them (no fallback to GStreamer,
// which decodes differently and behaves differently from one machine's plugin set to another's).
void open_capture(cv::VideoCapture& video, const CameraOptions& options, SourceKind kind) {
  switch (kind) {
    case SourceKind::kIndex: video.open(std::stoi(options.source), cv::CAP_ANY); break;
    case SourceKind::kDevice: video.open(options.source, cv::CAP_V4L2); break;
    case SourceKind::kFile: video.open(options.source, cv::CAP_FFMPEG); break;
    case SourceKind::kGstreamerPipeline: video.open(options.source, cv::CAP_GSTREAMER); break;
    case SourceKind::kUrl:  // FFmpeg first, then whatever else this OpenCV has
      if (!video.open(options.source, cv::CAP_FFMPEG)) video.open(options.source, cv::CAP_ANY);
      break;
    case SourceKind::kImageSequence: video.open(options.source, cv::CAP_IMAGES); break;
    case SourceKind::kUnknown: break;
  }
  if (!video.isOpened() || kind == SourceKind::kFile) return;
  // Only the newest frame matters: keep the driver's queue short where it has one.
  video.set(cv::CAP_PROP_BUFFERSIZE, 1);
  if (options.width > 0) video.set(cv::CAP_PROP_FRAME_WIDTH, options.width);
  if (options.height > 0) video.set(cv::CAP_PROP_FRAME_HEIGHT, options.height);
  if (options.fps > 0) video.set(cv::CAP_PROP_FPS, options.fps);
}

}  // namespace

Camera::Camera(CameraOptions options) : options_(std::move(options)), capture_(std::make_unique<Capture>()) {
  const SourceKind kind = source_kind(options_.source);
  is_file_ = kind == SourceKind::kFile;
  open_capture(capture_->video, options_, kind);
  if (!capture_->video.isOpened()) {
    const bool missing = (kind == SourceKind::kDevice || kind == SourceKind::kUnknown) &&
                         !std::filesystem::exists(options_.source);
    fail(ErrorCode::kNotFound, "cannot open camera '" + options_.source + "'" + (missing ? ": no such file" : "") +
                                    " (an index like 0, a device like /dev/video0, a video file, an image sequence like "
                                    "frames/%06d.png, a URL or a GStreamer pipeline ending in appsink)");
  }
  cv::Mat first;
  if (!capture_->video.read(first) || first.empty()) {
    fail(ErrorCode::kIoError, "camera '" + options_.source + "' opened but delivered no frame");
  }
  if (first.type() != CV_8UC3) {
    fail(ErrorCode::kUnimplemented, "camera '" + options_.source + "' delivers " + std::to_string(first.channels()) +
                                         "-channel frames; act_drive needs 8-bit colour (BGR)");
  }
  width_ = first.cols;
  height_ = first.rows;
  latest_ = std::make_shared<const Frame>(Frame{first, Clock::now(), 0});
  thread_ = std::thread([this] { run(); });
}

Camera::~Camera() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

std::shared_ptr<const Frame> Camera::latest() const {
  std::lock_guard lock(mutex_);
  return latest_;
}

FrameSource::State Camera::state() const {
  std::lock_guard lock(mutex_);
  return state_;
}

std::string Camera::problem() const {
  std::lock_guard lock(mutex_);
  return problem_;
}

void Camera::set_problem(State state, const std::string& problem) {
  std::lock_guard lock(mutex_);
  state_ = state;
  problem_ = problem;
}

void Camera::run() {
  cv::VideoCapture& video = capture_->video;
  // A video file plays at its own rate (or --camera-fps), not as fast as it decodes.
  double file_fps = options_.fps > 0 ? options_.fps : video.get(cv::CAP_PROP_FPS);
  if (!(file_fps > 0 && file_fps < 1000)) file_fps = 30;
  const auto file_start = Clock::now();
  uint64_t index = 1;
  while (!stop_.load()) {
    if (is_file_) {
      std::this_thread::sleep_until(file_start + std::chrono::duration_cast<Clock::duration>(
                                                     std::chrono::duration<double>(static_cast<double>(index) / file_fps)));
    }
    cv::Mat image;
    const bool ok = video.read(image) && !image.empty();
    if (ok) {
      auto frame = std::make_shared<const Frame>(Frame{std::move(image), Clock::now(), index++});
      std::lock_guard lock(mutex_);
      latest_ = std::move(frame);
      state_ = State::kRunning;
      problem_.clear();
      continue;
    }
    if (is_file_) {
      set_problem(State::kEnded, "end of video file " + options_.source + " after " + std::to_string(index) + " frames");
      return;
    }
    // A live camera failed (unplugged, stream dropped): reopen it until it comes back.
    set_problem(State::kReconnecting, "camera '" + options_.source + "' stopped delivering frames; reopening");
    video.release();
    for (int i = 0; i < 10 && !stop_.load(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(100));
    if (!stop_.load()) open_capture(video, options_, source_kind(options_.source));
  }
}

}  // namespace act::drive
