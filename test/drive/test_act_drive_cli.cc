// The act_drive binary as a user runs it: clear errors, --dry-run on the act-tiny fixture with a
// video file for the camera, signals against a pseudo-terminal Arduino, a network camera that
// stalls, and --record under SIGKILL.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "actengine/engine.h"
#include "apps/arduino/act_rover/rover_protocol.h"
#include "apps/drive/calibration.h"
#include "apps/drive/overlay_video.h"
#include "engine/media/media_io.h"
#include "drive/drive_cli_util.h"
#include "drive/drive_test_util.h"
#include "drive/fake_arduino.h"
#include "drive/stalling_stream.h"
#include "support/command.h"
#include "weights/import/safetensors.h"
#include "support/test_paths.h"

namespace act::drive::test {
namespace {

namespace fs = std::filesystem;
using act::test::q;
using act::test::run_command;

const std::string kDrive = ACT_DRIVE_BIN;

TEST(ActDriveCli, HelpListsTheOptions) {
  const auto r = run_command(kDrive + " --help");
  EXPECT_EQ(r.exit_code, 0);
  for (const char* flag : {"--model", "--camera", "--camera-size", "--serial", "--baud", "--calibration", "--control-hz",
                           "--max-frame-age", "--threads", "--control-priority", "--inference-cpus", "--stats-every",
                           "--record", "--dry-run", "--calibrate", "--state", "--duration", "--initial-state",
                           "--raw-endpoints", "--list-cameras", "--list-ports", "--loop", "--realtime"}) {
    EXPECT_NE(r.output.find(flag), std::string::npos) << flag;
  }
}

TEST(ActDriveCli, VersionPrintsTheProjectVersion) {
  for (const std::string& tool : {kDrive, std::string(ACT_PWM_WATCHDOG_BIN)}) {
    const auto r = run_command(tool + " --version");
    EXPECT_EQ(r.exit_code, 0) << r.output;
    const std::string name = fs::path(tool).filename().string();
    EXPECT_EQ(r.output, name + " " + act::version() + "\n");
  }
}

TEST(ActDriveCli, ClearErrorsForMissingInputs) {
  const std::string dir = act::test::scratch_dir();
  auto r = run_command(kDrive + " --camera 0 --dry-run");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("--model is required"), std::string::npos) << r.output;
  r = run_command(kDrive + " -m m.actb --camera 0");
  EXPECT_NE(r.output.find("--serial is required"), std::string::npos) << r.output;
  r = run_command(kDrive + " -m m.actb --camera " + q(dir + "/no-such-video.avi") + " --dry-run");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("cannot open camera"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("act_drive --list-cameras lists the cameras found"), std::string::npos) << r.output;
  std::ofstream(dir + "/cal.json") << R"({"steering": {"left_us": 1100, "center_us": 1500, "right_us": 1900},
                                          "throttle": {"reverse_us": 1300, "neutral_us": 1900, "forward_us": 1800}})";
  r = run_command(kDrive + " -m m.actb --camera 0 --dry-run -c " + q(dir + "/cal.json"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("'throttle.neutral_us' (1900) must lie strictly between"), std::string::npos) << r.output;
}

TEST(ActDriveCli, ClearErrorsForModelAndSerialPort) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string video = write_test_video(dir + "/v.avi", 60, 30, 128, 96);
  auto r = run_command(kDrive + " -m " + q(dir + "/none.actb") + " --camera " + q(video) + " --dry-run");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("none.actb"), std::string::npos) << r.output;
  const std::string blob = act_tiny_blob(dir);
  r = run_command(kDrive + " -m " + q(blob) + " --camera " + q(video) + " --serial " + q(dir + "/ttyNONE") + " --raw-endpoints");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("cannot open serial port " + dir + "/ttyNONE"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("act_drive --list-ports lists the serial ports found"), std::string::npos) << r.output;
  FakeArduino silent_board;
  silent_board.set_silent(true);
  r = run_command(kDrive + " -m " + q(blob) + " --camera " + q(video) + " --serial " + q(silent_board.port_path()) +
                  " --raw-endpoints --ready-timeout 1.5");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("no ready line from the board"), std::string::npos) << r.output;
  EXPECT_GT(silent_board.hellos(), 0);
}

TEST(ActDriveCli, RefusedDefaultsNameTheFix) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string video = write_test_video(dir + "/v.avi", 30, 30, 160, 120);  // 120x160 (HxW)
  const std::string blob = act_tiny_blob(dir);                                     // 96x128, 4:3 like the video
  FakeArduino board;
  // A real port without a calibration file: refused before the port is touched.
  auto r = run_command(kDrive + " -m " + q(blob) + " --camera " + q(video) + " --serial " + q(board.port_path()));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("without --calibration"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("act_drive --calibrate --serial"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("--raw-endpoints"), std::string::npos) << r.output;
  EXPECT_EQ(board.hellos(), 0);
  const std::string dry = kDrive + " -m " + q(blob) + " --camera " + q(video) + " --dry-run --threads 1 ";
  // WxH where HxW is meant: the camera delivers the transpose.
  r = run_command(dry + "--camera-size 160x120");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("did you mean --camera-size 120x160?"), std::string::npos) << r.output;
  // A size that fits the model only transposed (a camera that ignores the request would otherwise stretch).
  r = run_command(dry + "--camera-size 640x480");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("only fits the model's 96x128 input transposed"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("did you mean --camera-size 480x640?"), std::string::npos) << r.output;
  r = run_command(dry + "--initial-state 1,2,3");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("has 3 values but the model's state has 2 (or use --initial-state mean)"), std::string::npos) << r.output;
  r = run_command(dry + "--initial-state 1,x");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("'x' is not a number"), std::string::npos) << r.output;
}

// The first observation's state is the training mean read from the checkpoint's own statistics (not
// (0, 0), several standard deviations away for a real rover), or the values given.
TEST(ActDriveCli, InitialStateIsTheTrainingMeanOrTheValuesGiven) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string video = write_test_video(dir + "/v.avi", 15, 30, 128, 96);
  const std::string blob = act_tiny_blob(dir);
  const auto first_state = [&](const std::string& flags, const std::string& rec) {
    // In lockstep (--realtime off): the short video cannot end before the first inference, however
    // slow the machine (a sanitizer build under load).
    const auto r = run_command(kDrive + " -m " + q(blob) + " --camera " + q(video) + " --dry-run --realtime off --threads 1 --record " +
                               q(rec) + " " + flags + " >/dev/null");
    EXPECT_EQ(r.exit_code, 0) << r.output;
    std::ifstream log(rec + "/log.jsonl");
    std::string line;
    std::getline(log, line);
    EXPECT_FALSE(line.empty()) << "no observation recorded: " << r.output;
    return line.empty() ? std::vector<float>{} : nlohmann::json::parse(line)["state"].get<std::vector<float>>();
  };
  const SafetensorsFile stats = SafetensorsFile::open(act::test::fixture_dir("act-tiny") +
                                                      "/policy_preprocessor_step_3_normalizer_processor.safetensors");
  const std::vector<float> mean = stats.get("observation.state.mean").to_f32();
  const std::vector<float> by_default = first_state("", dir + "/rec-mean");
  ASSERT_EQ(by_default.size(), mean.size());
  for (size_t i = 0; i < mean.size(); ++i) EXPECT_NEAR(by_default[i], mean[i], 1e-5f * (1 + std::abs(mean[i]))) << i;
  EXPECT_EQ(first_state("--initial-state 0.25,-0.5", dir + "/rec-given"), (std::vector<float>{0.25f, -0.5f}));
}

