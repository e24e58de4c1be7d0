// What passes between act_drive's control loop and the people watching it (the live web page, a
// gamepad): their inputs (e-stop, mode, driving by hand) and the loop's status for display.
//
// The control loop never waits on a client: inputs are a few numbers behind a mutex that only this
// class's short sections hold, and the status is published with try_lock (a tick whose status a
// reader is copying just skips publishing).
#pragma once

#include <chrono>
#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "apps/drive/calibration.h"
#include "apps/drive/camera.h"

namespace act::drive {

/// DonkeyCar's local / user / local_angle: the policy drives, a human drives, or the policy steers
/// while a human holds the throttle.
enum class DriveMode { kAi, kManual, kAiSteer };
const char* mode_name(DriveMode mode);
/// "ai", "manual" or "ai-steer"; nullopt for anything else.
std::optional<DriveMode> parse_mode(const std::string& name);

/// The inputs as the control loop sees them at one tick.
struct PilotInput {
  bool estopped = false;
  DriveMode mode = DriveMode::kAi;
  bool overridden = false;         ///< manual input took over from the policy, until resume()
  double steering = 0, throttle = 0;  ///< the latest manual input, -1..1 on this car; 0 when stale
  /// A human drives both channels this tick.
  bool manual_drives() const { return mode == DriveMode::kManual || overridden; }
};

/// The control loop's status at its latest tick, for the page and /stats.
struct LiveStatus {
  int64_t tick = -1;
  double time_s = 0;
  std::string source, driver, fault;  ///< as recorded (recorder.h); fault "" when none
  PwmCommand command;
  double steering = 0, throttle = 0;  ///< the command sent, as positions -1..1 on this car
  /// The policy's coming commands (one per tick from this one on, positions -1..1): the chunk ahead.
  std::vector<float> steering_ahead, throttle_ahead;
  double capture_age_ms = 0, preprocess_ms = 0, infer_ms = 0, jitter_ms = 0;  ///< the latest of each
  uint64_t ticks = 0, inferences = 0, overruns = 0, frame_index = 0;
  PilotInput pilot;
  double control_hz = 0;
};

class Cockpit {
 public:
  /// Manual input older than this counts as released (a closed page or an unplugged gamepad stops
  /// the car instead of holding its last command).
  static constexpr std::chrono::milliseconds kManualTimeout{500};

  explicit Cockpit(DriveMode mode) : mode_(mode) {}

  /// Neutral from the next tick on, held until resume(). Anyone may press it.
  void estop();
  /// Ends an e-stop and a manual override: the mode's normal driver takes over again.
  void resume();
  void set_mode(DriveMode mode);
  /// A human's command, -1..1 on this car. In ai mode any input overrides the policy at once (until
  /// resume()); in ai-steer mode the throttle is the human's anyway and a steering input overrides.
  void manual(double steering, double throttle);
  /// The inputs at `now` (the control loop, each tick).
  PilotInput input(Clock::time_point now) const;

  /// The control loop: publishes its status unless a reader holds it right now (never waits).
  void publish(LiveStatus&& status);
  LiveStatus status() const;

 private:
  mutable std::mutex mutex_;
  bool estopped_ = false;     // guarded by mutex_
  DriveMode mode_;            // guarded by mutex_
  bool overridden_ = false;   // guarded by mutex_
  double steering_ = 0, throttle_ = 0;  // guarded by mutex_
  Clock::time_point manual_at_{};       // guarded by mutex_
  mutable std::mutex status_mutex_;
  LiveStatus status_;         // guarded by status_mutex_
};

}  // namespace act::drive
