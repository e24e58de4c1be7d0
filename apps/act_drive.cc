// act_drive: drives the RC rover. Camera -> preprocess -> infer -> action chunking -> PWM over a
// serial line to the Arduino (apps/arduino/act_rover), at a fixed control rate. See docs/rover.md.
#include <CLI/CLI.hpp>

#include <pthread.h>

#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>

#include <opencv2/core/utils/logger.hpp>

#include "actengine/engine.h"
#include "actengine/status.h"
#include "apps/drive/calibrate.h"
#include "apps/pytorch_options.h"
#include "apps/drive/calibration.h"
#include "apps/drive/camera.h"
#include "apps/drive/control_loop.h"
#include "apps/drive/devices.h"
#include "apps/drive/emergency_neutral.h"
#include "apps/drive/gamepad.h"
#include "apps/drive/inference.h"
#include "apps/drive/live_view.h"
#include "apps/drive/pwm_link.h"
#include "apps/drive/recorder.h"
#include "apps/drive/serial_link.h"
#include "apps/version.h"
#include "weights/blob/file_kind.h"

namespace {

using namespace act::drive;

std::atomic<bool> g_stop{false};
static_assert(std::atomic<bool>::is_always_lock_free, "the signal handler needs a lock-free flag");

void request_stop(int) { g_stop.store(true); }

// Any other signal that would end the process: the actuator is told to stop before the signal's own
// action (the board would also time out to failsafe by itself in 250 ms, act_pwm_watchdog at once).
void neutral_then_die(int signal) {
  emergency_neutral();
  std::signal(signal, SIG_DFL);
  std::raise(signal);
}

// Bumped when the process is about to stop and again when it continues (Ctrl-Z then fg, SIGSTOP then
// SIGCONT): the control loop then drops what it planned before and holds neutral until a chunk from a
// new frame (ControlOptions::resumptions).
std::atomic<uint64_t> g_resumptions{0};
static_assert(std::atomic<uint64_t>::is_always_lock_free, "a signal handler bumps the count");

void note_resumed(int) { g_resumptions.fetch_add(1); }

void install_suspend_handler(int signal);

// Ctrl-Z and friends suspend the process, and nothing drives while it sleeps: neutral first. The
// handler runs with its signal blocked, so the signal raised here is unblocked for the stop to happen
// now (raised while blocked it would re-pend and run this handler again as soon as it returned).
void neutral_then_suspend(int signal) {
  const int saved_errno = errno;
  emergency_neutral();
  g_resumptions.fetch_add(1);  // a command planned before the stop is not sent after it
  struct sigaction default_action{};
  default_action.sa_handler = SIG_DFL;
  sigemptyset(&default_action.sa_mask);
  sigaction(signal, &default_action, nullptr);
  sigset_t only;
  sigemptyset(&only);
  sigaddset(&only, signal);
  pthread_sigmask(SIG_UNBLOCK, &only, nullptr);
  raise(signal);  // stops here until SIGCONT (nothing happens in an orphaned process group)
  pthread_sigmask(SIG_BLOCK, &only, nullptr);  // a second Ctrl-Z now waits until this handler returns
  install_suspend_handler(signal);
  errno = saved_errno;
}

void install_suspend_handler(int signal) {
  struct sigaction suspend{};
  suspend.sa_handler = neutral_then_suspend;
  sigemptyset(&suspend.sa_mask);
  suspend.sa_flags = SA_RESTART;  // as std::signal had it: a serial write in progress is not cut short
  sigaction(signal, &suspend, nullptr);
}

void install_signal_handlers() {
  // Stop requests: neutral, the summary, exit 0. SIGHUP is an SSH or Wi-Fi drop taking the terminal.
  struct sigaction stop{};
  stop.sa_handler = request_stop;
  sigemptyset(&stop.sa_mask);
  for (int s : {SIGINT, SIGTERM, SIGHUP}) sigaction(s, &stop, nullptr);
  std::signal(SIGPIPE, SIG_IGN);  // a vanished port (or terminal) is an error code, not a death
  // Every other catchable signal whose default action ends the process (SIGKILL cannot be caught:
  // the board's own watchdog covers it).
  std::vector<int> fatal{SIGQUIT, SIGABRT, SIGFPE, SIGILL, SIGTRAP, SIGSYS, SIGUSR1, SIGUSR2, SIGALRM,
                         SIGVTALRM, SIGPROF, SIGXCPU, SIGIO, SIGPWR, SIGSTKFLT};
  for (int s = SIGRTMIN; s <= SIGRTMAX; ++s) fatal.push_back(s);  // real-time signals end a process too
#if !defined(__SANITIZE_ADDRESS__)
  fatal.insert(fatal.end(), {SIGSEGV, SIGBUS});  // AddressSanitizer reports these itself
#endif
  for (int s : fatal) std::signal(s, neutral_then_die);
  // A file grew past RLIMIT_FSIZE (--record, --overlay-video): the write fails with EFBIG instead, the
  // recording stops with a message (Recorder) and driving goes on.
  std::signal(SIGXFSZ, SIG_IGN);
  for (int s : {SIGTSTP, SIGTTIN, SIGTTOU}) install_suspend_handler(s);
  struct sigaction resumed{};
  resumed.sa_handler = note_resumed;
  sigemptyset(&resumed.sa_mask);
  resumed.sa_flags = SA_RESTART;
  sigaction(SIGCONT, &resumed, nullptr);
}

// Sends neutral and closes the link on every way out of main (errors and exceptions included).
struct NeutralOnExit {
  ActuatorLink* link = nullptr;
  PwmCommand safe;
  ~NeutralOnExit() {
    if (link) link->shutdown(safe);
  }
};

// "HxW" (height first, as every size in the project).
bool parse_size(const std::string& text, int& height, int& width) {
  const size_t x = text.find('x');
  if (x == std::string::npos) return false;
  try {
    height = std::stoi(text.substr(0, x));
    width = std::stoi(text.substr(x + 1));
  } catch (const std::exception&) {
    return false;
  }
  return width > 0 && height > 0;
}

std::string hxw(int height, int width) { return std::to_string(height) + "x" + std::to_string(width); }

bool same_aspect(int height_a, int width_a, int height_b, int width_b) {
  return std::abs(static_cast<double>(width_a) / height_a - static_cast<double>(width_b) / height_b) <= 0.01;
}

// --camera-size is HxW; a size written WxH (the old order, and OpenCV's) is refused when only its
// transpose fits what the camera delivered or what the model expects.
void check_camera_size(const std::string& requested, int height, int width, const Camera& camera, const act::CameraInfo& input) {
  if (height == width) return;
  const std::string fix = ": --camera-size is HxW (height first); did you mean --camera-size " + hxw(width, height) + "?";
  if (camera.height() == width && camera.width() == height) {
    act::fail(act::StatusCode::kInvalidArgument, "--camera-size " + requested + " asks for height " + std::to_string(height) +
              ", width " + std::to_string(width) + " but the camera delivers " + hxw(camera.height(), camera.width()) + fix);
  }
  if (!same_aspect(height, width, input.height, input.width) && same_aspect(width, height, input.height, input.width)) {
    act::fail(act::StatusCode::kInvalidArgument, "--camera-size " + requested + " (height " + std::to_string(height) + ", width " +
              std::to_string(width) + ") only fits the model's " + hxw(input.height, input.width) + " input transposed" + fix);
  }
}

// --initial-state: "mean" (the training statistics' middle) or state_dim comma-separated numbers.
std::vector<float> parse_initial_state(const std::string& text, const act::ModelInfo& info) {
  if (text == "mean") return training_mean_state(info);
  std::vector<float> values;
  std::stringstream items(text);
  for (std::string item; std::getline(items, item, ',');) {
    try {
      size_t used = 0;
      values.push_back(std::stof(item, &used));
      if (used != item.size()) throw std::invalid_argument(item);
    } catch (const std::exception&) {
      act::fail(act::StatusCode::kInvalidArgument, "--initial-state '" + text + "': '" + item + "' is not a number (expected "
                "'mean' or " + std::to_string(info.state_dim) + " comma-separated values)");
    }
  }
  if (values.size() != static_cast<size_t>(info.state_dim)) {
    act::fail(act::StatusCode::kInvalidArgument, "--initial-state '" + text + "' has " + std::to_string(values.size()) +
              " values but the model's state has " + std::to_string(info.state_dim) + " (or use --initial-state mean)");
  }
  return values;
}

struct Options {
  std::string model, camera, serial, calibration_path, record_dir, camera_size, state = "last-action";
  std::string initial_state = "mean";
  std::string http, mode = "ai", gamepad, overlay_video, realtime = "on";  // live view, driving by hand, replays
  bool raw_endpoints = false, list_cameras = false, list_ports = false;
  double camera_fps = 0, control_hz = 30, stats_every = 0, duration = 0, ready_timeout = 5.0;
  int max_frame_age_ms = 200, threads = 0, baud = 115200;
  int control_priority = 0, inference_priority = 0;
  std::vector<int> control_cpus, inference_cpus;
  bool dry_run = false, calibrate = false, loop = false;
  std::string pwm, pwm_sysfs_root = kPwmSysfsRoot;
  act::DeploymentOptions deployment;
};

Calibration load_calibration(const Options& opt) {
  if (opt.calibration_path.empty()) {  // --dry-run or --raw-endpoints: run() refused every other case
    std::cerr << "act_drive: warning: no --calibration file: using 1000/1500/2000 us endpoints, forward and reverse "
                 "throttle capped at 0.3 (act_drive --calibrate helps write one)\n";
    return Calibration::starting_template();
  }
  return Calibration::load(opt.calibration_path);
}

// Checks that act_drive can feed this model and act on its output; throws with what does not fit.
void check_model(const act::ModelInfo& info, const Calibration& calibration, const Options& opt) {
  using act::StatusCode;
  act::check(info.cameras.size() == 1, StatusCode::kUnimplemented,
             "act_drive drives with one camera; the model has " + std::to_string(info.cameras.size()));
  act::check(info.env_state_dim == 0, StatusCode::kUnimplemented,
             "the model needs an environment state (" + info.env_state_key + "), which a rover does not have");
  act::check(calibration.max_action_index() < info.action_dim, StatusCode::kInvalidArgument,
             "the calibration uses action index " + std::to_string(calibration.max_action_index()) + " but the model has " +
                 std::to_string(info.action_dim) + " action values");
  calibration.check_units(info);
  act::check(opt.state != "last-action" || info.state_dim <= info.action_dim, StatusCode::kInvalidArgument,
             "--state last-action: the model's state has " + std::to_string(info.state_dim) + " values but its action only " +
                 std::to_string(info.action_dim) + " (use --state zeros)");
}

nlohmann::ordered_json record_meta(const Options& opt, const act::ModelInfo& info, const Camera& camera,
                                   const Calibration& calibration) {
  return {{"format", "act_drive recording 1"},
          {"model", opt.model},
          {"model_summary", info.summary},
          {"image_key", info.cameras.front().key},
          {"image_height", info.cameras.front().height},
          {"image_width", info.cameras.front().width},
          {"image_format", "PNG, RGB, the model's input size: the exact bytes the model saw"},
          {"camera", opt.camera},
          {"camera_width", camera.width()},
          {"camera_height", camera.height()},
          {"control_hz", opt.control_hz},
          // ticks.csv's action.<name> and command.<name> columns: the blob's names (empty: 0, 1, ...)
          {"action_names", info.action_names},
          {"state", opt.state},
          {"calibration", calibration.to_json()}};
}

CameraOptions camera_options_of(const Options& opt) {
  CameraOptions camera_options{opt.camera, 0, 0, opt.camera_fps};
  camera_options.stepped = opt.realtime == "off";
  camera_options.loop = opt.loop;
  if (!opt.camera_size.empty() && !parse_size(opt.camera_size, camera_options.height, camera_options.width)) {
    act::fail(act::StatusCode::kInvalidArgument, "--camera-size '" + opt.camera_size + "': expected HxW, e.g. 360x640");
  }
  return camera_options;
}

InferenceWorkerOptions worker_options_of(const Options& opt) {
  InferenceWorkerOptions worker_options;
  worker_options.max_frame_age = std::chrono::milliseconds(opt.max_frame_age_ms);
  if (opt.realtime == "off") worker_options.max_frame_age = std::chrono::hours(24);  // a replay's frames have no age
  worker_options.placement = {opt.inference_priority, opt.inference_cpus};
  worker_options.keep_model_inputs = !opt.record_dir.empty();
  return worker_options;
}

// Checks the camera against the model's input (a requested size it did not deliver fails, another
// aspect ratio warns), then says what drives what.
void report_model_and_camera(const Options& opt, const act::ModelInfo& info, const CameraOptions& camera_options,
                             const Camera& camera) {
  const act::CameraInfo& input = info.cameras.front();
  if (!opt.camera_size.empty()) check_camera_size(opt.camera_size, camera_options.height, camera_options.width, camera, input);
  if (!same_aspect(camera.height(), camera.width(), input.height, input.width)) {
    std::cerr << "act_drive: warning: the camera delivers " << hxw(camera.height(), camera.width())
              << " (HxW) but the model expects " << hxw(input.height, input.width)
              << ": frames are stretched (use --camera-size HxW with the training aspect ratio)\n";
  }
  std::cerr << "act_drive: model " << info.summary << "; " << (info.temporal_ensembling ? "temporal ensembling" : "queue of ")
            << (info.temporal_ensembling ? "" : std::to_string(info.n_action_steps) + " of " + std::to_string(info.chunk_size) + " actions")
            << "\nact_drive: camera " << opt.camera << " " << hxw(camera.height(), camera.width()) << " -> "
            << hxw(input.height, input.width) << " (HxW)\n";
}

/// Live view and driving by hand: the cockpit carries e-stop, mode and manual input into the loop.
struct ManualControls {
  std::optional<Cockpit> cockpit;
  std::optional<LiveView> live_view;
  std::optional<Gamepad> gamepad;
};

// Set up before the board is touched, so that a busy port or a wrong gamepad fails first.
void open_manual_controls(const Options& opt, const act::CameraInfo& input, const Camera& camera, ManualControls& manual) {
  if (!opt.http.empty() || !opt.gamepad.empty() || opt.mode != "ai") manual.cockpit.emplace(*parse_mode(opt.mode));
  if (!opt.gamepad.empty()) {
    manual.gamepad.emplace(opt.gamepad, *manual.cockpit, std::cerr);
    std::cerr << "act_drive: gamepad " << opt.gamepad << " (" << manual.gamepad->name() << "): left stick steers, right stick "
              << "throttle, B e-stop, Start resume\n";
  }
  if (!opt.http.empty()) {
    LiveViewOptions view_options;
    parse_http_address(opt.http, view_options);
    view_options.image_height = input.height;
    view_options.image_width = input.width;
    manual.live_view.emplace(view_options, *manual.cockpit, camera);
    std::cerr << "act_drive: live view on " << manual.live_view->url() << " (token " << manual.live_view->token()
              << ": needed to resume, change mode or drive from the page; the e-stop needs none)\n";
  }
}

// Where the commands go: standard output (--dry-run), the Pi's PWM pins (--pwm) or the board on
// --serial, which is connected here (ready, failsafe set, neutral).
std::unique_ptr<ActuatorLink> open_link(const Options& opt, const Calibration& calibration) {
  if (opt.dry_run) return std::make_unique<DryRunLink>(std::cout);
  if (!opt.pwm.empty()) {
    PwmLinkOptions pwm_options;
    pwm_options.channels = parse_pwm_channels(opt.pwm);
    pwm_options.sysfs_root = opt.pwm_sysfs_root;
    pwm_options.neutral = calibration.safe_command();
    pwm_options.watchdog_path = default_watchdog_path();
    auto pwm = std::make_unique<PwmSysfsLink>(pwm_options, std::cerr);
    std::cerr << "act_drive: PWM " << opt.pwm_sysfs_root << "/" << opt.pwm << " at 50 Hz, neutral; watchdog pid "
              << pwm->watchdog_pid() << "\n";
    return pwm;
  }
  SerialLinkOptions serial_options;
  serial_options.path = opt.serial;
  serial_options.baud = opt.baud;
  serial_options.ready_timeout = std::chrono::milliseconds(static_cast<int64_t>(opt.ready_timeout * 1000));
  serial_options.failsafe = calibration.safe_command();
  auto serial = std::make_unique<SerialLink>(serial_options, std::cerr);
  serial->connect();
  std::cerr << "act_drive: board ready on " << opt.serial << "\n";
  return serial;
}

ControlOptions control_options_of(const Options& opt, const std::vector<float>& initial_state, ManualControls& manual,
                                  std::optional<OverlayVideo>& overlay) {
  ControlOptions control;
  control.cockpit = manual.cockpit ? &*manual.cockpit : nullptr;
  control.overlay = overlay ? &*overlay : nullptr;
  control.realtime = opt.realtime == "on";
  control.control_hz = opt.control_hz;
  control.max_frame_age = std::chrono::milliseconds(opt.max_frame_age_ms);
  control.stats_every_s = opt.stats_every;
  control.duration_s = opt.duration;
  control.state_source = opt.state == "zeros" ? ControlOptions::StateSource::kZeros : ControlOptions::StateSource::kLastAction;
  control.initial_state = initial_state;
  control.placement = {opt.control_priority, opt.control_cpus};
  control.deployment = opt.deployment;
  control.resumptions = &g_resumptions;
  return control;
}

// Closes the recording and the overlay video, saying where they went and what was dropped.
void close_outputs(const Options& opt, std::optional<Recorder>& recorder, std::optional<OverlayVideo>& overlay) {
  if (recorder) {
    recorder->close();
    std::cerr << "act_drive: recorded to " << opt.record_dir;
    if (recorder->dropped_frames() > 0) std::cerr << " (" << recorder->dropped_frames() << " frames dropped: disk too slow)";
    if (!recorder->failure().empty()) {
      std::cerr << " (stopped early: a write failed, see above; " << recorder->unrecorded_ticks() << " ticks not recorded)";
    }
    std::cerr << "\n";
  }
  if (overlay) {
    overlay->close();
    std::cerr << "act_drive: overlay video " << opt.overlay_video << ": " << overlay->frames_written() << " ticks";
    if (overlay->dropped() > 0) std::cerr << " (" << overlay->dropped() << " dropped: the encoder was too slow)";
    std::cerr << "\n";
  }
}

int drive(const Options& opt) {
  const Calibration calibration = load_calibration(opt);
  const CameraOptions camera_options = camera_options_of(opt);
  Camera camera(camera_options);

  InferenceWorker worker([&] { return open_engine_model(opt.model, opt.threads); }, camera, worker_options_of(opt), std::cerr);
  const act::ModelInfo info = with_deployment(worker.info(), opt.deployment);  // fails early on a bad override
  check_model(info, calibration, opt);
  const std::vector<float> initial_state = parse_initial_state(opt.initial_state, info);
  const act::CameraInfo& input = info.cameras.front();
  report_model_and_camera(opt, info, camera_options, camera);

  ManualControls manual;
  open_manual_controls(opt, input, camera, manual);

  std::unique_ptr<ActuatorLink> link;
  NeutralOnExit neutral_on_exit;  // declared after the link: sends neutral before it is destroyed
  neutral_on_exit.safe = calibration.safe_command();
  link = open_link(opt, calibration);
  neutral_on_exit.link = link.get();

  std::optional<Recorder> recorder;
  if (!opt.record_dir.empty()) {
    recorder.emplace(opt.record_dir, info.state_dim, info.action_dim, input.height, input.width,
                     record_meta(opt, info, camera, calibration), &std::cerr);
  }

  std::optional<OverlayVideo> overlay;
  // A replay (--realtime off) waits for the encoder: its video has every tick, however slow the encoder.
  if (!opt.overlay_video.empty()) overlay.emplace(opt.overlay_video, opt.control_hz, input.height, input.width, 4, opt.realtime == "off");

  ControlLoop loop(control_options_of(opt, initial_state, manual, overlay), calibration, camera, worker, *link,
                   recorder ? &*recorder : nullptr, std::cerr);
  const DriveSummary summary = loop.run(g_stop);
  close_outputs(opt, recorder, overlay);
  std::cerr << summary.to_string();
  if (!camera.stop()) {
    std::cerr << "act_drive: camera '" << opt.camera << "' is blocked in its backend and did not stop within "
              << Camera::kStopTimeout.count() << " ms: exiting without waiting for it\n";
  }
  return summary.exit_code;
}

// A model, checkpoint or recording given as the camera says what it is instead of "cannot open camera".
void check_camera_kind(const std::string& camera) {
  switch (const act::FileKind kind = act::file_kind(camera)) {
    case act::FileKind::kRecording:
      act::fail(act::StatusCode::kInvalidArgument, act::wrong_kind_message(camera, kind, "a camera") +
                "; to replay it as a camera: --camera " + camera + "/frames/%06d.png");
    case act::FileKind::kLeRobotCheckpoint:
    case act::FileKind::kTrainingCheckpoint:
    case act::FileKind::kLeRobotDataset:
    case act::FileKind::kActb:
    case act::FileKind::kPyTorchZip:
    case act::FileKind::kPyTorchLegacy:
    case act::FileKind::kSafetensors:
      act::fail(act::StatusCode::kInvalidArgument, act::wrong_kind_message(camera, kind, "a camera"));
    default: break;
  }
}

// act_drive from the parsed options to its exit code: calibration, or driving.
int run(const Options& opt) {
  try {
    if (opt.list_cameras || opt.list_ports) {
      if (opt.list_cameras) list_cameras(std::cout);
      if (opt.list_ports) {
        list_ports(std::cout);
        list_pwm_channels(opt.pwm_sysfs_root, std::cout);
      }
      return 0;
    }
    if (!opt.pwm.empty()) {
      parse_pwm_channels(opt.pwm);  // a typo is the first thing said
      act::check(opt.serial.empty() && !opt.dry_run && !opt.calibrate, act::StatusCode::kInvalidArgument,
                 "--pwm drives the pins itself: not with --serial, --dry-run or --calibrate (write the calibration "
                 "file from act_drive --calibrate's template and check it with a --duration run)");
    }
    if (opt.realtime == "off" && !opt.dry_run) {
      act::fail(act::StatusCode::kInvalidArgument, "--realtime off replays a file faster than real time: only with --dry-run");
    }
    if (opt.loop && opt.realtime == "off" && opt.duration <= 0) {
      std::cerr << "act_drive: warning: --loop --realtime off without --duration replays the file over and over as fast as "
                   "the machine allows, until Ctrl-C\n";
    }
    if (opt.mode != "ai" && opt.http.empty() && opt.gamepad.empty()) {
      act::fail(act::StatusCode::kInvalidArgument, "--mode " + opt.mode + " needs a way to drive by hand: add --http PORT "
                "(the page's stick and keys) or --gamepad /dev/input/eventN");
    }
    if (opt.calibrate) {
      return run_calibration(CalibrateOptions{opt.serial, opt.baud, opt.calibration_path}, g_stop, std::cin, std::cout, std::cerr);
    }
    if (opt.model.empty()) act::fail(act::StatusCode::kInvalidArgument, "--model is required");
    if (opt.camera.empty()) act::fail(act::StatusCode::kInvalidArgument, "--camera is required");
    // Both checked before the camera opens, so the wrong kind of file is the first thing said.
    if (const std::string hint = act::not_a_blob_hint(opt.model); !hint.empty()) act::fail(act::StatusCode::kInvalidArgument, hint);
    check_camera_kind(opt.camera);
    if (opt.serial.empty() && opt.pwm.empty() && !opt.dry_run) {
      act::fail(act::StatusCode::kInvalidArgument, "--serial is required (or --pwm for the Pi's own PWM pins, or --dry-run "
                                                   "to print the commands)");
    }
    if (!opt.dry_run && opt.calibration_path.empty() && !opt.raw_endpoints) {
      act::fail(act::StatusCode::kInvalidArgument,
                (opt.pwm.empty() ? "--serial " + opt.serial : "--pwm " + opt.pwm) +
                " without --calibration: refusing to drive a real car on guessed pulse widths. "
                "Measure them with act_drive --calibrate --serial PORT -c calibration.json and pass "
                "-c calibration.json, or accept raw 1000/1500/2000 us endpoints (throttle capped at 0.3) with --raw-endpoints");
    }
    return drive(opt);
  } catch (const std::exception& e) {
    std::cerr << "act_drive: error: " << e.what() << "\n";
    return 1;
  }
}

// The model, the camera, the board and the control rate.
void add_model_camera_and_board_options(CLI::App& app, Options& opt) {
  app.add_option("-m,--model", opt.model, "the .actb model (act_convert output)");
  app.add_option("--camera", opt.camera, "camera: an index (0), a device (/dev/video0), a video file, an image "
                 "sequence (frames/%06d.png), a URL or a GStreamer pipeline ending in appsink");
  app.add_option("--camera-size", opt.camera_size, "capture resolution HxW to request, height first like every size "
                                                   "here, e.g. 480x640 (default: the camera's); frames are then resized "
                                                   "to the model's input");
  app.add_option("--camera-fps", opt.camera_fps, "capture rate to request; a video file or image sequence plays at "
                                                 "this rate (default: a video's own, 30 for an image sequence)")->check(CLI::NonNegativeNumber);
  app.add_option("--serial", opt.serial, "the Arduino's serial port, e.g. /dev/ttyUSB0 or /dev/ttyACM0");
  app.add_option("--baud", opt.baud, "serial baud rate (the sketch's ROVER_BAUD)")->capture_default_str();
  app.add_option("--ready-timeout", opt.ready_timeout, "seconds to wait for the board's ready line after opening the port")
      ->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("-c,--calibration", opt.calibration_path, "calibration JSON: PWM endpoints, inversion, throttle cap, "
                                                           "rate limits (README, act_drive --calibrate)");
  app.add_option("--control-hz", opt.control_hz, "control rate: commands per second")->capture_default_str()
      ->check(CLI::Range(1.0, 500.0));
  app.add_option("--max-frame-age", opt.max_frame_age_ms, "milliseconds; an older frame is never used (the rover holds "
                                                          "neutral instead); a video file's or image sequence's frame "
                                                          "ages from when the next one is due")->capture_default_str()->check(CLI::Range(1, 10000));
  app.add_option("-t,--threads", opt.threads, "inference threads (0 = all cores)")->capture_default_str()
      ->check(CLI::Range(0, act::kMaxThreads));
  act::add_deployment_options(app, opt.deployment);
  app.add_option("--initial-state", opt.initial_state, "observation.state before the first action and after every hold: "
                 "'mean' (the training mean from the model's statistics) or comma-separated values")->capture_default_str();
  app.add_flag("--raw-endpoints", opt.raw_endpoints, "drive --serial without a calibration file: 1000/1500/2000 us "
                                                     "endpoints, throttle capped at 0.3");
}

// Listing devices, the model's state, real-time scheduling, statistics and the run's length.
void add_loop_options(CLI::App& app, Options& opt) {
  app.add_flag("--list-cameras", opt.list_cameras, "list the V4L2 cameras and exit");
  app.add_flag("--list-ports", opt.list_ports, "list the serial ports (USB ones with maker and product) and the PWM chips "
               "and channels (--pwm), then exit");
  app.add_option("--state", opt.state, "the model's observation.state: the last action executed, or zeros")
      ->capture_default_str()->check(CLI::IsMember({"last-action", "zeros"}));
  app.add_option("--control-priority", opt.control_priority, "SCHED_FIFO priority of the control thread (1-99, 0 = off; "
                                                            "needs CAP_SYS_NICE, falls back with a warning)")
      ->capture_default_str()->check(CLI::Range(0, 99));
  app.add_option("--inference-priority", opt.inference_priority, "SCHED_FIFO priority of the inference threads (0 = off)")
      ->capture_default_str()->check(CLI::Range(0, 99));
  app.add_option("--control-cpus", opt.control_cpus, "pin the control thread to these CPUs (comma-separated, e.g. 3)")->delimiter(',');
  app.add_option("--inference-cpus", opt.inference_cpus, "pin the inference threads to these CPUs (comma-separated, e.g. 0,1,2)")->delimiter(',');
  app.add_option("--stats-every", opt.stats_every, "print latency statistics every S seconds (0 = only at exit)")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
  app.add_option("--duration", opt.duration, "stop after S seconds (0 = run until Ctrl-C or the video ends)")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
}

// Recording, the live view, driving by hand, replay, calibration and the Pi's PWM pins.
void add_output_and_manual_options(CLI::App& app, Options& opt) {
  app.add_option("--record", opt.record_dir, "save frames, states, actions and timings to this new folder (README: "
                                             "recording format; usable as act_convert calibration input)");
  app.add_option("--http", opt.http, "serve the live view (frame, gauges, e-stop, driving by hand) on [ADDR:]PORT, "
                                     "e.g. 8887; 127.0.0.1 unless an address is given (0.0.0.0: every interface)");
  app.add_option("--gamepad", opt.gamepad, "drive by hand with this evdev gamepad (/dev/input/eventN): left stick "
                                           "steers, right stick throttle, B e-stop, Start resume");
  app.add_option("--mode", opt.mode, "who drives: ai (the policy; manual input overrides it until resumed), manual "
                                     "(by hand), ai-steer (the policy steers, the throttle is by hand)")
      ->capture_default_str()->check(CLI::IsMember({"ai", "manual", "ai-steer"}));
  app.add_option("--overlay-video", opt.overlay_video, "write every tick as a video frame: the model's view with the "
                                                      "gauges, the chunk ahead and who drove (e.g. out.mp4)");
  app.add_option("--realtime", opt.realtime, "off: replay a video file or image sequence as fast as the machine allows, "
                                             "each inference waited for (with --dry-run, e.g. for --overlay-video)")
      ->capture_default_str()->check(CLI::IsMember({"on", "off"}));
  app.add_flag("--loop", opt.loop, "a video file or image sequence camera restarts from its first frame at its end "
                                   "(the run then ends at --duration or Ctrl-C)");
  app.add_flag("--dry-run", opt.dry_run, "print the commands instead of writing them to the serial port");
  app.add_flag("--calibrate", opt.calibrate, "find the PWM endpoints interactively on --serial, then write --calibration; "
                                             "without --serial, write a calibration file to edit to --calibration FILE "
                                             "(kept if it exists; printed without -c)");
  // The Pi's own PWM pins instead of the Arduino (docs/rover.md, "On the Pi's own PWM pins").
  app.add_option("--pwm", opt.pwm, "drive the servo and ESC from Linux PWM channels CHIP:STEERING,THROTTLE, e.g. "
                                   "pwmchip0:0,1 (Raspberry Pi: dtoverlay=pwm-2chan); act_pwm_watchdog holds neutral "
                                   "if act_drive dies");
  app.add_option("--pwm-sysfs-root", opt.pwm_sysfs_root, "where the PWM chips are (a test and expert knob)")->capture_default_str();
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"act_drive: drive the RC rover with an ACT policy. Camera -> model -> action chunks -> PWM commands "
               "over serial to the Arduino sketch apps/arduino/act_rover, at a fixed control rate. Holds neutral "
               "whenever something is wrong (stale frames, inference errors, serial errors, signals)."};
  Options opt;
  app.set_version_flag("--version", act::version_line("act_drive"));
  add_model_camera_and_board_options(app, opt);
  add_loop_options(app, opt);
  add_output_and_manual_options(app, opt);
  CLI11_PARSE(app, argc, argv);

  install_signal_handlers();
  // act_drive names camera problems itself; OpenCV's backend chatter (GStreamer probing a file...)
  // only confuses. OPENCV_LOG_LEVEL still overrides.
  if (!std::getenv("OPENCV_LOG_LEVEL")) cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
  const int exit_code = run(opt);
  if (Camera::left_a_thread_behind()) {
    // All of the way out is done (neutral, recording, summary or error) but a capture thread stuck
    // in its backend: the process ends under it, without static destructors (see Camera::stop).
    std::fflush(nullptr);  // std::cout writes through stdout's buffer, which _Exit drops
    std::_Exit(exit_code);
  }
  return exit_code;
}
