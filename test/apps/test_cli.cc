// act_convert and act_eval as a user runs them: exit codes, what they print, files they leave.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "actengine/engine.h"
#include "support/act_test_util.h"
#include "support/command.h"
#include "support/test_paths.h"

namespace fs = std::filesystem;

namespace {

using act::test::CommandResult;
using act::test::run_command;
using act::test::q;

TEST(ActConvertCli, HelpDescribesUsage) {
  const CommandResult r = run_command(std::string(ACT_CONVERT_BIN) + " --help");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.output.find("checkpoint"), std::string::npos);
  EXPECT_NE(r.output.find("--output"), std::string::npos);
}

// One version, the project's (the top CMakeLists.txt), on every tool and in the library.
TEST(ToolsCli, VersionPrintsTheToolAndTheProjectVersion) {
  const std::string version = act::version();
  ASSERT_FALSE(version.empty());
  EXPECT_EQ(version.find_first_not_of("0123456789."), std::string::npos) << version;
  std::vector<std::string> tools{ACT_CONVERT_BIN, ACT_EVAL_BIN, ACT_BENCH_BIN};
#ifdef ACT_DRIVE_BIN
  tools.push_back(ACT_DRIVE_BIN);
#endif
  for (const std::string& tool : tools) {
    const CommandResult r = run_command(q(tool) + " --version");
    EXPECT_EQ(r.exit_code, 0) << tool << ": " << r.output;
    EXPECT_EQ(r.output, fs::path(tool).filename().string() + " " + version + "\n");
  }
}

TEST(ActConvertCli, MissingArgumentsIsAUsageError) {
  const CommandResult r = run_command(std::string(ACT_CONVERT_BIN));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("required"), std::string::npos) << r.output;
}

