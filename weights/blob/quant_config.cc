#include "weights/blob/quant_config.h"

#include <cfloat>
#include <cmath>
#include <cstdio>

#include "actengine/status.h"
#include "weights/blob/file_util.h"

namespace act {

const char* quant_mode_name(QuantMode mode) {
  switch (mode) {
    case QuantMode::kDynamic: return "dynamic";
    case QuantMode::kStatic: return "static";
    case QuantMode::kMixed: return "mixed";
  }
  return "?";
}

const ActivationQuant& QuantConfig::activation(const std::string& value_name) const {
  const auto it = activations.find(value_name);
  if (it == activations.end()) {
    fail(StatusCode::kDataLoss, "the blob has no quantization parameters for activation \"" + value_name + "\"");
  }
  return it->second;
}

nlohmann::json QuantConfig::to_json() const {
  nlohmann::json j;
  j["mode"] = quant_mode_name(mode);
  j["calibration"] = calibration;
  j["activations"] = nlohmann::json::object();
  for (const auto& [name, q] : activations) j["activations"][name] = {q.scale, q.zero_point};
  j["float_layers"] = float_layers;
  j["attention"] = int8_attention ? "int8" : "fp32";
  return j;
}

namespace {

// [scale, zero_point] of activation `name`, range-checked: the scale's inverse quantizes every
// value of that activation, so an implausible one is damage, not a model.
ActivationQuant activation_from_json(const std::string& name, const nlohmann::json& v) {
  ActivationQuant q{};
  const std::string where = "bad quantization parameters for activation \"" + name + "\"";
  if (!v.is_array() || v.size() != 2 || !detail::json_to_f32(v.at(0), &q.scale) || !detail::json_to_i32(v.at(1), &q.zero_point)) {
    fail(StatusCode::kDataLoss, where + ": expected [scale, zero point], got " + v.dump().substr(0, 80));
  }
  if (!(q.scale >= FLT_MIN && q.scale <= kMaxActivationScale)) {
    char range[96];
    std::snprintf(range, sizeof range, "scale %g is outside [%g, %g]", static_cast<double>(q.scale), static_cast<double>(FLT_MIN),
                  static_cast<double>(kMaxActivationScale));
    fail(StatusCode::kDataLoss, where + ": " + range);
  }
  if (q.zero_point < -128 || q.zero_point > 127) {
    fail(StatusCode::kDataLoss, where + ": zero point " + std::to_string(q.zero_point) + " is outside [-128, 127]");
  }
  return q;
}

}  // namespace

QuantConfig QuantConfig::from_json(const nlohmann::json& j) {
  QuantConfig c;
  try {
    const std::string mode = j.at("mode").get<std::string>();
    if (mode == "dynamic") {
      c.mode = QuantMode::kDynamic;
    } else if (mode == "static") {
      c.mode = QuantMode::kStatic;
    } else if (mode == "mixed") {
      c.mode = QuantMode::kMixed;
    } else {
      fail(StatusCode::kDataLoss, "unknown quantization mode \"" + mode + "\"");
    }
    c.calibration = j.value("calibration", "");
    for (const auto& [name, v] : j.at("activations").items()) {
      c.activations[name] = activation_from_json(name, v);
    }
    c.float_layers = j.at("float_layers").get<std::vector<std::string>>();
    const std::string attention = j.value("attention", "fp32");
    if (attention != "int8" && attention != "fp32") {
      fail(StatusCode::kDataLoss, "unknown attention precision \"" + attention + "\" (int8 or fp32)");
    }
    c.int8_attention = attention == "int8";
  } catch (const nlohmann::json::exception& e) {
    fail(StatusCode::kDataLoss, std::string("malformed quantization section: ") + e.what());
  }
  return c;
}

}  // namespace act