// --overlay-video: one video frame per tick, the steering gauge's marker where the command sent puts it.
TEST(ActDriveCli, OverlayVideoDrawsEveryTick) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string video = write_test_video(dir + "/v.avi", 60, 30, 128, 96);
  const std::string blob = act_tiny_blob(dir);
  const auto r = run_command("(" + kDrive + " -m " + q(blob) + " --camera " + q(video) + " --dry-run --threads 1 --overlay-video " +
                             q(dir + "/overlay.mp4") + " 2>" + q(dir + "/stderr.txt") + ")");
  const std::string log = read_text(dir + "/stderr.txt");
  ASSERT_EQ(r.exit_code, 0) << log;
  // The commands on stdout: the first is the neutral sent before the first tick, then one per tick.
  std::vector<RoverMessage> sent;
  std::istringstream lines(r.output);
  for (std::string time, line; lines >> time >> line;) {
    RoverMessage m{};
    ASSERT_EQ(rover_parse(line.c_str(), line.size(), &m), ROVER_OK) << line;
    sent.push_back(m);
  }
  const std::unique_ptr<act::media::VideoReader> overlay = act::media::open_video(dir + "/overlay.mp4", cv::CAP_ANY);
  ASSERT_TRUE(overlay);
  std::vector<cv::Mat> frames;
  for (cv::Mat frame; overlay->read(frame);) frames.push_back(frame.clone());
  EXPECT_NE(log.find("overlay video " + dir + "/overlay.mp4: " + std::to_string(frames.size()) + " ticks"), std::string::npos) << log;
  EXPECT_NE(log.find(" s: " + std::to_string(frames.size()) + " ticks ("), std::string::npos) << log;  // every tick
  ASSERT_GT(sent.size(), frames.size());
  ASSERT_GT(frames.size(), 30u);
  EXPECT_EQ(frames[0].cols, 128 * 4);
  EXPECT_EQ(frames[0].rows, 96 * 4 + 120);
  int checked = 0;
  for (size_t k = 0; k < frames.size(); k += 7) {
    // The steering gauge spans x 10..251 at y 404..420 (-1..+1); the template's 1000..2000 us endpoints.
    const double position = (sent[k + 1].fields[1] - 1500) / 500.0;
    const int x = 10 + 120 + static_cast<int>(position * 120);
    const cv::Vec3b pixel = frames[k].at<cv::Vec3b>(96 * 4 + 28, x);
    EXPECT_GT(pixel[0], 180) << "tick " << k << " steering " << sent[k + 1].fields[1];  // the marker's blue
    ++checked;
  }
  EXPECT_GT(checked, 4);
}

// --realtime off: the video replayed in lockstep, so two runs send the same commands, every frame
// gets its tick and none is missed, however loaded the machine.
TEST(ActDriveCli, RealtimeOffReplaysAFileTheSameEveryTime) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string video = write_test_video(dir + "/v.avi", 90, 30, 128, 96);
  const std::string blob = act_tiny_blob(dir);
  const std::string replay = kDrive + " -m " + q(blob) + " --camera " + q(video) + " --threads 1 --realtime off";
  const auto commands_of = [&](const std::string& name) {
    const auto r = run_command("(" + replay + " --dry-run 2>" + q(dir + "/" + name + ".log") + ")");
    EXPECT_EQ(r.exit_code, 0) << read_text(dir + "/" + name + ".log");
    std::vector<std::string> lines;
    std::istringstream out(r.output);
    for (std::string time, line; out >> time >> line;) lines.push_back(line);  // without the times
    return lines;
  };
  const std::vector<std::string> first = commands_of("first"), second = commands_of("second");
  EXPECT_EQ(first, second);
  const std::string log = read_text(dir + "/first.log");
  // Frames 0..89 one per tick, the first tick waiting for the first chunk, one more seeing the end
  // (held safe as a fault: no frame).
  EXPECT_NE(log.find(": 91 ticks (89 driving, 2 safe: 0 e-stop, 1 waiting for a chunk, 1 fault, 0 overrun; 0 missed)"),
            std::string::npos) << log;
  // Only for a file, only in a dry run.
  auto r = run_command(replay);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("--realtime off replays a file faster than real time: only with --dry-run"), std::string::npos) << r.output;
  r = run_command(kDrive + " -m " + q(blob) + " --camera 0 --dry-run --realtime off");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("'0' is a live source"), std::string::npos) << r.output;
}

// `frames` numbered PNG frames, 128x96, in `dir`; returns their pattern for --camera.
std::string write_test_sequence(const std::string& dir, int frames) {
  fs::create_directories(dir);
  for (int i = 0; i < frames; ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "/%06d.png", i);
    act::media::write_image(dir + name, cv::Mat(96, 128, CV_8UC3, cv::Scalar(10 * i, 80, 160)));
  }
  return dir + "/%06d.png";
}

// The summary's "N ticks (" count, or -1.
long summary_ticks(const std::string& log) {
  const size_t at = log.find(" s: ");
  return at == std::string::npos ? -1 : std::strtol(log.c_str() + at + 4, nullptr, 10);
}

// A replay's overlay video has every tick: the replay waits for the encoder instead of dropping
// ticks (a replay's ticks come as fast as the machine allows, much faster than the encoder).
TEST(ActDriveCli, RealtimeOffOverlayVideoKeepsEveryTick) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string video = write_test_video(dir + "/v.avi", 240, 30, 128, 96);
  const std::string blob = act_tiny_blob(dir);
  const auto r = run_command("(" + kDrive + " -m " + q(blob) + " --camera " + q(video) + " --dry-run --realtime off --threads 1 " +
                             "--overlay-video " + q(dir + "/overlay.mp4") + " 2>" + q(dir + "/stderr.txt") + " >/dev/null)");
  const std::string log = read_text(dir + "/stderr.txt");
  ASSERT_EQ(r.exit_code, 0) << log;
  const std::unique_ptr<act::media::VideoReader> overlay = act::media::open_video(dir + "/overlay.mp4", cv::CAP_ANY);
  ASSERT_TRUE(overlay);
  long frames = 0;
  for (cv::Mat frame; overlay->read(frame);) ++frames;
  EXPECT_EQ(frames, summary_ticks(log)) << log;
  EXPECT_EQ(frames, 241) << log;  // the 240 frames and the tick that sees the end
  EXPECT_NE(log.find("overlay video " + dir + "/overlay.mp4: 241 ticks\n"), std::string::npos) << log;
  EXPECT_EQ(log.find("dropped"), std::string::npos) << log;
}

