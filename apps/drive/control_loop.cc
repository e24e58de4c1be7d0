#include "apps/drive/control_loop.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <sstream>
#include <thread>

#include "actengine/scheduler.h"
#include "actengine/status.h"

namespace act::drive {
namespace {

// Fault episodes kept for the summary (a flapping camera must not grow memory for hours).
constexpr size_t kMaxFaultEvents = 1000;

// Latency statistics of one stage, in constant memory however long the rover drives: the whole run
// for the exit summary, and what came since the last periodic report.
struct StageSamples {
  LatencyHistogram whole_run, since_report;
  void add(double v) {
    whole_run.add(v);
    since_report.add(v);
  }
};

std::string format_stage(const char* name, const LatencySummary& s) {
  char line[160];
  std::snprintf(line, sizeof line, "  %-16s n %6zu  mean %8.2f  p50 %8.2f  p99 %8.2f  max %8.2f ms\n", name, s.count,
                s.mean, s.p50, s.p99, s.max);
  return line;
}

// A fault without its changing details ("stale frame (240 ms old)" -> "stale frame"): one warning
// per episode, not per tick.
std::string fault_kind(const std::string& fault) { return fault.substr(0, fault.find(" (")); }

// The policy steers, a human holds the throttle (--mode ai-steer).
constexpr const char* kAiSteerSource = "chunk+manual-throttle";

// Who chose a tick's command, from its source ("chunk", "manual...", "safe:<reason>").
std::string driver_of(const std::string& source) {
  if (source == "chunk") return "ai";
  if (source == kAiSteerSource) return "ai-steer";
  return source == "manual" ? "manual" : "safe";
}

// Raises the estimate at once and lowers it slowly: a slow inference must not be forgotten quickly.
double track_latency(double estimate, double sample) { return sample > estimate ? sample : 0.9 * estimate + 0.1 * sample; }

}  // namespace

std::vector<float> training_mean_state(const ModelInfo& info) {
  std::vector<float> mean(info.state_low.size());
  for (size_t i = 0; i < mean.size(); ++i) mean[i] = (info.state_low[i] + info.state_high[i]) / 2.0f;
  return mean;
}

std::vector<float> safe_raw_action(const Calibration& calibration, int action_dim) {
  std::vector<float> action(static_cast<size_t>(action_dim), 0.0f);
  if (calibration.action_units == Calibration::Units::kMicroseconds) {
    for (const ChannelCalibration* ch : {&calibration.steering, &calibration.throttle}) {
      if (ch->action_index < action_dim) action[static_cast<size_t>(ch->action_index)] = static_cast<float>(ch->mid_us);
    }
  }
  return action;
}

std::string DriveSummary::to_string() const {
  std::ostringstream s;
  char line[1024];
  std::snprintf(line, sizeof line,
                "act_drive: %s after %.1f s: %llu ticks (%llu driving, %llu safe: %llu e-stop, %llu waiting for a chunk, "
                "%llu fault, %llu overrun; %llu missed), %llu overruns, "
                "%llu inferences, %llu inference errors, %llu stale-frame ticks, %llu ticks with the link down\n",
                end_reason.c_str(), elapsed_s, static_cast<unsigned long long>(ticks),
                static_cast<unsigned long long>(driving_ticks), static_cast<unsigned long long>(safe_ticks),
                static_cast<unsigned long long>(estop_ticks), static_cast<unsigned long long>(waiting_ticks),
                static_cast<unsigned long long>(fault_ticks), static_cast<unsigned long long>(overrun_ticks),
                static_cast<unsigned long long>(missed_ticks), static_cast<unsigned long long>(overrun_events),
                static_cast<unsigned long long>(inferences), static_cast<unsigned long long>(inference_errors),
                static_cast<unsigned long long>(stale_frames), static_cast<unsigned long long>(link_down_ticks));
  s << line;
  if (manual_ticks > 0) s << "  " << manual_ticks << " ticks driven by hand\n";
  if (late_ticks > 0) {
    s << "  " << late_ticks << " ticks sent neutral because the control loop ran late (a starved CPU: give it --control-priority)\n";
  }
  s << format_stage("capture age", capture_age_ms) << format_stage("preprocess", preprocess_ms)
    << format_stage("infer", infer_ms) << format_stage("serial write", serial_write_ms)
    << format_stage("tick jitter", jitter_ms) << "  " << link_summary << "\n";
  return s.str();
}

ModelInfo with_deployment(const ModelInfo& info, const DeploymentOptions& deployment) {
  ModelInfo out = info;
  if (deployment.n_action_steps) out.n_action_steps = *deployment.n_action_steps;
  if (deployment.temporal_ensemble_coeff) {
    out.temporal_ensembling = deployment.temporal_ensemble_coeff->has_value();
    out.temporal_ensemble_coeff = deployment.temporal_ensemble_coeff->value_or(0.0);
  }
  if (const std::string problem = ChunkScheduler::deployment_problem(out); !problem.empty()) {
    fail(StatusCode::kInvalidArgument, "--n-action-steps / --temporal-ensemble-coeff with this model: " + problem);
  }
  return out;
}

namespace {

// Ticks of margin on top of the measured inference latency before the chunk runs out: they absorb
// jitter in the inference time (a busy machine).
constexpr int kInferenceMarginTicks = 2;

// How far from the training mean a state may go, in the statistics' half-widths, before the warning.
constexpr double kTrainingRangeHalfWidths = 3.0;

// ControlOptions::initial_state, or without one the safe action's first state_dim values.
std::vector<float> initial_state(const ControlOptions& options, int state_dim, const std::vector<float>& safe_action) {
  std::vector<float> state(static_cast<size_t>(state_dim), 0.0f);
  if (options.state_source != ControlOptions::StateSource::kLastAction) return state;
  if (!options.initial_state.empty()) {
    if (options.initial_state.size() != state.size()) {
      fail(StatusCode::kInvalidArgument, "the initial state has " + std::to_string(options.initial_state.size()) +
                                             " values, the model's state " + std::to_string(state_dim));
    }
    return options.initial_state;
  }
  std::copy_n(safe_action.begin(), std::min(state.size(), safe_action.size()), state.begin());
  return state;
}

ChunkScheduler make_scheduler(const ModelInfo& info) {
  StatusOr<ChunkScheduler> scheduler = ChunkScheduler::create(info);
  if (!scheduler.ok()) throw Error(scheduler.status().with_context("act_drive"));
  return std::move(scheduler).value();
}

// One tick of the loop: its index, when it was due and when the loop woke up for it, and how late
// that was after the tick the loop waited for (before skipping the missed ones).
struct Tick {
  int64_t index;
  Clock::time_point scheduled, now;
  Clock::duration late{};
};

// One run of the control loop: the state that lives from the first tick to the last, and the steps
// of a tick in the order they happen.
class ControlRun {
 public:
  ControlRun(const ControlOptions& options, const Calibration& calibration, const FrameSource& frames,
             InferenceWorker& inference, ActuatorLink& link, Recorder* recorder, std::ostream& log)
      : options_(options),
        calibration_(calibration),
        frames_(frames),
        inference_(inference),
        link_(link),
        recorder_(recorder),
        log_(log),
        info_(with_deployment(inference.info(), options.deployment)),
        period_(std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / options.control_hz))),
        period_s_(1.0 / options.control_hz),
        safe_(calibration.safe_command()),
        scheduler_(make_scheduler(info_)),
        limiter_(calibration),
        action_(static_cast<size_t>(info_.action_dim)),
        initial_state_(initial_state(options, info_.state_dim, safe_raw_action(calibration, info_.action_dim))),
        state_(initial_state_) {}

