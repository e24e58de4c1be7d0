#include "apps/drive/overlay_video.h"

#include <algorithm>
#include <cstdio>

#include <opencv2/imgproc.hpp>

#include "actengine/status.h"
#include "actengine/vision.h"

namespace act::drive {
namespace {

// Ticks waiting for the encoder beyond this are dropped rather than growing memory.
constexpr size_t kMaxQueued = 64;
// Height of the band under the image holding the gauges and the chunk ahead.
constexpr int kBandHeight = 120;

const cv::Scalar kSteeringColour(255, 204, 68), kThrottleColour(51, 153, 255), kGrey(110, 110, 110), kWhite(230, 230, 230);

// A horizontal gauge: -1 at the left end, +1 at the right, the value as a marker.
void gauge(cv::Mat& image, cv::Rect area, double value, const cv::Scalar& colour, const char* label) {
  cv::rectangle(image, area, cv::Scalar(60, 60, 60), cv::FILLED);
  const int middle = area.x + area.width / 2;
  cv::line(image, {middle, area.y}, {middle, area.y + area.height}, kGrey);
  const int x = middle + static_cast<int>(std::clamp(value, -1.0, 1.0) * area.width / 2);
  cv::rectangle(image, cv::Rect(x - 3, area.y, 6, area.height), colour, cv::FILLED);
  cv::putText(image, label, {area.x, area.y - 3}, cv::FONT_HERSHEY_SIMPLEX, 0.4, kWhite);
}

// The coming commands as a line over `area` (one point per tick, -1 bottom .. +1 top).
void ahead(cv::Mat& image, cv::Rect area, const std::vector<float>& values, const cv::Scalar& colour) {
  for (size_t i = 1; i < values.size(); ++i) {
    const auto point = [&](size_t k) {
      return cv::Point(area.x + static_cast<int>(k * area.width / values.size()),
                       area.y + area.height / 2 - static_cast<int>(std::clamp(values[k], -1.0f, 1.0f) * area.height / 2));
    };
    cv::line(image, point(i - 1), point(i), colour, 1, cv::LINE_AA);
  }
}

}  // namespace

OverlayVideo::OverlayVideo(const std::string& path, double fps, int image_height, int image_width, int scale,
                           bool wait_for_encoder)
    : image_height_(image_height), image_width_(image_width), scale_(scale), wait_for_encoder_(wait_for_encoder) {
  const cv::Size size(image_width * scale, image_height * scale + kBandHeight);
  writer_ = media::create_video(path, "mp4v", fps, size);
  if (!writer_) {
    fail(StatusCode::kIoError, "--overlay-video: OpenCV cannot write " + path + " (use an .mp4 or .avi file in an existing folder)");
  }
  thread_ = std::thread([this] { run(); });
}

OverlayVideo::~OverlayVideo() { close(); }

void OverlayVideo::add(LiveStatus status, std::shared_ptr<const Frame> frame) {
  {
    std::unique_lock lock(mutex_);
    if (wait_for_encoder_) room_.wait(lock, [this] { return closing_ || queue_.size() < kMaxQueued; });
    if (closing_) return;
    if (queue_.size() >= kMaxQueued) {
      ++dropped_;
      return;
    }
    queue_.emplace_back(std::move(status), std::move(frame));
  }
  wake_.notify_one();
}

void OverlayVideo::close() {
  {
    std::lock_guard lock(mutex_);
    closing_ = true;
  }
  wake_.notify_one();
  room_.notify_all();
  if (thread_.joinable()) thread_.join();
  writer_.reset();
}

uint64_t OverlayVideo::frames_written() const {
  std::lock_guard lock(mutex_);
  return written_;
}

uint64_t OverlayVideo::dropped() const {
  std::lock_guard lock(mutex_);
  return dropped_;
}

void OverlayVideo::run() {
  for (;;) {
    std::pair<LiveStatus, std::shared_ptr<const Frame>> tick;
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [this] { return closing_ || !queue_.empty(); });
      if (queue_.empty()) return;  // closing, everything written
      tick = std::move(queue_.front());
      queue_.pop_front();
    }
    room_.notify_all();
    writer_->write(draw(tick.first, tick.second.get()));
    std::lock_guard lock(mutex_);
    ++written_;
  }
}

cv::Mat OverlayVideo::draw(const LiveStatus& s, const Frame* frame) const {
  const int width = image_width_ * scale_, height = image_height_ * scale_;
  cv::Mat image(height + kBandHeight, width, CV_8UC3, cv::Scalar(25, 25, 25));
  std::vector<uint8_t> rgb;
  if (frame && frame_to_model_rgb(frame->bgr, image_height_, image_width_, rgb).ok()) {
    cv::Mat bgr;
    cv::cvtColor(cv::Mat(image_height_, image_width_, CV_8UC3, rgb.data()), bgr, cv::COLOR_RGB2BGR);
    cv::resize(bgr, image(cv::Rect(0, 0, width, height)), {width, height}, 0, 0, cv::INTER_NEAREST);
  }
  char line[160];
  std::snprintf(line, sizeof line, "tick %lld  %s  %u/%u us", static_cast<long long>(s.tick), s.driver.c_str(),
                s.command.steering_us, s.command.throttle_us);
  cv::putText(image, line, {6, 18}, cv::FONT_HERSHEY_SIMPLEX, 0.5, kWhite, 1, cv::LINE_AA);
  if (!s.fault.empty()) cv::putText(image, s.fault, {6, 38}, cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(80, 80, 255), 1, cv::LINE_AA);
  const int half = width / 2 - 15;
  gauge(image, cv::Rect(10, height + 20, half, 16), s.steering, kSteeringColour, "steering");
  gauge(image, cv::Rect(width / 2 + 5, height + 20, half, 16), s.throttle, kThrottleColour, "throttle");
  const cv::Rect plan(10, height + 48, width - 20, kBandHeight - 56);
  cv::rectangle(image, plan, cv::Scalar(45, 45, 45), cv::FILLED);
  ahead(image, plan, s.steering_ahead, kSteeringColour);
  ahead(image, plan, s.throttle_ahead, kThrottleColour);
  return image;
}

}  // namespace act::drive
