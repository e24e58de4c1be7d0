#include "apps/progress.h"

#include <unistd.h>

#include <cmath>

namespace act {

namespace {

// "42 s", "3 min 05 s", "1 h 02 min".
std::string duration_text(double seconds) {
  char buf[32];
  const long s = std::lround(seconds);
  if (s < 60) {
    std::snprintf(buf, sizeof buf, "%ld s", s);
  } else if (s < 3600) {
    std::snprintf(buf, sizeof buf, "%ld min %02ld s", s / 60, s % 60);
  } else {
    std::snprintf(buf, sizeof buf, "%ld h %02ld min", s / 3600, s / 60 % 60);
  }
  return buf;
}

}  // namespace

ProgressLine::ProgressLine(std::FILE* out, std::string prefix, bool terminal)
    : out_(out), prefix_(std::move(prefix)), terminal_(terminal) {}

ProgressLine::~ProgressLine() { finish(); }

bool ProgressLine::stderr_is_terminal() { return ::isatty(STDERR_FILENO) == 1; }

std::string ProgressLine::render(size_t done, size_t total, const char* unit) const {
  std::string text = prefix_ + ": " + task_ + ": " + std::to_string(done) + "/" + std::to_string(total) + " " + unit;
  const double elapsed = std::chrono::duration<double>(Clock::now() - started_).count();
  if (done > 0 && elapsed > 0) {
    const double rate = static_cast<double>(done) / elapsed;
    char buf[96];
    if (rate >= 1) {
      std::snprintf(buf, sizeof buf, ", %.1f/s", rate);
    } else {
      std::snprintf(buf, sizeof buf, ", %.1f s each", 1 / rate);
    }
    text += buf;
    if (done < total) text += ", " + duration_text(static_cast<double>(total - done) / rate) + " left";
  }
  return text;
}

void ProgressLine::update(const std::string& task, size_t done, size_t total, const char* unit) {
  if (task != task_) {
    finish();
    task_ = task;
    started_ = Clock::now();
    printed_quarter_ = 0;
    if (!terminal_) std::fprintf(out_, "%s\n", render(done, total, unit).c_str());
  }
  if (terminal_) {
    std::fprintf(out_, "\r%s\033[K", render(done, total, unit).c_str());
    line_open_ = true;
  } else if (total > 0 && done * 4 / total > printed_quarter_) {
    printed_quarter_ = done * 4 / total;
    std::fprintf(out_, "%s\n", render(done, total, unit).c_str());
  }
  std::fflush(out_);
}

void ProgressLine::message(const std::string& text) {
  finish();
  std::fprintf(out_, "%s: %s\n", prefix_.c_str(), text.c_str());
  std::fflush(out_);
}

void ProgressLine::finish() {
  if (!line_open_) return;
  std::fputc('\n', out_);
  std::fflush(out_);
  line_open_ = false;
}

}  // namespace act
