// Frames for act_drive: an OpenCV capture thread that keeps only the newest frame. Frames become
// model inputs through act::frame_to_model_rgb (actengine/vision.h), the conversion
// act_convert's INT8 calibration uses too.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <opencv2/core.hpp>

namespace act::drive {

using Clock = std::chrono::steady_clock;

struct Frame {
  cv::Mat bgr;                  ///< as the camera delivered it (OpenCV's BGR order)
  Clock::time_point captured;   ///< when the capture thread received it
  uint64_t index = 0;           ///< 0, 1, 2... since the source opened
};

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
};

struct CameraOptions {
  /// An index ("0"), a device (/dev/video0), a video file, an image sequence (frames/%06d.png), a URL
  /// or a GStreamer pipeline ending in appsink.
  std::string source;
  int width = 0;       ///< requested capture size; 0 = the driver's default
  int height = 0;
  double fps = 0;      ///< requested rate (a video file plays at its own rate when 0)
};

class Camera : public FrameSource {
 public:
  /// Opens the source and starts the capture thread; throws act::Error when it cannot be opened.
  explicit Camera(CameraOptions options);
  ~Camera() override;
  Camera(const Camera&) = delete;
  Camera& operator=(const Camera&) = delete;

  std::shared_ptr<const Frame> latest() const override;
  State state() const override;
  std::string problem() const override;
  /// The size frames arrive in (after the driver applied the request).
  int width() const { return width_; }
  int height() const { return height_; }
  bool is_file() const { return is_file_; }

 private:
  struct Capture;
  void run();
  void set_problem(State state, const std::string& problem);

  CameraOptions options_;
  bool is_file_ = false;
  int width_ = 0, height_ = 0;
  std::unique_ptr<Capture> capture_;
  mutable std::mutex mutex_;
  std::shared_ptr<const Frame> latest_;  // guarded by mutex_
  State state_ = State::kRunning;        // guarded by mutex_
  std::string problem_;                  // guarded by mutex_
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace act::drive