// A producer far faster than the encoder (500 ticks added at once, each a 512x504 frame to draw and
// encode): a replay's overlay waits for the encoder and keeps every tick.
TEST(OverlayVideo, AReplayWaitsForTheEncoderInsteadOfDropping) {
  const std::string dir = act::test::scratch_dir();
  auto frame = std::make_shared<const Frame>(Frame{cv::Mat(96, 128, CV_8UC3, cv::Scalar(20, 120, 220)), Clock::now(), 0, {}});
  OverlayVideo overlay(dir + "/o.avi", 30, 96, 128, 4, /*wait_for_encoder=*/true);
  for (int t = 0; t < 500; ++t) {
    LiveStatus status;
    status.tick = t;
    overlay.add(status, frame);
  }
  overlay.close();
  EXPECT_EQ(overlay.frames_written(), 500u);
  EXPECT_EQ(overlay.dropped(), 0u);
  const std::unique_ptr<act::media::VideoReader> video = act::media::open_video(dir + "/o.avi", cv::CAP_ANY);
  ASSERT_TRUE(video);
  int frames = 0;
  for (cv::Mat image; video->read(image);) ++frames;
  EXPECT_EQ(frames, 500);
}

// --loop: a video file and an image sequence restart at their end, so a replay longer than the file
// runs to --duration; without it each ends with the file. An image sequence replays offline too.
TEST(ActDriveCli, LoopRestartsAVideoFileAndAnImageSequence) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string blob = act_tiny_blob(dir);
  const std::string video = write_test_video(dir + "/v.avi", 10, 30, 128, 96);
  const std::string sequence = write_test_sequence(dir + "/seq", 10);
  for (const std::string& camera : {video, sequence}) {
    const std::string replay = kDrive + " -m " + q(blob) + " --camera " + q(camera) + " --dry-run --realtime off --threads 1 ";
    auto r = run_command("(" + replay + "--loop --duration 2 --record " + q(dir + "/rec" + std::to_string(camera.size())) +
                         " 2>" + q(dir + "/loop.txt") + " >/dev/null)");
    std::string log = read_text(dir + "/loop.txt");
    ASSERT_EQ(r.exit_code, 0) << log;
    EXPECT_NE(log.find("act_drive: --duration reached"), std::string::npos) << camera << "\n" << log;
    EXPECT_GE(summary_ticks(log), 60) << log;  // 2 s at 30 Hz: six passes of the file
    // The observations of the last second saw frames of the third pass (frame indices go on counting).
    std::ifstream observations(dir + "/rec" + std::to_string(camera.size()) + "/log.jsonl");
    uint64_t last_frame = 0;
    for (std::string line; std::getline(observations, line);) last_frame = nlohmann::json::parse(line)["frame_index"].get<uint64_t>();
    EXPECT_GE(last_frame, 50u) << camera;
    r = run_command("(" + replay + "--duration 2 2>" + q(dir + "/once.txt") + " >/dev/null)");
    log = read_text(dir + "/once.txt");
    ASSERT_EQ(r.exit_code, 0) << log;
    EXPECT_NE(log.find(camera == video ? "act_drive: end of video file" : "act_drive: end of image sequence"), std::string::npos) << log;
    EXPECT_EQ(summary_ticks(log), 11) << log;
  }
  const auto r = run_command(kDrive + " -m " + q(blob) + " --camera 0 --dry-run --loop");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("--loop replays a video file or an image sequence; '0' is a live source"), std::string::npos) << r.output;
}

// A file at 1 fps played in real time: each frame stands for 1000 ms, more than --max-frame-age 400,
// and is no stale frame for it (a file's frame ages from when the next is due; before, every tick
// from 400 ms into each frame was one).
TEST(ActDriveCli, ASlowFileIsNoStaleFrameInRealTime) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string blob = act_tiny_blob(dir);
  const std::string video = write_test_video(dir + "/v.avi", 10, 1, 128, 96);
  const std::string sequence = write_test_sequence(dir + "/seq", 10);
  for (const std::string& camera : {video, sequence}) {
    const auto r = run_command("(" + kDrive + " -m " + q(blob) + " --camera " + q(camera) + " --camera-fps 1 --dry-run --threads 1 " +
                               "--duration 2 --max-frame-age 400 2>" + q(dir + "/stderr.txt") + " >/dev/null)");
    const std::string log = read_text(dir + "/stderr.txt");
    ASSERT_EQ(r.exit_code, 0) << log;
    EXPECT_NE(log.find("act_drive: --duration reached"), std::string::npos) << log;
    EXPECT_NE(log.find(" inference errors, 0 stale-frame ticks"), std::string::npos) << camera << "\n" << log;
    EXPECT_EQ(log.find("stale frame"), std::string::npos) << log;
  }
}

// The blob's action names (act_convert --action-names) name a recording's action columns, and
// act_eval's report on that recording uses them; an older blob without names keeps command.0, ...
TEST(ActDriveCli, RecordingsAndEvalUseTheBlobsActionNames) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string named = dir + "/named.actb";
  const auto converted = run_command(std::string(ACT_CONVERT_BIN) + " " + q(act::test::fixture_dir("act-tiny")) + " -o " +
                                     q(named) + " -q --action-names steering,throttle");
  ASSERT_EQ(converted.exit_code, 0) << converted.output;
  const std::string video = write_test_video(dir + "/v.avi", 20, 30, 128, 96);
  const auto first_line = [](const std::string& path) {
    std::ifstream in(path);
    std::string line;
    std::getline(in, line);
    return line;
  };
  for (const std::string& blob : {named, act_tiny_blob(dir)}) {
    const bool has_names = blob == named;
    const std::string rec = dir + (has_names ? "/rec-named" : "/rec-plain");
    const auto r = run_command(kDrive + " -m " + q(blob) + " --camera " + q(video) + " --dry-run --realtime off --threads 1 --record " +
                               q(rec) + " >/dev/null");
    ASSERT_EQ(r.exit_code, 0) << r.output;
    const std::string header = first_line(rec + "/ticks.csv");
    const std::string expected = has_names ? "tick,time_s,jitter_ms,source,action.steering,action.throttle,steering_us,throttle_us,"
                                             "sent,driver,frame,state.0,state.1,command.steering,command.throttle"
                                           : "tick,time_s,jitter_ms,source,action.0,action.1,steering_us,throttle_us,"
                                             "sent,driver,frame,state.0,state.1,command.0,command.1";
    EXPECT_EQ(header, expected);
    const auto eval = run_command(std::string(ACT_EVAL_BIN) + " -m " + q(blob) + " -t 1 --episode " + q(rec) + " --json " +
                                  q(rec + "/eval.json"));
    ASSERT_EQ(eval.exit_code, 0) << eval.output;
    std::ifstream report(rec + "/eval.json");
    const nlohmann::json j = nlohmann::json::parse(report);
    EXPECT_EQ(j.at("action_names"), has_names ? nlohmann::json({"steering", "throttle"}) : nlohmann::json({"command.0", "command.1"}));
    if (has_names) {
      EXPECT_NE(eval.output.find("steering: first action MSE"), std::string::npos) << eval.output;
    }
  }
}

