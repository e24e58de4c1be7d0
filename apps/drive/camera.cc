#include "apps/drive/camera.h"

#include <algorithm>
#include <atomic>
#include <cctype>
#include <condition_variable>
#include <cmath>
#include <filesystem>
#include <mutex>
#include <vector>

#include <sys/stat.h>

#include "actengine/status.h"
#include "engine/media/media_io.h"

namespace act::drive {

// What a --camera string names; each kind opens through one OpenCV backend (open_capture). Outside
// the anonymous namespace: Camera::Shared holds one.
enum class SourceKind {
  kIndex,              // "0"
  kDevice,             // /dev/video0
  kFile,               // a video file
  kGstreamerPipeline,  // e.g. a Pi camera: "libcamerasrc ! video/x-raw,width=640,height=480 ! videoconvert !
                       //   video/x-raw,format=BGR ! appsink"
  kUrl,                // rtsp://, http://... (may hold %-escapes, so before image sequences)
  kImageSequence,      // frames/%06d.png, played like a video file
  kUnknown,            // none of these: a path that does not exist, or a folder
};

namespace {

bool is_index(const std::string& s) {
  return !s.empty() && s.size() < 4 && std::all_of(s.begin(), s.end(), [](unsigned char c) { return std::isdigit(c); });
}

// A file replayed at its frame rate (not a live source): it ends, can loop and can be stepped.
bool is_replay_kind(SourceKind kind) { return kind == SourceKind::kFile || kind == SourceKind::kImageSequence; }

SourceKind source_kind(const std::string& s) {
  if (is_index(s)) return SourceKind::kIndex;
  if (s.rfind("/dev/", 0) == 0) return SourceKind::kDevice;
  if (std::filesystem::is_regular_file(s)) return SourceKind::kFile;
  if (s.find(" ! ") != std::string::npos) return SourceKind::kGstreamerPipeline;
  if (s.find("://") != std::string::npos) return SourceKind::kUrl;
  if (s.find('%') != std::string::npos) return SourceKind::kImageSequence;
  return SourceKind::kUnknown;
}

// A FIFO or a socket where a frame file should be blocks the backend's open or its first read
// forever: refused at once, as every other reader of files refuses one. Devices (/dev/video0) pass.
void refuse_special_file(const std::string& path, const std::string& source) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0 || S_ISREG(st.st_mode) || S_ISCHR(st.st_mode) || S_ISDIR(st.st_mode)) return;
  const char* kind = S_ISFIFO(st.st_mode) ? "a FIFO" : S_ISSOCK(st.st_mode) ? "a socket" : "a block device";
  fail(StatusCode::kInvalidArgument, "camera '" + source + "': " + (path == source ? "" : "'" + path + "' ") +
                                         "is not a regular file (" + kind + ")");
}

// The first files an image sequence such as frames/%06d.png names (OpenCV starts at the first of
// indices 0-4 that exists), when the pattern holds exactly one %d conversion (none otherwise).
std::vector<std::string> first_sequence_files(const std::string& pattern) {
  const size_t percent = pattern.find('%');
  if (percent == std::string::npos || pattern.find('%', percent + 1) != std::string::npos) return {};
  size_t end = percent + 1;
  while (end < pattern.size() && std::isdigit(static_cast<unsigned char>(pattern[end]))) ++end;
  if (end >= pattern.size() || pattern[end] != 'd' || end - percent > 4) return {};
  const std::string spec = pattern.substr(percent + 1, end - percent - 1);  // "06" in %06d
  const size_t width = spec.empty() ? 0 : static_cast<size_t>(std::stoi(spec));
  std::vector<std::string> files;
  for (int i = 0; i < 5; ++i) {
    std::string number = std::to_string(i);
    if (number.size() < width) number.insert(0, width - number.size(), spec[0] == '0' ? '0' : ' ');
    files.push_back(pattern.substr(0, percent) + number + pattern.substr(end + 1));
  }
  return files;
}

