// act_convert --precision int8 as a user runs it (on the LeRobot fixtures), and the calibration
// range choices it is built on.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include <nlohmann/json.hpp>

#include "apps/convert/activation_stats.h"
#include "support/command.h"
#include "weights/blob/error.h"
#include "support/test_paths.h"

namespace fs = std::filesystem;

namespace act {
namespace {

using test::CommandResult;
using test::q;
using test::run_command;

// ------------------------------------------------------------------------- calibration methods

std::vector<float> heavy_tailed(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::exponential_distribution<float> body(4.0f);
  std::vector<float> v(n);
  for (auto& x : v) x = body(rng);  // ReLU-like: >= 0, a long right tail
  v[n / 2] = 40.0f;                 // one outlier far beyond the body
  return v;
}

RangeObserver observe(const std::vector<float>& v) {
  RangeObserver o;
  o.observe_range(v);
  o.observe_histogram(v);
  return o;
}

TEST(RangeObserver, MinMaxCoversTheWholeRange) {
  std::vector<float> v = {-1.5f, 0.25f, 3.0f, NAN, 2.0f};
  RangeObserver o;
  o.observe_range(v);
  EXPECT_EQ(o.min(), -1.5f);
  EXPECT_EQ(o.max(), 3.0f);
  const ActivationQuant a = o.choose(CalibrationMethod::kMinMax);
  EXPECT_NEAR(a.scale, 4.5f / 255.0f, 1e-7f);
  // -1.5 and 3.0 land on the ends of the int8 range (within the zero point's rounding).
  EXPECT_NEAR(-1.5f / a.scale + static_cast<float>(a.zero_point), -128.0f, 0.51f);
  EXPECT_NEAR(3.0f / a.scale + static_cast<float>(a.zero_point), 127.0f, 0.51f);
}

TEST(RangeObserver, PercentileClipsAnOutlier) {
  const RangeObserver o = observe(heavy_tailed(100000, 1));
  const ActivationQuant a = o.choose(CalibrationMethod::kPercentile, 99.9);
  EXPECT_LT(a.scale * 255.0f, 10.0f);  // far below the outlier's 40
  EXPECT_GT(a.scale * 255.0f, 1.0f);   // but above the body (99.9% of Exp(4) is ~1.7)
  EXPECT_EQ(a.zero_point, -128);       // non-negative data: 0 is the lowest code
}

TEST(RangeObserver, MseMinimizesTheExpectedError) {
  // A body with a thin tail of large values: clipping the tail trades a little clipping error for
  // a finer step over the body.
  std::vector<float> v = heavy_tailed(100000, 2);
  for (size_t i = 0; i < 30; ++i) v[i * 997] = 8.0f + static_cast<float>(i) * 0.5f;
  const RangeObserver o = observe(v);
  const ActivationQuant minmax = o.choose(CalibrationMethod::kMinMax);
  const ActivationQuant pct = o.choose(CalibrationMethod::kPercentile, 99.9);
  const ActivationQuant mse = o.choose(CalibrationMethod::kMse);
  EXPECT_LT(mse.scale, minmax.scale);
  EXPECT_LT(o.expected_squared_error(mse), o.expected_squared_error(minmax));
  EXPECT_LE(o.expected_squared_error(mse), o.expected_squared_error(pct));
}

TEST(RangeObserver, ConstantDataGivesAUsableScale) {
  const RangeObserver o = observe(std::vector<float>(100, 0.0f));
  for (auto m : {CalibrationMethod::kMinMax, CalibrationMethod::kPercentile, CalibrationMethod::kMse}) {
    const ActivationQuant a = o.choose(m);
    EXPECT_GT(a.scale, 0.0f);
    EXPECT_TRUE(std::isfinite(a.scale));
  }
}

TEST(RangeObserver, UnknownMethodIsAnError) {
  EXPECT_THROW(parse_calibration_method("kl"), Error);
  EXPECT_EQ(parse_calibration_method("mse"), CalibrationMethod::kMse);
}

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

// Leftovers of a conversion in a folder: temporary blobs, scratch folders.
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
  for (const char* signal : {"INT", "TERM"}) {
    const std::string dir = test::scratch_dir();
    // Mixed mode runs long enough (sensitivity analysis) to be interrupted in the middle.
    const CommandResult r = run_command("timeout -s " + std::string(signal) + " 2 " + ACT_CONVERT_BIN + " " + q(src) + " -o " +
                                        q(dir + "/k.actb") + " --precision int8 --mode mixed --target-mse 1e-12 --calib " + q(src));
    EXPECT_EQ(r.exit_code, 124) << signal << ": " << r.output;  // timeout's code: the conversion was still running
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
