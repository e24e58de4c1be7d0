// act_drive --overlay-video out.mp4: every control tick as one video frame, the frame as the model
// saw it (enlarged) with the steering and throttle sent, the policy's chunk ahead, who drove and the
// fault. Drawn and encoded on its own thread so that a real-time control loop never waits on the
// encoder: ticks arriving faster than it encodes are dropped and counted. An offline replay
// (--realtime off) waits for the encoder instead, so that its video has every tick.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <utility>

#include "apps/drive/camera.h"
#include "apps/drive/cockpit.h"
#include "engine/media/media_io.h"

namespace act::drive {

class OverlayVideo {
 public:
  /// Opens `path` for a video at `fps` of image_height x image_width frames shown `scale` times
  /// larger; throws act::Error when OpenCV cannot write it (the extension picks the container).
  /// `wait_for_encoder`: add() blocks while the queue is full instead of dropping the tick.
  OverlayVideo(const std::string& path, double fps, int image_height, int image_width, int scale = 4,
               bool wait_for_encoder = false);
  ~OverlayVideo();
  OverlayVideo(const OverlayVideo&) = delete;
  OverlayVideo& operator=(const OverlayVideo&) = delete;

  /// One tick: its status and the newest camera frame (null before the first). Dropped when the
  /// encoder is a whole queue behind, or waited for with `wait_for_encoder`.
  void add(LiveStatus status, std::shared_ptr<const Frame> frame);
  /// Writes what is queued and closes the file (also done by the destructor).
  void close();
  uint64_t frames_written() const;
  uint64_t dropped() const;

 private:
  void run();
  cv::Mat draw(const LiveStatus& status, const Frame* frame) const;

  int image_height_, image_width_, scale_;
  bool wait_for_encoder_;
  std::unique_ptr<media::VideoWriter> writer_;  // null once closed
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::condition_variable room_;  // the encoder took a tick off the queue (wait_for_encoder)
  std::deque<std::pair<LiveStatus, std::shared_ptr<const Frame>>> queue_;  // guarded by mutex_
  uint64_t written_ = 0, dropped_ = 0;  // guarded by mutex_
  bool closing_ = false;                // guarded by mutex_
  std::thread thread_;
};

}  // namespace act::drive
