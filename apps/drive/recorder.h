// --record DIR: what act_drive saw and did, for debugging and as act_convert calibration input.
//
//   DIR/meta.json         model, camera, control rate, calibration, column meanings
//   DIR/frames/NNNNNN.png the model's input image of each inference (RGB, the model's size)
//   DIR/log.jsonl         one line per inference: {"frame": "frames/NNNNNN.png", "state": [...],
//                         "tick", "time_s", "frame_index", "frame_age_ms"} (what act_convert
//                         --calib reads from a recording)
//   DIR/ticks.csv         one row per control tick: the action, where it came from, the PWM sent;
//                         then who chose it (driver: ai, manual or safe), the tick's camera frame,
//                         the state and the command actually sent in the model's units (what
//                         apps/drive/recording_to_lerobot.py trains on, manual driving included)
//   DIR/tick_frames/NNNNNNNN.png  each camera frame a tick saw (the camera's frame index), at the
//                         model's input size, preprocessed as the model sees it
//
// A writer thread does the file work so the control loop never waits on the disk. A row is written
// after its frame, the rows of a batch with one write per table, and frames appear by atomic
// rename, so a killed or crashed run leaves complete files holding everything up to its last
// moments, and a full disk leaves whole rows naming frames that exist.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <ostream>
#include <optional>
#include <string>
#include <thread>
#include <variant>

#include <sys/types.h>
#include <vector>

#include <nlohmann/json.hpp>

#include "apps/drive/calibration.h"
#include "apps/drive/camera.h"

namespace act::drive {

struct ObservationRecord {
  int64_t tick = 0;           ///< the control tick the frame belongs to
  double time_s = 0;          ///< capture time, seconds since the loop started
  uint64_t frame_index = 0;   ///< the camera's frame counter
  double frame_age_ms = 0;    ///< age when inference took it
  std::vector<float> state;
  std::vector<uint8_t> rgb;   ///< height x width x 3
  int height = 0, width = 0;
};

struct TickRecord {
  int64_t tick = 0;
  double time_s = 0;          ///< when the tick ran, seconds since the loop started
  double jitter_ms = 0;       ///< how late it woke up
  std::string source;         ///< "chunk", or "safe:<reason>"
  std::vector<float> action;  ///< the raw action (empty for a safe action)
  PwmCommand pwm;
  bool sent = false;          ///< false when the link was down
  std::string driver;         ///< who chose the command: "ai", "manual" or "safe"
  std::vector<float> state;   ///< observation.state at this tick
  std::vector<float> command; ///< the command sent, as a raw action (Calibration::action_of)
  std::shared_ptr<const Frame> frame;  ///< the newest camera frame (null before the first)
};

class Recorder {
 public:
  /// Creates DIR (which must not exist or be empty) and its files; throws act::Error otherwise.
  /// Tick frames are stored at image_height x image_width (the model's input). On the first write
  /// error (a full disk, RLIMIT_FSIZE) the recording stops: the tables keep their whole rows (a
  /// write cut short is cut back), one message goes to `log` (when given) and failure() says it;
  /// driving goes on. ticks.csv names the action columns action.<name> and command.<name> after
  /// meta's "action_names" (the blob's, ModelInfo::action_names) when it has them, else action.0, ...
  Recorder(const std::string& dir, int state_dim, int action_dim, int image_height, int image_width,
           const nlohmann::ordered_json& meta, std::ostream* log = nullptr);
  ~Recorder();
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  void add(ObservationRecord record);
  void add(TickRecord record);
  /// Writes everything queued and closes the files (also done by the destructor).
  void close();
  uint64_t dropped_frames() const;
  /// After close(): the ticks given to add() whose rows are not on disk (those from the failed write
  /// on, when failure() says the recording stopped early).
  uint64_t unrecorded_ticks() const;
  /// Why the recording stopped early, "" while it records.
  std::string failure() const;
  const std::string& dir() const { return dir_; }

 private:
  using Item = std::variant<ObservationRecord, TickRecord>;
  void run();
  std::string write(const ObservationRecord& record);  // "" or what failed
  std::string write(const TickRecord& record);
  void stop_recording(const std::string& problem);

  std::string dir_;
  int state_dim_, action_dim_, image_height_, image_width_;
  int log_ = -1, ticks_ = -1;  // the tables' descriptors
  std::ostream* log_stream_ = nullptr;
  uint64_t observations_written_ = 0;  // writer thread only
  uint64_t observations_pending_ = 0, observations_kept_ = 0;  // writer thread only: lines made, on disk
  uint64_t ticks_pending_ = 0, ticks_written_ = 0;  // writer thread only: rows made, on disk
  std::string log_rows_, tick_rows_;  // writer thread only: this batch's rows, not yet written
  off_t log_end_ = 0, ticks_end_ = 0;  // the tables' sizes: every byte before is a whole row
  std::optional<uint64_t> last_tick_frame_;  // writer thread only: the camera index last stored
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<Item> queue_;     // guarded by mutex_
  size_t queued_frames_ = 0;   // guarded by mutex_
  uint64_t dropped_frames_ = 0;  // guarded by mutex_
  uint64_t ticks_offered_ = 0;  // guarded by mutex_
  bool closing_ = false;       // guarded by mutex_
  std::string failure_;        // guarded by mutex_
  std::thread thread_;
};

}  // namespace act::drive