TEST(ActConvertCli, MissingCheckpointNamesThePath) {
  const std::string dir = act::test::scratch_dir();
  const CommandResult r = run_command(std::string(ACT_CONVERT_BIN) + " " + q(dir + "/nope") + " -o " + q(dir + "/m.actb"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find(dir + "/nope"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir + "/m.actb"));
}

// OpenCV's image and video I/O pulls in about 250 libraries: the apps load it from their module
// (engine/media/media_io.h) when they first read an image, never at start.
TEST(ActConvertCli, ImagesAndVideoComeFromAModuleLoadedOnFirstUse) {
  std::vector<std::string> apps{ACT_CONVERT_BIN, ACT_EVAL_BIN};
#ifdef ACT_DRIVE_BIN
  apps.push_back(ACT_DRIVE_BIN);
#endif
  for (const std::string& app : apps) {
    const CommandResult r = run_command("readelf -d " + q(app));
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_NE(r.output.find("libopencv_core"), std::string::npos) << app << r.output;  // the readelf output is the right one
    EXPECT_EQ(r.output.find("libopencv_imgcodecs"), std::string::npos) << app << r.output;
    EXPECT_EQ(r.output.find("libopencv_videoio"), std::string::npos) << app << r.output;
  }
  // A copy away from the module starts, and says what is missing when it needs an image.
  const std::string src = act::test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  const std::string dir = act::test::scratch_dir();
  fs::create_directories(dir + "/bin");
  fs::copy_file(ACT_CONVERT_BIN, dir + "/bin/act_convert");
  EXPECT_EQ(run_command(q(dir + "/bin/act_convert") + " --help").exit_code, 0);
  const CommandResult r = run_command(q(dir + "/bin/act_convert") + " " + q(src) + " -o " + q(dir + "/m.actb") +
                                      " --precision int8 --calib " + q(src));  // its folder holds sample images
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("cannot load the image and video support"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("libact_media_io.so"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir + "/m.actb"));
}

TEST(ActConvertCli, ConvertsAndEvalReproducesLeRobot) {
  for (const std::string fixture : {"act-tiny", "act-tiny-legacy"}) {
    const std::string src = act::test::fixture_dir(fixture);
    ACT_REQUIRE_PATH(src);
    const std::string dir = act::test::scratch_dir();
    const std::string blob = dir + "/" + fixture + ".actb";
    const CommandResult c = run_command(std::string(ACT_CONVERT_BIN) + " " + q(src) + " -o " + q(blob));
    ASSERT_EQ(c.exit_code, 0) << c.output;
    EXPECT_NE(c.output.find("resnet18, D 64, 4 heads"), std::string::npos) << c.output;
    EXPECT_NE(c.output.find(fixture == "act-tiny" ? "current LeRobot layout" : "legacy LeRobot layout"), std::string::npos);
    EXPECT_NE(c.output.find("training-only"), std::string::npos);
    ASSERT_TRUE(fs::exists(blob));

    const std::string out = dir + "/actions.safetensors";
    const CommandResult e = run_command(std::string(ACT_EVAL_BIN) + " --model " + q(blob) + " --input " + q(src + "/reference.safetensors") +
                      " --compare --output " + q(out));
    EXPECT_EQ(e.exit_code, 0) << e.output;
    EXPECT_NE(e.output.find("PASS"), std::string::npos) << e.output;
    EXPECT_TRUE(fs::exists(out));
    // The uint8 twin of the images gives the same answer.
    const CommandResult u8 = run_command(std::string(ACT_EVAL_BIN) + " -m " + q(blob) + " -i " + q(src + "/reference.safetensors") +
                       " --compare --images u8 --threads 1");
    EXPECT_EQ(u8.exit_code, 0) << u8.output;
  }
}

TEST(ActEvalCli, CompareFailsBeyondTolerance) {
  const std::string src = act::test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  const std::string dir = act::test::scratch_dir();
  const std::string blob = dir + "/tiny.actb";
  ASSERT_EQ(run_command(std::string(ACT_CONVERT_BIN) + " " + q(src) + " -o " + q(blob) + " -q").exit_code, 0);
  // The legacy fixture's reference belongs to other weights: the comparison must fail.
  const CommandResult e = run_command(std::string(ACT_EVAL_BIN) + " -m " + q(blob) + " -i " +
                    q(act::test::fixture_dir("act-tiny-legacy") + "/reference.safetensors") + " --compare");
  EXPECT_EQ(e.exit_code, 1) << e.output;
  EXPECT_NE(e.output.find("FAIL"), std::string::npos) << e.output;
}

TEST(ActEvalCli, CompareFailsOnNonFiniteValues) {
  // std::max skips NaN: a comparison built on it once printed PASS for a reference full of NaN.
  const std::string src = act::test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  const std::string dir = act::test::scratch_dir();
  const std::string blob = dir + "/tiny.actb";
  ASSERT_EQ(run_command(std::string(ACT_CONVERT_BIN) + " " + q(src) + " -o " + q(blob) + " -q").exit_code, 0);
  for (const size_t first : {size_t{0}, size_t{20}}) {
    for (const float value : {std::nanf(""), INFINITY}) {
      const std::string input = dir + "/reference_nan.safetensors";
      act::test::write_with_values_replaced(src + "/reference.safetensors", input, "output.action", first, value);
      const CommandResult e = run_command(std::string(ACT_EVAL_BIN) + " -m " + q(blob) + " -i " + q(input) + " --compare");
      EXPECT_EQ(e.exit_code, 1) << e.output;
      EXPECT_NE(e.output.find("NaN or infinite"), std::string::npos) << e.output;
      EXPECT_NE(e.output.find("FAIL"), std::string::npos) << e.output;
    }
  }
}

TEST(ToolsCli, TheWrongKindOfFileSaysWhatItIsAndWhatToRun) {
  // act_eval -i frame.png once said "header length 727905341920923785 exceeds the limit", and a
  // checkpoint folder given as a model "cannot map ...: not a regular file".
  const std::string src = act::test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  const std::string dir = act::test::scratch_dir();
  const std::string blob = dir + "/tiny.actb";
  ASSERT_EQ(run_command(std::string(ACT_CONVERT_BIN) + " " + q(src) + " -o " + q(blob) + " -q").exit_code, 0);
  const std::string png = src + "/sample0.observation.images.front.png";
  const CommandResult image_as_input = run_command(std::string(ACT_EVAL_BIN) + " -m " + q(blob) + " -i " + q(png));
  EXPECT_EQ(image_as_input.exit_code, 1);
  EXPECT_NE(image_as_input.output.find("is a PNG image, not an observation file"), std::string::npos) << image_as_input.output;
  for (const std::string& tool : {std::string(ACT_EVAL_BIN) + " -i " + q(src + "/reference.safetensors") + " -m ",
                                  std::string(ACT_BENCH_BIN) + " --num_runs 1 -m "}) {
    const CommandResult folder_as_model = run_command(tool + q(src));
    EXPECT_EQ(folder_as_model.exit_code, 1) << folder_as_model.output;
    EXPECT_NE(folder_as_model.output.find("is a LeRobot checkpoint folder, not an .actb blob: convert it first with "
                                          "act_convert"), std::string::npos) << folder_as_model.output;
  }
  // act_convert finds the policy in LeRobot's training output and says where.
  const std::string last = dir + "/checkpoints/last";
  fs::create_directories(last);
  fs::copy(src, last + "/pretrained_model", fs::copy_options::recursive);
  const CommandResult training = run_command(std::string(ACT_CONVERT_BIN) + " " + q(last) + " -o " + q(dir + "/t.actb"));
  EXPECT_EQ(training.exit_code, 0) << training.output;
  EXPECT_NE(training.output.find("the policy of this training checkpoint is in"), std::string::npos) << training.output;
}

TEST(ActEvalCli, CorruptModelAndMissingInputAreClearErrors) {
  const std::string dir = act::test::scratch_dir();
  std::ofstream(dir + "/junk.actb") << "this is not a model";
  const CommandResult bad_model = run_command(std::string(ACT_EVAL_BIN) + " -m " + q(dir + "/junk.actb") + " -i " + q(dir + "/x"));
  EXPECT_EQ(bad_model.exit_code, 1);
  EXPECT_NE(bad_model.output.find("junk.actb"), std::string::npos) << bad_model.output;

  const std::string src = act::test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  const std::string blob = dir + "/tiny.actb";
  ASSERT_EQ(run_command(std::string(ACT_CONVERT_BIN) + " " + q(src) + " -o " + q(blob) + " -q").exit_code, 0);
  const CommandResult no_input = run_command(std::string(ACT_EVAL_BIN) + " -m " + q(blob) + " -i " + q(dir + "/missing.safetensors"));
  EXPECT_EQ(no_input.exit_code, 1);
  EXPECT_NE(no_input.output.find("missing.safetensors"), std::string::npos) << no_input.output;
  // An observation file without output.action cannot be compared.
  const CommandResult no_ref = run_command(std::string(ACT_EVAL_BIN) + " -m " + q(blob) + " -i " +
                         q(src + "/policy_preprocessor_step_3_normalizer_processor.safetensors") + " --compare");
  EXPECT_EQ(no_ref.exit_code, 1);
  EXPECT_NE(no_ref.output.find("input.observation.state"), std::string::npos) << no_ref.output;
}

}  // namespace
