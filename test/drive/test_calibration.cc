// Calibration: file parsing and validation, the action -> PWM map, the rate limiter.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <fstream>

#include "actengine/status.h"
#include "apps/drive/calibration.h"
#include "support/test_paths.h"

namespace act::drive {
namespace {

nlohmann::json example() {
  return nlohmann::json::parse(R"({
    "action_units": "normalized",
    "steering": {"action_index": 0, "left_us": 1100, "center_us": 1500, "right_us": 1900, "invert": false,
                 "rate_limit_us_per_s": 0},
    "throttle": {"action_index": 1, "reverse_us": 1300, "neutral_us": 1500, "forward_us": 1800, "invert": false,
                 "max_forward": 0.5, "max_reverse": 1.0, "rate_limit_us_per_s": 0}
  })");
}

std::string error_of(const nlohmann::json& j) {
  try {
    Calibration::from_json(j, "test.json");
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(Calibration, MapsNormalizedActionsPiecewiseLinearly) {
  const Calibration c = Calibration::from_json(example(), "test.json");
  const float center[] = {0, 0}, left[] = {-1, 0}, right[] = {1, 0}, half_left[] = {-0.5f, 0};
  EXPECT_EQ(c.map(center), (PwmCommand{1500, 1500}));
  EXPECT_EQ(c.map(left).steering_us, 1100);
  EXPECT_EQ(c.map(right).steering_us, 1900);
  EXPECT_EQ(c.map(half_left).steering_us, 1300);
  const float beyond[] = {7, -9};
  EXPECT_EQ(c.map(beyond), (PwmCommand{1900, 1300}));  // clamped to the endpoints
  const float full_forward[] = {0, 1}, reverse[] = {0, -0.5f};
  EXPECT_EQ(c.map(full_forward).throttle_us, 1650);  // max_forward 0.5
  EXPECT_EQ(c.map(reverse).throttle_us, 1400);
  EXPECT_EQ(c.safe_command(), (PwmCommand{1500, 1500}));
}

TEST(Calibration, InvertAndMicrosecondUnits) {
  nlohmann::json j = example();
  j["steering"]["invert"] = true;
  Calibration c = Calibration::from_json(j, "test.json");
  const float right[] = {1, 0};
  EXPECT_EQ(c.map(right).steering_us, 1100);

  j = example();
  j["action_units"] = "microseconds";
  c = Calibration::from_json(j, "test.json");
  const float us[] = {1700, 1800};
  EXPECT_EQ(c.map(us), (PwmCommand{1700, 1650}));  // steering passes through, throttle capped at 0.5
  const float beyond[] = {2500, 1000};
  EXPECT_EQ(c.map(beyond), (PwmCommand{1900, 1300}));
}

TEST(Calibration, NonFiniteActionsMapToTheSafeCommand) {
  // NaN once went through clamp and lround and reached the wire as "$C,10,0,0".
  const float nan = std::nanf(""), inf = INFINITY;
  for (const char* units : {"normalized", "microseconds"}) {
    nlohmann::json j = example();
    j["action_units"] = units;
    const Calibration c = Calibration::from_json(j, "test.json");
    for (const auto& action : {std::array{nan, 0.0f}, std::array{0.0f, nan}, std::array{inf, 0.0f},
                               std::array{0.0f, -inf}}) {
      EXPECT_EQ(c.map(action), c.safe_command()) << units << " " << action[0] << ", " << action[1];
    }
  }
}

TEST(Calibration, UnitsMustFitTheModelsActions) {
  // "microseconds" on a model with normalised actions once drove at full lock and in reverse.
  ModelInfo normalized_model, pulse_model;
  normalized_model.action_low = {-0.8f, -0.3f};
  normalized_model.action_high = {0.8f, 0.9f};
  pulse_model.action_low = {1300.0f, 1400.0f};
  pulse_model.action_high = {1700.0f, 1800.0f};
  nlohmann::json j = example();
  const Calibration normalized = Calibration::from_json(j, "test.json");
  j["action_units"] = "microseconds";
  const Calibration microseconds = Calibration::from_json(j, "test.json");
  EXPECT_NO_THROW(normalized.check_units(normalized_model));
  EXPECT_NO_THROW(microseconds.check_units(pulse_model));
  const auto message = [](const Calibration& c, const ModelInfo& m) {
    try {
      c.check_units(m);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message(microseconds, normalized_model).find("set \"action_units\": \"normalized\""), std::string::npos)
      << message(microseconds, normalized_model);
  EXPECT_NE(message(normalized, pulse_model).find("set \"action_units\": \"microseconds\""), std::string::npos)
      << message(normalized, pulse_model);
}

TEST(Calibration, ErrorsNameTheField) {
  auto with = [](const char* channel, const char* key, nlohmann::json value) {
    nlohmann::json j = example();
    j[channel][key] = value;
    return j;
  };
  EXPECT_NE(error_of(with("steering", "center_us", 2000)).find("'steering.center_us' (2000) must lie strictly between"),
            std::string::npos);
  EXPECT_NE(error_of(with("throttle", "forward_us", 3000)).find("'throttle.forward_us' = 3000 us is outside"),
            std::string::npos);
  EXPECT_NE(error_of(with("throttle", "max_forward", 1.5)).find("'throttle.max_forward' must be in 0..1"), std::string::npos);
  EXPECT_NE(error_of(with("steering", "invert", "yes")).find("'steering.invert' has the wrong type"), std::string::npos);
  EXPECT_NE(error_of(with("steering", "centre_us", 1500)).find("unknown field 'steering.centre_us'"), std::string::npos);
  EXPECT_NE(error_of(with("throttle", "action_index", 0)).find("same action_index"), std::string::npos);
  nlohmann::json j = example();
  j.erase("throttle");
  EXPECT_NE(error_of(j).find("missing object 'throttle'"), std::string::npos);
  j = example();
  j["steering"].erase("left_us");
  EXPECT_NE(error_of(j).find("missing field 'steering.left_us'"), std::string::npos);
  EXPECT_NE(error_of(j).find("test.json"), std::string::npos);
}

TEST(Calibration, NumbersAreRangeCheckedBeforeNarrowing) {
  // As a file has them: 2^32 + 1500 used to be read as 1500, 2^32 + 2000 as 2000, 2^32 + 1 as 1,
  // and 1500.9 as 1500.
  const std::string dir = act::test::scratch_dir();
  const auto load_error = [&](const std::string& steering, const std::string& throttle) {
    std::ofstream(dir + "/c.json") << R"({"steering": {"left_us": 1100, "right_us": 1900, )" << steering
                                   << R"(}, "throttle": {"reverse_us": 1300, "neutral_us": 1500, )" << throttle << "}}";
    try {
      Calibration::load(dir + "/c.json");
    } catch (const act::Error& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  std::string e = load_error(R"("center_us": 4294968796)", R"("forward_us": 1800)");
  EXPECT_NE(e.find("'steering.center_us' = 4294968796 is out of range"), std::string::npos) << e;
  e = load_error(R"("center_us": 1500)", R"("forward_us": 4294969296)");
  EXPECT_NE(e.find("'throttle.forward_us' = 4294969296 is out of range"), std::string::npos) << e;
  e = load_error(R"("center_us": 1500, "action_index": 4294967297)", R"("forward_us": 1800)");
  EXPECT_NE(e.find("'steering.action_index' = 4294967297 is out of range"), std::string::npos) << e;
  e = load_error(R"("center_us": 1500.9)", R"("forward_us": 1800)");
  EXPECT_NE(e.find("'steering.center_us' = 1500.9 is not a whole number"), std::string::npos) << e;
  e = load_error(R"("center_us": -4294965796)", R"("forward_us": 1800)");
  EXPECT_NE(e.find("'steering.center_us' = -4294965796 is out of range"), std::string::npos) << e;
  EXPECT_NE(e.find("c.json"), std::string::npos) << e;
  EXPECT_EQ(load_error(R"("center_us": 1500)", R"("forward_us": 1800)"), "accepted");
}

TEST(Calibration, LoadReportsMissingAndInvalidFiles) {
  const std::string dir = act::test::scratch_dir();
  try {
    Calibration::load(dir + "/none.json");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("none.json cannot be opened"), std::string::npos);
  }
  std::ofstream(dir + "/bad.json") << "{ \"steering\": ";
  try {
    Calibration::load(dir + "/bad.json");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("not valid JSON"), std::string::npos);
  }
  // A key given twice: nlohmann keeps the last one, so a later "invert": false could undo an earlier
  // true without a word. Refused, naming the key.
  std::ofstream(dir + "/twice.json") << R"({"action_units": "normalized", "action_units": "microseconds"})";
  try {
    Calibration::load(dir + "/twice.json");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("duplicate key 'action_units'"), std::string::npos) << e.what();
  }
  std::ofstream(dir + "/good.json") << example().dump();
  const Calibration c = Calibration::load(dir + "/good.json");
  EXPECT_EQ(Calibration::from_json(c.to_json(), "round trip").to_json(), c.to_json());
}

TEST(Calibration, RateLimiterBoundsTheChangePerTick) {
  nlohmann::json j = example();
  j["steering"]["rate_limit_us_per_s"] = 3000;  // 100 us per tick at 30 Hz
  RateLimiter limiter(Calibration::from_json(j, "test.json"));
  PwmCommand out = limiter.step({1900, 1650}, 1.0 / 30);
  EXPECT_EQ(out, (PwmCommand{1600, 1650}));  // throttle has no limit
  out = limiter.step({1900, 1650}, 1.0 / 30);
  EXPECT_EQ(out.steering_us, 1700);
  limiter.reset({1500, 1500});
  EXPECT_EQ(limiter.step({1100, 1500}, 1.0 / 30).steering_us, 1400);
}

}  // namespace
}  // namespace act::drive
