#include "apps/drive/pwm_link.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <thread>
#include <vector>

#include "actengine/status.h"
#include "apps/drive/emergency_neutral.h"
#include "apps/executable_dir.h"

namespace act::drive {
namespace {

namespace fs = std::filesystem;

constexpr const char* kPermissionHint =
    "permission denied: run act_drive as a member of the 'gpio' group (Raspberry Pi OS's udev rules give it the "
    "PWM files; elsewhere add a udev rule: SUBSYSTEM==\"pwm*\", PROGRAM=\"/bin/sh -c 'chgrp -R gpio /sys/class/pwm "
    "&& chmod -R g=u /sys/class/pwm'\") or as root";

// Sysfs attributes are written whole; O_APPEND makes a plain file (the tests' fake tree) keep every value
// written, one a line, and changes nothing for sysfs, which ignores the file offset.
int open_attribute(const std::string& path) { return ::open(path.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC); }

std::string format_value(int64_t value) { return std::to_string(value) + "\n"; }

bool write_text(int fd, const std::string& text) {
  return ::write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size());
}

// Writes `value` to the attribute file `path` once (setup): 0, or the errno of the failed write.
// Throws naming the file when it cannot be opened.
int try_write_attribute(const std::string& path, int64_t value) {
  const int fd = open_attribute(path);
  if (fd < 0) {
    const int err = errno;
    fail(StatusCode::kIoError, "cannot open " + path + ": " + (err == EACCES ? kPermissionHint : std::strerror(err)));
  }
  const int err = write_text(fd, format_value(value)) ? 0 : errno;
  ::close(fd);
  return err;
}

void check_written(int err, const std::string& path, int64_t value) {
  check(err == 0, StatusCode::kIoError, "cannot write " + std::to_string(value) + " to " + path + ": " + std::strerror(err));
}

void write_attribute(const std::string& path, int64_t value) { check_written(try_write_attribute(path, value), path, value); }

int64_t duty_ns(uint16_t pulse_us) { return static_cast<int64_t>(pulse_us) * 1000; }

bool in_range(uint16_t us) { return us >= ROVER_PWM_MIN_US && us <= ROVER_PWM_MAX_US; }

int read_channel_count(const std::string& chip_dir) {
  std::ifstream in(chip_dir + "/npwm");
  int count = -1;
  in >> count;
  return in ? count : -1;
}

}  // namespace

PwmChannels parse_pwm_channels(const std::string& text) {
  const auto bad = [&] {
    fail(StatusCode::kInvalidArgument, "--pwm '" + text + "': expected CHIP:STEERING,THROTTLE, e.g. pwmchip0:0,1");
  };
  const size_t colon = text.find(':'), comma = text.find(',');
  if (colon == std::string::npos || colon == 0 || comma == std::string::npos || comma < colon) bad();
  PwmChannels channels;
  channels.chip = text.substr(0, colon);
  if (channels.chip.find('/') != std::string::npos) bad();
  const auto number = [&](const std::string& part) {
    if (part.empty() || part.size() > 3 || !std::all_of(part.begin(), part.end(), [](char c) { return c >= '0' && c <= '9'; })) bad();
    return std::stoi(part);
  };
  channels.steering = number(text.substr(colon + 1, comma - colon - 1));
  channels.throttle = number(text.substr(comma + 1));
  check(channels.steering != channels.throttle, StatusCode::kInvalidArgument,
        "--pwm '" + text + "': steering and throttle need two different channels");
  return channels;
}

// ---- PwmSysfsLink ----

PwmSysfsLink::PwmSysfsLink(PwmLinkOptions options, std::ostream& log) : options_(std::move(options)), log_(log) {
  check(in_range(options_.neutral.steering_us) && in_range(options_.neutral.throttle_us), StatusCode::kInvalidArgument,
        "the neutral pulse widths are outside " + std::to_string(ROVER_PWM_MIN_US) + ".." + std::to_string(ROVER_PWM_MAX_US) + " us");
  const std::string chip_dir = options_.sysfs_root + "/" + options_.channels.chip;
  check(fs::is_directory(chip_dir), StatusCode::kNotFound,
        "no PWM chip " + chip_dir + ": the kernel's PWM driver is not enabled; " + kPwmOverlayHint +
            "; act_drive --list-ports lists the chips found");
  const int count = read_channel_count(chip_dir);
  check(count > 0, StatusCode::kIoError, "cannot read the channel count " + chip_dir + "/npwm");
  for (const int channel : {options_.channels.steering, options_.channels.throttle}) {
    check(channel < count, StatusCode::kNotFound,
          chip_dir + " has " + std::to_string(count) + " channel" + (count == 1 ? "" : "s") + " (0.." + std::to_string(count - 1) +
              "), not " + std::to_string(channel) + "; " + kPwmOverlayHint);
  }
  try {
    open_channel(steering_, options_.channels.steering, options_.neutral.steering_us);
    open_channel(throttle_, options_.channels.throttle, options_.neutral.throttle_us);
    start_watchdog();
  } catch (...) {
    close_all();
    throw;
  }
  const std::string neutral_steering = format_value(duty_ns(options_.neutral.steering_us));
  const std::string neutral_throttle = format_value(duty_ns(options_.neutral.throttle_us));
  const EmergencyWrite neutral[] = {{steering_.duty_fd, neutral_steering}, {throttle_.duty_fd, neutral_throttle}};
  arm_emergency_writes(neutral);
}

