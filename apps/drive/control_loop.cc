#include "apps/drive/control_loop.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <thread>

namespace act::drive {
namespace {

// Fault episodes kept for the summary (a flapping camera must not grow memory for hours).
constexpr size_t kMaxFaultEvents = 1000;

double ms_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

// Latency samples of one stage: all of them for the exit summary, and a mark for periodic stats.
struct StageSamples {
  std::vector<double> all;
  size_t reported = 0;
  void add(double v) { all.push_back(v); }
  LatencySummary since_report() const {
    return summarize(std::vector<double>(all.begin() + static_cast<std::ptrdiff_t>(reported), all.end()));
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

// Raises the estimate at once and lowers it slowly: a slow inference must not be forgotten quickly.
double track_latency(double estimate, double sample) { return sample > estimate ? sample : 0.9 * estimate + 0.1 * sample; }

}  // namespace

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
                "act_drive: %s after %.1f s: %llu ticks (%llu driving, %llu safe, %llu missed), %llu overrun ticks in %llu overruns, "
                "%llu inferences, %llu inference errors, %llu stale-frame ticks, %llu ticks with the link down\n",
                end_reason.c_str(), elapsed_s, static_cast<unsigned long long>(ticks),
                static_cast<unsigned long long>(driving_ticks), static_cast<unsigned long long>(safe_ticks),
                static_cast<unsigned long long>(missed_ticks),
                static_cast<unsigned long long>(overrun_ticks), static_cast<unsigned long long>(overrun_events),
                static_cast<unsigned long long>(inferences), static_cast<unsigned long long>(inference_errors),
                static_cast<unsigned long long>(stale_frames), static_cast<unsigned long long>(link_down_ticks));
  s << line << format_stage("capture age", capture_age_ms) << format_stage("preprocess", preprocess_ms)
    << format_stage("infer", infer_ms) << format_stage("serial write", serial_write_ms)
    << format_stage("tick jitter", jitter_ms) << "  " << link_summary << "\n";
  return s.str();
}

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
  const ModelInfo& info = inference_.info();
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / options_.control_hz));
  const double period_s = 1.0 / options_.control_hz;
  const PwmCommand safe = calibration_.safe_command();
  const std::vector<float> safe_action = safe_raw_action(calibration_, info.action_dim);

  ChunkScheduler scheduler(info);
  RateLimiter limiter(calibration_);
  DriveSummary summary;
  StageSamples capture_age, preprocess, infer, serial_write, jitter;
  std::vector<float> action(static_cast<size_t>(info.action_dim));
  std::vector<float> last_action = safe_action;  // the state the model sees (--state last-action)
  double latency_ticks = 0;
  int consecutive_errors = 0;
  bool executing = false;        // a chunk was driving the last tick: running dry now is an overrun
  bool overrunning = false;      // in an overrun: no action since the chunk ran out
  std::string fault;             // why the rover holds the safe action this tick ("" = no fault)
  std::string previous_fault;
  auto tick_time = [&](int64_t tick) { return std::chrono::duration<double>(period * tick).count(); };

  const auto start = Clock::now();
  auto last_stats = start;
  auto tick_of = [&](Clock::time_point t) { return static_cast<int64_t>(std::llround((t - start) / std::chrono::duration<double>(period))); };

  link_.send(safe, start);  // neutral on start
  for (int64_t tick = 0;; ++tick) {
    auto scheduled = start + period * tick;
    std::this_thread::sleep_until(scheduled);
    const auto now = Clock::now();
    if (now - scheduled >= period) {
      // Woke up a whole period late (a stalled machine): skip the missed ticks instead of bursting.
      const int64_t behind = (now - scheduled) / period;
      tick += behind;
      summary.missed_ticks += static_cast<uint64_t>(behind);
      scheduled = start + period * tick;
    }
    jitter.add(ms_between(scheduled, now));
    if (stop.load()) {
      summary.end_reason = "stopped by a signal";
      break;
    }
    if (options_.duration_s > 0 && now - start >= std::chrono::duration<double>(options_.duration_s)) {
      summary.end_reason = "--duration reached";
      break;
    }
    fault.clear();

    // A finished inference: a new chunk, or a fault.
    if (std::optional<InferenceResult> result = inference_.take_result()) {
      if (result->stale_frame) {
        fault = "stale frame (" + std::to_string(std::lround(result->frame_age_ms)) + " ms old)";
      } else {
        ++summary.inferences;
        capture_age.add(result->frame_age_ms);
        preprocess.add(result->preprocess_ms);
        infer.add(result->infer_ms);
        if (!result->error.empty()) {
          ++summary.inference_errors;
          fault = result->error;
          if (++consecutive_errors >= options_.max_consecutive_inference_errors) {
            log_ << "act_drive: error: " << result->error << "\n";
            summary.end_reason = "inference failed " + std::to_string(consecutive_errors) + " times in a row";
            summary.exit_code = 1;
            link_.send(safe, now);
            break;
          }
        } else {
          consecutive_errors = 0;
          const int64_t observation_tick = std::min(tick, tick_of(result->frame_captured));
          latency_ticks = track_latency(latency_ticks, static_cast<double>(tick - observation_tick));
          if (recorder_) {
            recorder_->add(ObservationRecord{observation_tick, tick_time(observation_tick), result->frame_index,
                                             result->frame_age_ms, result->state, std::move(result->model_input),
                                             info.cameras.front().height, info.cameras.front().width});
          }
          scheduler.add(std::move(result->chunk), observation_tick);
        }
      }
    }

    // The camera: gone, or only old frames.
    const FrameSource::State source_state = frames_.state();
    if (source_state != FrameSource::State::kRunning) {
      fault = frames_.problem();
    } else if (const auto frame = frames_.latest(); !frame || now - frame->captured > options_.max_frame_age) {
      fault = "stale frame (newest is " + (frame ? std::to_string(std::lround(ms_between(frame->captured, now))) : "none") +
              " ms old, --max-frame-age " + std::to_string(options_.max_frame_age.count()) + " ms)";
    }

    // This tick's action.
    PwmCommand command = safe;
    std::string source;
    if (!fault.empty()) {
      scheduler.clear();
      executing = false;
      if (fault.rfind("stale frame", 0) == 0) ++summary.stale_frames;
      if (fault_kind(fault) != fault_kind(previous_fault)) {
        if (summary.faults.size() < kMaxFaultEvents) summary.faults.push_back({now, fault});
        log_ << "act_drive: warning: holding the safe action: " << fault << "\n";
      }
      source = "safe:fault";
    } else if (scheduler.action_at(tick, action)) {
      command = limiter.step(calibration_.map(action), period_s);
      last_action = action;
      executing = true;
      source = "chunk";
      ++summary.driving_ticks;
    } else {
      if (executing) {
        overrunning = true;
        ++summary.overrun_events;
        if (summary.overrun_events <= 5 || summary.overrun_events % 100 == 0) {
          log_ << "act_drive: warning: overrun #" << summary.overrun_events
               << ": the action chunk ran out before the next was ready (inference "
               << std::lround(latency_ticks * period_s * 1000) << " ms); holding the safe action\n";
        }
      }
      executing = false;
      if (overrunning) ++summary.overrun_ticks;
      source = overrunning ? "safe:overrun" : "safe:waiting";  // waiting: for the first chunk after start or a fault
    }
    if (source != "chunk") {
      overrunning = overrunning && fault.empty();
      limiter.reset(safe);
      last_action = safe_action;
      ++summary.safe_ticks;
    } else {
      overrunning = false;
    }
    previous_fault = fault;

    const auto write_start = Clock::now();
    const bool sent = link_.send(command, write_start);
    serial_write.add(ms_between(write_start, Clock::now()));
    if (!sent) ++summary.link_down_ticks;
    ++summary.ticks;
    if (recorder_) {
      recorder_->add(TickRecord{tick, tick_time(tick), ms_between(scheduled, now), source,
                                source == "chunk" ? action : std::vector<float>{}, command, sent});
    }

    if (source_state == FrameSource::State::kEnded) {
      summary.end_reason = frames_.problem();
      break;
    }

    // Keep the next chunk coming while this one executes.
    if (fault.empty() && !inference_.busy() &&
        scheduler.wants_inference(tick, static_cast<int>(std::ceil(latency_ticks)))) {
      std::vector<float> state(static_cast<size_t>(info.state_dim), 0.0f);
      if (options_.state_source == ControlOptions::StateSource::kLastAction) {
        std::copy_n(last_action.begin(), std::min(state.size(), last_action.size()), state.begin());
      }
      inference_.request(std::move(state));
    }

    if (options_.stats_every_s > 0 && now - last_stats >= std::chrono::duration<double>(options_.stats_every_s)) {
      last_stats = now;
      log_ << "act_drive: stats: " << summary.ticks << " ticks, " << summary.overrun_events << " overruns, "
           << summary.inferences << " inferences\n"
           << format_stage("capture age", capture_age.since_report()) << format_stage("preprocess", preprocess.since_report())
           << format_stage("infer", infer.since_report()) << format_stage("serial write", serial_write.since_report())
           << format_stage("tick jitter", jitter.since_report());
      for (StageSamples* s : {&capture_age, &preprocess, &infer, &serial_write, &jitter}) s->reported = s->all.size();
    }
  }

  link_.shutdown(safe);  // neutral on every way out of the loop
  summary.elapsed_s = std::chrono::duration<double>(Clock::now() - start).count();
  summary.capture_age_ms = summarize(capture_age.all);
  summary.preprocess_ms = summarize(preprocess.all);
  summary.infer_ms = summarize(infer.all);
  summary.serial_write_ms = summarize(serial_write.all);
  summary.jitter_ms = summarize(jitter.all);
  summary.link_summary = link_.summary();
  return summary;
}

}  // namespace act::drive
