// Every app given the wrong kind of file says what the file is and which command takes it, for each
// of its file arguments and each kind a user may mistake for another.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <vector>

#include "support/command.h"
#include "support/test_paths.h"

namespace fs = std::filesystem;

namespace {

using act::test::CommandResult;
using act::test::q;
using act::test::run_command;

// One file of a kind, and what the message must hold: the kind's name and the next command.
struct KindCase {
  std::string path, is, next;
};

// One file or folder of every kind, made from the act-tiny fixture in `dir`.
std::map<std::string, KindCase> make_kinds(const std::string& fixture, const std::string& dir) {
  const std::string blob = dir + "/tiny.actb";
  EXPECT_EQ(run_command(std::string(ACT_CONVERT_BIN) + " " + q(fixture) + " -o " + q(blob) + " -q").exit_code, 0);
  // Only the first bytes matter to the tools' checks: a torch.save zip and an MP4 header suffice.
  std::ofstream(dir + "/policy.pth", std::ios::binary) << std::string("PK\x03\x04", 4) << "archive/data.pkl";
  std::ofstream(dir + "/drive.mp4", std::ios::binary) << std::string("\0\0\0\x18" "ftypisom", 12);
  fs::create_directories(dir + "/run1/frames");
  std::ofstream(dir + "/run1/log.jsonl") << "{\"frame\": \"frames/000000.png\", \"state\": [0, 0]}\n";
  fs::create_directories(dir + "/obs");
  fs::copy_file(fixture + "/reference.safetensors", dir + "/obs/episode.safetensors");
  const std::string act_convert = "convert it first with act_convert";
  const std::string calib = "frames are calibration input: act_convert CHECKPOINT -o model.actb --precision int8 --calib";
  return {
      {"checkpoint", {fixture, "is a LeRobot checkpoint folder, not", act_convert}},
      {"safetensors", {dir + "/obs/episode.safetensors", "is a safetensors file, not", "observations go to act_eval -i"}},
      {"pth", {dir + "/policy.pth", "is a PyTorch checkpoint (torch.save zip), not", act_convert}},
      {"actb", {blob, "is an .actb blob, not", "already converted: run it with act_bench -m"}},
      {"image", {fixture + "/sample0.observation.images.front.png", "is a PNG image, not", calib}},
      {"video", {dir + "/drive.mp4", "is a video, not", calib}},
      {"recording", {dir + "/run1", "is an act_drive recording, not", calib}},
  };
}

// Runs `command_before + q(path) + command_after` for each named kind and checks the message.
void expect_refused(const std::map<std::string, KindCase>& kinds, const std::vector<std::string>& names,
                    const std::string& before, const std::string& after = "") {
  for (const std::string& name : names) {
    const KindCase& k = kinds.at(name);
    const std::string command = before + q(k.path) + after;
    const CommandResult r = run_command(command);
    EXPECT_EQ(r.exit_code, 1) << command << "\n" << r.output;
    EXPECT_NE(r.output.find(k.is), std::string::npos) << command << "\n" << r.output;
    EXPECT_NE(r.output.find(k.next), std::string::npos) << command << "\n" << r.output;
  }
}

class WrongKindOfFile : public ::testing::Test {
 protected:
  void SetUp() override {
    fixture_ = act::test::fixture_dir("act-tiny");
    ACT_REQUIRE_PATH(fixture_);
    dir_ = act::test::scratch_dir();
    kinds_ = make_kinds(fixture_, dir_);
  }
  std::string fixture_, dir_;
  std::map<std::string, KindCase> kinds_;
};

TEST_F(WrongKindOfFile, ActConvertCheckpoint) {
  const std::string out = " -o " + q(dir_ + "/out.actb");
  expect_refused(kinds_, {"safetensors", "actb", "image", "video", "recording"}, std::string(ACT_CONVERT_BIN) + " ", out);
  EXPECT_FALSE(fs::exists(dir_ + "/out.actb"));
}

TEST_F(WrongKindOfFile, ActConvertCalib) {
  // A checkpoint folder without images (the fixture keeps sample frames beside its weights).
  fs::create_directories(dir_ + "/ckpt");
  for (const char* file : {"config.json", "model.safetensors"}) fs::copy_file(fixture_ + "/" + file, dir_ + "/ckpt/" + file);
  kinds_["checkpoint"].path = dir_ + "/ckpt";
  expect_refused(kinds_, {"checkpoint", "pth", "actb"},
                 std::string(ACT_CONVERT_BIN) + " " + q(fixture_) + " -o " + q(dir_ + "/out.actb") + " --precision int8 --calib ");
  EXPECT_FALSE(fs::exists(dir_ + "/out.actb"));
}

TEST_F(WrongKindOfFile, ActEvalModelAndInput) {
  const std::string obs = q(kinds_.at("safetensors").path);
  expect_refused(kinds_, {"checkpoint", "safetensors", "pth", "image", "video", "recording"},
                 std::string(ACT_EVAL_BIN) + " -i " + obs + " -m ");
  expect_refused(kinds_, {"checkpoint", "pth", "actb", "image", "video", "recording"},
                 std::string(ACT_EVAL_BIN) + " -m " + q(kinds_.at("actb").path) + " -i ");
}

TEST_F(WrongKindOfFile, ActBenchModelAndInput) {
  expect_refused(kinds_, {"checkpoint", "safetensors", "pth", "image", "video", "recording"},
                 std::string(ACT_BENCH_BIN) + " --num_runs 1 -m ");
  expect_refused(kinds_, {"checkpoint", "pth", "actb", "image", "video", "recording"},
                 std::string(ACT_BENCH_BIN) + " --num_runs 1 -m " + q(kinds_.at("actb").path) + " --input ");
}

#ifdef ACT_DRIVE_BIN
TEST_F(WrongKindOfFile, ActDriveModelAndCamera) {
  const std::string drive = std::string(ACT_DRIVE_BIN) + " --dry-run --duration 1 ";
  expect_refused(kinds_, {"checkpoint", "safetensors", "pth", "image", "video", "recording"},
                 drive + "--camera " + q(kinds_.at("video").path) + " -m ");
  expect_refused(kinds_, {"checkpoint", "safetensors", "pth", "actb"}, drive + "-m " + q(kinds_.at("actb").path) + " --camera ");
  // A recording as the camera also says how to replay it.
  const CommandResult r = run_command(drive + "-m " + q(kinds_.at("actb").path) + " --camera " + q(dir_ + "/run1"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("--camera " + dir_ + "/run1/frames/%06d.png"), std::string::npos) << r.output;
}
#endif

}  // namespace