PwmSysfsLink::~PwmSysfsLink() { shutdown(options_.neutral); }

void PwmSysfsLink::open_channel(Channel& channel, int number, uint16_t neutral_us) {
  const std::string chip_dir = options_.sysfs_root + "/" + options_.channels.chip;
  channel.dir = chip_dir + "/pwm" + std::to_string(number);
  if (!fs::exists(channel.dir)) write_attribute(chip_dir + "/export", number);
  // After an export udev needs a moment to give the new files their group and mode.
  const auto deadline = Clock::now() + options_.export_timeout;
  int err = 0;
  while ((channel.duty_fd = open_attribute(channel.dir + "/duty_cycle")) < 0) {
    err = errno;
    if ((err != ENOENT && err != EACCES) || Clock::now() > deadline) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  if (channel.duty_fd < 0) {
    fail(err == ENOENT ? StatusCode::kNotFound : StatusCode::kIoError,
         "PWM channel " + channel.dir + " is not usable: " +
             (err == EACCES ? std::string(kPermissionHint)
                            : std::string(std::strerror(err)) + (err == ENOENT ? std::string("; ") + kPwmOverlayHint : "")));
  }
  // The kernel refuses a period shorter than the duty cycle a previous user left (and any duty cycle
  // before a period is set): the period first, and after clearing the duty cycle when refused.
  const std::string period = channel.dir + "/period";
  err = try_write_attribute(period, kServoPeriodNs);
  if (err == EINVAL) {
    write_attribute(channel.dir + "/duty_cycle", 0);
    err = try_write_attribute(period, kServoPeriodNs);
  }
  check_written(err, period, kServoPeriodNs);
  write_attribute(channel.dir + "/duty_cycle", duty_ns(neutral_us));
  write_attribute(channel.dir + "/enable", 1);
}

void PwmSysfsLink::start_watchdog() {
  int pair[2];
  check(::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, pair) == 0, StatusCode::kIoError,
        std::string("cannot create the watchdog's heartbeat socket: ") + std::strerror(errno));
  heartbeat_fd_ = pair[0];
  const int child_end = pair[1];
  // Everything the child needs is built before fork: act_drive's other threads are running, so the
  // child may only make async-signal-safe calls until exec.
  std::vector<std::string> args = {options_.watchdog_path,
                                   "--heartbeat-fd", std::to_string(child_end),
                                   "--stale-ms", std::to_string(options_.watchdog_stale.count()),
                                   "--neutral", steering_.dir + "/duty_cycle=" + std::to_string(duty_ns(options_.neutral.steering_us)),
                                   "--neutral", throttle_.dir + "/duty_cycle=" + std::to_string(duty_ns(options_.neutral.throttle_us))};
  std::vector<char*> argv;
  for (std::string& arg : args) argv.push_back(arg.data());
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid == 0) {
    // Its own session: a signal to act_drive's process group (Ctrl-C, a terminal hang-up, kill -- -PGID)
    // does not reach it.
    ::setsid();
    ::fcntl(child_end, F_SETFD, 0);  // the one descriptor it keeps across exec
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  const int fork_error = errno;
  ::close(child_end);
  check(pid > 0, StatusCode::kIoError,
        std::string("cannot start the PWM watchdog: fork: ") + std::strerror(fork_error));
  watchdog_pid_ = pid;
  // It answers with one byte once it holds the duty-cycle files open; an exec or open failure closes the socket.
  pollfd ready{heartbeat_fd_, POLLIN, 0};
  char answer = 0;
  const bool started = ::poll(&ready, 1, 5000) == 1 && ::read(heartbeat_fd_, &answer, 1) == 1 && answer == 'R';
  if (!started) {
    ::kill(pid, SIGKILL);
    ::waitpid(pid, nullptr, 0);
    watchdog_pid_ = -1;
    fail(StatusCode::kIoError, "the PWM watchdog " + options_.watchdog_path +
                                   " did not start (its message, if any, is above; act_drive does not drive PWM without it)");
  }
}

