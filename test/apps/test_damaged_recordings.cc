// Damaged recordings as act_eval and act_convert meet them: a FIFO where a frame should be (refused at
// once, never waited on), a missing frame, a tick that is no number, a log.jsonl line with a key twice.
// Each is an error naming the file (and line), never a hang or a frame quietly left out.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "support/command.h"
#include "support/test_paths.h"

namespace {

namespace fs = std::filesystem;
using act::test::CommandResult;
using act::test::q;
using act::test::run_command;

using act::test::fixture_image;

// An act_drive recording of 8 ticks driven by hand, a new camera frame every other tick, and the
// log.jsonl of the 4 frames the policy would have seen. `tick_3` replaces the fourth tick's number.
std::string write_recording(const std::string& dir, const std::string& tick_3 = "3") {
  fs::create_directories(dir + "/tick_frames");
  fs::create_directories(dir + "/frames");
  std::string ticks = "tick,time_s,jitter_ms,source,action.0,action.1,steering_us,throttle_us,sent,driver,frame,"
                      "state.0,state.1,command.0,command.1\n";
  std::ofstream log(dir + "/log.jsonl");
  for (int t = 0; t < 8; ++t) {
    char name[40];
    std::snprintf(name, sizeof name, "tick_frames/%08d.png", t / 2);
    if (t % 2 == 0) {
      fs::copy_file(fixture_image(t / 2), dir + "/" + name);
      const std::string frame = "frames/00000" + std::to_string(t / 2) + ".png";
      fs::copy_file(fixture_image(t / 2), dir + "/" + frame);
      log << R"({"frame": ")" << frame << R"(", "state": [0.25, -0.5], "tick": )" << t << "}\n";
    }
    ticks += (t == 3 ? tick_3 : std::to_string(t)) + ",0.1,0.0,manual,,,1500,1500,1,manual," + name + ",0.25,-0.5,0.1,-0.1\n";
  }
  std::ofstream(dir + "/ticks.csv") << ticks;
  return dir;
}

std::string tiny_blob(const std::string& dir) {
  const std::string blob = dir + "/tiny.actb";
  const CommandResult c = run_command(std::string(ACT_CONVERT_BIN) + " " + q(act::test::fixture_dir("act-tiny")) + " -o " +
                                      q(blob) + " -q");
  EXPECT_EQ(c.exit_code, 0) << c.output;
  return blob;
}

// `timeout`: a reader that waits on a FIFO ends as exit 124 instead of hanging the suite.
CommandResult eval(const std::string& blob, const std::string& rec) {
  return run_command("timeout 30 " + std::string(ACT_EVAL_BIN) + " --episode " + q(rec) + " -m " + q(blob));
}

CommandResult calibrate(const std::string& dir, const std::string& rec) {
  return run_command("timeout 30 " + std::string(ACT_CONVERT_BIN) + " " + q(act::test::fixture_dir("act-tiny")) + " -o " +
                     q(dir + "/int8.actb") + " --precision int8 --holdout 1 --threads 1 --calib " + q(rec));
}

TEST(DamagedRecording, ActEvalRefusesAFifoTickFrameAtOnce) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string blob = tiny_blob(dir);
  const std::string rec = write_recording(dir + "/rec");
  const CommandResult good = eval(blob, rec);
  ASSERT_EQ(good.exit_code, 0) << good.output;
  fs::remove(rec + "/tick_frames/00000002.png");
  ASSERT_EQ(::mkfifo((rec + "/tick_frames/00000002.png").c_str(), 0644), 0);
  const CommandResult fifo = eval(blob, rec);
  EXPECT_EQ(fifo.exit_code, 1) << fifo.output;  // 124: it waited on the FIFO
  EXPECT_NE(fifo.output.find("ticks.csv line 6: cannot read '" + rec + "/tick_frames/00000002.png': not a regular file (a FIFO)"),
            std::string::npos) << fifo.output;
}

