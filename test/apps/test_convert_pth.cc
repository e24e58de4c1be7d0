// act_convert on PyTorch .pth files (--explain, refusing to guess, malicious pickles) and --package.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>

#include "support/command.h"
#include "support/test_paths.h"

namespace fs = std::filesystem;

namespace {

using act::test::CommandResult;
using act::test::q;
using act::test::run_command;

std::string pth(const std::string& name) { return act::test::generated_checkpoint_dir("pth") + "/" + name; }

TEST(ActConvertPth, ExplainNamesTheSourceTensorsAndRefusesToGuess) {
  ACT_REQUIRE_PATH(pth("tiny_wrapped_noprefix.pth"));
  const CommandResult r = run_command(std::string(ACT_CONVERT_BIN) + " " + q(pth("tiny_wrapped_noprefix.pth")) + " --explain");
  EXPECT_EQ(r.exit_code, 1) << r.output;  // facts are missing
  for (const char* text : {"state dict: entry 'model_state_dict'", "epoch: int 42", "added it",
                           "dim_model  64", "<- model.encoder_latent_input_proj.weight [64, 32]", "chunk_size  10",
                           "refusing to guess", "n_action_steps:", "cameras:"}) {
    EXPECT_NE(r.output.find(text), std::string::npos) << text << "\n" << r.output;
  }
}

TEST(ActConvertPth, ConvertsWithFlagsAndWritesARobotPackage) {
  ACT_REQUIRE_PATH(pth("tiny_plain.pth"));
  const std::string fixture = act::test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(fixture);
  const std::string dir = act::test::scratch_dir();
  const CommandResult r = run_command(
      std::string(ACT_CONVERT_BIN) + " " + q(pth("tiny_plain.pth")) + " --stats " + q(pth("tiny_stats.json")) +
      " --image-size 96x128 --n-action-steps 10 --n-heads 4 --assume-lerobot-defaults --package " + q(dir + "/pkg"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("PyTorch zip .pth"), std::string::npos) << r.output;
  for (const char* file : {"model.actb", "drive_calibration.json", "README.md"}) {
    EXPECT_TRUE(fs::exists(dir + "/pkg/" + file)) << file;
  }
  std::ifstream readme(dir + "/pkg/README.md");
  const std::string text((std::istreambuf_iterator<char>(readme)), std::istreambuf_iterator<char>());
  for (const char* step : {"build_packages.sh", "apt install ./actengine_*_arm64.deb", "act_bench --model", "act_drive"}) {
    EXPECT_NE(text.find(step), std::string::npos) << step;
  }
  // The package's blob is the folder's.
  const CommandResult ref = run_command(std::string(ACT_CONVERT_BIN) + " " + q(fixture) + " -q -o " + q(dir + "/ref.actb"));
  ASSERT_EQ(ref.exit_code, 0) << ref.output;
  EXPECT_EQ(run_command("cmp " + q(dir + "/ref.actb") + " " + q(dir + "/pkg/model.actb")).exit_code, 0);
}

TEST(ActConvertPth, MaliciousPickleIsAnErrorAndRunsNothing) {
  ACT_REQUIRE_PATH(pth("evil_os_system.pth"));
  const std::string dir = act::test::scratch_dir();
  const CommandResult r = run_command(std::string(ACT_CONVERT_BIN) + " " + q(pth("evil_os_system.pth")) + " -o " + q(dir + "/m.actb"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("GLOBAL 'posix.system' is not allowed"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir + "/m.actb"));
  EXPECT_FALSE(fs::exists(pth("PWNED")));
}

TEST(ActConvertPth, PthOptionsDoNotApplyToAFolder) {
  const std::string fixture = act::test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(fixture);
  const std::string dir = act::test::scratch_dir();
  const CommandResult r = run_command(std::string(ACT_CONVERT_BIN) + " " + q(fixture) + " --n-action-steps 5 -o " + q(dir + "/m.actb"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("do not apply to a LeRobot checkpoint folder"), std::string::npos) << r.output;
}

}  // namespace
