#include "apps/drive/recorder.h"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "weights/blob/error.h"

namespace fs = std::filesystem;

namespace act::drive {
namespace {

// Frames waiting for the disk beyond this are dropped (and counted) rather than growing memory.
constexpr size_t kMaxQueuedFrames = 64;

std::FILE* open_table(const fs::path& path) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) fail(ErrorCode::kIoError, "--record: cannot create " + path.string() + ": " + std::strerror(errno));
  return f;
}

// count values as ",v0,v1...", empty for missing ones.
void write_values(std::FILE* f, const std::vector<float>& values, size_t count) {
  for (size_t i = 0; i < count; ++i) {
    if (i < values.size()) {
      std::fprintf(f, ",%.9g", static_cast<double>(values[i]));
    } else {
      std::fputc(',', f);
    }
  }
}

}  // namespace

Recorder::Recorder(const std::string& dir, int state_dim, int action_dim, const nlohmann::ordered_json& meta)
    : dir_(dir), state_dim_(state_dim), action_dim_(action_dim) {
  std::error_code ec;
  if (fs::exists(dir) && !fs::is_empty(dir, ec)) {
    fail(ErrorCode::kInvalidArgument, "--record: " + dir + " exists and is not empty (choose a new folder)");
  }
  fs::create_directories(fs::path(dir) / "frames", ec);
  if (ec) fail(ErrorCode::kIoError, "--record: cannot create " + dir + "/frames: " + ec.message());
  {
    std::ofstream out(fs::path(dir) / "meta.json");
    out << meta.dump(2) << "\n";
    if (!out) fail(ErrorCode::kIoError, "--record: cannot write " + dir + "/meta.json");
  }
  log_ = open_table(fs::path(dir) / "log.jsonl");
  ticks_ = open_table(fs::path(dir) / "ticks.csv");
  std::fprintf(ticks_, "tick,time_s,jitter_ms,source");
  for (int i = 0; i < action_dim_; ++i) std::fprintf(ticks_, ",action.%d", i);
  std::fprintf(ticks_, ",steering_us,throttle_us,sent\n");
  std::fflush(ticks_);
  thread_ = std::thread([this] { run(); });
}

Recorder::~Recorder() { close(); }

void Recorder::add(ObservationRecord record) {
  {
    std::lock_guard lock(mutex_);
    if (closing_) return;
    if (queued_frames_ >= kMaxQueuedFrames) {
      ++dropped_frames_;
      return;
    }
    ++queued_frames_;
    queue_.emplace_back(std::move(record));
  }
  wake_.notify_one();
}

void Recorder::add(TickRecord record) {
  {
    std::lock_guard lock(mutex_);
    if (closing_) return;
    queue_.emplace_back(std::move(record));
  }
  wake_.notify_one();
}

uint64_t Recorder::dropped_frames() const {
  std::lock_guard lock(mutex_);
  return dropped_frames_;
}

void Recorder::close() {
  {
    std::lock_guard lock(mutex_);
    closing_ = true;
  }
  wake_.notify_one();
  if (thread_.joinable()) thread_.join();
  for (std::FILE** f : {&log_, &ticks_}) {
    if (*f) std::fclose(*f);
    *f = nullptr;
  }
}

void Recorder::run() {
  for (;;) {
    std::deque<Item> batch;
    bool closing = false;
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [this] { return closing_ || !queue_.empty(); });
      batch.swap(queue_);
      closing = closing_;
    }
    for (const Item& item : batch) {
      std::visit([this](const auto& record) { write(record); }, item);
      if (std::holds_alternative<ObservationRecord>(item)) {
        std::lock_guard lock(mutex_);
        --queued_frames_;
      }
    }
    // Flushed per batch: a kill loses at most the rows of the last few milliseconds.
    std::fflush(log_);
    std::fflush(ticks_);
    if (closing) return;
  }
}

void Recorder::write(const ObservationRecord& record) {
  char name[32];
  std::snprintf(name, sizeof name, "frames/%06llu.png", static_cast<unsigned long long>(observations_written_++));
  const fs::path final_path = fs::path(dir_) / name;
  const fs::path temp_path = final_path.string() + ".tmp.png";
  cv::Mat rgb(record.height, record.width, CV_8UC3, const_cast<uint8_t*>(record.rgb.data()));
  cv::Mat bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);  // imwrite takes BGR; the PNG holds the RGB image
  std::error_code ec;
  if (cv::imwrite(temp_path.string(), bgr)) fs::rename(temp_path, final_path, ec);
  const nlohmann::ordered_json line = {{"frame", name},
                                       {"state", record.state},
                                       {"tick", record.tick},
                                       {"time_s", record.time_s},
                                       {"frame_index", record.frame_index},
                                       {"frame_age_ms", record.frame_age_ms}};
  std::fputs(line.dump().c_str(), log_);
  std::fputc('\n', log_);
}

void Recorder::write(const TickRecord& record) {
  std::fprintf(ticks_, "%lld,%.6f,%.3f,%s", static_cast<long long>(record.tick), record.time_s, record.jitter_ms,
               record.source.c_str());
  write_values(ticks_, record.action, static_cast<size_t>(action_dim_));
  std::fprintf(ticks_, ",%u,%u,%d\n", record.pwm.steering_us, record.pwm.throttle_us, record.sent ? 1 : 0);
}

}  // namespace act::drive
