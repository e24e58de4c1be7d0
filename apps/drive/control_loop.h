// act_drive's fixed-rate control loop: each tick picks the action (from the chunks the inference
// worker delivers, or the safe action when anything is wrong), maps it to PWM and sends it, and
// keeps the next inference going so the control rate never waits for the model.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <ostream>
#include <string>
#include <vector>

#include "actengine/convert.h"
#include "apps/bench_support.h"
#include "apps/drive/calibration.h"
#include "apps/drive/camera.h"
#include "apps/drive/cockpit.h"
#include "apps/drive/inference.h"
#include "apps/drive/overlay_video.h"
#include "apps/drive/recorder.h"
#include "apps/drive/serial_link.h"

namespace act::drive {

struct ControlOptions {
  double control_hz = 30;
  /// A frame older than this is never used: the rover holds the safe action instead.
  std::chrono::milliseconds max_frame_age{200};
  /// Print the statistics every this many seconds (0 = only at exit).
  double stats_every_s = 0;
  /// Stop after this many seconds (0 = until a signal or the video ends).
  double duration_s = 0;
  /// A tick whose loop woke up or reached the wire more than this late (a starved CPU, a stopped
  /// process) sends the safe command, drops the chunk and waits for one from a frame captured after
  /// it: what was planned before the stall is stale (the board's own watchdog stops the car after
  /// 250 ms without a command). Real-time runs only.
  std::chrono::milliseconds max_tick_lateness{100};
  /// Inference failures in a row (errors, non-finite actions) that end the run.
  int max_consecutive_inference_errors = 30;
  /// What the model gets as observation.state: the last raw action executed (its first state_dim
  /// values, zero-padded), or zeros.
  enum class StateSource { kLastAction, kZeros } state_source = StateSource::kLastAction;
  /// The state before the first action and again after every hold (the rover restarts from a stop),
  /// with kLastAction: state_dim values (act_drive's default is the training mean, --initial-state).
  /// Empty = the safe action's first state_dim values.
  std::vector<float> initial_state;
  /// The live page and gamepad: e-stop, modes, driving by hand, and where the status goes. Null =
  /// the policy drives alone.
  Cockpit* cockpit = nullptr;
  /// False: an offline replay of a file as fast as the machine allows (--realtime off, dry runs
  /// only). Ticks follow each other at once, each advances the camera to its time, and each
  /// inference is waited for, so a replay is the same however fast the machine is.
  bool realtime = true;
  /// Every tick drawn into a video (--overlay-video); null = none.
  OverlayVideo* overlay = nullptr;
  ThreadPlacement placement;  ///< for the control thread (the one calling run())
  DeploymentOptions deployment;  ///< replaces the blob's n_action_steps / temporal ensembling
  /// Bumped (by act_drive's signal handlers) when the process stops and when it continues. When it
  /// changes, the chunk and any inference of an older frame are dropped, the safe action is held until
  /// a chunk from a frame captured after the resume, and the cockpit (if any) is e-stopped; a command
  /// chosen before the change is replaced by the safe one. Null = never suspended.
  const std::atomic<uint64_t>* resumptions = nullptr;
};

/// `info` with `deployment`'s choices in place of the blob's; throws act::Error(kInvalidArgument) when
/// they do not fit its chunk (LeRobot's rules, ChunkScheduler::deployment_problem).
ModelInfo with_deployment(const ModelInfo& info, const DeploymentOptions& deployment);

/// The first tick of each period during which the rover held the safe action because of a fault.
struct FaultEvent {
  Clock::time_point when;
  std::string what;
};

struct DriveSummary {
  int exit_code = 0;
  std::string end_reason;
  uint64_t ticks = 0, driving_ticks = 0, safe_ticks = 0;
  /// The safe ticks by reason (with overrun_ticks they add up to safe_ticks): the e-stop held, no
  /// chunk yet (after start, an e-stop or a fault), a fault (stale frame, inference error, ...).
  uint64_t estop_ticks = 0, waiting_ticks = 0, fault_ticks = 0;
  uint64_t manual_ticks = 0;  ///< ticks a human drove (part of neither of the two above)
  uint64_t missed_ticks = 0;  ///< ticks skipped because the loop woke up a whole period late
  /// Ticks that sent the safe command because the loop ran more than max_tick_lateness late.
  uint64_t late_ticks = 0;
  uint64_t overrun_ticks = 0, overrun_events = 0;  ///< the chunk ran out before the next was ready
  uint64_t inferences = 0, inference_errors = 0, stale_frames = 0, link_down_ticks = 0;
  double elapsed_s = 0;
  LatencySummary capture_age_ms, preprocess_ms, infer_ms, serial_write_ms, jitter_ms;
  std::vector<FaultEvent> faults;  ///< the first 1000
  std::string link_summary;
  /// Several lines, for the exit report.
  std::string to_string() const;
};

class ControlLoop {
 public:
  ControlLoop(ControlOptions options, const Calibration& calibration, const FrameSource& frames,
              InferenceWorker& inference, ActuatorLink& link, Recorder* recorder, std::ostream& log);
  /// Runs until `stop` becomes true, the video ends, `duration_s` passes or inference keeps
  /// failing; always ends with the link's shutdown (neutral).
  DriveSummary run(const std::atomic<bool>& stop);

 private:
  ControlOptions options_;
  const Calibration& calibration_;
  const FrameSource& frames_;
  InferenceWorker& inference_;
  ActuatorLink& link_;
  Recorder* recorder_;
  std::ostream& log_;
};

/// The middle of the model's training statistics for observation.state (ModelInfo::state_low/high).
std::vector<float> training_mean_state(const ModelInfo& info);

/// The raw action that corresponds to the safe command (centre, neutral) in the model's units.
std::vector<float> safe_raw_action(const Calibration& calibration, int action_dim);

}  // namespace act::drive
