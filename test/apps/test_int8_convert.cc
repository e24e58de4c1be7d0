// act_convert --precision int8 as a user runs it (on the LeRobot fixtures). The calibration range
// choices it is built on are tested in test/weights/test_activation_ranges.cc.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <utility>

#include <nlohmann/json.hpp>

#include "actengine/status.h"
#include "support/command.h"
#include "support/test_paths.h"

namespace fs = std::filesystem;

namespace act {
namespace {

using test::CommandResult;
using test::q;
using test::run_command;

// ------------------------------------------------------------------------------- act_convert

struct Converted {
  CommandResult result;
  nlohmann::json report;
};

Converted convert_int8(const std::string& fixture, const std::string& out, const std::string& flags) {
  const std::string src = test::fixture_dir(fixture);
  const std::string report = out + ".json";
  Converted c;
  c.result = run_command(std::string(ACT_CONVERT_BIN) + " " + q(src) + " -o " + q(out) + " --precision int8 --report " +
                         q(report) + " " + flags);
  if (fs::exists(report)) c.report = nlohmann::json::parse(std::ifstream(report));
  return c;
}

// Leftovers of a conversion in a folder: named temporary blobs (there should never be any).
std::vector<std::string> leftovers(const std::string& dir) {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    if (name.find(".tmp") != std::string::npos) out.push_back(name);
  }
  return out;
}

TEST(ActConvertInt8, StaticMeetsTheAccuracyAndSizeTargets) {
  for (const std::string fixture : {"act-tiny", "act-tiny-legacy"}) {
    const std::string src = test::fixture_dir(fixture);
    ACT_REQUIRE_PATH(src);
    const std::string dir = test::scratch_dir();
    const std::string blob = dir + "/int8.actb";
    // Both kinds of frame source: PNG folders (both fixtures' frames: 8) and an observation file.
    const Converted c = convert_int8(fixture, blob, "--mode static --calib " + q(test::fixture_dir("act-tiny")) + " --calib " +
                                                        q(test::fixture_dir("act-tiny-legacy")) + " --calib " +
                                                        q(src + "/reference.safetensors") + " --holdout 3");
    ASSERT_EQ(c.result.exit_code, 0) << c.result.output;
    ASSERT_TRUE(fs::exists(blob));
    EXPECT_TRUE(leftovers(dir).empty());
    const auto& r = c.report;
    EXPECT_EQ(r["mode"], "static");
    EXPECT_EQ(r["calibration"], "mse");
    EXPECT_EQ(r["holdout_frames"], 3);
    EXPECT_LE(r["action_error"]["mse"].get<double>(), 1e-3) << c.result.output;
    EXPECT_LE(r["action_error"]["max_abs"].get<double>(), 0.05) << c.result.output;
    EXPECT_EQ(r["action_error"]["per_dim_mse"].size(), 2u);
    EXPECT_LE(r["int8_bytes"].get<double>(), 0.28 * r["fp32_bytes"].get<double>());
    EXPECT_EQ(r["int8_bytes"].get<uint64_t>(), fs::file_size(blob));
    // Every conv and linear of the model reports its SQNR; the first layers are well above noise.
    ASSERT_GE(r["layers"].size(), 20u);
    EXPECT_GT(r["layers"][0]["sqnr_db"].get<double>(), 25.0) << r["layers"][0];
    EXPECT_NE(c.result.output.find("per-layer SQNR"), std::string::npos);

    // act_eval runs the INT8 blob unchanged, and stays near LeRobot's FP32 reference.
    const CommandResult e = run_command(std::string(ACT_EVAL_BIN) + " -m " + q(blob) + " -i " +
                                        q(src + "/reference.safetensors") + " --compare --tol 0.2");
    EXPECT_EQ(e.exit_code, 0) << e.output;
  }
}

// The report names the action dimensions (--action-names), gives the per-dimension table in every
// form, and says whether the result is good.
TEST(ActConvertInt8, ReportNamesTheActionsAndGivesAVerdict) {
  const std::string src = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  const std::string dir = test::scratch_dir();
  const Converted c = convert_int8("act-tiny", dir + "/n.actb", "--calib " + q(src) + " --calib-samples 3 --holdout 1 "
                                   "--action-names steering,throttle");
  ASSERT_EQ(c.result.exit_code, 0) << c.result.output;
  EXPECT_NE(c.result.output.find("\n  steering "), std::string::npos) << c.result.output;
  EXPECT_NE(c.result.output.find("\n  throttle "), std::string::npos) << c.result.output;
  EXPECT_EQ(c.result.output.find("\n  [0] "), std::string::npos) << c.result.output;
  // act-tiny's static INT8 is within 0.05 of FP32 (about 0.02, normalised).
  EXPECT_NE(c.result.output.find("verdict        good: INT8's held-out actions are within"), std::string::npos) << c.result.output;
  EXPECT_EQ(c.report["action_names"], nlohmann::json({"steering", "throttle"}));
  EXPECT_EQ(c.report["verdict"].get<std::string>().rfind("good: ", 0), 0u) << c.report["verdict"];
  const CommandResult html = run_command(std::string(ACT_CONVERT_BIN) + " " + q(src) + " -o " + q(dir + "/h.actb") +
                                         " --precision int8 -q --calib " + q(src) + " --calib-samples 3 --holdout 1 "
                                         "--action-names steering,throttle --report " + q(dir + "/r.html"));
  ASSERT_EQ(html.exit_code, 0) << html.output;
  std::ifstream in(dir + "/r.html");
  const std::string page((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(page.find("Held-out error per action dimension"), std::string::npos);
  EXPECT_NE(page.find("<td>steering</td>"), std::string::npos);
  EXPECT_NE(page.find("<th>verdict</th><td>good: "), std::string::npos);
  const CommandResult wrong = run_command(std::string(ACT_CONVERT_BIN) + " " + q(src) + " -o " + q(dir + "/w.actb") +
                                          " --precision int8 --calib " + q(src) + " --action-names steering");
  EXPECT_EQ(wrong.exit_code, 1) << wrong.output;
  EXPECT_NE(wrong.output.find("--action-names gives 1 names but the model's actions have 2 values"), std::string::npos)
      << wrong.output;
  EXPECT_FALSE(fs::exists(dir + "/w.actb"));
}

TEST(ActConvertInt8, DynamicNeedsNoCalibration) {
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  const std::string dir = test::scratch_dir();
  const Converted c = convert_int8("act-tiny", dir + "/dyn.actb", "--mode dynamic");
  ASSERT_EQ(c.result.exit_code, 0) << c.result.output;
  EXPECT_EQ(c.report["mode"], "dynamic");
  EXPECT_NE(c.result.output.find("synthetic frames"), std::string::npos) << c.result.output;
  EXPECT_LE(c.report["action_error"]["mse"].get<double>(), 1e-3);
}

TEST(ActConvertInt8, StaticWithoutFramesSaysWhatItNeeds) {
  ACT_REQUIRE_PATH(test::fixture_dir("act-tiny"));
  const std::string dir = test::scratch_dir();
  const Converted c = convert_int8("act-tiny", dir + "/st.actb", "--mode static");
  EXPECT_EQ(c.result.exit_code, 1);
  EXPECT_NE(c.result.output.find("--calib"), std::string::npos) << c.result.output;
  EXPECT_FALSE(fs::exists(dir + "/st.actb"));
}

TEST(ActConvertInt8, UnwritableReportFailsBeforeTheBlobIsWritten) {
  const std::string src = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  const std::string dir = test::scratch_dir();
  const auto r = run_command(std::string(ACT_CONVERT_BIN) + " " + q(src) + " -o " + q(dir + "/m.actb") +
                             " --precision int8 --mode dynamic --report " + q(dir + "/missing/r.json"));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find(dir + "/missing/r.json"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir + "/m.actb"));
  EXPECT_TRUE(leftovers(dir).empty());
}

TEST(ActConvertInt8, RecordingStatesMustFitTheModel) {
  // An act_drive recording made with another model logs states of another length: calibrating on
  // sampled states instead once hid that behind a note saying the source had none.
  const std::string src = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  const std::string dir = test::scratch_dir();
  const auto make_recording = [&](const std::string& name, const std::string& state) {
    const std::string rec = dir + "/" + name;
    fs::create_directories(rec + "/frames");
    std::ofstream log(rec + "/log.jsonl");
    for (int i = 0; i < 4; ++i) {
      const std::string frame = "frames/00000" + std::to_string(i) + ".png";
      fs::copy_file(src + "/sample" + std::to_string(i) + ".observation.images.front.png", rec + "/" + frame);
      log << R"({"frame": ")" << frame << R"(", "state": )" << state << "}\n";
    }
    return rec;
  };
  const std::string good = make_recording("good", "[0.1, -0.2]");
  const std::string bad = make_recording("bad", "[0.1, -0.2, 0.3]");
  const auto convert = [&](const std::string& rec) {
    return run_command(std::string(ACT_CONVERT_BIN) + " " + q(src) + " -o " + q(dir + "/r.actb") +
                       " --precision int8 --holdout 1 --calib " + q(rec));
  };
  const CommandResult ok = convert(good);
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
  EXPECT_EQ(ok.output.find("sampled"), std::string::npos) << ok.output;
  fs::remove(dir + "/r.actb");
  const CommandResult refused = convert(bad);
  EXPECT_EQ(refused.exit_code, 1) << refused.output;
  EXPECT_NE(refused.output.find("the recording's state has 3 values, the model's has 2"), std::string::npos)
      << refused.output;
  EXPECT_FALSE(fs::exists(dir + "/r.actb"));
}

TEST(ActConvertInt8, MissedMaxMseWritesNothing) {
  const std::string src = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  const std::string dir = test::scratch_dir();
  const Converted c = convert_int8("act-tiny", dir + "/m.actb", "--calib " + q(src) + " --max-mse 1e-12");
  EXPECT_EQ(c.result.exit_code, 1);
  EXPECT_NE(c.result.output.find("--max-mse"), std::string::npos) << c.result.output;
  EXPECT_FALSE(fs::exists(dir + "/m.actb"));
  EXPECT_FALSE(fs::exists(dir + "/m.actb.json"));
  EXPECT_TRUE(leftovers(dir).empty());
}

TEST(ActConvertInt8, MixedKeepsTheFewestFloatLayersThatMeetTheTarget) {
  const std::string src = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  const std::string dir = test::scratch_dir();
  const Converted all = convert_int8("act-tiny", dir + "/s.actb", "--calib " + q(src) + " --holdout 1");
  ASSERT_EQ(all.result.exit_code, 0) << all.result.output;
  const double static_mse = all.report["action_error"]["mse"].get<double>();
  const double target = static_mse / 10.0;
  const Converted c =
      convert_int8("act-tiny", dir + "/x.actb", "--mode mixed --calib " + q(src) + " --holdout 1 --target-mse " + std::to_string(target));
  ASSERT_EQ(c.result.exit_code, 0) << c.result.output;
  EXPECT_EQ(c.report["mode"], "mixed");
  EXPECT_LE(c.report["action_error"]["mse"].get<double>(), target);
  const size_t kept = c.report["float_layers"].size();
  EXPECT_GE(kept, 1u);
  EXPECT_LT(kept, c.report["sensitivity"].size());  // not simply everything
  EXPECT_NE(c.result.output.find("layers in float"), std::string::npos);
  // The blob holds those layers in float: it is bigger than the all-int8 one.
  EXPECT_GT(fs::file_size(dir + "/x.actb"), fs::file_size(dir + "/s.actb"));
}

TEST(ActConvertInt8, InterruptedConversionLeavesNothing) {
  const std::string src = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  for (const auto& [signal, number] : {std::pair{"INT", 2}, std::pair{"TERM", 15}}) {
    const std::string dir = test::scratch_dir();
    // Mixed mode's sensitivity search is the middle of a conversion: the signal comes once it has
    // started (a fixed delay raced the whole conversion, about 2 s of act-tiny in Release).
    const std::string convert = std::string(ACT_CONVERT_BIN) + " " + q(src) + " -o " + q(dir + "/k.actb") +
                                " --precision int8 --mode mixed --target-mse 1e-12 --calib " + q(src);
    const std::string log = q(dir + "/convert.log");
    // env --default-signal: a script's background job would otherwise ignore SIGINT.
    const CommandResult r = run_command(
        "env --default-signal=INT " + convert + " 2>" + log + " & pid=$!; " +
        "while kill -0 $pid 2>/dev/null && ! grep -q 'sensitivity search' " + log + "; do sleep 0.02; done; " +
        "kill -" + signal + " $pid; wait $pid; code=$?; cat " + log + "; rm " + log + "; exit $code");
    EXPECT_EQ(r.exit_code, 128 + number) << signal << ": " << r.output;  // killed by the signal while running
    EXPECT_EQ(r.output.find("wrote"), std::string::npos) << signal << ": " << r.output;
    EXPECT_FALSE(fs::exists(dir + "/k.actb")) << signal;
    EXPECT_TRUE(leftovers(dir).empty()) << signal << ": " << testing::PrintToString(leftovers(dir));
  }
}

TEST(ActConvertInt8, Fp32WithInt8FlagsIsAUsageError) {
  const std::string src = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  const std::string dir = test::scratch_dir();
  const CommandResult r = run_command(std::string(ACT_CONVERT_BIN) + " " + q(src) + " -o " + q(dir + "/f.actb") + " --calib " + q(src));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("--precision int8"), std::string::npos) << r.output;
  // --action-names names an FP32 blob's actions too (they are stored in it).
  const CommandResult names = run_command(std::string(ACT_CONVERT_BIN) + " " + q(src) + " -o " + q(dir + "/f.actb") +
                                          " --action-names steering,throttle");
  EXPECT_EQ(names.exit_code, 0) << names.output;
  const CommandResult twice = run_command(std::string(ACT_CONVERT_BIN) + " " + q(src) + " -o " + q(dir + "/g.actb") +
                                          " --action-names steering,steering");
  EXPECT_EQ(twice.exit_code, 1) << twice.output;
  EXPECT_NE(twice.output.find("--action-names: action name 'steering' is given twice"), std::string::npos) << twice.output;
}

// --linear-inputs as a user gives it: per tensor makes every FFN hidden activation per tensor in
// the report (the other inputs stay per token) and the text says so; it needs int8 and calibration.
TEST(ActConvertInt8, LinearInputCodesFlag) {
  const std::string src = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  const std::string dir = test::scratch_dir();
  const Converted c = convert_int8("act-tiny", dir + "/t.actb", "--mode static --calib " + q(src) +
                                                               " --holdout 1 --linear-inputs per-tensor --attention fp32");
  ASSERT_EQ(c.result.exit_code, 0) << c.result.output;
  const auto& inputs = c.report["linear_inputs"];
  ASSERT_FALSE(inputs.empty()) << c.report.dump(2);
  size_t per_tensor = 0;
  for (const auto& l : inputs) {
    EXPECT_EQ(l["codes"], l["ffn"].get<int>() >= 0 ? "per_tensor" : "per_token") << l;
    per_tensor += l["codes"] == "per_tensor";
  }
  EXPECT_GT(per_tensor, 0u);
  EXPECT_NE(c.result.output.find("linear inputs  " + std::to_string(per_tensor) + " of " + std::to_string(inputs.size())),
            std::string::npos) << c.result.output;

  const Converted dynamic = convert_int8("act-tiny", dir + "/d.actb", "--mode dynamic --linear-inputs per-tensor");
  EXPECT_EQ(dynamic.result.exit_code, 1);
  EXPECT_NE(dynamic.result.output.find("--linear-inputs needs calibration"), std::string::npos) << dynamic.result.output;
  EXPECT_FALSE(fs::exists(dir + "/d.actb"));
  const CommandResult fp32 = run_command(std::string(ACT_CONVERT_BIN) + " " + q(src) + " -o " + q(dir + "/f.actb") +
                                         " --linear-inputs per-token");
  EXPECT_EQ(fp32.exit_code, 1);
  EXPECT_NE(fp32.output.find("--precision int8"), std::string::npos) << fp32.output;
}

TEST(ActConvertInt8, UnreadableCalibrationSourceIsNamed) {
  const std::string src = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(src);
  const std::string dir = test::scratch_dir();
  const std::string bogus = dir + "/clip.mp4";
  std::ofstream(bogus) << "not a video";
  const Converted c = convert_int8("act-tiny", dir + "/b.actb", "--calib " + q(bogus));
  EXPECT_EQ(c.result.exit_code, 1);
  EXPECT_NE(c.result.output.find(bogus), std::string::npos) << c.result.output;
  EXPECT_FALSE(fs::exists(dir + "/b.actb"));
  const Converted missing = convert_int8("act-tiny", dir + "/b.actb", "--calib " + q(dir + "/nothing-here"));
  EXPECT_EQ(missing.result.exit_code, 1);
  EXPECT_NE(missing.result.output.find("nothing-here"), std::string::npos) << missing.result.output;
}

}  // namespace
}  // namespace act
