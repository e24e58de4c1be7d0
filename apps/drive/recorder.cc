#include "apps/drive/recorder.h"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <utility>

#include <fcntl.h>
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

// A table (log.jsonl, ticks.csv): rows are gathered per batch and written with one call each.
int open_table(const fs::path& path) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) fail(StatusCode::kIoError, "--record: cannot create " + path.string() + ": " + std::strerror(errno));
  return fd;
}

// count values as ",v0,v1...", empty for missing ones.
void append_values(std::string& out, const std::vector<float>& values, size_t count) {
  char text[32];
  for (size_t i = 0; i < count; ++i) {
    out += ',';
    if (i < values.size()) {
      std::snprintf(text, sizeof text, "%.9g", static_cast<double>(values[i]));
      out += text;
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

// Appends `rows` (whole rows) to the table at `end`, its size: "" or what failed. A write cut short
// (a full disk, the file-size limit) is cut back to `end`, so the table never ends mid-row.
std::string append_rows(int fd, const fs::path& path, const std::string& rows, off_t& end) {
  size_t done = 0;
  while (done < rows.size()) {
    const ssize_t n = ::pwrite(fd, rows.data() + done, rows.size() - done, end + static_cast<off_t>(done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int error = n < 0 ? errno : ENOSPC;
      if (::ftruncate(fd, end) != 0) {}  // best effort: the message says the recording stopped
      return "cannot write " + path.string() + ": " + std::strerror(error);
    }
    done += static_cast<size_t>(n);
  }
  end += static_cast<off_t>(rows.size());
  return "";
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
  std::vector<std::string> names;  // the action columns' suffixes: the blob's names, or 0, 1, ...
  if (meta.contains("action_names")) names = meta.at("action_names").get<std::vector<std::string>>();
  for (int i = static_cast<int>(names.size()); i < action_dim_; ++i) names.push_back(std::to_string(i));
  std::string header = "tick,time_s,jitter_ms,source";
  for (int i = 0; i < action_dim_; ++i) header.append(",action.").append(names[static_cast<size_t>(i)]);
  header += ",steering_us,throttle_us,sent,driver,frame";
  for (int i = 0; i < state_dim_; ++i) header.append(",state.").append(std::to_string(i));
  for (int i = 0; i < action_dim_; ++i) header.append(",command.").append(names[static_cast<size_t>(i)]);
  header += "\n";
  if (const std::string problem = append_rows(ticks_, fs::path(dir) / "ticks.csv", header, ticks_end_); !problem.empty()) {
    ::close(log_);  // no destructor runs for a constructor that throws
    ::close(ticks_);
    fail(StatusCode::kIoError, "--record: " + problem);
  }
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
    ++ticks_offered_;
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

uint64_t Recorder::unrecorded_ticks() const {
  std::lock_guard lock(mutex_);
  return thread_.joinable() ? 0 : ticks_offered_ - ticks_written_;
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
  for (int* fd : {&log_, &ticks_}) {
    if (*fd >= 0) ::close(*fd);
    *fd = -1;
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
    // The rows gathered before a failed frame are whole and name frames on disk: they are kept.
    std::string table_problem = append_rows(log_, fs::path(dir_) / "log.jsonl", log_rows_, log_end_);
    if (table_problem.empty()) {
      observations_kept_ = observations_pending_;
      table_problem = append_rows(ticks_, fs::path(dir_) / "ticks.csv", tick_rows_, ticks_end_);
    }
    if (table_problem.empty()) ticks_written_ = ticks_pending_;
    log_rows_.clear();
    tick_rows_.clear();
    if (problem.empty()) problem = table_problem;
    if (!problem.empty()) return stop_recording(problem);
    if (closing) return;
  }
}

// A write failed (a full disk, the file-size limit): the tables end with their last whole row, so
// what is on disk stays a recording that act_convert and act_eval read, and nothing more is
// recorded. Driving goes on.
void Recorder::stop_recording(const std::string& problem) {
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
  log_rows_ += line.dump();
  log_rows_ += '\n';
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
  char text[96];
  std::snprintf(text, sizeof text, "%lld,%.6f,%.3f,", static_cast<long long>(record.tick), record.time_s, record.jitter_ms);
  tick_rows_ += text;
  tick_rows_ += record.source;
  append_values(tick_rows_, record.action, static_cast<size_t>(action_dim_));
  std::snprintf(text, sizeof text, ",%u,%u,%d,", record.pwm.steering_us, record.pwm.throttle_us, record.sent ? 1 : 0);
  tick_rows_ += text;
  tick_rows_ += record.driver + "," + frame;
  append_values(tick_rows_, record.state, static_cast<size_t>(state_dim_));
  append_values(tick_rows_, record.command, static_cast<size_t>(action_dim_));
  tick_rows_ += '\n';
  ++ticks_pending_;
  return "";
}

}  // namespace act::drive