  DriveSummary run(const std::atomic<bool>& stop) {
    frames_.start_playback();
    start_ = Clock::now();
    last_stats_ = start_;
    link_.send(safe_, start_);  // neutral on start
    for (int64_t next = 0;; ++next) {
      const Tick tick = wait_for(next);
      next = tick.index;
      if (std::string reason = end_reason(tick, stop); !reason.empty()) {
        summary_.end_reason = std::move(reason);
        break;
      }
      fault_.clear();
      note_resumption(tick.now);
      note_stall(tick);
      if (!take_inference_result(tick)) break;
      const FrameSource::State source_state = frames_.state();
      check_camera(source_state, tick.now);
      PwmCommand command = safe_;
      if (recorder_) tick_state_ = state_;  // the state before this tick's action, as a dataset has it
      const std::string source = choose_action(tick, command);
      send(tick, source, command);
      if (options_.cockpit || options_.overlay) publish(tick, source, command);
      if (source_state == FrameSource::State::kEnded) {
        summary_.end_reason = frames_.problem();
        break;
      }
      request_inference(tick.index);
      report_stats(tick.now);
    }
    return finish();
  }

 private:
  double tick_time(int64_t tick) const { return std::chrono::duration<double>(period_ * tick).count(); }
  int64_t tick_of(Clock::time_point t) const {
    return static_cast<int64_t>(std::llround((t - start_) / std::chrono::duration<double>(period_)));
  }

