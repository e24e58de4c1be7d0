// Actions -> PWM pulse widths for the rover's steering servo and ESC, from a JSON calibration file.
//
// The model's actions are, per channel, either "normalized" (-1 = full left / full reverse,
// 0 = center / neutral, +1 = full right / full forward) or "microseconds" (pulse widths, as recorded
// from the same car). Either way they become a normalized value, are clamped, inverted when asked,
// capped (throttle), mapped piecewise-linearly onto the endpoints, then rate-limited.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "actengine/engine.h"

namespace act::drive {

/// One command to the board: pulse widths in microseconds.
struct PwmCommand {
  uint16_t steering_us = 1500;
  uint16_t throttle_us = 1500;
  bool operator==(const PwmCommand&) const = default;
};

/// One output channel. For steering low/mid/high are left/center/right, for throttle
/// reverse/neutral/forward. `mid` lies strictly between `low` and `high` (either order).
struct ChannelCalibration {
  int action_index = 0;              ///< which action value drives this channel
  int low_us = 1000, mid_us = 1500, high_us = 2000;
  bool invert = false;               ///< flip the direction (a model trained on a mirrored car)
  double rate_limit_us_per_s = 0;    ///< largest change of the pulse width per second; 0 = unlimited
};

struct Calibration {
  enum class Units { kNormalized, kMicroseconds };
  Units action_units = Units::kNormalized;
  ChannelCalibration steering{0, 1000, 1500, 2000, false, 0};
  ChannelCalibration throttle{1, 1000, 1500, 2000, false, 0};
  double max_forward = 1.0;  ///< throttle cap, a fraction of full forward (0..1)
  double max_reverse = 1.0;  ///< throttle cap, a fraction of full reverse (0..1)

  /// Where every calibration starts before its endpoints are measured (`act_drive --calibrate`'s
  /// template, the package's drive_calibration.json, --raw-endpoints and --dry-run without a file):
  /// 1000/1500/2000 us endpoints with the throttle capped at 0.3 of full either way, so that a
  /// wrong guess cannot launch the car.
  static Calibration starting_template();
  /// Parses and validates; throws act::Error naming `source` and the offending field. Fields whose
  /// name starts with '_' are comments; any other unknown field is an error (a typo must not fall
  /// back to a default silently).
  static Calibration from_json(const nlohmann::json& json, const std::string& source);
  /// Reads a calibration file; throws act::Error (missing file, bad JSON, bad field).
  static Calibration load(const std::string& path);
  nlohmann::ordered_json to_json() const;

  /// Center steering, neutral throttle: what the rover holds whenever anything is wrong.
  PwmCommand safe_command() const;
  /// The pulse widths for one raw action (no rate limit). A NaN or infinite value in a channel's
  /// action gives safe_command(): this is the last step before the wire, and a non-finite number
  /// must never become a pulse width (it once became "$C,10,0,0").
  PwmCommand map(std::span<const float> action) const;
  /// A human's command (a stick or the web page): -1 = full left / full reverse, +1 = full right /
  /// full forward on this car (so `invert`, which is about the model, does not apply); clamped and
  /// throttle-capped like map(). Non-finite values give safe_command().
  PwmCommand map_manual(double steering_value, double throttle_value) const;
  /// The raw action (action_dim values, in the model's units, zeros where no channel reads) that
  /// map() would turn into `command`: what was actually executed, as a training target.
  std::vector<float> action_of(PwmCommand command, int action_dim) const;
  /// The largest action index used (to check against the model's action_dim).
  int max_action_index() const;
  /// Throws act::Error(kInvalidArgument) when action_units cannot be the units of the model's
  /// actions (ModelInfo::action_low/high): "microseconds" for a model whose actions span about
  /// [-1, 1], or "normalized" for one whose actions are pulse widths. Either would drive at full lock.
  void check_units(const ModelInfo& model) const;
};

/// Where a pulse width lies on its channel: -1 at low_us (full left / reverse), 0 at mid_us, +1 at
/// high_us (unclamped).
double position_of(double us, const ChannelCalibration& ch);

/// Limits how fast each pulse width may change between control ticks (calibration rate limits).
class RateLimiter {
 public:
  explicit RateLimiter(const Calibration& calibration);
  /// Moves from the last output towards `target` by at most rate * dt_s per channel.
  PwmCommand step(PwmCommand target, double dt_s);
  /// Jumps to `command` (safe actions are never rate-limited).
  void reset(PwmCommand command) { last_ = command; }

 private:
  double steering_rate_, throttle_rate_;
  PwmCommand last_;
};

}  // namespace act::drive
