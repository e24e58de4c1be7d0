// Progress of a long loop on stderr, one way for every app (act_convert's calibration and mixed
// search, act_bench's runs): on a terminal one line rewritten in place (carriage return) with the
// count, the rate and the time left; elsewhere (a log file, CI) a plain line at the start of each
// task and at each quarter of it, so a log stays short.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdio>
#include <string>

namespace act {

class ProgressLine {
 public:
  /// `prefix` starts every line ("act_convert"); `terminal`: render in place (see stderr_is_terminal).
  ProgressLine(std::FILE* out, std::string prefix, bool terminal);
  ~ProgressLine();  // ends an open line
  ProgressLine(const ProgressLine&) = delete;
  ProgressLine& operator=(const ProgressLine&) = delete;

  /// True when stderr is a terminal (the apps' progress goes there).
  static bool stderr_is_terminal();

  /// `done` of `total` `unit`s of `task` (e.g. "calibrating (mse)", 3, 64, "frames"). A new
  /// task restarts the clock for its rate; report done 0 at its start so the first rate is right.
  void update(const std::string& task, size_t done, size_t total, const char* unit);
  /// A line of its own (ends an open progress line first).
  void message(const std::string& text);
  /// Ends an open progress line.
  void finish();

 private:
  using Clock = std::chrono::steady_clock;
  std::string render(size_t done, size_t total, const char* unit) const;

  std::FILE* out_;
  std::string prefix_;
  bool terminal_;
  bool line_open_ = false;     // terminal: a progress line without its newline yet
  std::string task_;           // the current task
  Clock::time_point started_;  // when it started
  size_t printed_quarter_ = 0;  // not a terminal: the last quarter printed (1..4; 0 = the start)
};

}  // namespace act
