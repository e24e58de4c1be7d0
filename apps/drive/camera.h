// Frames for act_drive: an OpenCV capture thread that keeps only the newest frame. Frames become
// model inputs through act::frame_to_model_rgb (actengine/vision.h), the conversion
// act_convert's INT8 calibration uses too.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>

#include <opencv2/core.hpp>

namespace act::drive {

using Clock = std::chrono::steady_clock;

/// Milliseconds from `a` to `b`.
inline double ms_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

struct Frame {
  cv::Mat bgr;                  ///< as the camera delivered it (OpenCV's BGR order)
  Clock::time_point captured;   ///< when the capture thread received it
  uint64_t index = 0;           ///< 0, 1, 2... since the source opened
  /// A replayed file's (video or image sequence) frame interval, 1 / its frame rate: the frame is
  /// the file's current one until the next is due. Zero for a live source.
  Clock::duration interval{};
};

/// How old `frame` is at `now` as --max-frame-age judges it: a live camera's frame from its capture,
/// a replayed file's from when the next frame was due (a 5 fps file's frames each stand for 200 ms
/// and are not stale then; they are when the file's reader falls behind its own frame rate).
inline Clock::duration frame_age(const Frame& frame, Clock::time_point now) {
  return now - frame.captured - frame.interval;
}

/// Where the control loop gets frames. The camera is one; tests substitute others.
class FrameSource {
 public:
  enum class State {
    kRunning,       ///< delivering frames
    kReconnecting,  ///< a live camera failed; trying to reopen it
    kEnded,         ///< a video file reached its end: no more frames will come
  };
  virtual ~FrameSource() = default;
  /// The newest frame, or null before the first. Never blocks on the camera.
  virtual std::shared_ptr<const Frame> latest() const = 0;
  virtual State state() const = 0;
  /// Why the source is not running (empty while it runs).
  virtual std::string problem() const = 0;
  /// An offline replay: makes the frame for `time_s` (seconds since the first frame) the latest,
  /// waiting for it to be read. Sources that run in real time ignore it.
  virtual void advance_to(double /*time_s*/) const {}
  /// The control loop's start. A video file played in real time starts its clock here, so that what
  /// comes before (loading the model) does not use up its first frames. Live sources ignore it.
  virtual void start_playback() const {}
};

struct CameraOptions {
  /// An index ("0"), a device (/dev/video0), a video file, an image sequence (frames/%06d.png), a URL
  /// or a GStreamer pipeline ending in appsink.
  std::string source;
  int width = 0;       ///< requested capture size; 0 = the driver's default
  int height = 0;
  double fps = 0;      ///< requested rate (a video file plays at its own rate when 0)
  /// Sources read through FFmpeg (video files, URLs): how long opening may take, and how long a read
  /// may wait for a frame before the stream counts as stalled and is reopened (OpenCV's default is
  /// 30 s for each). Opening covers FFmpeg's probing, which can read a few seconds of a live stream.
  std::chrono::milliseconds open_timeout{10000};
  std::chrono::milliseconds read_timeout{2000};
  /// A file's frames are read only when advance_to() asks for them, not at their rate (an offline
  /// replay, --realtime off). Refused for a live source.
  bool stepped = false;
  /// A video file or image sequence restarts from its first frame at its end instead of ending
  /// (--loop); frame indices go on counting. Refused for a live source.
  bool loop = false;
};

class Camera : public FrameSource {
 public:
  /// Opens the source and starts the capture thread; throws act::Error when it cannot be opened.
  explicit Camera(CameraOptions options);
  /// Stops the capture thread (see stop()).
  ~Camera() override;
  Camera(const Camera&) = delete;
  Camera& operator=(const Camera&) = delete;

  /// How long stop() waits by default: a healthy capture thread ends within a frame interval.
  static constexpr std::chrono::milliseconds kStopTimeout{500};
  /// Ends the capture thread, waiting for it at most `timeout`: a backend can block for much longer
  /// (FFmpeg on a pipe or on a stream while it opens, a hung V4L2 driver), and a rover that is told
  /// to stop must not wait for it. False when the thread is still blocked: it is then left behind,
  /// holding everything it uses, and frames stop. Calling it again returns the same answer at once.
  bool stop(std::chrono::milliseconds timeout = kStopTimeout);
  /// Whether any Camera of this process left its capture thread behind. The process should then end
  /// with std::_Exit: static destructors must not run while that thread may still wake up in OpenCV.
  static bool left_a_thread_behind();

  std::shared_ptr<const Frame> latest() const override;
  State state() const override;
  std::string problem() const override;
  void advance_to(double time_s) const override;
  void start_playback() const override;
  /// The size frames arrive in (after the driver applied the request).
  int width() const { return width_; }
  int height() const { return height_; }
  bool is_file() const { return is_file_; }
  /// A video file or an image sequence: played at its frame rate (its own or CameraOptions::fps),
  /// ending (or looping) at its end, and steppable (--realtime off).
  bool is_replay() const { return is_replay_; }

 private:
  // The capture, the newest frame and the thread's state, owned jointly by the Camera and its
  // thread: a thread left behind by stop() never touches freed memory.
  struct Shared;
  std::shared_ptr<Shared> shared_;
  bool is_file_ = false, is_replay_ = false;
  int width_ = 0, height_ = 0;
  std::thread thread_;
  bool thread_left_behind_ = false;
};

}  // namespace act::drive
