// act_drive without an Arduino: the steering servo and the ESC on two channels of the Linux kernel's
// PWM driver (/sys/class/pwm; on a Raspberry Pi the pwm-2chan device-tree overlay), a 50 Hz servo
// period and pulse widths from the calibration file. The kernel keeps the last duty cycle when
// act_drive dies, so a separate process, act_pwm_watchdog (apps/act_pwm_watchdog.cc), writes
// neutral when act_drive's heartbeat stops: at once when act_drive is gone, after 250 ms when it hangs.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <cstdint>
#include <ostream>
#include <string>

#include "apps/drive/serial_link.h"

namespace act::drive {

inline constexpr const char* kPwmSysfsRoot = "/sys/class/pwm";
inline constexpr int64_t kServoPeriodNs = 20'000'000;  // 50 Hz, what every hobby servo and ESC expects
inline constexpr const char* kPwmOverlayHint =
    "on a Raspberry Pi add the line 'dtoverlay=pwm-2chan' to /boot/firmware/config.txt and reboot "
    "(it puts hardware PWM on GPIO 18 and 19; which chip and channel numbers they get depends on the model and kernel)";

/// `--pwm CHIP:STEERING,THROTTLE`, e.g. pwmchip0:0,1.
struct PwmChannels {
  std::string chip;
  int steering = 0;
  int throttle = 1;
};

/// Parses the --pwm text; throws act::Error(kInvalidArgument) naming it.
PwmChannels parse_pwm_channels(const std::string& text);

struct PwmLinkOptions {
  PwmChannels channels;
  /// Where the PWM chips are: /sys/class/pwm, or a fake tree in tests (act_drive --pwm-sysfs-root).
  std::string sysfs_root = kPwmSysfsRoot;
  /// Written on start, on every fault and on exit, and by the watchdog.
  PwmCommand neutral;
  /// The act_pwm_watchdog executable (default_watchdog_path()).
  std::string watchdog_path;
  /// The watchdog writes neutral when no heartbeat came for this long.
  std::chrono::milliseconds watchdog_stale{250};
  /// How long to wait for an exported channel's files to appear and become writable (udev sets their
  /// group and mode just after the export).
  std::chrono::milliseconds export_timeout{2000};
};

class PwmSysfsLink : public ActuatorLink {
 public:
  /// Exports and configures both channels, writes neutral, enables them and starts the watchdog.
  /// Throws act::Error naming the file and the fix (the overlay, permissions) when that fails.
  PwmSysfsLink(PwmLinkOptions options, std::ostream& log);
  ~PwmSysfsLink() override;
  PwmSysfsLink(const PwmSysfsLink&) = delete;
  PwmSysfsLink& operator=(const PwmSysfsLink&) = delete;

  /// Writes both duty cycles and beats the watchdog. False (and neutral written) when the command
  /// is outside the pulse-width range, a write failed, or the watchdog is gone: no driving without it.
  bool send(PwmCommand command, Clock::time_point now) override;
  /// Beats the watchdog.
  void poll(Clock::time_point now) override;
  /// Writes `neutral` (the channels stay enabled: an ESC holds neutral on a steady 1.5 ms pulse),
  /// then ends the watchdog, which writes neutral once more and exits. Idempotent.
  void shutdown(PwmCommand neutral) override;
  std::string summary() const override;

  pid_t watchdog_pid() const { return watchdog_pid_; }

 private:
  struct Channel {
    std::string dir;  // <root>/<chip>/pwm<N>
    int duty_fd = -1;
  };
  void open_channel(Channel& channel, int number, uint16_t neutral_us);
  void start_watchdog();
  bool write_duty(PwmCommand command);
  bool beat();
  void close_all();

  PwmLinkOptions options_;
  std::ostream& log_;
  Channel steering_, throttle_;
  int heartbeat_fd_ = -1;
  pid_t watchdog_pid_ = -1;
  bool watchdog_lost_ = false;
  bool shut_down_ = false;
  uint64_t commands_ = 0, rejected_ = 0, write_errors_ = 0;
};

/// The act_pwm_watchdog beside the running executable (both are installed in the same directory).
std::string default_watchdog_path();

/// For --list-ports: one line per PWM chip under `root` with its channel count, or one line saying
/// there is none and how to enable the overlay.
void list_pwm_channels(const std::string& root, std::ostream& out);

}  // namespace act::drive
