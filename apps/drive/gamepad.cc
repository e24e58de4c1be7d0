#include "apps/drive/gamepad.h"

#include <fcntl.h>
#include <libevdev/libevdev.h>
#include <poll.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>

#include "actengine/status.h"

namespace act::drive {
namespace {

// Sticks rest a little off centre.
constexpr double kStickDeadZone = 0.08;
constexpr int kPostEveryMs = 100;

double position(int32_t value, const GamepadMapping::Axis& axis) {
  if (axis.maximum <= axis.minimum) return 0;
  const double p = 2.0 * (value - axis.minimum) / (axis.maximum - axis.minimum) - 1.0;
  return std::abs(p) < kStickDeadZone ? 0.0 : std::clamp(p, -1.0, 1.0);
}

GamepadMapping::Axis axis_of(libevdev* device, uint16_t code) {
  const input_absinfo* info = libevdev_get_abs_info(device, code);
  return {code, info->minimum, info->maximum};
}

}  // namespace

GamepadMapping::Action GamepadMapping::on_event(uint16_t type, uint16_t code, int32_t value) {
  if (type == EV_KEY && value == 1) {
    if (code == BTN_EAST) return Action::kEstop;
    if (code == BTN_START) return Action::kResume;
  }
  if (type != EV_ABS) return Action::kNone;
  if (code == steering_axis_.code) {
    steering_ = position(value, steering_axis_);
    return Action::kMoved;
  }
  if (code == throttle_axis_.code) {
    throttle_ = -position(value, throttle_axis_);  // evdev's Y grows downwards; up is forward
    return Action::kMoved;
  }
  return Action::kNone;
}

bool GamepadMapping::active() const { return steering_ != 0 || throttle_ != 0; }

Gamepad::Gamepad(const std::string& path, Cockpit& cockpit, std::ostream& log)
    : cockpit_(cockpit), log_(log), path_(path), mapping_({ABS_X, 0, 0}, {ABS_RY, 0, 0}) {
  fd_ = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd_ < 0) fail(StatusCode::kIoError, "--gamepad: cannot open " + path + ": " + std::strerror(errno));
  if (const int rc = libevdev_new_from_fd(fd_, &device_); rc < 0) {
    ::close(fd_);
    fail(StatusCode::kInvalidArgument, "--gamepad: " + path + " is not an input device: " + std::strerror(-rc));
  }
  name_ = libevdev_get_name(device_) ? libevdev_get_name(device_) : "";
  if (!libevdev_has_event_code(device_, EV_ABS, ABS_X)) {
    libevdev_free(device_);
    ::close(fd_);
    fail(StatusCode::kInvalidArgument, "--gamepad: " + path + " (" + name_ + ") has no stick (no ABS_X axis): not a gamepad");
  }
  const uint16_t throttle = libevdev_has_event_code(device_, EV_ABS, ABS_RY) ? ABS_RY : ABS_Y;
  mapping_ = GamepadMapping(axis_of(device_, ABS_X), axis_of(device_, throttle));
  thread_ = std::thread([this] { run(); });
}

Gamepad::~Gamepad() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
  libevdev_free(device_);
  ::close(fd_);
}

void Gamepad::run() {
  bool was_active = false;
  auto last_post = std::chrono::steady_clock::now();
  while (!stop_.load()) {
    pollfd ready{fd_, POLLIN, 0};
    ::poll(&ready, 1, kPostEveryMs);
    input_event ev{};
    int rc = 0;
    while ((rc = libevdev_next_event(device_, LIBEVDEV_READ_FLAG_NORMAL, &ev)) == LIBEVDEV_READ_STATUS_SUCCESS ||
           rc == LIBEVDEV_READ_STATUS_SYNC) {
      switch (mapping_.on_event(ev.type, ev.code, ev.value)) {
        case GamepadMapping::Action::kEstop: cockpit_.estop(); break;
        case GamepadMapping::Action::kResume: cockpit_.resume(); break;
        default: break;
      }
    }
    if (rc != -EAGAIN) {
      // Unplugged: a human who was driving stops driving (the cockpit's manual input goes stale).
      log_ << "act_drive: warning: gamepad " << path_ << " (" << name_ << ") is gone: " << std::strerror(-rc) << "\n";
      return;
    }
    const auto now = std::chrono::steady_clock::now();
    const bool active = mapping_.active();
    if ((active && now - last_post >= std::chrono::milliseconds(kPostEveryMs)) || active != was_active) {
      cockpit_.manual(mapping_.steering(), mapping_.throttle());
      last_post = now;
    }
    was_active = active;
  }
}

}  // namespace act::drive
