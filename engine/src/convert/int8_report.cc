// Int8Report as JSON (act_convert --report) and as the text act_convert prints, and its notes.
#include <algorithm>
#include <cstdio>
#include <sstream>
#include <string>
#include <utility>

#include <nlohmann/json.hpp>

#include "actengine/convert.h"
#include "engine/src/convert/int8_converter.h"

namespace act {

std::string format_number(double v, const char* printf_format) {
  char buf[64];
  std::snprintf(buf, sizeof buf, printf_format, v);
  return buf;
}

namespace {

nlohmann::json action_error_json(const ActionError& e) {
  return {{"mse", e.mse},
          {"max_abs", e.max_abs},
          {"mse_physical", e.mse_physical},
          {"max_abs_physical", e.max_abs_physical},
          {"per_dim_mse", e.per_dim_mse},
          {"per_dim_max_abs", e.per_dim_max_abs},
          {"per_dim_mse_physical", e.per_dim_mse_physical},
          {"per_dim_max_abs_physical", e.per_dim_max_abs_physical}};
}

}  // namespace

// Whether the held-out error is good, from the largest normalised |err| of INT8 against FP32 (a
// normalised unit: a training standard deviation, or half the range). 0.05 is what static
// calibration with --calib-method mse reaches on the checkpoints docs/int8.md lists.
std::string Int8Report::verdict() const {
  const ActionError& e = action_error;
  char text[512];
  if (e.max_abs <= 0.05) {
    std::snprintf(text, sizeof text, "good: INT8's held-out actions are within %.3g of FP32's (max |err|, normalised; "
                  "0.05 or less is good); confirm on an episode: act_eval --episode ... -m fp32.actb -m int8.actb", e.max_abs);
  } else if (e.max_abs <= 0.2) {
    std::snprintf(text, sizeof text, "check: max |err| %.3g normalised is above 0.05: compare on an episode with act_eval "
                  "--episode (--max-added-error), or try --mode mixed --target-mse", e.max_abs);
  } else {
    std::snprintf(text, sizeof text, "poor: max |err| %.3g normalised (above 0.2): try more calibration frames from the "
                  "robot's camera, --mode mixed --target-mse, or --precision fp32", e.max_abs);
  }
  return text;
}

void Int8Report::note_frames_given(size_t given, size_t calib_samples) {
  const size_t used = calibration_frames + holdout_frames;
  std::string note = std::to_string(given) + " frames given, " + std::to_string(calibration_frames) +
                     " used for calibration, " + std::to_string(holdout_frames) + " held out";
  if (given > used) {
    note += ", " + std::to_string(given - used) + " left out (--calib-samples " + std::to_string(calib_samples) +
            " sets how many are used)";
  }
  notes.insert(notes.begin(), std::move(note));
}

std::string Int8Report::to_json() const {
  nlohmann::json r;
  r["mode"] = int8_mode_name(mode);
  r["calibration"] = calibration;
  r["calibration_frames"] = calibration_frames;
  r["holdout_frames"] = holdout_frames;
  r["preprocessing"] = preprocessing;
  r["notes"] = notes;
  r["fp32_bytes"] = fp32_bytes;
  r["int8_bytes"] = int8_bytes;
  r["float_layers"] = float_layers;
  r["attention"] = {{"precision", int8_attention ? "int8" : "fp32"}};
  if (fp32_attention_error) r["attention"]["fp32_action_error"] = action_error_json(*fp32_attention_error);
  if (int8_attention_error) r["attention"]["int8_action_error"] = action_error_json(*int8_attention_error);
  r["linear_inputs"] = nlohmann::json::array();
  for (const auto& l : linear_inputs) {
    r["linear_inputs"].push_back({{"value", l.value},
                                  {"reader", l.reader},
                                  {"ffn", l.ffn},
                                  {"codes", l.per_tensor ? "per_tensor" : "per_token"},
                                  {"scale", l.scale},
                                  {"zero_point", l.zero_point},
                                  {"sqnr_per_tensor_db", l.sqnr_per_tensor_db},
                                  {"sqnr_per_token_db", l.sqnr_per_token_db}});
  }
  if (per_token_inputs_error) r["linear_inputs_per_token_error"] = action_error_json(*per_token_inputs_error);
  if (chosen_inputs_error) r["linear_inputs_chosen_error"] = action_error_json(*chosen_inputs_error);
  r["action_error"] = action_error_json(action_error);
  r["action_keys"] = action_keys;
  if (!sensitivity.empty()) {
    r["sensitivity"] = nlohmann::json::array();
    for (const auto& s : sensitivity) r["sensitivity"].push_back({{"layer", s.layer}, {"mse_alone_int8", s.mse_alone_int8}});
  }
  r["layers"] = nlohmann::json::array();
  for (const auto& l : layers) {
    r["layers"].push_back({{"layer", l.layer}, {"value", l.value}, {"op", l.op}, {"kept_float", l.kept_float}, {"sqnr_db", l.sqnr_db}});
  }
  r["activations"] = nlohmann::json::array();
  for (const auto& a : activations) {
    r["activations"].push_back({{"value", a.value},
                                {"scale", a.scale},
                                {"zero_point", a.zero_point},
                                {"quantized_range", {a.quantized_min(), a.quantized_max()}},
                                {"observed_range", {a.observed_min, a.observed_max}}});
  }
  r["verdict"] = verdict();
  r["seconds"] = seconds;
  return r.dump(2);
}

std::string Int8Report::to_text() const {
  std::ostringstream s;
  s << "INT8 " << int8_mode_name(mode);
  if (!calibration.empty()) s << ", calibration " << calibration;
  s << ": " << calibration_frames << " calibration frames, " << holdout_frames << " held out\n";
  s << "preprocessing  " << preprocessing << "\n";
  const double fp = static_cast<double>(fp32_bytes), q = static_cast<double>(int8_bytes);
  s << "size           fp32 " << format_number(fp / 1e6, "%.1f") << " MB -> int8 " << format_number(q / 1e6, "%.1f")
    << " MB (" << format_number(100.0 * q / fp, "%.1f") << " %)\n";
  const ActionError& e = action_error;
  s << "held-out error normalised: MSE " << format_number(e.mse) << ", max |err| " << format_number(e.max_abs)
    << "; physical: MSE " << format_number(e.mse_physical) << ", max |err| " << format_number(e.max_abs_physical) << "\n";
  s << "per action dim (normalised MSE / max | physical MSE / max):\n";
  for (size_t a = 0; a < e.per_dim_mse.size(); ++a) {
    s << "  [" << a << "] " << format_number(e.per_dim_mse[a]) << " / " << format_number(e.per_dim_max_abs[a]) << " | "
      << format_number(e.per_dim_mse_physical[a]) << " / " << format_number(e.per_dim_max_abs_physical[a]) << "\n";
  }
  s << "attention      " << (int8_attention ? "int8" : "fp32");
  if (fp32_attention_error && int8_attention_error) {
    s << " (held-out MSE " << format_number(int8_attention_error->mse) << ", max |err| "
      << format_number(int8_attention_error->max_abs) << " with int8 attention; " << format_number(fp32_attention_error->mse)
      << ", " << format_number(fp32_attention_error->max_abs) << " with float)";
  }
  s << "\n";
  if (!linear_inputs.empty()) {
    const auto per_tensor = std::count_if(linear_inputs.begin(), linear_inputs.end(), [](const auto& l) { return l.per_tensor; });
    const auto tried = std::count_if(linear_inputs.begin(), linear_inputs.end(), [](const auto& l) { return l.ffn >= 0; });
    s << "linear inputs  " << per_tensor << " of " << linear_inputs.size() << " with calibrated per-tensor codes (" << tried
      << " tried: the FFNs' hidden activations), the rest per token";
    if (per_token_inputs_error && chosen_inputs_error) {
      s << " (held-out MSE " << format_number(chosen_inputs_error->mse) << ", max |err| "
        << format_number(chosen_inputs_error->max_abs) << "; all per token " << format_number(per_token_inputs_error->mse) << ", "
        << format_number(per_token_inputs_error->max_abs) << ")";
    }
    s << "\n  codes        SQNR dB per tensor / per token (estimated)  value\n";
    for (const auto& l : linear_inputs) {
      s << "  " << (l.per_tensor ? "per tensor" : "per token ") << "   " << format_number(l.sqnr_per_tensor_db, "%6.1f")
        << " / " << format_number(l.sqnr_per_token_db, "%6.1f") << "                           " << l.value
        << (l.ffn >= 0 ? " (FFN " + std::to_string(l.ffn) + ")" : "") << "\n";
    }
  }
  s << "layers in float " << (float_layers.empty() ? "none (besides the action head and state projections, always float)" : "")
    << "\n";
  for (const auto& l : float_layers) s << "  " << l << "\n";
  s << "per-layer SQNR (dB, int8 vs fp32 output; layers named as float_layers and --keep-float name them):\n";
  for (const auto& l : layers) {
    s << "  " << format_number(l.sqnr_db, "%6.1f") << "  " << l.layer << " (" << l.value << ", " << l.op
      << (l.kept_float ? ", kept in float" : "") << ")\n";
  }
  for (const auto& n : notes) s << (n.rfind("warning: ", 0) == 0 ? "" : "note: ") << n << "\n";
  s << "verdict        " << verdict() << "\n";
  return s.str();
}

}  // namespace act