void refuse_special_files(const std::string& source, SourceKind kind) {
  if (kind == SourceKind::kImageSequence) {
    for (const std::string& file : first_sequence_files(source)) refuse_special_file(file, source);
  } else if (kind == SourceKind::kDevice || kind == SourceKind::kUnknown) {
    refuse_special_file(source, source);
  }
}

// Files go through FFmpeg only, as act_convert's calibration reads them (no fallback to GStreamer,
// which decodes differently and behaves differently from one machine's plugin set to another's).
// FFmpeg opens get the timeouts, so a stalled stream fails its read instead of blocking the capture
// thread for OpenCV's default 30 s. The other backends of OpenCV 4.6 do not take them; stop() does
// not wait for those either.
// Null when the source does not open.
std::unique_ptr<media::VideoReader> open_capture(const CameraOptions& options, SourceKind kind) {
  const std::vector<int> ffmpeg_timeouts{cv::CAP_PROP_OPEN_TIMEOUT_MSEC, static_cast<int>(options.open_timeout.count()),
                                         cv::CAP_PROP_READ_TIMEOUT_MSEC, static_cast<int>(options.read_timeout.count())};
  std::unique_ptr<media::VideoReader> video;
  switch (kind) {
    case SourceKind::kIndex: video = media::open_camera(std::stoi(options.source), cv::CAP_ANY); break;
    case SourceKind::kDevice: video = media::open_video(options.source, cv::CAP_V4L2); break;
    case SourceKind::kFile: video = media::open_video(options.source, cv::CAP_FFMPEG, ffmpeg_timeouts); break;
    case SourceKind::kGstreamerPipeline: video = media::open_video(options.source, cv::CAP_GSTREAMER); break;
    case SourceKind::kUrl:  // FFmpeg first, then GStreamer (CAP_ANY would try FFmpeg again, without the timeouts)
      video = media::open_video(options.source, cv::CAP_FFMPEG, ffmpeg_timeouts);
      if (!video) video = media::open_video(options.source, cv::CAP_GSTREAMER);
      break;
    case SourceKind::kImageSequence: video = media::open_video(options.source, cv::CAP_IMAGES); break;
    case SourceKind::kUnknown: break;
  }
  if (!video || kind == SourceKind::kFile) return video;
  // Only the newest frame matters: keep the driver's queue short where it has one.
  video->set(cv::CAP_PROP_BUFFERSIZE, 1);
  if (options.width > 0) video->set(cv::CAP_PROP_FRAME_WIDTH, options.width);
  if (options.height > 0) video->set(cv::CAP_PROP_FRAME_HEIGHT, options.height);
  if (options.fps > 0) video->set(cv::CAP_PROP_FPS, options.fps);
  return video;
}

// Set once a capture thread is left behind (Camera::stop); read when the process ends.
std::atomic<bool> g_thread_left_behind{false};

}  // namespace

struct Camera::Shared {
  Shared(CameraOptions camera, SourceKind camera_kind) : options(std::move(camera)), kind(camera_kind) {}

  // The capture thread's body: reads frames until stopped or, for a file, until its end.
  void run();
  // The next frame into `image`; a file that ended restarts from its first frame with --loop.
  bool read_next(cv::Mat& image);
  // Waits until `deadline` or a stop request; true when stopping.
  bool wait_for_stop(Clock::time_point deadline);
  // A file played in real time: waits for start_playback(); false when stopped first.
  bool wait_for_playback();
  void set_problem(State new_state, const std::string& new_problem);

  const CameraOptions options;
  const SourceKind kind;
  std::unique_ptr<media::VideoReader> video;  // the constructor's, then the capture thread's alone; null while closed
  std::mutex mutex;
  std::condition_variable changed;      // a stop request, or the end of the thread
  std::shared_ptr<const Frame> latest;  // guarded by mutex, as are the members below
  State state = State::kRunning;
  std::string problem;
  bool stop_requested = false;
  bool thread_ended = false;
  bool playing = false;    // start_playback() was called
  uint64_t wanted = 0;     // stepped: the newest frame index advance_to asked for
  double file_fps = 30;    // a file's frame rate (its own, or CameraOptions::fps); set before run()
  Clock::duration interval{};  // a replayed file's frame interval (Frame::interval); set before run()
};

