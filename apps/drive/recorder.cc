#include "apps/drive/recorder.h"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <opencv2/imgproc.hpp>

#include "actengine/status.h"
#include "actengine/vision.h"
#include "apps/media/media_io.h"

namespace fs = std::filesystem;

namespace act::drive {
namespace {

// Frames waiting for the disk beyond this are dropped (and counted) rather than growing memory.
constexpr size_t kMaxQueuedFrames = 64;

std::FILE* open_table(const fs::path& path) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) fail(StatusCode::kIoError, "--record: cannot create " + path.string() + ": " + std::strerror(errno));
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

// An RGB image as a PNG that appears complete or not at all (written aside, then renamed).
void write_png(const fs::path& path, const std::vector<uint8_t>& rgb, int height, int width) {
  const fs::path temp_path = path.string() + ".tmp.png";
  cv::Mat image(height, width, CV_8UC3, const_cast<uint8_t*>(rgb.data()));
  cv::Mat bgr;
  cv::cvtColor(image, bgr, cv::COLOR_RGB2BGR);  // imwrite takes BGR; the PNG holds the RGB image
  std::error_code ec;
  if (media::write_image(temp_path.string(), bgr)) fs::rename(temp_path, path, ec);
}

}  // namespace

Recorder::Recorder(const std::string& dir, int state_dim, int action_dim, int image_height, int image_width,
                   const nlohmann::ordered_json& meta)
    : dir_(dir), state_dim_(state_dim), action_dim_(action_dim), image_height_(image_height), image_width_(image_width) {
  std::error_code ec;
  if (fs::exists(dir) && !fs::is_empty(dir, ec)) {
    fail(StatusCode::kInvalidArgument, "--record: " + dir + " exists and is not empty (choose a new folder)");
  }
  for (const char* sub : {"frames", "tick_frames"}) {
    fs::create_directories(fs::path(dir) / sub, ec);
    if (ec) fail(StatusCode::kIoError, "--record: cannot create " + dir + "/" + sub + ": " + ec.message());
  }
  {
    std::ofstream out(fs::path(dir) / "meta.json");
    out << meta.dump(2) << "\n";
    if (!out) fail(StatusCode::kIoError, "--record: cannot write " + dir + "/meta.json");
  }
  log_ = open_table(fs::path(dir) / "log.jsonl");
  ticks_ = open_table(fs::path(dir) / "ticks.csv");
  std::fprintf(ticks_, "tick,time_s,jitter_ms,source");
  for (int i = 0; i < action_dim_; ++i) std::fprintf(ticks_, ",action.%d", i);
  std::fprintf(ticks_, ",steering_us,throttle_us,sent,driver,frame");
  for (int i = 0; i < state_dim_; ++i) std::fprintf(ticks_, ",state.%d", i);
  for (int i = 0; i < action_dim_; ++i) std::fprintf(ticks_, ",command.%d", i);
  std::fprintf(ticks_, "\n");
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
    if (record.frame && queued_frames_ >= kMaxQueuedFrames) {
      ++dropped_frames_;
      record.frame.reset();  // the row is kept, without its frame
    }
    if (record.frame) ++queued_frames_;
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
      if (std::holds_alternative<ObservationRecord>(item) || std::get_if<TickRecord>(&item)->frame) {
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
  write_png(fs::path(dir_) / name, record.rgb, record.height, record.width);
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
  std::string frame;
  if (record.frame) {
    char name[40];
    std::snprintf(name, sizeof name, "tick_frames/%08llu.png", static_cast<unsigned long long>(record.frame->index));
    frame = name;
    if (last_tick_frame_ != record.frame->index) {  // ticks outnumber camera frames: each is stored once
      last_tick_frame_ = record.frame->index;
      std::vector<uint8_t> rgb;
      if (frame_to_model_rgb(record.frame->bgr, image_height_, image_width_, rgb).ok()) {
        write_png(fs::path(dir_) / name, rgb, image_height_, image_width_);
      } else {
        frame.clear();
      }
    }
  }
  std::fprintf(ticks_, "%lld,%.6f,%.3f,%s", static_cast<long long>(record.tick), record.time_s, record.jitter_ms,
               record.source.c_str());
  write_values(ticks_, record.action, static_cast<size_t>(action_dim_));
  std::fprintf(ticks_, ",%u,%u,%d,%s,%s", record.pwm.steering_us, record.pwm.throttle_us, record.sent ? 1 : 0,
               record.driver.c_str(), frame.c_str());
  write_values(ticks_, record.state, static_cast<size_t>(state_dim_));
  write_values(ticks_, record.command, static_cast<size_t>(action_dim_));
  std::fputc('\n', ticks_);
}

}  // namespace act::drive
