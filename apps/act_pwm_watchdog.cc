// act_pwm_watchdog: makes the car safe when act_drive --pwm cannot. The kernel keeps driving the last
// duty cycle when act_drive dies (SIGKILL, the OOM killer, a crash no handler catches) or hangs, so
// act_drive starts this process in a session of its own and beats it through a socket every control
// tick. When the socket ends (act_drive is gone) it writes the neutral duty cycles and exits; when
// the beats stop for --stale-ms (act_drive hangs or is stopped) it writes them and keeps watching.
// Plain POSIX and nothing else: it must start fast and cannot fail in interesting ways.
#include <CLI/CLI.hpp>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "apps/version.h"

namespace {

using Clock = std::chrono::steady_clock;

struct NeutralWrite {
  int fd = -1;
  std::string text;  // the duty cycle in ns and a newline
};

// Filled before the handlers are installed, then only read.
std::vector<NeutralWrite> g_neutral;

void write_neutral() noexcept {
  for (const NeutralWrite& w : g_neutral) {
    const ssize_t ignored = ::write(w.fd, w.text.data(), w.text.size());
    (void)ignored;
  }
}

// A plain kill (a service manager stopping everything) still leaves the car at neutral.
void neutral_then_exit(int) {
  write_neutral();
  ::_exit(0);
}

long elapsed_ms(Clock::time_point since) {
  return static_cast<long>(std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - since).count());
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"act_pwm_watchdog: writes neutral PWM duty cycles when act_drive's heartbeat ends or stops. "
               "Started by act_drive --pwm; not meant to be run by hand."};
  int heartbeat_fd = -1;
  int stale_ms = 250;
  std::vector<std::string> neutral_specs;
  app.add_option("--heartbeat-fd", heartbeat_fd, "the socket act_drive beats")->required()->check(CLI::NonNegativeNumber);
  app.add_option("--stale-ms", stale_ms, "write neutral after this long without a beat")->capture_default_str()
      ->check(CLI::Range(10, 10000));
  app.add_option("--neutral", neutral_specs, "DUTY_CYCLE_FILE=NANOSECONDS, once per channel")->required();
  app.set_version_flag("--version", act::version_line("act_pwm_watchdog"));
  CLI11_PARSE(app, argc, argv);

  for (const std::string& spec : neutral_specs) {
    const size_t equals = spec.rfind('=');
    if (equals == std::string::npos || equals == 0 || equals + 1 == spec.size()) {
      std::fprintf(stderr, "act_pwm_watchdog: --neutral '%s': expected FILE=NANOSECONDS\n", spec.c_str());
      return 2;
    }
    const std::string path = spec.substr(0, equals);
    const int fd = ::open(path.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
    if (fd < 0) {
      std::fprintf(stderr, "act_pwm_watchdog: cannot open %s: %s\n", path.c_str(), std::strerror(errno));
      return 1;
    }
    g_neutral.push_back({fd, spec.substr(equals + 1) + "\n"});
  }
  // act_drive's signal mask and handlers are not this process's: unblock everything, ignore the
  // terminal's signals (it has none: setsid) and a closed socket's SIGPIPE.
  sigset_t none;
  sigemptyset(&none);
  sigprocmask(SIG_SETMASK, &none, nullptr);
  std::signal(SIGPIPE, SIG_IGN);
  std::signal(SIGHUP, SIG_IGN);
  std::signal(SIGINT, SIG_IGN);
  std::signal(SIGTERM, neutral_then_exit);

  const char ready = 'R';
  if (::write(heartbeat_fd, &ready, 1) != 1) {
    write_neutral();  // act_drive is already gone
    return 0;
  }
  Clock::time_point last_beat = Clock::now();
  bool holding_neutral = false;
  for (;;) {
    const long wait_ms = holding_neutral ? -1 : std::max(0L, stale_ms - elapsed_ms(last_beat));
    pollfd heartbeat{heartbeat_fd, POLLIN, 0};
    const int events = ::poll(&heartbeat, 1, static_cast<int>(wait_ms));
    if (events < 0 && errno != EINTR) {
      write_neutral();
      std::fprintf(stderr, "act_pwm_watchdog: poll failed (%s): neutral written, exiting\n", std::strerror(errno));
      return 1;
    }
    if (events > 0) {
      char beats[256];
      const ssize_t n = ::read(heartbeat_fd, beats, sizeof beats);
      if (n == 0 || (n < 0 && errno != EINTR && errno != EAGAIN)) {
        // act_drive exited or died: whatever it managed to write last, the car stops now.
        write_neutral();
        return 0;
      }
      if (n > 0) {
        last_beat = Clock::now();
        if (holding_neutral) std::fprintf(stderr, "act_pwm_watchdog: act_drive's heartbeat is back\n");
        holding_neutral = false;
      }
    }
    if (!holding_neutral && elapsed_ms(last_beat) >= stale_ms) {
      write_neutral();
      holding_neutral = true;
      std::fprintf(stderr, "act_pwm_watchdog: no heartbeat from act_drive for %ld ms (hung or stopped): neutral written\n",
                   elapsed_ms(last_beat));
    }
  }
}