Camera::Camera(CameraOptions options) {
  const SourceKind kind = source_kind(options.source);
  refuse_special_files(options.source, kind);
  shared_ = std::make_shared<Shared>(std::move(options), kind);
  const std::string& source = shared_->options.source;
  is_file_ = kind == SourceKind::kFile;
  is_replay_ = is_replay_kind(kind);
  if (shared_->options.stepped && !is_replay_) {
    fail(StatusCode::kInvalidArgument, "--realtime off replays a video file or an image sequence; '" + source +
                                           "' is a live source");
  }
  if (shared_->options.loop && !is_replay_) {
    fail(StatusCode::kInvalidArgument, "--loop replays a video file or an image sequence; '" + source + "' is a live source");
  }
  std::unique_ptr<media::VideoReader>& video = shared_->video;
  video = open_capture(shared_->options, kind);
  if (!video) {
    const bool missing = (kind == SourceKind::kDevice || kind == SourceKind::kUnknown) && !std::filesystem::exists(source);
    fail(StatusCode::kNotFound, "cannot open camera '" + source + "'" + (missing ? ": no such file" : "") +
                                    " (an index like 0, a device like /dev/video0, a video file, an image sequence like "
                                    "frames/%06d.png, a URL or a GStreamer pipeline ending in appsink; act_drive --list-cameras "
                                    "lists the cameras found)");
  }
  cv::Mat first;
  if (!video->read(first) || first.empty()) {
    fail(StatusCode::kIoError, "camera '" + source + "' opened but delivered no frame");
  }
  if (first.type() != CV_8UC3) {
    fail(StatusCode::kUnimplemented, "camera '" + source + "' delivers " + std::to_string(first.channels()) +
                                          "-channel frames; act_drive needs 8-bit colour (BGR)");
  }
  width_ = first.cols;
  height_ = first.rows;
  // A video's own rate, or --camera-fps; an image sequence has none (OpenCV's image reader says 1).
  const double own_fps = kind == SourceKind::kImageSequence ? 0.0 : video->get(cv::CAP_PROP_FPS);
  const double fps = shared_->options.fps > 0 ? shared_->options.fps : own_fps;
  if (fps > 0 && fps < 1000) shared_->file_fps = fps;
  if (is_replay_) {
    shared_->interval = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / shared_->file_fps));
  }
  shared_->latest = std::make_shared<const Frame>(Frame{first, Clock::now(), 0, shared_->interval});
  thread_ = std::thread([shared = shared_] {
    shared->run();
    std::lock_guard lock(shared->mutex);
    shared->thread_ended = true;
    shared->changed.notify_all();
  });
}

Camera::~Camera() { stop(); }

bool Camera::stop(std::chrono::milliseconds timeout) {
  if (!thread_.joinable()) return !thread_left_behind_;
  std::unique_lock lock(shared_->mutex);
  shared_->stop_requested = true;
  shared_->changed.notify_all();
  const bool ended = shared_->changed.wait_for(lock, timeout, [&] { return shared_->thread_ended; });
  lock.unlock();
  if (ended) {
    thread_.join();
  } else {
    thread_.detach();
    thread_left_behind_ = true;
    g_thread_left_behind.store(true);
  }
  return ended;
}

bool Camera::left_a_thread_behind() { return g_thread_left_behind.load(); }

std::shared_ptr<const Frame> Camera::latest() const {
  std::lock_guard lock(shared_->mutex);
  return shared_->latest;
}

void Camera::advance_to(double time_s) const {
  if (!shared_->options.stepped) return;
  Shared& s = *shared_;
  const auto wanted = static_cast<uint64_t>(std::floor(time_s * s.file_fps + 1e-6));
  std::unique_lock lock(s.mutex);
  s.wanted = std::max(s.wanted, wanted);
  s.changed.notify_all();
  s.changed.wait(lock, [&] { return s.latest->index >= wanted || s.state == State::kEnded || s.thread_ended; });
}

