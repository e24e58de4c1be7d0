#include "apps/drive/calibration.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <set>

#include "actengine/status.h"
#include "apps/arduino/act_rover/rover_protocol.h"
#include "weights/blob/file_util.h"

namespace act::drive {
namespace {

// Names of one channel's endpoints in the file.
struct EndpointNames {
  const char* low;
  const char* mid;
  const char* high;
};
constexpr EndpointNames kSteeringNames{"left_us", "center_us", "right_us"};
constexpr EndpointNames kThrottleNames{"reverse_us", "neutral_us", "forward_us"};

[[noreturn]] void bad(const std::string& source, const std::string& what) {
  fail(StatusCode::kInvalidArgument, "calibration " + source + ": " + what);
}

void reject_unknown_keys(const nlohmann::json& object, const std::set<std::string>& known, const std::string& source,
                         const std::string& where) {
  for (const auto& [key, value] : object.items()) {
    if (!known.count(key) && key.rfind('_', 0) != 0) bad(source, "unknown field '" + where + key + "'");
  }
}

template <typename T>
T get_or(const nlohmann::json& object, const char* key, T fallback, const std::string& source, const std::string& where) {
  if (!object.contains(key)) return fallback;
  try {
    return object.at(key).get<T>();
  } catch (const nlohmann::json::exception&) {
    bad(source, "field '" + where + key + "' has the wrong type (" + object.at(key).dump() + ")");
  }
}

// An integer field: a whole number that fits an int, checked before it is narrowed (get<int>() would
// read 2^32+1500 as 1500 and 1500.9 as 1500). Refused, naming the key, otherwise.
int get_int_or(const nlohmann::json& object, const char* key, int fallback, const std::string& source, const std::string& where) {
  if (!object.contains(key)) return fallback;
  const nlohmann::json& value = object.at(key);
  const std::string field = "'" + where + key + "' = " + value.dump();
  constexpr int64_t kMin = std::numeric_limits<int>::min(), kMax = std::numeric_limits<int>::max();
  if (value.is_number_unsigned()) {
    if (value.get<uint64_t>() > static_cast<uint64_t>(kMax)) bad(source, field + " is out of range");
    return static_cast<int>(value.get<uint64_t>());
  }
  if (value.is_number_integer()) {
    const int64_t v = value.get<int64_t>();
    if (v < kMin || v > kMax) bad(source, field + " is out of range");
    return static_cast<int>(v);
  }
  if (value.is_number_float()) bad(source, field + " is not a whole number");
  bad(source, "field '" + where + key + "' has the wrong type (" + value.dump() + ")");
}

int get_pulse(const nlohmann::json& object, const char* key, const std::string& source, const std::string& where) {
  if (!object.contains(key)) bad(source, "missing field '" + where + key + "'");
  const int us = get_int_or(object, key, 0, source, where);
  if (us < ROVER_PWM_MIN_US || us > ROVER_PWM_MAX_US) {
    bad(source, "'" + where + key + "' = " + std::to_string(us) + " us is outside " + std::to_string(ROVER_PWM_MIN_US) +
                    ".." + std::to_string(ROVER_PWM_MAX_US) + " us");
  }
  return us;
}

ChannelCalibration parse_channel(const nlohmann::json& json, const char* name, const EndpointNames& names,
                                 int default_index, const std::string& source) {
  if (!json.contains(name) || !json.at(name).is_object()) bad(source, std::string("missing object '") + name + "'");
  const nlohmann::json& c = json.at(name);
  const std::string where = std::string(name) + ".";
  std::set<std::string> known{"action_index", names.low, names.mid, names.high, "invert", "rate_limit_us_per_s"};
  if (std::string(name) == "throttle") known.insert({"max_forward", "max_reverse"});
  reject_unknown_keys(c, known, source, where);
  ChannelCalibration ch;
  ch.action_index = get_int_or(c, "action_index", default_index, source, where);
  ch.low_us = get_pulse(c, names.low, source, where);
  ch.mid_us = get_pulse(c, names.mid, source, where);
  ch.high_us = get_pulse(c, names.high, source, where);
  ch.invert = get_or<bool>(c, "invert", false, source, where);
  ch.rate_limit_us_per_s = get_or<double>(c, "rate_limit_us_per_s", 0.0, source, where);
  if (ch.action_index < 0) bad(source, "'" + where + "action_index' must be >= 0");
  if (!(std::min(ch.low_us, ch.high_us) < ch.mid_us && ch.mid_us < std::max(ch.low_us, ch.high_us))) {
    bad(source, "'" + where + names.mid + "' (" + std::to_string(ch.mid_us) + ") must lie strictly between '" + names.low +
                    "' (" + std::to_string(ch.low_us) + ") and '" + names.high + "' (" + std::to_string(ch.high_us) + ")");
  }
  if (!(ch.rate_limit_us_per_s >= 0) || !std::isfinite(ch.rate_limit_us_per_s)) {
    bad(source, "'" + where + "rate_limit_us_per_s' must be >= 0 (0 = unlimited)");
  }
  return ch;
}

// Pulse width -> normalized value through a channel's endpoints (the inverse of the output map).
double normalized_from_us(double us, const ChannelCalibration& ch) {
  const double above = (us - ch.mid_us) / static_cast<double>(ch.high_us - ch.mid_us);
  if (above >= 0) return above;
  return -(us - ch.mid_us) / static_cast<double>(ch.low_us - ch.mid_us);
}

uint16_t us_from_normalized(double v, const ChannelCalibration& ch) {
  const double us = v >= 0 ? ch.mid_us + v * (ch.high_us - ch.mid_us) : ch.mid_us - v * (ch.low_us - ch.mid_us);
  return static_cast<uint16_t>(std::lround(us));
}

nlohmann::ordered_json channel_json(const ChannelCalibration& ch, const EndpointNames& names) {
  return {{"action_index", ch.action_index}, {names.low, ch.low_us}, {names.mid, ch.mid_us}, {names.high, ch.high_us},
          {"invert", ch.invert}, {"rate_limit_us_per_s", ch.rate_limit_us_per_s}};
}

}  // namespace

Calibration Calibration::from_json(const nlohmann::json& json, const std::string& source) {
  if (!json.is_object()) bad(source, "expected a JSON object");
  reject_unknown_keys(json, {"action_units", "steering", "throttle"}, source, "");
  Calibration cal;
  const std::string units = get_or<std::string>(json, "action_units", "normalized", source, "");
  if (units == "normalized") {
    cal.action_units = Units::kNormalized;
  } else if (units == "microseconds") {
    cal.action_units = Units::kMicroseconds;
  } else {
    bad(source, "'action_units' is \"" + units + "\"; expected \"normalized\" or \"microseconds\"");
  }
  cal.steering = parse_channel(json, "steering", kSteeringNames, 0, source);
  cal.throttle = parse_channel(json, "throttle", kThrottleNames, 1, source);
  const nlohmann::json& t = json.at("throttle");
  cal.max_forward = get_or<double>(t, "max_forward", 1.0, source, "throttle.");
  cal.max_reverse = get_or<double>(t, "max_reverse", 1.0, source, "throttle.");
  for (const auto& [name, value] : {std::pair{"max_forward", cal.max_forward}, std::pair{"max_reverse", cal.max_reverse}}) {
    if (!(value >= 0.0 && value <= 1.0)) bad(source, std::string("'throttle.") + name + "' must be in 0..1 (a fraction of full throttle)");
  }
  if (cal.steering.action_index == cal.throttle.action_index) {
    bad(source, "steering and throttle use the same action_index " + std::to_string(cal.steering.action_index));
  }
  return cal;
}

Calibration Calibration::starting_template() {
  Calibration calibration;
  calibration.max_forward = 0.3;
  calibration.max_reverse = 0.3;
  return calibration;
}

Calibration Calibration::load(const std::string& path) {
  try {
    return from_json(nlohmann::json(detail::read_json_file(path)), path);
  } catch (const Error& e) {
    if (e.code() == StatusCode::kNotFound) {
      fail(e.code(), "calibration file " + path + " cannot be opened: " + e.what());
    }
    throw;
  }
}

nlohmann::ordered_json Calibration::to_json() const {
  nlohmann::ordered_json throttle_json = channel_json(throttle, kThrottleNames);
  throttle_json["max_forward"] = max_forward;
  throttle_json["max_reverse"] = max_reverse;
  return {{"action_units", action_units == Units::kNormalized ? "normalized" : "microseconds"},
          {"steering", channel_json(steering, kSteeringNames)},
          {"throttle", throttle_json}};
}

PwmCommand Calibration::safe_command() const {
  return {static_cast<uint16_t>(steering.mid_us), static_cast<uint16_t>(throttle.mid_us)};
}

void Calibration::check_units(const ModelInfo& model) const {
  // Pulse widths are hundreds to thousands of microseconds; normalised actions are a few units at most.
  constexpr double kSmallestPulseScale = 100.0;
  for (const auto* ch : {&steering, &throttle}) {
    const size_t i = static_cast<size_t>(ch->action_index);
    if (i >= model.action_low.size() || i >= model.action_high.size()) continue;
    const double lo = model.action_low[i], hi = model.action_high[i];
    const double scale = std::max(std::fabs(lo), std::fabs(hi));
    char range[96];
    std::snprintf(range, sizeof range, "action %zu of the model spans about [%.4g, %.4g]", i, lo, hi);
    if (action_units == Units::kMicroseconds && scale < kSmallestPulseScale) {
      fail(StatusCode::kInvalidArgument, std::string("the calibration says \"action_units\": \"microseconds\", but ") +
           range + ": set \"action_units\": \"normalized\"");
    }
    if (action_units == Units::kNormalized && scale >= kSmallestPulseScale) {
      fail(StatusCode::kInvalidArgument, std::string("the calibration says \"action_units\": \"normalized\", but ") +
           range + " (pulse widths?): set \"action_units\": \"microseconds\"");
    }
  }
}

int Calibration::max_action_index() const { return std::max(steering.action_index, throttle.action_index); }

PwmCommand Calibration::map(std::span<const float> action) const {
  for (const ChannelCalibration* ch : {&steering, &throttle}) {
    if (!std::isfinite(action[static_cast<size_t>(ch->action_index)])) return safe_command();
  }
  auto normalized = [&](const ChannelCalibration& ch) {
    const double raw = action[static_cast<size_t>(ch.action_index)];
    double v = action_units == Units::kNormalized ? raw : normalized_from_us(raw, ch);
    v = std::clamp(v, -1.0, 1.0);
    return ch.invert ? -v : v;
  };
  const double steer = normalized(steering);
  const double throttle_value = std::clamp(normalized(throttle), -max_reverse, max_forward);
  return {us_from_normalized(steer, steering), us_from_normalized(throttle_value, throttle)};
}

double position_of(double us, const ChannelCalibration& ch) { return normalized_from_us(us, ch); }

PwmCommand Calibration::map_manual(double steering_value, double throttle_value) const {
  if (!std::isfinite(steering_value) || !std::isfinite(throttle_value)) return safe_command();
  return {us_from_normalized(std::clamp(steering_value, -1.0, 1.0), steering),
          us_from_normalized(std::clamp(throttle_value, -max_reverse, max_forward), throttle)};
}

std::vector<float> Calibration::action_of(PwmCommand command, int action_dim) const {
  std::vector<float> action(static_cast<size_t>(action_dim), 0.0f);
  for (const auto& [ch, us] : {std::pair{&steering, command.steering_us}, std::pair{&throttle, command.throttle_us}}) {
    if (ch->action_index >= action_dim) continue;
    double v = normalized_from_us(us, *ch);
    if (ch->invert) v = -v;
    action[static_cast<size_t>(ch->action_index)] =
        static_cast<float>(action_units == Units::kNormalized ? v : us_from_normalized(v, *ch));
  }
  return action;
}

RateLimiter::RateLimiter(const Calibration& calibration)
    : steering_rate_(calibration.steering.rate_limit_us_per_s),
      throttle_rate_(calibration.throttle.rate_limit_us_per_s),
      last_(calibration.safe_command()) {}

PwmCommand RateLimiter::step(PwmCommand target, double dt_s) {
  auto limit = [dt_s](uint16_t from, uint16_t to, double rate) {
    if (rate <= 0) return to;
    const double max_step = std::max(1.0, rate * dt_s);
    const double delta = std::clamp(static_cast<double>(to) - from, -max_step, max_step);
    return static_cast<uint16_t>(std::lround(from + delta));
  };
  last_ = {limit(last_.steering_us, target.steering_us, steering_rate_),
           limit(last_.throttle_us, target.throttle_us, throttle_rate_)};
  return last_;
}

}  // namespace act::drive
