// act_convert on PyTorch .pth files (--explain, refusing to guess, malicious pickles) and --package.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>

#include <nlohmann/json.hpp>

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
  for (const char* file : {"model.actb", "drive_calibration.json", "README.md", "config.json", "policy_preprocessor.json",
                           "policy_postprocessor.json"}) {
    EXPECT_TRUE(fs::exists(dir + "/pkg/" + file)) << file;
  }
  // LeRobot's --policy.path files (engine/python/lerobot_policy_actengine): a .pth has no config.json,
  // so the features come from the flags; the blob normalises, the processors do not.
  const nlohmann::json config = nlohmann::json::parse(std::ifstream(dir + "/pkg/config.json"));
  EXPECT_EQ(config["type"], "actengine");
  int cameras = 0;
  for (const auto& [key, feature] : config["input_features"].items()) {
    if (feature["type"] == "VISUAL") {
      ++cameras;
      EXPECT_EQ(feature["shape"], nlohmann::json::array({3, 96, 128})) << key;
    }
  }
  EXPECT_EQ(cameras, 1);
  EXPECT_EQ(config["input_features"]["observation.state"]["shape"], nlohmann::json::array({2}));
  EXPECT_EQ(config["output_features"]["action"]["shape"], nlohmann::json::array({2}));
  EXPECT_EQ(config["n_action_steps"], 10);
  EXPECT_EQ(config["normalization"], "blob");
  EXPECT_EQ(config["blob"], "model.actb");
  for (const char* name : {"policy_preprocessor.json", "policy_postprocessor.json"}) {
    const nlohmann::json processor = nlohmann::json::parse(std::ifstream(dir + "/pkg/" + name));
    ASSERT_FALSE(processor["steps"].empty()) << name;
    for (const auto& step : processor["steps"]) {
      EXPECT_EQ(std::string(step["registry_name"]).find("normalizer"), std::string::npos) << name;
    }
  }
  std::ifstream readme(dir + "/pkg/README.md");
  const std::string text((std::istreambuf_iterator<char>(readme)), std::istreambuf_iterator<char>());
  for (const char* step : {"build_packages.sh", "apt install ./actengine-tools_*_arm64.deb", "act_bench --model", "act_drive"}) {
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
  const CommandResult r = run_command(std::string(ACT_CONVERT_BIN) + " " + q(fixture) + " --n-heads 4 -o " + q(dir + "/m.actb"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("do not apply to a LeRobot checkpoint folder"), std::string::npos) << r.output;
}

// --n-action-steps and --temporal-ensemble-coeff replace the checkpoint's for every input kind, checked
// as LeRobot's ACTConfig checks them (the fixture: chunk_size 10, n_action_steps 10, no ensembling).
TEST(ActConvertDeployment, OverridesApplyToEveryInputKind) {
  ACT_REQUIRE_PATH(pth("tiny_plain.pth"));
  const std::string fixture = act::test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(fixture);
  const std::string dir = act::test::scratch_dir();
  const std::string pth_flags = " --stats " + q(pth("tiny_stats.json")) + " --image-size 96x128 --n-heads 4 --assume-lerobot-defaults";
  const std::string ensemble = " --n-action-steps 1 --temporal-ensemble-coeff 0.01 -o " + q(dir + "/m.actb");
  for (const std::string& input : {q(fixture), q(fixture + "/model.safetensors"), q(pth("tiny_plain.pth")) + pth_flags}) {
    const CommandResult r = run_command(std::string(ACT_CONVERT_BIN) + " " + input + ensemble);
    ASSERT_EQ(r.exit_code, 0) << input << "\n" << r.output;
    EXPECT_NE(r.output.find("n_action_steps 1, temporal ensembling coeff 0.01"), std::string::npos) << input << "\n" << r.output;
    // The blob holds them: act_drive's scheduler reads them from there.
    const CommandResult explain = run_command(std::string(ACT_CONVERT_BIN) + " " + input + " --n-action-steps 4 -o " + q(dir + "/q.actb"));
    ASSERT_EQ(explain.exit_code, 0) << explain.output;
    EXPECT_NE(explain.output.find("n_action_steps 4\n"), std::string::npos) << explain.output;
  }
  // The .pth explanation names the flag as the source.
  const CommandResult explain = run_command(std::string(ACT_CONVERT_BIN) + " " + q(pth("tiny_plain.pth")) + pth_flags +
                                            " --n-action-steps 1 --temporal-ensemble-coeff 0.01 --explain");
  EXPECT_NE(explain.output.find("<- --temporal-ensemble-coeff"), std::string::npos) << explain.output;

  fs::remove(dir + "/m.actb");
  const std::pair<std::string, std::string> refused[] = {
      {" --n-action-steps 4 --temporal-ensemble-coeff 0.01", "temporal ensembling needs n_action_steps == 1 (LeRobot's rule), got 4"},
      {" --n-action-steps 11", "n_action_steps 11 must be in [1, chunk_size 10]"},
      {" --n-action-steps 1 --temporal-ensemble-coeff 20", "overflow float32"},
      {" --n-action-steps 1 --temporal-ensemble-coeff nan", "expected a finite number or none, got 'nan'"},
      {" --n-action-steps 1 --temporal-ensemble-coeff 0.01x", "expected a finite number or none"},
  };
  for (const auto& [flags, message] : refused) {
    for (const std::string& input : {q(fixture), q(pth("tiny_plain.pth")) + pth_flags}) {
      const CommandResult r = run_command(std::string(ACT_CONVERT_BIN) + " " + input + flags + " -o " + q(dir + "/m.actb"));
      EXPECT_NE(r.exit_code, 0) << flags;
      EXPECT_NE(r.output.find(message), std::string::npos) << input << flags << "\n" << r.output;
      EXPECT_FALSE(fs::exists(dir + "/m.actb"));
    }
  }
  // Refused from config.json alone, before the weights are read: a folder without them still gets
  // the override's error, not the missing weights'.
  const std::string no_weights = dir + "/no-weights";
  fs::create_directories(no_weights);
  fs::copy_file(fixture + "/config.json", no_weights + "/config.json");
  const CommandResult early = run_command(std::string(ACT_CONVERT_BIN) + " " + q(no_weights) + " --n-action-steps 11 -o " +
                                          q(dir + "/m.actb"));
  EXPECT_EQ(early.exit_code, 1) << early.output;
  EXPECT_NE(early.output.find("n_action_steps 11 must be in [1, chunk_size 10]"), std::string::npos) << early.output;
  EXPECT_FALSE(fs::exists(dir + "/m.actb"));
}

}  // namespace