  // Sleeps until tick `index` is due. Woken up a whole period late (a stalled machine), it skips the
  // missed ticks instead of bursting: the tick returned is then a later one.
  Tick wait_for(int64_t index) {
    if (!options_.realtime) {  // a replay: no waiting, the camera steps to the tick's time
      frames_.advance_to(static_cast<double>(index) / options_.control_hz);  // exact: period_ is rounded to ns
      const auto now = Clock::now();
      return {index, now, now};
    }
    Clock::time_point scheduled = start_ + period_ * index;
    std::this_thread::sleep_until(scheduled);
    const auto now = Clock::now();
    const Clock::duration late = now - scheduled;
    if (late >= period_) {
      const int64_t behind = (now - scheduled) / period_;
      index += behind;
      summary_.missed_ticks += static_cast<uint64_t>(behind);
      scheduled = start_ + period_ * index;
    }
    jitter_.add(ms_between(scheduled, now));
    return {index, scheduled, now, late};
  }

  // Why the run ends at this tick, or "" to go on.
  std::string end_reason(const Tick& tick, const std::atomic<bool>& stop) const {
    if (stop.load()) return "stopped by a signal";
    const double elapsed_s = options_.realtime ? std::chrono::duration<double>(tick.now - start_).count() : tick_time(tick.index);
    if (options_.duration_s > 0 && elapsed_s >= options_.duration_s) {
      return "--duration reached";
    }
    return "";
  }

  // A finished inference: a new chunk, or a fault. False when inference keeps failing (the run ends).
  bool take_inference_result(const Tick& tick) {
    std::optional<InferenceResult> result = inference_.take_result();
    if (!result) return true;
    if (options_.realtime && resumed_at_ && result->frame_captured < *resumed_at_) return true;  // from before a suspension
    if (result->stale_frame) {
      fault_ = "stale frame (" + std::to_string(std::lround(result->frame_age_ms)) + " ms old)";
      return true;
    }
    ++summary_.inferences;
    capture_age_.add(result->frame_age_ms);
    preprocess_.add(result->preprocess_ms);
    infer_.add(result->infer_ms);
    last_capture_age_ms_ = result->frame_age_ms;
    last_preprocess_ms_ = result->preprocess_ms;
    last_infer_ms_ = result->infer_ms;
    if (!result->error.empty()) return inference_failed(result->error, tick.now);
    // A replay's inference ran on the frame of the tick that asked for it, the tick before this one.
    const int64_t observation_tick = options_.realtime ? std::min(tick.index, tick_of(result->frame_captured)) : tick.index - 1;
    if (const Status added = scheduler_.add(result->chunk, observation_tick); !added.ok()) {
      return inference_failed("the model returned an unusable chunk: " + added.message(), tick.now);
    }
    consecutive_errors_ = 0;
    latency_ticks_ = track_latency(latency_ticks_, static_cast<double>(tick.index - observation_tick));
    if (recorder_) {
      recorder_->add(ObservationRecord{observation_tick, tick_time(observation_tick), result->frame_index,
                                       result->frame_age_ms, result->state, std::move(result->model_input),
                                       info_.cameras.front().height, info_.cameras.front().width});
    }
    return true;
  }