TEST(ActDriveCli, DeploymentOptionsReplaceTheBlobs) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string blob = act_tiny_blob(dir);  // n_action_steps 10 of chunk 10, no ensembling
  const std::string video = write_test_video(dir + "/v.avi", 30, 30, 128, 96);
  const std::string drive = kDrive + " -m " + q(blob) + " --camera " + q(video) + " --dry-run --threads 1 ";
  // Runs act_drive with `flags`; returns its log (stderr; the commands on stdout are not needed here).
  const auto log_of = [&](const std::string& flags) {
    const auto r = run_command("(" + drive + flags + " 2>" + q(dir + "/stderr.txt") + " >/dev/null)");
    const std::string log = read_text(dir + "/stderr.txt");
    EXPECT_EQ(r.exit_code, 0) << log;
    return log;
  };
  const std::string queue = log_of("--n-action-steps 2");
  EXPECT_NE(queue.find("queue of 2 of 10 actions"), std::string::npos) << queue;
  const std::string ensemble = log_of("--n-action-steps 1 --temporal-ensemble-coeff 0.01");
  EXPECT_NE(ensemble.find("temporal ensembling"), std::string::npos) << ensemble;
  const auto refused = run_command(drive + "--n-action-steps 11");
  EXPECT_EQ(refused.exit_code, 1);
  EXPECT_NE(refused.output.find("n_action_steps 11 must be in [1, chunk_size 10]"), std::string::npos) << refused.output;
  const auto needs_one = run_command(drive + "--temporal-ensemble-coeff 0.01");
  EXPECT_EQ(needs_one.exit_code, 1);
  EXPECT_NE(needs_one.output.find("needs n_action_steps == 1"), std::string::npos) << needs_one.output;
}

TEST(ActDriveCli, DryRunDrivesTheRealModelUntilTheVideoEnds) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string blob = act_tiny_blob(dir);
  // A camera at 160x120: resized to the model's 128x96.
  const std::string video = write_test_video(dir + "/v.avi", 45, 30, 160, 120);
  const auto r = run_command("(" + kDrive + " -m " + q(blob) + " --camera " + q(video) + " --dry-run --threads 1 --record " +
                             q(dir + "/rec") + " --stats-every 0.5 2>" + q(dir + "/stderr.txt") + ")");
  const std::string log = read_text(dir + "/stderr.txt");
  EXPECT_EQ(r.exit_code, 0) << log;
  EXPECT_NE(log.find("end of video file"), std::string::npos) << log;
  EXPECT_NE(log.find("act_drive: stats:"), std::string::npos) << log;
  EXPECT_NE(log.find("no --calibration file"), std::string::npos) << log;
  std::istringstream lines(r.output);
  std::string time, line, last;
  int commands = 0;
  while (lines >> time >> line) {
    RoverMessage m{};
    ASSERT_EQ(rover_parse(line.c_str(), line.size(), &m), ROVER_OK) << line;
    ++commands;
    last = line;
  }
  EXPECT_GE(commands, 30) << r.output;  // 1.5 s of video at 30 Hz
  RoverMessage m{};
  ASSERT_EQ(rover_parse(last.c_str(), last.size(), &m), ROVER_OK);
  EXPECT_EQ(m.fields[1], 1500);
  EXPECT_EQ(m.fields[2], 1500);
  const cv::Mat frame = act::media::read_image(dir + "/rec/frames/000000.png");
  EXPECT_EQ(frame.cols, 128);
  EXPECT_EQ(frame.rows, 96);
  EXPECT_NE(read_text(dir + "/rec/meta.json").find("\"image_width\": 128"), std::string::npos);
  // The recording is INT8 calibration input as it is.
  const auto convert = run_command(std::string(ACT_CONVERT_BIN) + " " + q(act::test::fixture_dir("act-tiny")) + " -o " +
                                   q(dir + "/int8.actb") + " --precision int8 --calib " + q(dir + "/rec") + " --threads 1");
  EXPECT_EQ(convert.exit_code, 0) << convert.output;
  EXPECT_TRUE(fs::exists(dir + "/int8.actb")) << convert.output;
}

// Every signal that can end act_drive sends neutral first: the stop requests (SIGINT, SIGTERM, SIGHUP
// when an SSH session drops) end cleanly with the summary; the others end by the signal itself.
// "TERM", or "RTMIN", "RTMIN5", "RTMAX" for the real-time signals (sigabbrev_np names none of them).
std::string signal_name(int signal) {
  if (signal == SIGRTMAX) return "RTMAX";
  if (signal >= SIGRTMIN) return signal == SIGRTMIN ? "RTMIN" : "RTMIN" + std::to_string(signal - SIGRTMIN);
  return sigabbrev_np(signal);
}

struct SignalCase {
  int signal;
  bool clean_exit;
};

class ActDriveSignal : public ::testing::TestWithParam<SignalCase> {};

TEST_P(ActDriveSignal, SendsNeutralBeforeItEnds) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const SignalCase c = GetParam();
  const std::string dir = act::test::scratch_dir();
  const std::string blob = act_tiny_blob(dir);
  const std::string video = write_test_video(dir + "/v.avi", 300, 30, 128, 96);
  FakeArduino board;
  const std::string port = board.port_path();
  const std::string log_path = dir + "/log.txt";
  const pid_t pid = start_act_drive({"-m", blob, "--camera", video, "--serial", port, "--raw-endpoints", "--threads", "1"}, log_path);
  ASSERT_GE(pid, 0);
  // Wait until it drives, then signal it.
  const auto deadline = Clock::now() + std::chrono::seconds(20);
  while (board.commands().size() < 40 && Clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const auto signalled = Clock::now();
  ::kill(pid, c.signal);
  int status = 0;
  ::waitpid(pid, &status, 0);
  const std::string log = read_text(log_path);
  if (c.clean_exit) {
    ASSERT_TRUE(WIFEXITED(status)) << log;
    EXPECT_EQ(WEXITSTATUS(status), 0) << log;
    EXPECT_NE(log.find("stopped by a signal"), std::string::npos) << log;
  } else {
    ASSERT_TRUE(WIFSIGNALED(status)) << log;
    EXPECT_EQ(WTERMSIG(status), c.signal) << log;
  }
  // The fake board reads the port on its own thread: give it a moment for the last line.
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  const auto commands = board.commands();
  ASSERT_GE(commands.size(), 40u) << log;
  EXPECT_EQ(commands.back().type, 'C');
  EXPECT_EQ(commands.back().steering_us, 1500);
  EXPECT_EQ(commands.back().throttle_us, 1500);
  EXPECT_TRUE(board.bad_lines().empty());
  const auto neutral = std::find_if(commands.begin(), commands.end(), [&](const FakeArduino::Command& command) {
    return command.when >= signalled && command.steering_us == 1500 && command.throttle_us == 1500;
  });
  if (neutral != commands.end()) {
    report_fault_timing("SIG" + signal_name(c.signal),
                        std::chrono::duration<double, std::milli>(neutral->when - signalled).count());
  }
}

