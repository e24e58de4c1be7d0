// act_drive --gamepad /dev/input/eventN: driving by hand with a gamepad, read through Debian's
// libevdev. The left stick steers, the right stick's vertical axis is the throttle (up = forward;
// the left stick's when the pad has no right stick), the east button (B / circle) is an e-stop and
// Start resumes: whoever holds the pad stands by the car, so it needs no token.
#pragma once

#include <atomic>
#include <cstdint>
#include <ostream>
#include <string>
#include <thread>

#include "apps/drive/cockpit.h"

struct libevdev;

namespace act::drive {

/// evdev events -> stick positions and buttons (no device: the tests feed it events).
class GamepadMapping {
 public:
  struct Axis {
    uint16_t code;
    int minimum, maximum;
  };
  enum class Action { kNone, kMoved, kEstop, kResume };
  GamepadMapping(Axis steering, Axis throttle) : steering_axis_(steering), throttle_axis_(throttle) {}
  /// One event (linux/input.h type, code, value): what it asks for.
  Action on_event(uint16_t type, uint16_t code, int32_t value);
  double steering() const { return steering_; }  ///< -1 (left) .. +1 (right)
  double throttle() const { return throttle_; }  ///< -1 (reverse) .. +1 (forward)
  /// Either stick away from its centre (beyond the dead zone).
  bool active() const;

 private:
  Axis steering_axis_, throttle_axis_;
  double steering_ = 0, throttle_ = 0;
};

/// A thread reading one gamepad into the cockpit: the sticks' positions ten times a second while
/// either is off centre and once when both return; the buttons at once.
class Gamepad {
 public:
  /// Opens `path`; throws act::Error naming it when it is not a readable gamepad.
  Gamepad(const std::string& path, Cockpit& cockpit, std::ostream& log);
  ~Gamepad();
  Gamepad(const Gamepad&) = delete;
  Gamepad& operator=(const Gamepad&) = delete;
  const std::string& name() const { return name_; }

 private:
  void run();

  Cockpit& cockpit_;
  std::ostream& log_;
  int fd_ = -1;
  ::libevdev* device_ = nullptr;
  std::string path_, name_;
  GamepadMapping mapping_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace act::drive
