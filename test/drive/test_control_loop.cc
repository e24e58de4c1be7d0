// The control loop end to end in-process: a video file (or a hand-fed source) for the camera, a fake
// model, and a pseudo-terminal Arduino that parses and acknowledges every line. Checks the command
// stream: rate, values within calibration, neutral on shutdown and within 250 ms of each fault.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <mutex>
#include <optional>
#include <sstream>


#include "apps/drive/control_loop.h"
#include "engine/media/media_io.h"
#include "drive/drive_test_util.h"
#include "drive/fake_arduino.h"
#include "support/test_paths.h"

namespace act::drive::test {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;


bool is(const FakeArduino::Command& c, PwmCommand p) { return c.steering_us == p.steering_us && c.throttle_us == p.throttle_us; }

// The drive commands (C lines) in arrival order.
std::vector<FakeArduino::Command> drive_commands(const FakeArduino& board) {
  std::vector<FakeArduino::Command> out;
  for (const auto& c : board.commands()) {
    if (c.type == 'C') out.push_back(c);
  }
  return out;
}

// Checks that the rover went neutral within kFaultDeadline of `fault` and stayed neutral until `until`.
::testing::AssertionResult neutral_after(const std::vector<FakeArduino::Command>& commands, Clock::time_point fault,
                                         Clock::time_point until, const std::string& fault_name) {
  const FakeArduino::Command* first = nullptr;
  for (const auto& c : commands) {
    if (c.when >= fault && is(c, kSafe)) {
      first = &c;
      break;
    }
  }
  if (!first) return ::testing::AssertionFailure() << "no neutral command after the fault";
  report_fault_timing(fault_name, ms(first->when - fault));
  if (first->when - fault > kFaultDeadline) {
    return ::testing::AssertionFailure() << "first neutral " << ms(first->when - fault) << " ms after the fault";
  }
  for (const auto& c : commands) {
    if (c.when > fault + kFaultDeadline && c.when < until && !is(c, kSafe)) {
      return ::testing::AssertionFailure() << "a driving command " << c.steering_us << "/" << c.throttle_us << " "
                                           << ms(c.when - fault) << " ms after the fault";
    }
  }
  return ::testing::AssertionSuccess();
}

// The serial link, with a control thread that can be made to stall after a command (as a starved
// CPU or SIGSTOP stalls it): the stall happens once, after the send it is asked for, and its end is
// noted.
class StallingLink : public ActuatorLink {
 public:
  explicit StallingLink(ActuatorLink& link) : link_(link) {}
  void stall_after_next_send(milliseconds how_long) { stall_.store(how_long); }
  std::optional<Clock::time_point> stall_ended() const {
    std::lock_guard lock(mutex_);
    return stall_ended_;
  }
  bool send(PwmCommand command, Clock::time_point now) override {
    const bool sent = link_.send(command, now);
    if (const milliseconds stall = stall_.exchange(milliseconds(0)); stall.count() > 0) {
      std::this_thread::sleep_for(stall);
      std::lock_guard lock(mutex_);
      stall_ended_ = Clock::now();
    }
    return sent;
  }
  void poll(Clock::time_point now) override { link_.poll(now); }
  void shutdown(PwmCommand neutral) override { link_.shutdown(neutral); }
  std::string summary() const override { return link_.summary(); }

 private:
  ActuatorLink& link_;
  std::atomic<milliseconds> stall_{milliseconds(0)};
  mutable std::mutex mutex_;
  std::optional<Clock::time_point> stall_ended_;
};

// One loop run with a fake model and a pseudo-terminal board.
struct Rig {
  std::string dir = act::test::scratch_dir();
  std::unique_ptr<FakeArduino> board;
  std::shared_ptr<FakeModelControls> controls = std::make_shared<FakeModelControls>();
  Calibration calibration = test_calibration();
  ModelInfo info = fake_model_info();
  ControlOptions options;
  std::ostringstream log;
  std::atomic<bool> stop{false};
  Clock::time_point started;
  std::string recording;
  StallingLink* link = nullptr;  // during run()