INSTANTIATE_TEST_SUITE_P(Signals, ActDriveSignal,
                         ::testing::Values(SignalCase{SIGTERM, true}, SignalCase{SIGINT, true}, SignalCase{SIGHUP, true},
                                           SignalCase{SIGQUIT, false}, SignalCase{SIGUSR1, false},
                                           SignalCase{SIGRTMIN, false}, SignalCase{SIGRTMIN + 5, false},
                                           SignalCase{SIGRTMAX, false}),
                         [](const ::testing::TestParamInfo<SignalCase>& case_info) { return signal_name(case_info.param.signal); });

// Polls for the end of `pid` until `limit` passes (a hang detector): its wait status, or none.
std::optional<int> wait_for_exit(pid_t pid, std::chrono::seconds limit) {
  const auto deadline = Clock::now() + limit;
  int status = 0;
  while (::waitpid(pid, &status, WNOHANG) == 0) {
    if (Clock::now() > deadline) return std::nullopt;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return status;
}

// act_drive as a shell runs it in the foreground of a terminal: a new session on a pseudo-terminal
// whose foreground process group is act_drive's own. The session leader (this "shell") stays outside
// that group, so the group is not orphaned and the terminal's Ctrl-Z really stops it.
struct TerminalJob {
  int terminal = -1;  // the pty's master: what a user types
  pid_t shell = -1, drive = -1;
};

TerminalJob start_act_drive_in_terminal(const std::vector<std::string>& args, const std::string& log_path) {
  TerminalJob job;
  job.terminal = ::posix_openpt(O_RDWR | O_NOCTTY);
  if (job.terminal < 0 || ::grantpt(job.terminal) != 0 || ::unlockpt(job.terminal) != 0) return job;
  const std::string slave = ::ptsname(job.terminal);
  std::vector<char*> argv{const_cast<char*>(ACT_DRIVE_BIN)};
  for (const std::string& arg : args) argv.push_back(const_cast<char*>(arg.c_str()));
  argv.push_back(nullptr);
  int pid_pipe[2];
  if (::pipe(pid_pipe) != 0) return job;
  job.shell = fork();
  if (job.shell == 0) {  // only async-signal-safe calls from here on (the test process has threads)
    ::setsid();
    const int tty = ::open(slave.c_str(), O_RDWR);  // the new session's controlling terminal
    const pid_t drive = fork();
    if (drive == 0) {
      ::setpgid(0, 0);
      const int log = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      ::dup2(tty, 0);
      ::dup2(log, 1);
      ::dup2(log, 2);
      const rlimit no_core_dump{0, 0};
      ::setrlimit(RLIMIT_CORE, &no_core_dump);
      ::execv(ACT_DRIVE_BIN, argv.data());
      ::_exit(127);
    }
    ::setpgid(drive, drive);
    ::tcsetpgrp(tty, drive);  // act_drive in the foreground
    if (::write(pid_pipe[1], &drive, sizeof drive) != sizeof drive) ::_exit(126);
    int status = 0;
    ::waitpid(drive, &status, 0);
    ::_exit(WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status));
  }
  ::close(pid_pipe[1]);
  if (::read(pid_pipe[0], &job.drive, sizeof job.drive) != sizeof job.drive) job.drive = -1;
  ::close(pid_pipe[0]);
  return job;
}

// From /proc/PID/stat: the state letter ('T' = stopped) and the CPU time used so far, in clock ticks.
std::pair<char, long long> process_state(pid_t pid) {
  const std::string line = read_text("/proc/" + std::to_string(pid) + "/stat");
  std::string field;
  std::vector<std::string> fields;
  const size_t comm_end = line.rfind(')');
  if (comm_end == std::string::npos) return {'?', 0};
  std::istringstream rest(line.substr(comm_end + 2));
  while (rest >> field) fields.push_back(field);
  if (fields.size() < 13) return {'?', 0};
  return {fields[0][0], std::stoll(fields[11]) + std::stoll(fields[12])};  // state, utime + stime
}

struct SuspendCase {
  const char* name;
  int signal;  // 0: Ctrl-Z typed on the terminal
};

class ActDriveSuspend : public ::testing::TestWithParam<SuspendCase> {};