  // The process was suspended and continued since the last tick: what was planned before is stale.
  void note_resumption(Clock::time_point now) {
    if (!options_.resumptions) return;
    const uint64_t count = options_.resumptions->load();
    if (count == resumptions_seen_) return;
    resumptions_seen_ = count;
    resumed_at_ = now;
    scheduler_.clear();
    executing_ = false;
    overrunning_ = false;
    if (options_.cockpit) options_.cockpit->estop();
    if (summary_.faults.size() < kMaxFaultEvents) summary_.faults.push_back({now, "resumed after a suspension"});
    log_ << "act_drive: warning: resumed after a suspension: holding the safe action until a chunk from a new frame"
         << (options_.cockpit ? "; e-stopped (resume from the live view or the gamepad)" : "") << "\n";
  }

  // The loop woke up long after the tick it waited for (the CPU starved, the process stopped): the
  // chunk and any inference of an older frame are stale, and the board may have stopped the car by
  // itself. The tick holds the safe action (a fault) and the policy restarts from a new frame.
  void note_stall(const Tick& tick) {
    if (!options_.realtime || tick.late <= options_.max_tick_lateness) return;
    resumed_at_ = tick.now;
    scheduler_.clear();
    executing_ = false;
    overrunning_ = false;
    fault_ = "control loop late (" + std::to_string(std::lround(ms_between(tick.now - tick.late, tick.now))) +
             " ms after its tick, over " + std::to_string(options_.max_tick_lateness.count()) +
             " ms: a starved CPU? give it --control-priority)";
  }

  // Counts a failed inference as this tick's fault; false (after sending the safe command) when it
  // is one failure too many in a row.
  bool inference_failed(const std::string& error, Clock::time_point now) {
    ++summary_.inference_errors;
    fault_ = error;
    if (++consecutive_errors_ < options_.max_consecutive_inference_errors) return true;
    log_ << "act_drive: error: " << error << "\n";
    summary_.end_reason = "inference failed " + std::to_string(consecutive_errors_) + " times in a row";
    summary_.exit_code = 1;
    link_.send(safe_, now);
    return false;
  }

  // The camera: gone, or only old frames.
  void check_camera(FrameSource::State source_state, Clock::time_point now) {
    if (source_state != FrameSource::State::kRunning) {
      fault_ = frames_.problem();
    } else if (const auto frame = frames_.latest();
               !frame || (options_.realtime && frame_age(*frame, now) > options_.max_frame_age)) {  // a replay's have no age
      fault_ = "stale frame (newest is " + (frame ? std::to_string(std::lround(ms_between(frame->captured, now))) : "none") + " ms old";
      if (frame && frame->interval > Clock::duration::zero()) {  // a file's: its age counts from its successor's due time
        fault_ += ", " + std::to_string(std::lround(ms_between(frame->captured + frame->interval, now))) + " ms past the next frame's due time";
      }
      fault_ += ", --max-frame-age " + std::to_string(options_.max_frame_age.count()) + " ms)";
    }
  }