void Camera::start_playback() const {
  Shared& s = *shared_;
  std::lock_guard lock(s.mutex);
  if (s.playing) return;
  s.playing = true;
  // A file played in real time: its first frame counts as delivered now, when its clock starts.
  if (is_replay_ && !s.options.stepped && s.latest->index == 0) {
    s.latest = std::make_shared<const Frame>(Frame{s.latest->bgr, Clock::now(), 0, s.interval});
  }
  s.changed.notify_all();
}

FrameSource::State Camera::state() const {
  std::lock_guard lock(shared_->mutex);
  return shared_->state;
}

std::string Camera::problem() const {
  std::lock_guard lock(shared_->mutex);
  return shared_->problem;
}

void Camera::Shared::set_problem(State new_state, const std::string& new_problem) {
  std::lock_guard lock(mutex);
  state = new_state;
  problem = new_problem;
}

bool Camera::Shared::wait_for_stop(Clock::time_point deadline) {
  std::unique_lock lock(mutex);
  return changed.wait_until(lock, deadline, [this] { return stop_requested; });
}

bool Camera::Shared::wait_for_playback() {
  std::unique_lock lock(mutex);
  changed.wait(lock, [this] { return playing || stop_requested; });
  return !stop_requested;
}

bool Camera::Shared::read_next(cv::Mat& image) {
  if (video && video->read(image) && !image.empty()) return true;
  if (!options.loop || !is_replay_kind(kind)) return false;
  video = open_capture(options, kind);  // from its first frame again
  return video && video->read(image) && !image.empty();
}

void Camera::Shared::run() {
  const bool is_file = is_replay_kind(kind);
  // A video file or image sequence plays at its own rate (or --camera-fps), not as fast as it
  // decodes, from the control loop's start.
  if (is_file && !options.stepped && !wait_for_playback()) return;
  const auto file_start = Clock::now();
  const auto file_frame_due = [&](uint64_t i) {
    return file_start +
           std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(static_cast<double>(i) / file_fps));
  };
  // Stepped: a frame when advance_to asks for it.
  const auto frame_wanted = [this](uint64_t i) {
    std::unique_lock lock(mutex);
    changed.wait(lock, [&] { return stop_requested || wanted >= i; });
    return !stop_requested;
  };
  uint64_t index = 1;
  // A live source is read at once, a file's frame when it is due; a stop request ends either wait.
  while (options.stepped ? frame_wanted(index) : !wait_for_stop(is_file ? file_frame_due(index) : Clock::time_point{})) {
    cv::Mat image;
    const auto read_start = Clock::now();
    if (read_next(image)) {
      auto frame = std::make_shared<const Frame>(Frame{std::move(image), Clock::now(), index++, interval});
      {
        std::lock_guard lock(mutex);
        latest = std::move(frame);
        state = State::kRunning;
        problem.clear();
      }
      changed.notify_all();  // advance_to waits for it
      continue;
    }
    if (is_file) {
      set_problem(State::kEnded, std::string(kind == SourceKind::kFile ? "end of video file " : "end of image sequence ") +
                                     options.source + " after " + std::to_string(index) + " frames");
      return;
    }
    // A live camera failed (unplugged, stream dropped) or stalled (no frame within read_timeout):
    // reopen it until it comes back.
    std::string what = "camera '" + options.source + "' stopped delivering frames";
    const auto waited = std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - read_start);
    if (waited >= options.read_timeout) what += " (stalled: no frame for " + std::to_string(waited.count()) + " ms)";
    set_problem(State::kReconnecting, what + "; reopening");
    video.reset();
    if (wait_for_stop(Clock::now() + std::chrono::seconds(1))) return;
    video = open_capture(options, kind);
  }
}

}  // namespace act::drive