TEST(DamagedRecording, ActEvalRefusesAMissingTickFrameAndATickThatIsNoNumber) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string blob = tiny_blob(dir);
  const std::string rec = write_recording(dir + "/rec");
  fs::remove(rec + "/tick_frames/00000001.png");
  const CommandResult missing = eval(blob, rec);
  EXPECT_EQ(missing.exit_code, 1) << missing.output;
  EXPECT_NE(missing.output.find("ticks.csv line 4: cannot open '" + rec + "/tick_frames/00000001.png'"), std::string::npos)
      << missing.output;
  std::ofstream(rec + "/tick_frames/00000001.png") << "not a png";
  const CommandResult unreadable = eval(blob, rec);
  EXPECT_EQ(unreadable.exit_code, 1) << unreadable.output;
  EXPECT_NE(unreadable.output.find("ticks.csv line 4: cannot decode '" + rec + "/tick_frames/00000001.png' as an image"),
            std::string::npos) << unreadable.output;

  const std::string abc = write_recording(dir + "/abc", "abc");
  const CommandResult tick = eval(blob, abc);
  EXPECT_EQ(tick.exit_code, 1) << tick.output;
  EXPECT_NE(tick.output.find("ticks.csv line 5 column 'tick': 'abc' is not a tick number"), std::string::npos) << tick.output;
}

TEST(DamagedRecording, ActEvalRefusesADuplicateKeyInAnOlderRecordingsLog) {
  // A recording without the per-tick columns: act_eval reads the frames and states from log.jsonl.
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string blob = tiny_blob(dir);
  const std::string rec = dir + "/rec";
  fs::create_directories(rec + "/frames");
  fs::copy_file(fixture_image(0), rec + "/frames/000000.png");
  std::ofstream(rec + "/ticks.csv") << "tick,time_s,jitter_ms,source,action.0,action.1\n0,0,0,chunk,0.1,-0.1\n1,0,0,chunk,0.1,-0.1\n";
  std::ofstream(rec + "/log.jsonl") << R"({"frame": "frames/000000.png", "state": [0.25, -0.5], "tick": 0})" << "\n";
  const CommandResult good = eval(blob, rec);
  ASSERT_EQ(good.exit_code, 0) << good.output;
  std::ofstream(rec + "/log.jsonl") << R"({"frame": "frames/000000.png", "state": [0.25, -0.5], "tick": 0, "tick": 1})" << "\n";
  const CommandResult duplicate = eval(blob, rec);
  EXPECT_EQ(duplicate.exit_code, 1) << duplicate.output;
  EXPECT_NE(duplicate.output.find("log.jsonl line 1': not valid JSON: duplicate key 'tick'"), std::string::npos) << duplicate.output;
}

TEST(DamagedRecording, ActConvertRefusesAFifoFrameAtOnce) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string rec = write_recording(dir + "/rec");
  fs::remove(rec + "/frames/000001.png");
  ASSERT_EQ(::mkfifo((rec + "/frames/000001.png").c_str(), 0644), 0);
  const CommandResult fifo = calibrate(dir, rec);
  EXPECT_EQ(fifo.exit_code, 1) << fifo.output;  // 124: it waited on the FIFO
  EXPECT_NE(fifo.output.find("cannot read '" + rec + "/frames/000001.png': not a regular file (a FIFO)"), std::string::npos)
      << fifo.output;
  EXPECT_FALSE(fs::exists(dir + "/int8.actb"));
}

TEST(DamagedRecording, ActConvertRefusesADuplicateKeyAndDoesNotFallBackToTheImages) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  const std::string rec = write_recording(dir + "/rec");
  std::ofstream(rec + "/log.jsonl", std::ios::app)
      << R"({"frame": "frames/000000.png", "state": [0.25, -0.5], "state": [9, 9], "tick": 8})" << "\n";
  const CommandResult duplicate = calibrate(dir, rec);
  EXPECT_EQ(duplicate.exit_code, 1) << duplicate.output;
  EXPECT_NE(duplicate.output.find(rec + "/log.jsonl:5"), std::string::npos) << duplicate.output;
  EXPECT_NE(duplicate.output.find("'state'"), std::string::npos) << duplicate.output;
  EXPECT_FALSE(fs::exists(dir + "/int8.actb"));
  // A log that names no frame: an error, not the folder's images calibrated without their states.
  std::ofstream(rec + "/log.jsonl", std::ios::trunc) << R"({"tick": 0})" << "\n";
  const CommandResult empty = calibrate(dir, rec);
  EXPECT_EQ(empty.exit_code, 1) << empty.output;
  EXPECT_NE(empty.output.find(rec + "/log.jsonl names no frame"), std::string::npos) << empty.output;
  // A last line cut short by a crash is still only skipped, with a note.
  write_recording(dir + "/cut");
  std::ofstream(dir + "/cut/log.jsonl", std::ios::app) << R"({"frame": "frames/0000)";
  const CommandResult cut = calibrate(dir, dir + "/cut");
  EXPECT_EQ(cut.exit_code, 0) << cut.output;
}

}  // namespace