  // This tick's action into `command` (left safe unless someone drives); returns its source for the
  // recording: "chunk", "chunk+manual-throttle" (ai-steer), "manual", "safe:e-stop", "safe:fault",
  // "safe:overrun" or "safe:waiting".
  std::string choose_action(const Tick& tick, PwmCommand& command) {
    pilot_ = options_.cockpit ? options_.cockpit->input(tick.now) : PilotInput{};
    std::string source;
    if (pilot_.estopped || pilot_.manual_drives()) {
      scheduler_.clear();  // the policy starts afresh when it drives again
      executing_ = false;
    }
    if (pilot_.estopped) {
      source = "safe:e-stop";
    } else if (pilot_.manual_drives()) {
      command = limiter_.step(calibration_.map_manual(pilot_.steering, pilot_.throttle), period_s_);
      follow_action(calibration_.action_of(command, info_.action_dim));
      ++summary_.manual_ticks;
      overrunning_ = false;
      previous_fault_.clear();
      return "manual";
    } else if (!fault_.empty()) {
      hold_for_fault(tick.now);
      source = "safe:fault";
    } else if (scheduler_.action_at(tick.index, action_).ok()) {
      PwmCommand target = calibration_.map(action_);
      source = "chunk";
      if (pilot_.mode == DriveMode::kAiSteer) {
        target.throttle_us = calibration_.map_manual(0, pilot_.throttle).throttle_us;
        source = kAiSteerSource;
      }
      command = limiter_.step(target, period_s_);
      follow_action(source == "chunk" ? action_ : calibration_.action_of(command, info_.action_dim));
      executing_ = true;
      ++summary_.driving_ticks;
    } else {
      source = run_dry();
    }
    if (source.rfind("safe:", 0) == 0) {
      overrunning_ = overrunning_ && fault_.empty();
      limiter_.reset(safe_);
      state_ = initial_state_;
      count_safe_tick(source);
    } else {
      overrunning_ = false;
    }
    previous_fault_ = fault_;
    return source;
  }

  // A safe tick, counted by its reason (overrun ticks are counted where the overrun is seen).
  void count_safe_tick(const std::string& source) {
    ++summary_.safe_ticks;
    if (source == "safe:e-stop") ++summary_.estop_ticks;
    if (source == "safe:waiting") ++summary_.waiting_ticks;
    if (source == "safe:fault") ++summary_.fault_ticks;
  }

  // With --state last-action the executed action becomes the next state (its first state_dim values,
  // zero-padded); warns once when that leaves the training range.
  void follow_action(const std::vector<float>& action) {
    if (options_.state_source != ControlOptions::StateSource::kLastAction) return;
    std::fill(state_.begin(), state_.end(), 0.0f);
    std::copy_n(action.begin(), std::min(state_.size(), action.size()), state_.begin());
    if (warned_state_range_) return;
    for (size_t i = 0; i < std::min(state_.size(), info_.state_low.size()); ++i) {
      // Normalised -1 / +1 are the mean -/+ one standard deviation (or the min and max): 3 of those
      // half-widths from the middle is well outside what the model was trained on.
      const double middle = (info_.state_low[i] + info_.state_high[i]) / 2.0;
      const double half = (info_.state_high[i] - info_.state_low[i]) / 2.0;
      if (std::abs(state_[i] - middle) <= kTrainingRangeHalfWidths * std::abs(half)) continue;
      warned_state_range_ = true;
      log_ << "act_drive: warning: observation.state[" << i << "] = " << state_[i] << " left the training range ["
           << middle - kTrainingRangeHalfWidths * std::abs(half) << ", " << middle + kTrainingRangeHalfWidths * std::abs(half)
           << "] (the training mean -/+ 3 standard deviations): the policy is extrapolating (warned once)\n";
      return;
    }
  }

  // A fault drops every chunk; warns once per episode (a new kind of fault starts one).
  void hold_for_fault(Clock::time_point now) {
    scheduler_.clear();
    executing_ = false;
    if (fault_.rfind("stale frame", 0) == 0) ++summary_.stale_frames;
    if (fault_kind(fault_) != fault_kind(previous_fault_)) {
      if (summary_.faults.size() < kMaxFaultEvents) summary_.faults.push_back({now, fault_});
      log_ << "act_drive: warning: holding the safe action: " << fault_ << "\n";
    }
  }

