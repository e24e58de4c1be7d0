// The one HTML report of the apps: act_eval --report (an episode's evaluation) and act_convert
// --report (an INT8 conversion). A single self-contained file: inline SVG charts and inline CSS, no
// script, no network access.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

namespace act::eval {

/// Renders what `report` holds: "episode" (EpisodeEvaluation::to_json, with "episode_path" and
/// "episode_kind"): actions over time per dimension, the error histogram and per-frame errors;
/// "int8" (Int8Report::to_json, with "calibration_sources"): calibration settings, per-layer SQNR
/// with the layers kept in float marked, the calibrated activations. "title" heads the page.
std::string render_html_report(const nlohmann::ordered_json& report);

}  // namespace act::eval
