#include "apps/drive/recorder.h"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <utility>

#include <unistd.h>

#include <opencv2/imgproc.hpp>

#include "actengine/status.h"
#include "actengine/vision.h"
#include "engine/media/media_io.h"

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

// An RGB image as a PNG that appears complete or not at all (written aside, then renamed). Returns
// "" or what failed (a full disk, the file-size limit).
std::string write_png(const fs::path& path, const std::vector<uint8_t>& rgb, int height, int width) {
  const fs::path temp_path = path.string() + ".tmp.png";
  cv::Mat image(height, width, CV_8UC3, const_cast<uint8_t*>(rgb.data()));
  cv::Mat bgr;
  cv::cvtColor(image, bgr, cv::COLOR_RGB2BGR);  // the encoder takes BGR; the PNG holds the RGB image
  std::vector<uchar> png;
  if (!media::encode_image(".png", bgr, png)) return "cannot encode " + path.string();
  std::FILE* f = std::fopen(temp_path.c_str(), "wb");
  if (!f) return "cannot create " + temp_path.string() + ": " + std::strerror(errno);
  const bool written = std::fwrite(png.data(), 1, png.size(), f) == png.size();
  const int write_errno = errno;
  if (std::fclose(f) != 0 || !written) {
    const int error = written ? errno : write_errno;
    std::error_code ignored;
    fs::remove(temp_path, ignored);
    return "cannot write " + path.string() + ": " + std::strerror(error);
  }
  std::error_code ec;
  fs::rename(temp_path, path, ec);
  return ec ? "cannot rename " + temp_path.string() + ": " + ec.message() : "";
}

// The table's bytes so far are all on disk: "" or what failed.
std::string flush_table(std::FILE* f, const fs::path& path) {
  if (std::fflush(f) == 0 && !std::ferror(f)) return "";
  return "cannot write " + path.string() + ": " + std::strerror(errno);
}

}  // namespace

Recorder::Recorder(const std::string& dir, int state_dim, int action_dim, int image_height, int image_width,
                   const nlohmann::ordered_json& meta, std::ostream* log)
    : dir_(dir), state_dim_(state_dim), action_dim_(action_dim), image_height_(image_height), image_width_(image_width), log_stream_(log) {
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
  if (const std::string problem = flush_table(ticks_, fs::path(dir) / "ticks.csv"); !problem.empty()) {
    fail(StatusCode::kIoError, "--record: " + problem);
  }
  log_good_ = std::ftell(log_);
  ticks_good_ = std::ftell(ticks_);
  thread_ = std::thread([this] { run(); });
}

Recorder::~Recorder() { close(); }

void Recorder::add(ObservationRecord record) {
  {
    std::lock_guard lock(mutex_);
    if (closing_ || !failure_.empty()) return;
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
    if (closing_ || !failure_.empty()) return;
    if (record.frame && queued_frames_ >= kMaxQueuedFrames) {
      ++dropped_frames_;
      record.frame.reset();  // the row is kept, without its frame
    }
    if (record.frame) ++queued_frames_;
    queue_.emplace_back(std::move(record));
  }
  wake_.notify_one();
}

std::string Recorder::failure() const {
  std::lock_guard lock(mutex_);
  return failure_;
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
    std::string problem;
    for (const Item& item : batch) {
      if (problem.empty()) problem = std::visit([this](const auto& record) { return write(record); }, item);
      if (std::holds_alternative<ObservationRecord>(item) || std::get_if<TickRecord>(&item)->frame) {
        std::lock_guard lock(mutex_);
        --queued_frames_;
      }
    }
    // Flushed per batch: a kill loses at most the rows of the last few milliseconds.
    if (problem.empty()) problem = flush_table(log_, fs::path(dir_) / "log.jsonl");
    if (problem.empty()) problem = flush_table(ticks_, fs::path(dir_) / "ticks.csv");
    if (!problem.empty()) return stop_recording(problem);
    log_good_ = std::ftell(log_);
    ticks_good_ = std::ftell(ticks_);
    ticks_written_ = ticks_pending_;
    observations_kept_ = observations_pending_;
    if (closing) return;
  }
}

// A write failed (a full disk, the file-size limit): the tables are cut back to their last whole
// batch, so what is on disk stays a recording that act_convert and act_eval read, and nothing more
// is recorded. Driving goes on.
void Recorder::stop_recording(const std::string& problem) {
  for (auto [f, good] : {std::pair{log_, log_good_}, std::pair{ticks_, ticks_good_}}) {
    if (good >= 0 && ::ftruncate(::fileno(f), good) != 0) {}  // best effort: the message below says it stopped
  }
  std::string message = "--record: " + problem + ": the recording stops here (" + std::to_string(ticks_written_) +
                        " ticks and " + std::to_string(observations_kept_) + " observations kept in " + dir_ + "); driving goes on";
  if (log_stream_) *log_stream_ << "act_drive: error: " + message + "\n" << std::flush;
  std::lock_guard lock(mutex_);
  failure_ = std::move(message);
  queue_.clear();
  queued_frames_ = 0;
}

std::string Recorder::write(const ObservationRecord& record) {
  char name[32];
  std::snprintf(name, sizeof name, "frames/%06llu.png", static_cast<unsigned long long>(observations_written_++));
  // No line for a frame that is not on disk.
  if (std::string problem = write_png(fs::path(dir_) / name, record.rgb, record.height, record.width); !problem.empty()) {
    return problem;
  }
  const nlohmann::ordered_json line = {{"frame", name},
                                       {"state", record.state},
                                       {"tick", record.tick},
                                       {"time_s", record.time_s},
                                       {"frame_index", record.frame_index},
                                       {"frame_age_ms", record.frame_age_ms}};
  std::fputs(line.dump().c_str(), log_);
  std::fputc('\n', log_);
  ++observations_pending_;
  return "";
}

std::string Recorder::write(const TickRecord& record) {
  std::string frame;
  if (record.frame) {
    char name[40];
    std::snprintf(name, sizeof name, "tick_frames/%08llu.png", static_cast<unsigned long long>(record.frame->index));
    frame = name;
    if (last_tick_frame_ != record.frame->index) {  // ticks outnumber camera frames: each is stored once
      last_tick_frame_ = record.frame->index;
      std::vector<uint8_t> rgb;
      if (frame_to_model_rgb(record.frame->bgr, image_height_, image_width_, rgb).ok()) {
        if (std::string problem = write_png(fs::path(dir_) / name, rgb, image_height_, image_width_); !problem.empty()) {
          return problem;
        }
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
  ++ticks_pending_;
  return "";
}

}  // namespace act::drive
