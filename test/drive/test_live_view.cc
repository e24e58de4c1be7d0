// act_drive --http in a real browser (test/browser/drive_page.js, headless chromium): the page shows
// the model's frames and the gauges, its e-stop puts neutral on the serial line within 250 ms and holds
// it, resume needs the token, and driving by hand from the page reaches the serial line.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "drive/drive_cli_util.h"
#include "drive/drive_test_util.h"
#include "drive/fake_arduino.h"
#include "support/command.h"
#include "support/test_paths.h"

namespace act::drive::test {
namespace {

namespace fs = std::filesystem;
using act::test::q;
using act::test::run_command;

// The board's commands as (epoch milliseconds, command): the page's clicks are timed with Date.now().
struct TimedCommand {
  double epoch_ms;
  uint16_t steering_us, throttle_us;
};

std::vector<TimedCommand> timed_commands(const FakeArduino& board) {
  const auto offset = std::chrono::system_clock::now().time_since_epoch() - Clock::now().time_since_epoch();
  std::vector<TimedCommand> out;
  for (const auto& c : board.commands()) {
    if (c.type != 'C') continue;
    const double ms = std::chrono::duration<double, std::milli>(c.when.time_since_epoch() + offset).count();
    out.push_back({ms, c.steering_us, c.throttle_us});
  }
  return out;
}

std::vector<TimedCommand> between(const std::vector<TimedCommand>& commands, double from_ms, double to_ms) {
  std::vector<TimedCommand> out;
  for (const auto& c : commands) {
    if (c.epoch_ms >= from_ms && c.epoch_ms <= to_ms) out.push_back(c);
  }
  return out;
}

TEST(ActDriveLiveView, EstopResumeAndDrivingByHandFromTheBrowser) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  ACT_REQUIRE_PATH(std::string(ACT_BROWSER_DIR) + "/node_modules/playwright-core");
  const std::string dir = act::test::scratch_dir();
  const std::string blob = act_tiny_blob(dir);
  const std::string video = write_test_video(dir + "/v.avi", 900, 30, 128, 96);  // 30 s, longer than the test
  // Steering 1100..1900 us, throttle 1300..1800 us capped at half forward: full right and full
  // forward by hand are 1900 / 1650 us.
  std::ofstream(dir + "/cal.json") << R"({"steering": {"left_us": 1100, "center_us": 1500, "right_us": 1900},
    "throttle": {"reverse_us": 1300, "neutral_us": 1500, "forward_us": 1800, "max_forward": 0.5}})";
  FakeArduino board;
  const std::string port = board.port_path(), log_path = dir + "/log.txt", cal = dir + "/cal.json", rec = dir + "/rec";
  const pid_t pid = start_act_drive({"-m", blob, "--camera", video, "--serial", port, "-c", cal, "--threads", "1", "--http",
                                     "127.0.0.1:0", "--record", rec}, log_path);
  ASSERT_GE(pid, 0);
  std::smatch found;
  const std::regex announced("live view on (http://127\\.0\\.0\\.1:[0-9]+/) \\(token ([0-9a-f]+)");
  std::string log;
  for (const auto deadline = Clock::now() + std::chrono::seconds(30); Clock::now() < deadline;) {
    log = read_text(log_path);
    if (std::regex_search(log, found, announced)) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_EQ(found.size(), 3u) << log;
  const std::string url = found[1], token = found[2], out = dir + "/page.json";
  const auto page = run_command("node " + q(std::string(ACT_BROWSER_DIR) + "/drive_page.js") + " " + q(url) + " " + token + " " + q(out));
  ::kill(pid, SIGINT);
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_EQ(page.exit_code, 0) << page.output << read_text(log_path);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << read_text(log_path);
  const nlohmann::json r = nlohmann::json::parse(read_text(out));

  EXPECT_TRUE(r["external"].empty()) << r["external"];  // the page needs no network
  // Every command driving by hand carried the time the page issued it (X-Act-Issued, ms on the
  // server's clock), and the server took them as fresh (the keys and stick below reach the line).
  ASSERT_FALSE(r["manual_issued"].empty());
  for (const auto& issued : r["manual_issued"]) EXPECT_TRUE(issued.is_string() && std::stod(issued.get<std::string>()) > 0) << issued;
  EXPECT_EQ(r["image_width"], 128);                      // the model's input, not the camera's
  EXPECT_TRUE(r["frame_changed"]);
  std::set<double> steering, throttle;
  int with_chunk_ahead = 0;
  for (const auto& s : r["samples"]) {
    steering.insert(s["steering"].get<double>());
    throttle.insert(s["throttle"].get<double>());
    with_chunk_ahead += s["ahead_points"].get<int>() > 0;
  }
  EXPECT_LT(r["samples"].front()["frame_index"], r["samples"].back()["frame_index"]);
  EXPECT_GT(steering.size() + throttle.size(), 2u) << r["samples"];  // the gauges move
  EXPECT_GT(with_chunk_ahead, 0);

  const std::vector<TimedCommand> commands = timed_commands(board);
  const auto is_neutral = [](const TimedCommand& c) { return c.steering_us == 1500 && c.throttle_us == 1500; };
  // E-stop: neutral within 250 ms of the click, and held through a resume without the token.
  const double t_estop = r["t_estop"], t_resume = r["t_resume"];
  EXPECT_EQ(r["estop_status"], 200);
  EXPECT_EQ(r["resume_without_token_status"], 403);
  EXPECT_EQ(r["resume_status"], 200);
  const auto after_estop = between(commands, t_estop, t_resume);
  ASSERT_FALSE(after_estop.empty());
  size_t first_neutral = 0;
  while (first_neutral < after_estop.size() && !is_neutral(after_estop[first_neutral])) ++first_neutral;
  ASSERT_LT(first_neutral, after_estop.size());
  EXPECT_LE(after_estop[first_neutral].epoch_ms - t_estop, 250.0);
  std::cout << "e-stop click to neutral on the serial line: " << after_estop[first_neutral].epoch_ms - t_estop << " ms\n";
  for (size_t i = first_neutral; i < after_estop.size(); ++i) {
    EXPECT_TRUE(is_neutral(after_estop[i])) << i << ": " << after_estop[i].steering_us << "/" << after_estop[i].throttle_us;
  }
  // The keys: full right, forward capped at half, within 250 ms; released, neutral (overridden, not resumed).
  const double t_keys_down = r["t_keys_down"], t_keys_up = r["t_keys_up"], t_stick_down = r["t_stick_down"];
  const auto by_keys = between(commands, t_keys_down + 250, t_keys_up);
  ASSERT_FALSE(by_keys.empty());
  for (const auto& c : by_keys) {
    EXPECT_EQ(c.steering_us, 1900);
    EXPECT_EQ(c.throttle_us, 1650);
  }
  for (const auto& c : between(commands, t_keys_up + 250, t_stick_down)) EXPECT_TRUE(is_neutral(c)) << c.steering_us << "/" << c.throttle_us;
  EXPECT_NE(r["mode_text"].get<std::string>().find("overridden"), std::string::npos) << r["mode_text"];
  // The stick, dragged full left.
  const auto by_stick = between(commands, t_stick_down + 250, r["t_stick_up"].get<double>());
  ASSERT_FALSE(by_stick.empty());
  for (const auto& c : by_stick) {
    EXPECT_EQ(c.steering_us, 1100);
    EXPECT_EQ(c.throttle_us, 1500);
  }
  const std::string final_log = read_text(log_path);
  EXPECT_NE(final_log.find("ticks driven by hand"), std::string::npos) << final_log;

  // The recording of this drive: act_convert calibrates on it, and its manual part becomes a LeRobot
  // dataset (through a stand-in of LeRobotDataset: LeRobot is not installed here).
  const auto calibrated = run_command(std::string(ACT_CONVERT_BIN) + " " + q(act::test::fixture_dir("act-tiny")) + " -o " +
                                      q(dir + "/int8.actb") + " --precision int8 --calib " + q(rec) + " --calib-samples 8 -q");
  EXPECT_EQ(calibrated.exit_code, 0) << calibrated.output;
  const auto dataset = run_command("PYTHONPATH=" + q(std::string(ACT_DRIVE_TEST_DIR) + "/lerobot_standin") + " /usr/bin/python3 " +
                                   q(std::string(ACT_DRIVE_APP_DIR) + "/recording_to_lerobot.py") + " " + q(rec) +
                                   " --repo-id test/rover --root " + q(dir + "/dataset") + " --min-frames 10");
  ASSERT_EQ(dataset.exit_code, 0) << dataset.output;
  const nlohmann::json d = nlohmann::json::parse(read_text(dir + "/dataset/standin.json"));
  EXPECT_EQ(d["fps"], 30);
  EXPECT_EQ(d["features"]["observation.images.front"]["shape"], (std::vector<int>{96, 128, 3}));
  // From the keys going down to the end (never resumed): one episode of manual ticks, each with
  // the command sent in the model's units: keys (full right, throttle capped at 0.5), released
  // (neutral), stick (full left).
  ASSERT_EQ(d["episodes"].size(), 1u) << dataset.output;
  std::set<std::vector<double>> actions;
  for (const auto& frame : d["episodes"][0]) actions.insert(frame["action"].get<std::vector<double>>());
  for (const std::vector<double>& expected : {std::vector<double>{1, 0.5}, {0, 0}, {-1, 0}}) {
    EXPECT_TRUE(actions.count(expected)) << expected[0] << ", " << expected[1] << " in " << d["episodes"][0].size() << " frames";
  }
  EXPECT_EQ(d["episodes"][0][0]["task"], "drive the track");
}

}  // namespace
}  // namespace act::drive::test