  explicit Rig(bool symlinked_port = false) {
    board = std::make_unique<FakeArduino>(symlinked_port ? dir + "/tty" : "");
    options.control_hz = 30;
  }

  // Runs the loop on its own thread; `during` runs on this thread meanwhile (then stop is set).
  DriveSummary run(const FrameSource& frames, const std::function<void()>& during) {
    SerialLinkOptions serial;
    serial.path = board->port_path();
    serial.hello_delay = milliseconds(0);
    serial.failsafe = calibration.safe_command();
    SerialLink serial_link(serial, log);
    serial_link.connect();
    StallingLink stalling(serial_link);
    link = &stalling;
    InferenceWorkerOptions worker_options;
    worker_options.max_frame_age = options.max_frame_age;
    worker_options.keep_model_inputs = !recording.empty();
    InferenceWorker worker([&] { return std::make_unique<FakeModel>(info, controls); }, frames, worker_options, log);
    std::optional<Recorder> recorder;
    if (!recording.empty()) recorder.emplace(recording, info.state_dim, info.action_dim, info.cameras.front().height,
                                               info.cameras.front().width, nlohmann::ordered_json{{"test", 1}});
    ControlLoop loop(options, calibration, frames, worker, stalling, recorder ? &*recorder : nullptr, log);
    DriveSummary summary;
    started = Clock::now();
    std::thread control([&] { summary = loop.run(stop); });
    during();
    stop.store(true);
    control.join();
    if (recorder) recorder->close();
    link = nullptr;
    EXPECT_TRUE(board->bad_lines().empty()) << board->bad_lines().front();
    const auto commands = drive_commands(*board);
    EXPECT_FALSE(commands.empty());
    if (!commands.empty()) {
      EXPECT_TRUE(is(commands.back(), kSafe)) << "the last command is not neutral";
    }
    return summary;
  }
};

std::unique_ptr<Camera> video_camera(const std::string& dir, int frames) {
  return std::make_unique<Camera>(CameraOptions{write_test_video(dir + "/camera.avi", frames, 30), 0, 0, 0});
}

void sleep_ms(int n) { std::this_thread::sleep_for(milliseconds(n)); }

TEST(ControlLoop, DrivesAtTheControlRateWithinCalibrationAndEndsNeutral) {
  Rig rig;
  auto camera = video_camera(rig.dir, 150);
  const DriveSummary summary = rig.run(*camera, [] { sleep_ms(2500); });
  const auto all = rig.board->commands();
  ASSERT_FALSE(all.empty());
  // The handshake: failsafe values first, then neutral.
  EXPECT_EQ(all.front().type, 'F');
  EXPECT_TRUE(is(all.front(), kSafe));
  const auto commands = drive_commands(*rig.board);
  EXPECT_TRUE(is(commands.front(), kSafe));

  // Rate over 2 s of steady driving: 30 Hz +-25% (a loaded 2-core CI machine).
  const auto from = rig.started + milliseconds(500), to = rig.started + milliseconds(2500);
  size_t in_window = 0, driving = 0;
  for (const auto& c : commands) {
    if (c.when >= from && c.when < to) ++in_window;
    if (is(c, kDriving)) ++driving;
    EXPECT_GE(c.steering_us, 1100);
    EXPECT_LE(c.steering_us, 1900);
    EXPECT_GE(c.throttle_us, 1300);
    EXPECT_LE(c.throttle_us, 1650);  // max_forward 0.5
  }
  EXPECT_GE(in_window, 45u);
  EXPECT_LE(in_window, 75u);
  EXPECT_GT(driving, commands.size() / 2) << rig.log.str();
  EXPECT_EQ(summary.end_reason, "stopped by a signal");
  EXPECT_EQ(summary.exit_code, 0);
  EXPECT_EQ(summary.inference_errors, 0u);
  EXPECT_GE(summary.inferences, 6u);  // one chunk of 10 steps per 1/3 s
  EXPECT_NE(summary.to_string().find("tick jitter"), std::string::npos);
}

TEST(ControlLoop, NeutralWithin250msOfTheModelReturningNaN) {
  Rig rig;
  rig.options.max_consecutive_inference_errors = 10;
  auto camera = video_camera(rig.dir, 150);
  const DriveSummary summary = rig.run(*camera, [&] {
    sleep_ms(1000);
    rig.controls->return_nan.store(true);
    sleep_ms(1200);
  });
  std::optional<Clock::time_point> nan_at;
  {
    std::lock_guard lock(rig.controls->mutex);
    nan_at = rig.controls->first_nan_returned;
  }
  ASSERT_TRUE(nan_at.has_value());
  EXPECT_TRUE(neutral_after(drive_commands(*rig.board), *nan_at, Clock::now(), "the model returns NaN"));
  EXPECT_GT(summary.inference_errors, 0u);
  EXPECT_NE(rig.log.str().find("non-finite action"), std::string::npos) << rig.log.str();
  // Inference that keeps failing ends the run.
  EXPECT_EQ(summary.exit_code, 1);
  EXPECT_NE(summary.end_reason.find("inference failed"), std::string::npos) << summary.end_reason;
}

TEST(ControlLoop, NeutralWithin250msOfTheCameraEnding) {
  Rig rig;
  auto camera = video_camera(rig.dir, 30);  // one second
  const DriveSummary summary = rig.run(*camera, [&] {
    while (camera->state() != FrameSource::State::kEnded) sleep_ms(10);
    sleep_ms(300);
  });
  EXPECT_NE(summary.end_reason.find("end of video file"), std::string::npos) << summary.end_reason;
  // The camera failed when its next frame was due.
  const Clock::time_point ended = camera->latest()->captured + milliseconds(1000 / 30);
  const auto commands = drive_commands(*rig.board);
  EXPECT_TRUE(std::any_of(commands.begin(), commands.end(), [](const auto& c) { return is(c, kDriving); }));
  EXPECT_TRUE(neutral_after(commands, ended, Clock::now(), "the camera ends"));
}

TEST(ControlLoop, NeutralWithin250msOfStaleFramesThenDrivesAgain) {
  Rig rig;
  rig.options.max_frame_age = milliseconds(200);
  ManualFrameSource frames;
  frames.push();
  std::atomic<bool> feeding{true}, quit{false};
  std::thread feeder([&] {
    while (!quit.load()) {
      if (feeding.load()) frames.push();
      sleep_ms(33);
    }
  });
  Clock::time_point frozen, resumed;
  rig.run(frames, [&] {
    sleep_ms(1000);
    feeding.store(false);
    sleep_ms(40);  // the feeder may be mid-push
    frozen = frames.latest()->captured;
    sleep_ms(800);
    resumed = Clock::now();
    feeding.store(true);
    sleep_ms(1000);
  });
  quit.store(true);
  feeder.join();
  const auto commands = drive_commands(*rig.board);
  // Stale from the moment the newest frame is older than --max-frame-age.
  EXPECT_TRUE(neutral_after(commands, frozen + rig.options.max_frame_age, resumed, "frames older than --max-frame-age"));
  EXPECT_TRUE(std::any_of(commands.begin(), commands.end(), [&](const auto& c) { return c.when > resumed && is(c, kDriving); }))
      << "did not drive again after the frames came back";
  EXPECT_NE(rig.log.str().find("stale frame"), std::string::npos);
}

TEST(ControlLoop, SerialHangUpReconnectsAndSendsNeutralFirst) {
  Rig rig(/*symlinked_port=*/true);
  auto camera = video_camera(rig.dir, 150);
  Clock::time_point hang_up;
  const DriveSummary summary = rig.run(*camera, [&] {
    sleep_ms(800);
    hang_up = Clock::now();
    rig.board->replace();
    sleep_ms(2000);
  });
  std::vector<FakeArduino::Command> after;
  for (const auto& c : rig.board->commands()) {
    if (c.generation == 1) after.push_back(c);
  }
  ASSERT_GE(after.size(), 3u) << rig.log.str();
  EXPECT_EQ(after[0].type, 'F');  // failsafe values, then neutral, then driving resumes
  EXPECT_TRUE(is(after[0], kSafe));
  EXPECT_EQ(after[1].type, 'C');
  EXPECT_TRUE(is(after[1], kSafe));
  EXPECT_LT(ms(after[0].when - hang_up), 1500);
  report_fault_timing("the serial port hangs up (neutral first on the new port)", ms(after[1].when - hang_up));
  EXPECT_TRUE(std::any_of(after.begin(), after.end(), [](const auto& c) { return is(c, kDriving); }));
  EXPECT_GT(summary.link_down_ticks, 0u);
  EXPECT_NE(summary.link_summary.find("1 reconnects"), std::string::npos) << summary.link_summary;
  EXPECT_NE(rig.log.str().find("reconnecting"), std::string::npos);
}

TEST(ControlLoop, SlowInferenceOverrunsAreCountedAndHoldNeutral) {
  Rig rig;
  // 333 ms of actions per chunk, 250 ms inference: each chunk arrives with only ~2 of its ticks left.
  rig.controls->delay_ms.store(250);
  auto camera = video_camera(rig.dir, 150);
  const DriveSummary summary = rig.run(*camera, [] { sleep_ms(2500); });
  EXPECT_GE(summary.overrun_events, 2u);
  EXPECT_GT(summary.overrun_ticks, summary.overrun_events);
  EXPECT_NE(rig.log.str().find("overrun"), std::string::npos);
  // Between chunks the rover holds neutral; the control rate does not drop.
  const auto commands = drive_commands(*rig.board);
  EXPECT_TRUE(std::any_of(commands.begin(), commands.end(), [](const auto& c) { return is(c, kDriving); }));
  EXPECT_GE(summary.ticks, 55u);
}

TEST(ControlLoop, TemporalEnsemblingDrivesAtTheControlRate) {
  Rig rig;
  rig.info = fake_model_info(/*ensembling=*/true);
  auto camera = video_camera(rig.dir, 150);
  const DriveSummary summary = rig.run(*camera, [] { sleep_ms(1500); });
  const auto commands = drive_commands(*rig.board);
  size_t driving = 0;
  for (const auto& c : commands) driving += is(c, kDriving);
  EXPECT_GT(driving, 25u) << rig.log.str();
  EXPECT_GT(summary.inferences, 10u);  // ensembling keeps inferring
}

TEST(ControlLoop, DeploymentOptionsReplaceTheModelsAsLeRobotChecksThem) {
  const ModelInfo queue = fake_model_info(false, 10);  // chunk 10
  EXPECT_EQ(with_deployment(queue, {.n_action_steps = 3, .temporal_ensemble_coeff = std::nullopt}).n_action_steps, 3);
  const ModelInfo ensembling = with_deployment(queue, {.n_action_steps = 1, .temporal_ensemble_coeff = 0.05});
  EXPECT_TRUE(ensembling.temporal_ensembling);
  EXPECT_DOUBLE_EQ(ensembling.temporal_ensemble_coeff, 0.05);
  DeploymentOptions off;
  off.temporal_ensemble_coeff.emplace(std::nullopt);
  EXPECT_FALSE(with_deployment(fake_model_info(true), off).temporal_ensembling);
  const auto refused = [&](const DeploymentOptions& d, const std::string& why) {
    try {
      with_deployment(queue, d);
      ADD_FAILURE() << "accepted; expected: " << why;
    } catch (const std::exception& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
    }
  };
  refused({.n_action_steps = 11, .temporal_ensemble_coeff = std::nullopt}, "must be in [1, chunk_size 10]");
  refused({.n_action_steps = std::nullopt, .temporal_ensemble_coeff = 0.01}, "needs n_action_steps == 1");
  refused({.n_action_steps = 1, .temporal_ensemble_coeff = 1e9}, "overflow float32");
}

TEST(ControlLoop, RecordWritesFramesObservationsAndTicks) {
  Rig rig;
  rig.recording = rig.dir + "/rec";
  auto camera = video_camera(rig.dir, 150);
  const DriveSummary summary = rig.run(*camera, [] { sleep_ms(1200); });
  ASSERT_TRUE(fs::exists(rig.recording + "/meta.json"));
  auto lines = [](const std::string& path) {
    std::ifstream in(path);
    std::vector<std::string> out;
    for (std::string line; std::getline(in, line);) out.push_back(line);
    return out;
  };
  const auto observations = lines(rig.recording + "/log.jsonl");
  const auto ticks = lines(rig.recording + "/ticks.csv");
  ASSERT_GE(observations.size(), 2u);
  // Today's columns first (readers go by name, but nothing moved), then who drove, the frame, the state
  // and the command in the model's units.
  EXPECT_EQ(ticks[0], "tick,time_s,jitter_ms,source,action.0,action.1,steering_us,throttle_us,sent,driver,frame,state.0,"
                      "state.1,command.0,command.1");
  EXPECT_EQ(ticks.size() - 1, summary.ticks);
  size_t pngs = 0;
  for (const auto& e : fs::directory_iterator(rig.recording + "/frames")) {
    EXPECT_EQ(e.path().extension(), ".png") << e.path();
    ++pngs;
  }
  EXPECT_EQ(pngs, observations.size());
  // The lines act_convert's calibration reads: {"frame": <relative path>, "state": [...]}.
  const nlohmann::json first_line = nlohmann::json::parse(observations[0]);
  EXPECT_EQ(first_line["frame"], "frames/000000.png");
  EXPECT_EQ(first_line["state"].size(), 2u);
  for (const char* key : {"tick", "time_s", "frame_index", "frame_age_ms"}) EXPECT_TRUE(first_line.contains(key)) << key;
  const cv::Mat first = act::media::read_image(rig.recording + "/frames/000000.png");
  EXPECT_EQ(first.cols, 64);
  EXPECT_EQ(first.rows, 48);
  std::string driving_row;
  for (const auto& t : ticks) {
    if (t.find(",chunk,0.5,0.800000012,1700,1650,1,ai,tick_frames/") != std::string::npos) driving_row = t;
  }
  ASSERT_FALSE(driving_row.empty()) << ticks[ticks.size() / 2];
  // The command sent, back in the model's units: 1700 us is steering +0.5; throttle 0.8 capped at
  // max_forward 0.5 is 1650 us, +0.5.
  EXPECT_EQ(driving_row.substr(driving_row.size() - 8), ",0.5,0.5") << driving_row;
  const std::string frame = driving_row.substr(driving_row.find("tick_frames/"), 24);
  const cv::Mat tick_frame = act::media::read_image(rig.recording + "/" + frame);
  EXPECT_EQ(tick_frame.cols, 64) << frame;
  EXPECT_EQ(tick_frame.rows, 48) << frame;
}

// The first observation gets the initial state; the executed actions follow, and the one that leaves
// the training range (mean -/+ 3 standard deviations) is warned about once.
// A write that fails in the middle of a batch (here: every observation frame, its folder replaced
// by a file) once left the tables cut back to the previous batch while stdio still held the rest
// of this one's rows, which the close then wrote past the cut: a hole of NUL bytes and a row cut in
// two. Rows of ~20 kB (more than stdio's buffer) make that certain. Now the table holds whole rows.
TEST(Recorder, AFailedWriteLeavesWholeRowsOnly) {
  const std::string dir = act::test::scratch_dir() + "/rec";
  const int state_dim = 2000;
  std::ostringstream log;
  Recorder recorder(dir, state_dim, 2, 48, 64, nlohmann::ordered_json{{"test", 1}}, &log);
  fs::remove_all(dir + "/frames");
  std::ofstream(dir + "/frames") << "not a folder";
  for (int t = 0; t < 200; ++t) {
    TickRecord tick;
    tick.tick = t;
    tick.source = "chunk";
    tick.action = {0.25f, 0.5f};
    tick.pwm = kDriving;
    tick.sent = true;
    tick.driver = "ai";
    tick.state.assign(static_cast<size_t>(state_dim), 0.123456789f);
    tick.command = {0.25f, 0.5f};
    recorder.add(std::move(tick));
  }
  ObservationRecord observation;
  observation.tick = 199;
  observation.height = 48;
  observation.width = 64;
  observation.rgb.assign(48 * 64 * 3, 100);
  observation.state.assign(static_cast<size_t>(state_dim), 0.5f);
  recorder.add(std::move(observation));
  recorder.close();
  EXPECT_NE(recorder.failure().find("--record: cannot create " + dir + "/frames/000000.png.tmp.png: Not a directory: "
                                    "the recording stops here ("),
            std::string::npos) << recorder.failure();
  const std::string text = log.str();
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 1) << text;
  std::ifstream in(dir + "/ticks.csv", std::ios::binary);
  const std::string ticks((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_FALSE(ticks.empty());
  EXPECT_EQ(ticks.find('\0'), std::string::npos) << "NUL bytes in ticks.csv: a write past the cut";
  EXPECT_EQ(ticks.back(), '\n') << "ticks.csv ends mid-row";
  std::istringstream rows(ticks);
  std::string header, row;
  ASSERT_TRUE(std::getline(rows, header));
  size_t count = 0;
  while (std::getline(rows, row)) {
    ASSERT_EQ(std::count(row.begin(), row.end(), ','), std::count(header.begin(), header.end(), ',')) << "row " << count + 1;
    ++count;
  }
  EXPECT_EQ(count, 200u) << "the rows before the failed frame are whole: they are kept";
  EXPECT_EQ(recorder.unrecorded_ticks(), 0u);
  EXPECT_NE(recorder.failure().find("(200 ticks and 0 observations kept in "), std::string::npos) << recorder.failure();
  EXPECT_EQ(std::ifstream(dir + "/log.jsonl").peek(), std::char_traits<char>::eof()) << "a line for a frame not on disk";
}

TEST(ControlLoop, InitialStateThenLastActionWithOneRangeWarning) {
  Rig rig;
  rig.recording = rig.dir + "/rec";
  rig.info.state_low = {-0.1f, 0.7f};  // steering mean 0, std 0.1: 0.5 is 5 std away; throttle 0.8 +/- 0.1
  rig.info.state_high = {0.1f, 0.9f};
  rig.options.initial_state = {0.0f, 0.8f};
  auto camera = video_camera(rig.dir, 150);
  // Until a few inferences after the first chunk are recorded (not a fixed second: on a loaded machine
  // the first chunk can come late, leaving one observation, the initial state, in the recording).
  rig.run(*camera, [&] {
    eventually([&] {
      const auto commands = drive_commands(*rig.board);
      const bool driven = std::any_of(commands.begin(), commands.end(), [](const auto& c) { return c.steering_us == 1700; });
      std::ifstream log(rig.recording + "/log.jsonl");
      return driven && std::count(std::istreambuf_iterator<char>(log), std::istreambuf_iterator<char>(), '\n') >= 4;
    });
  });
  std::ifstream observations(rig.recording + "/log.jsonl");
  std::string first, line, last;
  std::getline(observations, first);
  while (std::getline(observations, line)) last = line;
  ASSERT_FALSE(last.empty()) << "one observation recorded: " << rig.log.str();
  EXPECT_EQ(nlohmann::json::parse(first)["state"], (std::vector<float>{0.0f, 0.8f}));
  EXPECT_EQ(nlohmann::json::parse(last)["state"], (std::vector<float>{0.5f, 0.8f}));  // the fake model's action
  const std::string log = rig.log.str();
  const std::string warning = "observation.state[0] = 0.5 left the training range [-0.3, 0.3]";
  ASSERT_NE(log.find(warning), std::string::npos) << log;
  EXPECT_EQ(log.find(warning, log.find(warning) + 1), std::string::npos) << "warned more than once: " << log;
}

// --mode ai-steer: the policy's steering (0.5: 1700 us) with the throttle by hand (0.25: 1575 us), then
// an e-stop holds neutral.
TEST(ControlLoop, AiSteerTakesTheThrottleByHandAndEstopHoldsNeutral) {
  Rig rig;
  Cockpit cockpit(DriveMode::kAiSteer);
  rig.options.cockpit = &cockpit;
  auto camera = video_camera(rig.dir, 150);
  Clock::time_point estopped;
  const DriveSummary summary = rig.run(*camera, [&] {
    for (int i = 0; i < 15; ++i) {  // a held stick: sent 10 times a second
      cockpit.manual(0, 0.25);
      sleep_ms(100);
    }
    cockpit.estop();
    estopped = Clock::now();
    for (int i = 0; i < 5; ++i) {
      cockpit.manual(0, 0.25);  // the e-stop wins over manual input
      sleep_ms(100);
    }
  });
  size_t steered = 0;
  for (const auto& c : drive_commands(*rig.board)) {
    if (c.when < rig.started + milliseconds(700)) continue;  // the first chunk
    if (c.when < estopped) {
      steered += is(c, PwmCommand{1700, 1575});
    } else if (c.when > estopped + milliseconds(250)) {  // the e-stop bound
      EXPECT_TRUE(is(c, kSafe)) << c.steering_us << "/" << c.throttle_us;
    }
  }
  EXPECT_GT(steered, 15u) << rig.log.str();
  EXPECT_EQ(summary.manual_ticks, 0u);  // ai-steer is the policy driving
  // The summary tells the e-stop's ticks (about 5 at 10 Hz) from the others held safe.
  EXPECT_GE(summary.estop_ticks, 3u) << summary.to_string();
  EXPECT_EQ(summary.safe_ticks, summary.estop_ticks + summary.waiting_ticks + summary.fault_ticks + summary.overrun_ticks);
  EXPECT_NE(summary.to_string().find(" safe: " + std::to_string(summary.estop_ticks) + " e-stop, "), std::string::npos)
      << summary.to_string();
}

// Ctrl-Z then fg (act_drive's signal handlers bump the count): the chunk planned before and an
// inference of an older frame are dropped, so nothing drives until a chunk of a frame captured after
// the resume; with a cockpit the car stays e-stopped until someone resumes.
TEST(ControlLoop, AfterASuspensionNothingPlannedBeforeDrives) {
  for (const bool with_cockpit : {false, true}) {
    SCOPED_TRACE(with_cockpit ? "with a cockpit" : "policy alone");
    Rig rig;
    rig.controls->delay_ms.store(150);  // an inference in flight at the resume finishes well after it
    std::atomic<uint64_t> resumptions{0};
    rig.options.resumptions = &resumptions;
    Cockpit cockpit(DriveMode::kAi);
    if (with_cockpit) rig.options.cockpit = &cockpit;
    auto camera = video_camera(rig.dir, 150);
    Clock::time_point resumed, released;
    rig.run(*camera, [&] {
      sleep_ms(1200);
      resumptions.fetch_add(2);  // stopped and continued at once: every frame is still fresh
      resumed = Clock::now();
      sleep_ms(700);
      released = Clock::now();
      cockpit.resume();
      sleep_ms(700);
    });
    const auto commands = drive_commands(*rig.board);
    EXPECT_TRUE(std::any_of(commands.begin(), commands.end(), [&](const auto& c) { return c.when < resumed && is(c, kDriving); }))
        << rig.log.str();
    const auto hold_until = with_cockpit ? released : resumed + milliseconds(150);
    for (const auto& c : commands) {
      if (c.when > resumed + milliseconds(40) && c.when < hold_until) {
        EXPECT_TRUE(is(c, kSafe)) << ms_between(resumed, c.when) << " ms after the resume: " << c.steering_us << "/" << c.throttle_us;
      }
    }
    EXPECT_TRUE(std::any_of(commands.begin(), commands.end(), [&](const auto& c) { return c.when > released && is(c, kDriving); }))
        << "did not drive again\n" << rig.log.str();
    EXPECT_NE(rig.log.str().find("resumed after a suspension"), std::string::npos) << rig.log.str();
  }
}

// A starved control loop (here: its thread held up for 400 ms after a command) used to drive on
// from the chunk it had when it ran again: LeRobot's n_action_steps = 100 covers 3.3 s. Now the
// first command after the stall is neutral, counted, and the policy drives again from a new frame.
TEST(ControlLoop, AfterAStallTheFirstCommandIsNeutral) {
  Rig rig;
  rig.info = fake_model_info(false, 100);
  auto camera = video_camera(rig.dir, 150);
  Clock::time_point stalled;
  std::optional<Clock::time_point> stall_ended;
  const DriveSummary summary = rig.run(*camera, [&] {
    ASSERT_TRUE(eventually([&] { return rig.controls->inferences.load() >= 1; }));
    sleep_ms(600);  // driving from the one chunk
    stalled = Clock::now();
    rig.link->stall_after_next_send(milliseconds(400));
    ASSERT_TRUE(eventually([&] { return rig.link->stall_ended().has_value(); }));
    stall_ended = rig.link->stall_ended();
    sleep_ms(800);
  });
  ASSERT_TRUE(stall_ended);
  const auto commands = drive_commands(*rig.board);
  EXPECT_TRUE(std::any_of(commands.begin(), commands.end(), [&](const auto& c) { return c.when < stalled && is(c, kDriving); }))
      << rig.log.str();
  const auto after = std::find_if(commands.begin(), commands.end(), [&](const auto& c) { return c.when >= *stall_ended; });
  ASSERT_NE(after, commands.end());
  EXPECT_TRUE(is(*after, kSafe)) << "the first command after the stall: " << after->steering_us << "/" << after->throttle_us;
  report_fault_timing("the control loop stalled 400 ms", ms(after->when - *stall_ended), "the first command (neutral) after the stall");
  EXPECT_TRUE(std::any_of(after, commands.end(), [](const auto& c) { return is(c, kDriving); }))
      << "did not drive again\n" << rig.log.str();
  EXPECT_GE(summary.late_ticks, 1u);
  EXPECT_NE(rig.log.str().find("holding the safe action: control loop late ("), std::string::npos) << rig.log.str();
  EXPECT_NE(summary.to_string().find("ticks sent neutral because the control loop ran late"), std::string::npos);
}

TEST(ControlLoop, ThreadPlacementFallsBackWithAWarning) {
  std::ostringstream log;
  std::thread([&] { apply_thread_placement({0, {1000}}, "test", log); }).join();  // no CPU 1000 here
  EXPECT_NE(log.str().find("cannot pin the test thread"), std::string::npos) << log.str();
}

TEST(ControlLoop, DryRunPrintsProtocolLines) {
  std::ostringstream out;
  DryRunLink link(out);
  link.send({1600, 1400}, Clock::now());
  link.shutdown({1500, 1500});
  std::istringstream lines(out.str());
  std::string time, line;
  int n = 0;
  while (lines >> time >> line) {
    RoverMessage m{};
    ASSERT_EQ(rover_parse(line.c_str(), line.size(), &m), ROVER_OK) << line;
    EXPECT_EQ(m.type, 'C');
    EXPECT_EQ(m.fields[0], n);
    ++n;
  }
  EXPECT_EQ(n, 2);
}

}  // namespace
}  // namespace act::drive::test