// Ctrl-Z (or SIGTTIN / SIGTTOU) puts neutral on the wire, then really suspends: no line and no CPU
// while stopped. After SIGCONT (fg) the first command is neutral again (nothing planned before the
// stop drives), the loop goes on, and Ctrl-C still ends it cleanly.
TEST_P(ActDriveSuspend, SendsNeutralThenStopsAndResumesSafely) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const SuspendCase c = GetParam();
  const std::string dir = act::test::scratch_dir();
  const std::string blob = act_tiny_blob(dir);
  const std::string video = write_test_video(dir + "/v.avi", 900, 30, 128, 96);
  FakeArduino board;
  const std::string log_path = dir + "/log.txt";
  TerminalJob job = start_act_drive_in_terminal({"-m", blob, "--camera", video, "--serial", board.port_path(),
                                                 "--raw-endpoints", "--threads", "1"}, log_path);
  ASSERT_GT(job.drive, 0) << "no pseudo-terminal";
  const auto end_job = [&] {
    ::kill(job.drive, SIGKILL);
    ::waitpid(job.shell, nullptr, 0);
    ::close(job.terminal);
  };
  auto deadline = Clock::now() + std::chrono::seconds(20);
  while (board.commands().size() < 40 && Clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  ASSERT_GE(board.commands().size(), 40u) << read_text(log_path);

  const auto suspended = Clock::now();
  if (c.signal == 0) {
    ASSERT_EQ(::write(job.terminal, "\x1a", 1), 1);  // Ctrl-Z
  } else {
    ::kill(job.drive, c.signal);
  }
  deadline = Clock::now() + std::chrono::seconds(5);
  while (process_state(job.drive).first != 'T' && Clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const auto [state, cpu_at_stop] = process_state(job.drive);
  if (state != 'T') end_job();
  ASSERT_EQ(state, 'T') << "act_drive did not stop within 5 s\n" << read_text(log_path);
  std::this_thread::sleep_for(std::chrono::milliseconds(100));  // the board's reader thread: the last line
  const size_t lines_at_stop = board.commands().size() + board.bad_lines().size();
  std::this_thread::sleep_for(std::chrono::milliseconds(700));
  auto commands = board.commands();
  EXPECT_EQ(commands.size() + board.bad_lines().size(), lines_at_stop) << "lines were written while stopped";
  EXPECT_EQ(process_state(job.drive).second, cpu_at_stop) << "CPU used while stopped";
  EXPECT_EQ(commands.back().steering_us, 1500);
  EXPECT_EQ(commands.back().throttle_us, 1500);
  EXPECT_TRUE(board.bad_lines().empty());
  const auto neutral = std::find_if(commands.begin(), commands.end(), [&](const FakeArduino::Command& command) {
    return command.when >= suspended && command.steering_us == 1500 && command.throttle_us == 1500;
  });
  ASSERT_NE(neutral, commands.end());
  report_fault_timing(std::string(c.name) + " (suspend)", std::chrono::duration<double, std::milli>(neutral->when - suspended).count());

  const size_t before_resume = commands.size();
  ::kill(job.drive, SIGCONT);  // fg
  deadline = Clock::now() + std::chrono::seconds(10);
  while (board.commands().size() < before_resume + 30 && Clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  commands = board.commands();
  if (commands.size() < before_resume + 30) end_job();
  ASSERT_GE(commands.size(), before_resume + 30) << "the loop did not go on after SIGCONT\n" << read_text(log_path);
  EXPECT_EQ(commands[before_resume].steering_us, 1500);  // the first command after the resume is neutral
  EXPECT_EQ(commands[before_resume].throttle_us, 1500);

  ASSERT_EQ(::write(job.terminal, "\x03", 1), 1);  // Ctrl-C
  const std::optional<int> status = wait_for_exit(job.shell, std::chrono::seconds(5));
  if (!status) end_job();
  ::close(job.terminal);
  const std::string log = read_text(log_path);
  ASSERT_TRUE(status) << "act_drive did not end within 5 s of Ctrl-C\n" << log;
  EXPECT_TRUE(WIFEXITED(*status) && WEXITSTATUS(*status) == 0) << log;
  EXPECT_NE(log.find("resumed after a suspension"), std::string::npos) << log;
  EXPECT_NE(log.find("stopped by a signal"), std::string::npos) << log;
  EXPECT_TRUE(board.bad_lines().empty());
}

INSTANTIATE_TEST_SUITE_P(Suspend, ActDriveSuspend,
                         ::testing::Values(SuspendCase{"CtrlZ", 0}, SuspendCase{"SIGTTIN", SIGTTIN},
                                           SuspendCase{"SIGTTOU", SIGTTOU}),
                         [](const ::testing::TestParamInfo<SuspendCase>& case_info) { return std::string(case_info.param.name); });


// SIGSTOP cannot be caught: nothing goes on the wire while stopped (the board's watchdog stops the
// car after 250 ms). After SIGCONT the loop wakes up long after its tick: the first command on the
// wire is neutral, not the rest of the chunk planned before the stop, and the run goes on.
TEST(ActDriveCli, AfterSigstopAndSigcontTheFirstCommandIsNeutral) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string blob = act_tiny_blob(dir);
  const std::string video = write_test_video(dir + "/v.avi", 600, 30, 128, 96);
  FakeArduino board;
  const std::string log_path = dir + "/log.txt";
  const pid_t pid = start_act_drive({"-m", blob, "--camera", video, "--serial", board.port_path(), "--raw-endpoints",
                                     "--threads", "1"}, log_path);
  ASSERT_GE(pid, 0);
  const auto end_run = [&] {
    ::kill(pid, SIGKILL);
    ::waitpid(pid, nullptr, 0);
  };
  auto deadline = Clock::now() + std::chrono::seconds(20);
  while (board.commands().size() < 40 && Clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  ::kill(pid, SIGSTOP);
  deadline = Clock::now() + std::chrono::seconds(5);
  while (process_state(pid).first != 'T' && Clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  if (process_state(pid).first != 'T') end_run();
  ASSERT_EQ(process_state(pid).first, 'T') << read_text(log_path);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // shorter than act-tiny's chunk of 10 ticks
  const size_t before = board.commands().size();
  const auto continued = Clock::now();
  ::kill(pid, SIGCONT);
  deadline = Clock::now() + std::chrono::seconds(10);
  while (board.commands().size() < before + 30 && Clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  ::kill(pid, SIGTERM);
  const std::optional<int> status = wait_for_exit(pid, std::chrono::seconds(5));
  if (!status) end_run();
  const std::string log = read_text(log_path);
  ASSERT_TRUE(status) << "act_drive did not end within 5 s of SIGTERM\n" << log;
  EXPECT_TRUE(WIFEXITED(*status) && WEXITSTATUS(*status) == 0) << log;
  const auto commands = board.commands();
  ASSERT_GE(commands.size(), before + 30) << "the loop did not go on after SIGCONT\n" << log;
  ASSERT_GE(before, 40u) << log;
  EXPECT_TRUE(std::any_of(commands.begin(), commands.begin() + static_cast<std::ptrdiff_t>(before),
                          [](const FakeArduino::Command& c) { return c.steering_us != 1500 || c.throttle_us != 1500; }))
      << "never drove before the stop\n" << log;
  EXPECT_EQ(commands[before].type, 'C');
  EXPECT_EQ(commands[before].steering_us, 1500) << "the first command after SIGCONT";
  EXPECT_EQ(commands[before].throttle_us, 1500) << "the first command after SIGCONT";
  EXPECT_NE(log.find("ticks sent neutral because the control loop ran late"), std::string::npos) << log;
  EXPECT_TRUE(board.bad_lines().empty());
  report_fault_timing("SIGSTOP then SIGCONT", std::chrono::duration<double, std::milli>(commands[before].when - continued).count(),
                      "the first command (neutral) after SIGCONT");
}

TEST(ActDriveCli, ExitsAtOnceWhenANetworkCameraStalls) {
  // The camera streams 1.5 s of video, then stalls with its connection open. The stall is detected
  // (FFmpeg's read timeout) and the camera is reopened; that open blocks in FFmpeg for seconds, and
  // SIGTERM then must not wait for it.
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string blob = act_tiny_blob(dir);
  StallingStreamServer camera(write_test_video(dir + "/v.avi", 45, 30, 128, 96), std::chrono::milliseconds(1500));
  const std::string out_path = dir + "/out.txt", log_path = dir + "/log.txt";
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::dup2(::open(out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644), 1);
    ::dup2(::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644), 2);
    ::execl(kDrive.c_str(), kDrive.c_str(), "-m", blob.c_str(), "--camera", camera.url().c_str(), "--dry-run", "--threads",
            "1", static_cast<char*>(nullptr));
    ::_exit(127);
  }
  const auto deadline = Clock::now() + std::chrono::seconds(20);
  while (camera.connections() < 2 && Clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const bool reopening = camera.connections() >= 2;
  ::kill(pid, SIGTERM);
  const std::optional<int> status = wait_for_exit(pid, std::chrono::seconds(5));
  if (!status) {
    ::kill(pid, SIGKILL);
    ::waitpid(pid, nullptr, 0);
  }
  const std::string log = read_text(log_path);
  ASSERT_TRUE(reopening) << "the stall was not detected within 20 s\n" << log;
  ASSERT_TRUE(status) << "act_drive did not exit within 5 s of SIGTERM\n" << log;
  ASSERT_TRUE(WIFEXITED(*status)) << log;
  EXPECT_EQ(WEXITSTATUS(*status), 0) << log;
  const std::string source = "camera '" + camera.url() + "'";
  EXPECT_NE(log.find(source + " stopped delivering frames (stalled: no frame for "), std::string::npos) << log;
  EXPECT_NE(log.find("stopped by a signal"), std::string::npos) << log;
  EXPECT_NE(log.find(source + " is blocked in its backend and did not stop within"), std::string::npos) << log;
  std::istringstream lines(read_text(out_path));
  std::string time, line, last;
  while (lines >> time >> line) last = line;
  RoverMessage m{};
  ASSERT_EQ(rover_parse(last.c_str(), last.size(), &m), ROVER_OK) << last;
  EXPECT_EQ(m.fields[1], 1500);  // neutral: the summary and the exit came after it
  EXPECT_EQ(m.fields[2], 1500);
}

TEST(ActDriveCli, RecordingSurvivesSigkill) {
  // --record flushes its rows after every batch and renames each frame into place, so a run killed
  // without warning leaves whole rows whose frames exist (a last partial row at most, which
  // act_convert --calib skips).
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string blob = act_tiny_blob(dir);
  const std::string video = write_test_video(dir + "/v.avi", 600, 30, 128, 96);
  const std::string rec = dir + "/rec";
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const int null = ::open("/dev/null", O_WRONLY);
    ::dup2(null, 1);
    ::dup2(null, 2);
    ::execl(kDrive.c_str(), kDrive.c_str(), "-m", blob.c_str(), "--camera", video.c_str(), "--dry-run", "--threads", "1",
            "--record", rec.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  const auto complete_rows = [&](const std::string& file) {
    const std::string text = read_text(rec + "/" + file);
    return static_cast<size_t>(std::count(text.begin(), text.end(), '\n'));
  };
  const auto deadline = Clock::now() + std::chrono::seconds(30);
  while (complete_rows("log.jsonl") < 10 && Clock::now() < deadline) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  ::kill(pid, SIGKILL);
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFSIGNALED(status));

  std::istringstream log(read_text(rec + "/log.jsonl"));
  std::string line;
  size_t rows = 0;
  while (std::getline(log, line)) {
    if (log.eof()) break;  // the last line had no newline: cut by the kill
    const auto row = nlohmann::json::parse(line, nullptr, false);
    ASSERT_FALSE(row.is_discarded()) << "row " << rows << ": " << line;
    EXPECT_TRUE(fs::exists(rec + "/" + row.at("frame").get<std::string>())) << line;
    ++rows;
  }
  EXPECT_GE(rows, 10u);
  std::istringstream ticks(read_text(rec + "/ticks.csv"));
  std::string header;
  ASSERT_TRUE(std::getline(ticks, header));
  size_t tick_rows = 0;
  while (std::getline(ticks, line)) {
    if (ticks.eof()) break;
    EXPECT_EQ(std::count(line.begin(), line.end(), ','), std::count(header.begin(), header.end(), ',')) << line;
    ++tick_rows;
  }
  EXPECT_GT(tick_rows, 0u);
}

// What a recording cut short by a failed write leaves: whole rows only (no row cut, no byte of a
// failed write), each naming a frame that is on disk; act_convert --calib and act_eval --episode
// read it.
void expect_whole_recording(const std::string& dir, const std::string& rec, const std::string& blob) {
  const std::string log_text = read_text(rec + "/log.jsonl");
  std::istringstream log(log_text);
  std::string line;
  size_t rows = 0;
  while (std::getline(log, line)) {
    ASSERT_FALSE(log.eof()) << "log.jsonl: a cut last line: " << line;
    const auto row = nlohmann::json::parse(line, nullptr, false);
    ASSERT_FALSE(row.is_discarded()) << "log.jsonl line " << rows + 1 << ": " << line;
    EXPECT_TRUE(fs::exists(rec + "/" + row.at("frame").get<std::string>())) << line;
    ++rows;
  }
  EXPECT_GT(rows, 0u);
  const std::string ticks_text = read_text(rec + "/ticks.csv");
  ASSERT_FALSE(ticks_text.empty());
  EXPECT_EQ(ticks_text.back(), '\n') << "ticks.csv cut mid-row";
  EXPECT_EQ(ticks_text.find('\0'), std::string::npos) << "ticks.csv holds NUL bytes (a write past a cut)";
  EXPECT_EQ(log_text.find('\0'), std::string::npos) << "log.jsonl holds NUL bytes (a write past a cut)";
  std::istringstream ticks(ticks_text);
  std::string header;
  ASSERT_TRUE(std::getline(ticks, header));
  const auto fields = [](const std::string& row) {
    std::vector<std::string> out(1);
    for (char c : row) {
      if (c == ',') {
        out.emplace_back();
      } else {
        out.back().push_back(c);
      }
    }
    return out;
  };
  const std::vector<std::string> names = fields(header);
  const size_t frame_column = static_cast<size_t>(std::find(names.begin(), names.end(), "frame") - names.begin());
  ASSERT_LT(frame_column, names.size()) << header;
  size_t tick_rows = 0, driving = 0;
  while (std::getline(ticks, line)) {
    const std::vector<std::string> cells = fields(line);
    ASSERT_EQ(cells.size(), names.size()) << "ticks.csv row " << tick_rows + 1 << ": " << line;
    EXPECT_TRUE(cells[frame_column].empty() || fs::exists(rec + "/" + cells[frame_column])) << line;
    if (line.find(",ai,") != std::string::npos) ++driving;
    ++tick_rows;
  }
  EXPECT_GT(driving, 0u) << "no tick driven by the policy was kept";
  const auto convert = run_command(std::string(ACT_CONVERT_BIN) + " " + q(act::test::fixture_dir("act-tiny")) + " -o " +
                                   q(dir + "/int8.actb") + " --precision int8 --calib " + q(rec) + " --threads 1 -q");
  EXPECT_EQ(convert.exit_code, 0) << convert.output;
  const auto eval = run_command("timeout 60 " + std::string(ACT_EVAL_BIN) + " --episode " + q(rec) + " -m " + q(blob));
  EXPECT_EQ(eval.exit_code, 0) << eval.output;
  EXPECT_EQ(eval.output.find("cut short"), std::string::npos) << eval.output;
}

TEST(ActDriveCli, RecordingStopsWithAMessageAtTheFileSizeLimit) {
  // RLIMIT_FSIZE (ulimit -f 48: room for each frame, not for the 900 rows of ticks.csv) sends SIGXFSZ
  // to the writer, which used to end the run. Now the write fails instead, the recording stops with
  // one message, driving goes on to the end of the video (a replay, --realtime off, for speed), and
  // what is on disk is a whole recording act_convert and act_eval read.
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string blob = act_tiny_blob(dir);
  const std::string video = write_test_video(dir + "/v.avi", 900, 30, 128, 96);
  const std::string rec = dir + "/rec";
  const auto r = run_command("bash -c " + q("ulimit -f 48 && exec " + kDrive + " -m " + q(blob) + " --camera " + q(video) +
                                            " --dry-run --realtime off --threads 1 --record " + q(rec) + " > /dev/null"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("act_drive: error: --record: cannot write " + rec), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("File too large: the recording stops here ("), std::string::npos) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n') < 40, true) << "one message, not one per write:\n" << r.output;
  EXPECT_NE(r.output.find("end of video file " + video + " after 900 frames"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("(stopped early: a write failed, see above; "), std::string::npos) << r.output;
  EXPECT_LE(read_text(rec + "/ticks.csv").size(), 48u * 1024u);
  expect_whole_recording(dir, rec, blob);
}

// A full disk: a tmpfs of 384 kB in a mount namespace of act_drive's own (unshare; root or user
// namespaces), so that the frames fill it. The recording stops with one message naming the error
// and what was kept, driving goes on, and the folder (copied out before the namespace goes) reads.
TEST(ActDriveCli, RecordingOnAFullDiskStopsWithAMessageAndStaysReadable) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string disk = dir + "/disk";
  fs::create_directories(disk);
  const auto probe = run_command("unshare -rm sh -c " + q("mount -t tmpfs -o size=64k tmpfs " + q(disk)));
  if (probe.exit_code != 0) GTEST_SKIP() << "cannot mount a tmpfs in a mount namespace here: " << probe.output;
  const std::string blob = act_tiny_blob(dir);
  const std::string video = write_test_video(dir + "/v.avi", 600, 30, 128, 96);
  const std::string rec = disk + "/rec", kept = dir + "/kept";
  const auto r = run_command("unshare -rm sh -c " +
                             q("mount -t tmpfs -o size=384k tmpfs " + q(disk) + " || exit 99; " + kDrive + " -m " + q(blob) +
                               " --camera " + q(video) + " --dry-run --realtime off --threads 1 --record " + q(rec) +
                               " > /dev/null; code=$?; cp -a " + q(rec) + " " + q(kept) + " && exit $code"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("act_drive: error: --record: cannot write " + rec), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("No space left on device: the recording stops here ("), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("libpng"), std::string::npos) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n') < 40, true) << "one message, not one per write:\n" << r.output;
  EXPECT_NE(r.output.find("end of video file " + video + " after 600 frames"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("(stopped early: a write failed, see above; "), std::string::npos) << r.output;
  expect_whole_recording(dir, kept, blob);
}

TEST(ActDriveCli, CalibrateWithoutAPortPrintsAFileToEdit) {
  const std::string dir = act::test::scratch_dir();
  const auto r = run_command("(" + kDrive + " --calibrate > " + q(dir + "/cal.json") + ")");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.output.find("Edit the pulse widths"), std::string::npos) << r.output;
  const Calibration printed = Calibration::load(dir + "/cal.json");
  EXPECT_EQ(printed.max_forward, 0.3);  // a guessed template never drives at full throttle
  EXPECT_EQ(printed.max_reverse, 0.3);
  // What it prints is a valid calibration file.
  const auto check = run_command(kDrive + " -m m.actb --camera " + q(dir + "/none.avi") + " --dry-run -c " + q(dir + "/cal.json"));
  EXPECT_EQ(check.output.find("calibration"), std::string::npos) << check.output;
  EXPECT_NE(check.output.find("cannot open camera"), std::string::npos) << check.output;
}

// --help says --calibrate writes --calibration: without a port, the template goes to that file
// (never over one that exists, which may hold measured endpoints).
TEST(ActDriveCli, CalibrateWithoutAPortWritesTheTemplateToTheFileGiven) {
  const std::string dir = act::test::scratch_dir();
  const std::string path = dir + "/calibration.json";
  auto r = run_command(kDrive + " --calibrate -c " + q(path));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("wrote a calibration template to " + path), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("Edit the pulse widths"), std::string::npos) << r.output;
  ASSERT_TRUE(fs::exists(path)) << r.output;
  const Calibration written = Calibration::load(path);
  EXPECT_EQ(written.max_forward, 0.3);
  EXPECT_EQ(written.steering.mid_us, 1500);
  // Edited, then --calibrate again without a port: the file is kept.
  nlohmann::json edited = nlohmann::json::parse(read_text(path));
  edited["steering"]["center_us"] = 1480;
  std::ofstream(path) << edited.dump(2);
  r = run_command(kDrive + " --calibrate -c " + q(path));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find(path + " exists: left as it is"), std::string::npos) << r.output;
  EXPECT_EQ(Calibration::load(path).steering.mid_us, 1480);
  // A folder that is not there is an error, not a silent success.
  r = run_command(kDrive + " --calibrate -c " + q(dir + "/missing/cal.json"));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("cannot write " + dir + "/missing/cal.json"), std::string::npos) << r.output;
}

TEST(ActDriveCli, ThePackagesCalibrationTemplateIsAValidCalibrationFile) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const auto convert = run_command(std::string(ACT_CONVERT_BIN) + " " + q(act::test::fixture_dir("act-tiny")) +
                                   " --package " + q(dir + "/pkg") + " -q");
  ASSERT_EQ(convert.exit_code, 0) << convert.output;
  const Calibration calibration = Calibration::load(dir + "/pkg/drive_calibration.json");
  EXPECT_EQ(calibration.max_forward, 0.3);
  const std::string text = read_text(dir + "/pkg/drive_calibration.json");
  EXPECT_NE(text.find("act_drive --calibrate"), std::string::npos) << text;
  EXPECT_NE(text.find("--camera-size 96x128"), std::string::npos) << text;  // HxW
}

TEST(ActDriveCli, CalibrateInteractivelyWritesTheEndpoints) {
  const std::string dir = act::test::scratch_dir();
  FakeArduino board;
  // An existing file is the starting point: what is not re-measured is kept.
  std::ofstream(dir + "/cal.json") << R"({"steering": {"left_us": 1100, "center_us": 1490, "right_us": 1900, "invert": true},
                                          "throttle": {"reverse_us": 1300, "neutral_us": 1510, "forward_us": 1800}})";
  std::ofstream(dir + "/input.txt") << "s 1200\nleft\ns 1850\nright\nt 1650\nforward\nt 1380\nreverse\nsave\nquit\n";
  const auto r = run_command(kDrive + " --calibrate --serial " + q(board.port_path()) + " -c " + q(dir + "/cal.json") + " < " +
                             q(dir + "/input.txt"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("saved"), std::string::npos) << r.output;
  const nlohmann::json cal = nlohmann::json::parse(read_text(dir + "/cal.json"));
  EXPECT_EQ(cal["steering"]["left_us"], 1200);
  EXPECT_EQ(cal["steering"]["right_us"], 1850);
  EXPECT_EQ(cal["throttle"]["forward_us"], 1650);
  EXPECT_EQ(cal["throttle"]["reverse_us"], 1380);
  EXPECT_EQ(cal["steering"]["center_us"], 1490);
  EXPECT_EQ(cal["steering"]["invert"], true);
  EXPECT_EQ(cal["throttle"]["neutral_us"], 1510);
  const auto commands = board.commands();
  ASSERT_FALSE(commands.empty());
  EXPECT_EQ(commands.back().throttle_us, 1510);  // neutral on the way out
  EXPECT_TRUE(board.bad_lines().empty());
}

}  // namespace
}  // namespace act::drive::test