  // No chunk covers the tick: an overrun when one was driving until now, else still waiting (for
  // the first chunk after start or a fault).
  std::string run_dry() {
    if (executing_) {
      overrunning_ = true;
      ++summary_.overrun_events;
      if (summary_.overrun_events <= 5 || summary_.overrun_events % 100 == 0) {
        log_ << "act_drive: warning: overrun #" << summary_.overrun_events
             << ": the action chunk ran out before the next was ready (inference "
             << std::lround(latency_ticks_ * period_s_ * 1000) << " ms); holding the safe action\n";
      }
    }
    executing_ = false;
    if (overrunning_) ++summary_.overrun_ticks;
    return overrunning_ ? "safe:overrun" : "safe:waiting";
  }

  void send(const Tick& tick, const std::string& source, const PwmCommand& chosen) {
    // Suspended since this tick began (its command was chosen before the stop), or too late for it
    // (woken up late, or stalled since): the safe one instead.
    const bool suspended = options_.resumptions && options_.resumptions->load() != resumptions_seen_;
    const auto write_start = Clock::now();
    const bool late = options_.realtime && (tick.late > options_.max_tick_lateness ||
                                            write_start - tick.scheduled > options_.max_tick_lateness);
    if (late) ++summary_.late_ticks;
    const PwmCommand& command = suspended || late ? safe_ : chosen;
    const bool sent = link_.send(command, write_start);
    serial_write_.add(ms_between(write_start, Clock::now()));
    if (!sent) ++summary_.link_down_ticks;
    ++summary_.ticks;
    if (recorder_) {
      recorder_->add(TickRecord{tick.index, tick_time(tick.index), ms_between(tick.scheduled, tick.now), source,
                                source.rfind("chunk", 0) == 0 ? action_ : std::vector<float>{}, command, sent, driver_of(source),
                                tick_state_, calibration_.action_of(command, info_.action_dim), frames_.latest()});
    }
  }

  // Keeps the next chunk coming while this one executes.
  void request_inference(int64_t tick) {
    if (!fault_.empty() || pilot_.estopped || pilot_.manual_drives() || inference_.busy()) return;
    const int lead_ticks = static_cast<int>(std::ceil(latency_ticks_)) + kInferenceMarginTicks;
    if (!scheduler_.wants_inference(tick, lead_ticks)) return;
    inference_.request(state_);
    if (!options_.realtime) inference_.wait_for_result();
  }

  // The status for the live page and the overlay video: this tick, and the policy's commands ahead of it.
  void publish(const Tick& tick, const std::string& source, const PwmCommand& command) {
    LiveStatus status;
    status.tick = tick.index;
    status.time_s = tick_time(tick.index);
    status.source = source;
    status.driver = driver_of(source);
    status.fault = pilot_.estopped ? "e-stop (resume to drive)" : fault_;
    status.command = command;
    status.steering = position_of(command.steering_us, calibration_.steering);
    status.throttle = position_of(command.throttle_us, calibration_.throttle);
    std::vector<float> ahead(action_.size());
    for (int64_t t = tick.index; scheduler_.action_at(t, ahead).ok(); ++t) {
      const PwmCommand planned = calibration_.map(ahead);
      status.steering_ahead.push_back(static_cast<float>(position_of(planned.steering_us, calibration_.steering)));
      status.throttle_ahead.push_back(static_cast<float>(position_of(planned.throttle_us, calibration_.throttle)));
    }
    status.capture_age_ms = last_capture_age_ms_;
    status.preprocess_ms = last_preprocess_ms_;
    status.infer_ms = last_infer_ms_;
    status.jitter_ms = ms_between(tick.scheduled, tick.now);
    status.ticks = summary_.ticks;
    status.inferences = summary_.inferences;
    status.overruns = summary_.overrun_events;
    std::shared_ptr<const Frame> frame = frames_.latest();
    if (frame) status.frame_index = frame->index;
    status.pilot = pilot_;
    status.control_hz = options_.control_hz;
    if (options_.overlay) options_.overlay->add(status, std::move(frame));
    if (options_.cockpit) options_.cockpit->publish(std::move(status));
  }

