// Test doubles for act_drive: a model whose output and speed the test controls, a frame source the
// test feeds by hand, and a short video file for the real camera.
#pragma once

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include <opencv2/imgproc.hpp>

#include "apps/drive/calibration.h"
#include "apps/drive/camera.h"
#include "apps/drive/inference.h"
#include "engine/media/media_io.h"

namespace act::drive::test {

/// Prints how long a fault took to reach neutral on the wire, for docs/reliability.md's fault-timing table
/// (scripts/fault_timing.sh collects these lines; the tests themselves assert only the safety bound).
inline void report_fault_timing(const std::string& fault, double ms, const char* until = "neutral on the wire") {
  std::printf("[fault timing] %s: %.1f ms to %s\n", fault.c_str(), ms, until);
}

/// The control loop's fault tests (serial and PWM): the bound, the safe command, the calibration they
/// drive through and what the fake model's default 0.5 / 0.8 becomes through it.
constexpr auto kFaultDeadline = std::chrono::milliseconds(250);
const PwmCommand kSafe{1500, 1500};
const PwmCommand kDriving{1700, 1650};

inline Calibration test_calibration() {
  return Calibration::from_json(nlohmann::json::parse(R"({
    "steering": {"left_us": 1100, "center_us": 1500, "right_us": 1900},
    "throttle": {"reverse_us": 1300, "neutral_us": 1500, "forward_us": 1800, "max_forward": 0.5}})"),
                                "test");
}

inline double ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

/// Polls `done` until it holds or `limit` passes (a hang detector, not a timing requirement).
inline bool eventually(const std::function<bool()>& done, std::chrono::seconds limit = std::chrono::seconds(10)) {
  const auto deadline = Clock::now() + limit;
  while (!done()) {
    if (Clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return true;
}

/// What a FakeModel does; shared between the test and the model living on the worker thread.
struct FakeModelControls {
  std::atomic<float> steering{0.5f};
  std::atomic<float> throttle{0.8f};
  std::atomic<bool> return_nan{false};
  std::atomic<int> delay_ms{5};
  std::atomic<int> inferences{0};
  std::mutex mutex;
  std::optional<Clock::time_point> first_nan_returned;  // guarded by mutex
};

inline ModelInfo fake_model_info(bool ensembling = false, int n_action_steps = 10) {
  ModelInfo info;
  info.cameras = {{"observation.images.front", 48, 64}};
  info.state_dim = 2;
  info.action_dim = 2;
  info.chunk_size = ensembling ? 20 : std::max(10, n_action_steps);
  info.n_action_steps = ensembling ? 1 : n_action_steps;
  info.temporal_ensembling = ensembling;
  info.temporal_ensemble_coeff = ensembling ? 0.01 : 0.0;
  info.precision = "fp32";
  info.summary = "fake model";
  return info;
}

/// Returns a constant chunk (steering, throttle from the controls), or NaN when told to.
class FakeModel : public ChunkModel {
 public:
  FakeModel(ModelInfo info, std::shared_ptr<FakeModelControls> controls) : info_(std::move(info)), controls_(std::move(controls)) {}
  const ModelInfo& info() const override { return info_; }
  Status infer(const Observation& observation, std::span<float> chunk) override {
    EXPECT_EQ(observation.images.size(), 1u);
    EXPECT_EQ(observation.state.size(), static_cast<size_t>(info_.state_dim));
    std::this_thread::sleep_for(std::chrono::milliseconds(controls_->delay_ms.load()));
    const bool nan = controls_->return_nan.load();
    for (int i = 0; i < info_.chunk_size; ++i) {
      chunk[static_cast<size_t>(i) * 2] = nan ? std::numeric_limits<float>::quiet_NaN() : controls_->steering.load();
      chunk[static_cast<size_t>(i) * 2 + 1] = controls_->throttle.load();
    }
    if (nan) {
      std::lock_guard lock(controls_->mutex);
      if (!controls_->first_nan_returned) controls_->first_nan_returned = Clock::now();
    }
    controls_->inferences.fetch_add(1);
    return Status::ok_status();
  }

 private:
  ModelInfo info_;
  std::shared_ptr<FakeModelControls> controls_;
};

/// Frames pushed by the test (a camera that can freeze at a moment the test chooses).
class ManualFrameSource : public FrameSource {
 public:
  std::shared_ptr<const Frame> latest() const override {
    std::lock_guard lock(mutex_);
    return latest_;
  }
  State state() const override { return State::kRunning; }
  std::string problem() const override { return ""; }
  void push() {
    auto frame = std::make_shared<const Frame>(Frame{cv::Mat(48, 64, CV_8UC3, cv::Scalar(10, 20, 30)), Clock::now(), index_++});
    std::lock_guard lock(mutex_);
    latest_ = std::move(frame);
  }

 private:
  mutable std::mutex mutex_;
  std::shared_ptr<const Frame> latest_;
  uint64_t index_ = 0;
};

/// Writes an MJPG .avi of `frames` frames (a moving gradient) at `fps`.
inline std::string write_test_video(const std::string& path, int frames, double fps, int width = 64, int height = 48) {
  const std::unique_ptr<act::media::VideoWriter> writer = act::media::create_video(path, "MJPG", fps, cv::Size(width, height));
  if (!writer) throw std::runtime_error("cannot write test video " + path);
  for (int i = 0; i < frames; ++i) {
    cv::Mat image(height, width, CV_8UC3);
    for (int y = 0; y < height; ++y) {
      for (int x = 0; x < width; ++x) image.at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<uint8_t>(x * 4 + i), static_cast<uint8_t>(y * 5), 128);
    }
    writer->write(image);
  }
  return path;
}

}  // namespace act::drive::test
