#include "apps/drive/cockpit.h"

#include <cmath>

namespace act::drive {
namespace {

// A stick or key this far from centre is an input (gamepad sticks rest slightly off centre).
constexpr double kInputDeadZone = 0.05;

}  // namespace

const char* mode_name(DriveMode mode) {
  switch (mode) {
    case DriveMode::kAi: return "ai";
    case DriveMode::kManual: return "manual";
    case DriveMode::kAiSteer: return "ai-steer";
  }
  return "?";
}

std::optional<DriveMode> parse_mode(const std::string& name) {
  for (DriveMode mode : {DriveMode::kAi, DriveMode::kManual, DriveMode::kAiSteer}) {
    if (name == mode_name(mode)) return mode;
  }
  return std::nullopt;
}

void Cockpit::estop() {
  std::lock_guard lock(mutex_);
  estopped_ = true;
}

void Cockpit::resume() {
  std::lock_guard lock(mutex_);
  estopped_ = false;
  overridden_ = false;
}

void Cockpit::set_mode(DriveMode mode) {
  std::lock_guard lock(mutex_);
  mode_ = mode;
  overridden_ = false;
}

void Cockpit::manual(double steering, double throttle) {
  if (!std::isfinite(steering) || !std::isfinite(throttle)) return;
  std::lock_guard lock(mutex_);
  steering_ = steering;
  throttle_ = throttle;
  manual_at_ = Clock::now();
  const bool steers = std::abs(steering) > kInputDeadZone, moves = steers || std::abs(throttle) > kInputDeadZone;
  if ((mode_ == DriveMode::kAi && moves) || (mode_ == DriveMode::kAiSteer && steers)) overridden_ = true;
}

PilotInput Cockpit::input(Clock::time_point now) const {
  std::lock_guard lock(mutex_);
  PilotInput in{estopped_, mode_, overridden_, 0, 0};
  if (now - manual_at_ <= kManualTimeout) {
    in.steering = steering_;
    in.throttle = throttle_;
  }
  return in;
}

void Cockpit::publish(LiveStatus&& status) {
  std::unique_lock lock(status_mutex_, std::try_to_lock);
  if (lock.owns_lock()) std::swap(status_, status);
}

LiveStatus Cockpit::status() const {
  std::lock_guard lock(status_mutex_);
  return status_;
}

}  // namespace act::drive