bool PwmSysfsLink::write_duty(PwmCommand command) {
  const bool ok = write_text(steering_.duty_fd, format_value(duty_ns(command.steering_us))) &&
                  write_text(throttle_.duty_fd, format_value(duty_ns(command.throttle_us)));
  if (!ok && ++write_errors_ <= 5) {
    log_ << "act_drive: warning: writing the PWM duty cycles failed: " << std::strerror(errno)
         << (write_errors_ == 5 ? " (further failures are only counted)" : "") << "\n";
  }
  return ok;
}

bool PwmSysfsLink::beat() {
  if (watchdog_lost_) return false;
  const char beat_byte = 'h';
  if (::send(heartbeat_fd_, &beat_byte, 1, MSG_NOSIGNAL | MSG_DONTWAIT) == 1 || errno == EAGAIN || errno == EINTR) {
    return true;  // a full buffer: the watchdog is slow to read, not gone
  }
  const int err = errno;
  watchdog_lost_ = true;
  log_ << "act_drive: error: the PWM watchdog (pid " << watchdog_pid_ << ") is gone (" << std::strerror(err)
       << "): holding neutral from now on\n";
  write_duty(options_.neutral);
  return false;
}

bool PwmSysfsLink::send(PwmCommand command, Clock::time_point now) {
  if (shut_down_) return false;
  poll(now);
  if (watchdog_lost_) return false;
  if (!in_range(command.steering_us) || !in_range(command.throttle_us)) {
    if (++rejected_ <= 5) {
      log_ << "act_drive: warning: refused PWM command " << command.steering_us << "/" << command.throttle_us << " us (outside "
           << ROVER_PWM_MIN_US << ".." << ROVER_PWM_MAX_US << "): neutral instead\n";
    }
    write_duty(options_.neutral);
    return false;
  }
  if (!write_duty(command)) return false;
  ++commands_;
  return true;
}

void PwmSysfsLink::poll(Clock::time_point) {
  if (!shut_down_) beat();
}

void PwmSysfsLink::shutdown(PwmCommand neutral) {
  if (shut_down_) return;
  shut_down_ = true;
  if (steering_.duty_fd >= 0 && throttle_.duty_fd >= 0) write_duty(neutral);
  close_all();
}

void PwmSysfsLink::close_all() {
  disarm_emergency_writes();
  for (Channel* channel : {&steering_, &throttle_}) {
    if (channel->duty_fd >= 0) ::close(channel->duty_fd);
    channel->duty_fd = -1;
  }
  if (heartbeat_fd_ >= 0) ::close(heartbeat_fd_);  // the watchdog sees the end, writes neutral and exits
  heartbeat_fd_ = -1;
  if (watchdog_pid_ > 0) {
    const auto deadline = Clock::now() + std::chrono::milliseconds(500);
    while (::waitpid(watchdog_pid_, nullptr, WNOHANG) == 0) {
      if (Clock::now() > deadline) {
        log_ << "act_drive: warning: the PWM watchdog (pid " << watchdog_pid_ << ") did not exit within 500 ms\n";
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    watchdog_pid_ = -1;
  }
}

std::string PwmSysfsLink::summary() const {
  return "pwm " + options_.sysfs_root + "/" + options_.channels.chip + " channels " + std::to_string(options_.channels.steering) +
         "," + std::to_string(options_.channels.throttle) + ": " + std::to_string(commands_) + " commands, " +
         std::to_string(rejected_) + " refused, " + std::to_string(write_errors_) + " write errors" +
         (watchdog_lost_ ? ", watchdog lost" : "");
}

std::string default_watchdog_path() { return (executable_dir() / "act_pwm_watchdog").string(); }

void list_pwm_channels(const std::string& root, std::ostream& out) {
  std::vector<fs::path> chips;
  std::error_code error;
  for (const auto& entry : fs::directory_iterator(root, error)) {
    if (entry.path().filename().string().rfind("pwmchip", 0) == 0) chips.push_back(entry.path());
  }
  std::sort(chips.begin(), chips.end());
  if (chips.empty()) {
    out << "pwm: no PWM chips under " << root << "; " << kPwmOverlayHint << "\n";
    return;
  }
  for (const fs::path& chip : chips) {
    const int count = read_channel_count(chip.string());
    out << "pwm: " << chip.string() << ": ";
    if (count <= 0) {
      out << "channel count unreadable\n";
      continue;
    }
    out << count << " channel" << (count == 1 ? "" : "s") << " (0.." << count - 1 << ")";
    if (count >= 2) out << ", e.g. --pwm " << chip.filename().string() << ":0,1";
    out << "\n";
  }
}

}  // namespace act::drive