  void report_stats(Clock::time_point now) {
    if (options_.stats_every_s <= 0 || now - last_stats_ < std::chrono::duration<double>(options_.stats_every_s)) return;
    last_stats_ = now;
    log_ << "act_drive: stats: " << summary_.ticks << " ticks, " << summary_.overrun_events << " overruns, "
         << summary_.inferences << " inferences\n"
         << format_stage("capture age", capture_age_.since_report.summary())
         << format_stage("preprocess", preprocess_.since_report.summary())
         << format_stage("infer", infer_.since_report.summary())
         << format_stage("serial write", serial_write_.since_report.summary())
         << format_stage("tick jitter", jitter_.since_report.summary());
    for (StageSamples* s : {&capture_age_, &preprocess_, &infer_, &serial_write_, &jitter_}) s->since_report.clear();
  }

  DriveSummary finish() {
    link_.shutdown(safe_);  // neutral on every way out of the loop
    summary_.elapsed_s = std::chrono::duration<double>(Clock::now() - start_).count();
    summary_.capture_age_ms = capture_age_.whole_run.summary();
    summary_.preprocess_ms = preprocess_.whole_run.summary();
    summary_.infer_ms = infer_.whole_run.summary();
    summary_.serial_write_ms = serial_write_.whole_run.summary();
    summary_.jitter_ms = jitter_.whole_run.summary();
    summary_.link_summary = link_.summary();
    return std::move(summary_);
  }

  const ControlOptions& options_;
  const Calibration& calibration_;
  const FrameSource& frames_;
  InferenceWorker& inference_;
  ActuatorLink& link_;
  Recorder* recorder_;
  std::ostream& log_;
  const ModelInfo info_;  // the blob's, with ControlOptions::deployment applied
  const Clock::duration period_;
  const double period_s_;
  const PwmCommand safe_;

  ChunkScheduler scheduler_;
  RateLimiter limiter_;
  DriveSummary summary_;
  StageSamples capture_age_, preprocess_, infer_, serial_write_, jitter_;
  Clock::time_point start_, last_stats_;
  std::vector<float> action_;
  const std::vector<float> initial_state_;
  std::vector<float> state_;  // what the model sees as observation.state next
  std::vector<float> tick_state_;  // state_ when the tick began (recorded)
  bool warned_state_range_ = false;
  PilotInput pilot_;  // this tick's e-stop, mode and manual input
  double last_capture_age_ms_ = 0, last_preprocess_ms_ = 0, last_infer_ms_ = 0;  // for the live page
  double latency_ticks_ = 0;
  int consecutive_errors_ = 0;
  bool executing_ = false;    // a chunk was driving the last tick: running dry now is an overrun
  bool overrunning_ = false;  // in an overrun: no action since the chunk ran out
  std::string fault_;         // why the rover holds the safe action this tick ("" = no fault)
  std::string previous_fault_;
  uint64_t resumptions_seen_ = options_.resumptions ? options_.resumptions->load() : 0;
  std::optional<Clock::time_point> resumed_at_;  // the latest resume after a suspension
};

}  // namespace

ControlLoop::ControlLoop(ControlOptions options, const Calibration& calibration, const FrameSource& frames,
                         InferenceWorker& inference, ActuatorLink& link, Recorder* recorder, std::ostream& log)
    : options_(std::move(options)),
      calibration_(calibration),
      frames_(frames),
      inference_(inference),
      link_(link),
      recorder_(recorder),
      log_(log) {}

DriveSummary ControlLoop::run(const std::atomic<bool>& stop) {
  apply_thread_placement(options_.placement, "control", log_);
  return ControlRun(options_, calibration_, frames_, inference_, link_, recorder_, log_).run(stop);
}

}  // namespace act::drive
