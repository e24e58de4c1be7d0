#include "apps/eval/html_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <vector>

namespace act::eval {

namespace {

using Json = nlohmann::ordered_json;

// Colours of the demonstration and of the models, in order.
constexpr const char* kDemonstrationColour = "#222222";
const std::vector<const char*> kModelColours = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e"};

const char* model_colour(size_t m) { return kModelColours[m % kModelColours.size()]; }

std::string escape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

// A number for people; NaN and null (a non-finite value in the JSON) read "non-finite".
std::string num(const Json& v) {
  if (!v.is_number()) return "non-finite";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v.get<double>());
  return buf;
}
std::string num(double v) { return std::isfinite(v) ? num(Json(v)) : "non-finite"; }

double value_or_nan(const Json& v) { return v.is_number() ? v.get<double>() : std::nan(""); }

struct Series {
  std::string name;
  const char* colour;
  std::vector<double> values;
};

constexpr int kWidth = 760, kHeight = 220, kLeft = 60, kRight = 10, kTop = 10, kBottom = 30;

// Lower and upper bounds of the finite values (a flat series gets some room).
std::pair<double, double> bounds(const std::vector<Series>& series) {
  double lo = INFINITY, hi = -INFINITY;
  for (const auto& s : series) {
    for (double v : s.values) {
      if (std::isfinite(v)) {
        lo = std::min(lo, v);
        hi = std::max(hi, v);
      }
    }
  }
  if (!std::isfinite(lo)) return {0, 1};
  if (hi - lo < 1e-12) return {lo - 0.5, hi + 0.5};
  return {lo, hi};
}

std::string axes(double y_lo, double y_hi, const std::string& x_label) {
  std::ostringstream s;
  const int bottom = kHeight - kBottom;
  s << "<line x1='" << kLeft << "' y1='" << kTop << "' x2='" << kLeft << "' y2='" << bottom << "' stroke='#888'/>"
    << "<line x1='" << kLeft << "' y1='" << bottom << "' x2='" << kWidth - kRight << "' y2='" << bottom << "' stroke='#888'/>"
    << "<text x='" << kLeft - 4 << "' y='" << kTop + 10 << "' text-anchor='end' font-size='10'>" << num(y_hi) << "</text>"
    << "<text x='" << kLeft - 4 << "' y='" << bottom << "' text-anchor='end' font-size='10'>" << num(y_lo) << "</text>"
    << "<text x='" << (kLeft + kWidth) / 2 << "' y='" << kHeight - 8 << "' text-anchor='middle' font-size='11'>"
    << escape(x_label) << "</text>";
  return s.str();
}

std::string legend(const std::vector<Series>& series) {
  std::ostringstream s;
  s << "<div class='legend'>";
  for (const auto& item : series) {
    s << "<span><i style='background:" << item.colour << "'></i>" << escape(item.name) << "</span>";
  }
  s << "</div>";
  return s.str();
}

// Lines over the index (a non-finite value breaks its line). The first series is drawn on top: the
// series are drawn last to first, each wider and paler than the one before it, so the demonstration
// and the reference model (FP32) stay visible over the models that follow it (INT8).
std::string line_chart(const std::vector<Series>& series, const std::string& x_label, const std::string& css_class) {
  const auto [lo, hi] = bounds(series);
  size_t n = 0;
  for (const auto& s : series) n = std::max(n, s.values.size());
  const double plot_w = kWidth - kLeft - kRight, plot_h = kHeight - kTop - kBottom;
  std::ostringstream s;
  s << "<svg class='chart " << css_class << "' width='" << kWidth << "' height='" << kHeight << "' viewBox='0 0 " << kWidth
    << " " << kHeight << "'>" << axes(lo, hi, x_label);
  for (size_t k = series.size(); k-- > 0;) {
    const Series& item = series[k];
    char style[96];
    std::snprintf(style, sizeof style, "stroke-width='%.1f' stroke-opacity='%.2f'", 1.5 + 2.0 * static_cast<double>(k),
                  k == 0 ? 1.0 : 0.7);
    s << "<path fill='none' " << style << " stroke='" << item.colour << "' d='";
    bool pen_down = false;
    for (size_t i = 0; i < item.values.size(); ++i) {
      const double v = item.values[i];
      if (!std::isfinite(v)) {
        pen_down = false;
        continue;
      }
      const double x = kLeft + (n > 1 ? plot_w * static_cast<double>(i) / static_cast<double>(n - 1) : plot_w / 2);
      const double y = kTop + plot_h * (hi - v) / (hi - lo);
      char point[64];
      std::snprintf(point, sizeof point, "%c%.1f %.1f ", pen_down ? 'L' : 'M', x, y);
      s << point;
      pen_down = true;
    }
    s << "'/>";
  }
  s << "</svg>" << legend(series);
  return s.str();
}

// Histograms of the series' values over shared bins, side by side in each bin.
std::string histogram(const std::vector<Series>& series, const std::string& x_label) {
  constexpr int kBins = 40;
  const auto [lo, hi] = bounds(series);
  std::vector<std::vector<size_t>> counts(series.size(), std::vector<size_t>(kBins));
  size_t most = 1;
  for (size_t k = 0; k < series.size(); ++k) {
    for (double v : series[k].values) {
      if (!std::isfinite(v)) continue;
      const int bin = std::clamp(static_cast<int>((v - lo) / (hi - lo) * kBins), 0, kBins - 1);
      most = std::max(most, ++counts[k][static_cast<size_t>(bin)]);
    }
  }
  const double plot_w = kWidth - kLeft - kRight, plot_h = kHeight - kTop - kBottom;
  const double bin_w = plot_w / kBins, bar_w = bin_w / static_cast<double>(std::max<size_t>(series.size(), 1));
  std::ostringstream s;
  s << "<svg class='chart histogram' width='" << kWidth << "' height='" << kHeight << "' viewBox='0 0 " << kWidth << " "
    << kHeight << "'>" << axes(0, static_cast<double>(most), x_label + " (from " + num(lo) + " to " + num(hi) + ")");
  for (size_t k = 0; k < series.size(); ++k) {
    for (int b = 0; b < kBins; ++b) {
      const double h = plot_h * static_cast<double>(counts[k][static_cast<size_t>(b)]) / static_cast<double>(most);
      if (h <= 0) continue;
      char rect[160];
      std::snprintf(rect, sizeof rect, "<rect x='%.1f' y='%.1f' width='%.1f' height='%.1f' fill='%s'/>",
                    kLeft + b * bin_w + static_cast<double>(k) * bar_w, kTop + plot_h - h, bar_w, h, series[k].colour);
      s << rect;
    }
  }
  s << "</svg>" << legend(series);
  return s.str();
}

std::string model_label(const Json& model) {
  return model.value("precision", std::string()) + " (" + model.value("path", std::string()) + ")";
}

// Each model's error against the demonstration (and the first model's), the baselines beside the
// first model, and the per-dimension errors.
void error_tables(std::ostringstream& out, const Json& r) {
  const std::vector<std::string> names = r["action_names"];
  const Json& models = r["models"];
  out << "<h2>Error against the demonstration</h2><table><tr><th>model</th><th>first action MSE (raw)</th>"
         "<th>first action max |err| (raw)</th><th>chunk MSE (normalised)</th><th>chunk max |err| (normalised)</th>"
         "<th>against the first model: chunk MSE (normalised)</th><th>error added, % of the first model's own</th></tr>";
  for (const auto& m : models) {
    const Json& demo = m["vs_demonstration"];
    out << "<tr><td>" << escape(model_label(m)) << "</td><td>" << num(demo["first_action"]["raw"]["mse"]) << "</td><td>"
        << num(demo["first_action"]["raw"]["max_abs"]) << "</td><td>" << num(demo["chunk"]["normalised"]["mse"]) << "</td><td>"
        << num(demo["chunk"]["normalised"]["max_abs"]) << "</td><td>"
        << (m.contains("vs_reference") ? num(m["vs_reference"]["chunk"]["normalised"]["mse"]) : "(reference)") << "</td><td>"
        << (m.contains("added_error_fraction") ? (m["added_error_fraction"].is_number()
                                                   ? num(100 * m["added_error_fraction"].get<double>()) + " %"
                                                   : num(m["added_error_fraction"]))
                                                : "")
        << "</td></tr>";
  }
  if (r.contains("baselines") && !models.empty()) {
    out << "</table><h3>Baselines (no policy), beside the first model</h3><table><tr><th>baseline</th>"
           "<th>chunk MSE (normalised)</th><th>first action MSE (raw)</th><th>the first model's chunk MSE (normalised)</th></tr>";
    for (const auto& b : r["baselines"]) {
      out << "<tr><td>" << escape(b["name"].get<std::string>()) << " (" << escape(b["description"].get<std::string>())
          << ")</td><td>" << num(b["vs_demonstration"]["chunk"]["normalised"]["mse"]) << "</td><td>"
          << num(b["vs_demonstration"]["first_action"]["raw"]["mse"]) << "</td><td>"
          << num(models[0]["vs_demonstration"]["chunk"]["normalised"]["mse"]) << "</td></tr>";
    }
  }
  out << "</table><h3>Per action dimension (first action, raw MSE against the demonstration)</h3><table><tr><th>model</th>";
  for (const auto& name : names) out << "<th>" << escape(name) << "</th>";
  out << "</tr>";
  for (const auto& m : models) {
    out << "<tr><td>" << escape(model_label(m)) << "</td>";
    for (const auto& name : names) out << "<td>" << num(m["vs_demonstration"]["first_action"]["raw"]["per_dimension"][name]["mse"]) << "</td>";
    out << "</tr>";
  }
  out << "</table>";
}

// The first actions over time against the demonstration, per dimension; then the errors' histogram
// and their course over the frames.
void action_and_error_charts(std::ostringstream& out, const Json& r) {
  const std::vector<std::string> names = r["action_names"];
  const std::vector<double> low = r["action_low"], high = r["action_high"];
  const Json& models = r["models"];
  const Json& per_frame = r["per_frame"];
  out << "<h2>Actions over time (first action of each chunk, raw units)</h2>";
  const Json& demonstration = per_frame["demonstration"];
  for (size_t d = 0; d < names.size(); ++d) {
    std::vector<Series> series{{"demonstration", kDemonstrationColour, {}}};
    for (const auto& row : demonstration) series[0].values.push_back(value_or_nan(row[d]));
    for (size_t m = 0; m < models.size(); ++m) {
      series.push_back({model_label(models[m]), model_colour(m), {}});
      for (const auto& row : per_frame["models"][m]["first_action"]) series.back().values.push_back(value_or_nan(row[d]));
    }
    out << "<h3>" << escape(names[d]) << "</h3>" << line_chart(series, "frame", "actions");
  }

  // Per-value first-action errors, normalised so that every dimension counts alike.
  std::vector<Series> errors, frame_errors;
  for (size_t m = 0; m < models.size(); ++m) {
    errors.push_back({model_label(models[m]), model_colour(m), {}});
    const Json& predicted = per_frame["models"][m]["first_action"];
    for (size_t f = 0; f < predicted.size(); ++f) {
      for (size_t d = 0; d < names.size(); ++d) {
        const double half = d < low.size() && high[d] > low[d] ? (high[d] - low[d]) / 2 : 1.0;
        errors.back().values.push_back((value_or_nan(predicted[f][d]) - value_or_nan(demonstration[f][d])) / half);
      }
    }
    frame_errors.push_back({model_label(models[m]), model_colour(m), {}});
    for (const auto& e : per_frame["models"][m]["error"]) frame_errors.back().values.push_back(value_or_nan(e));
  }
  out << "<h2>Error histogram (first action minus demonstration, normalised units)</h2>"
      << histogram(errors, "error") << "<h2>Error per frame (first action MSE, normalised)</h2>"
      << line_chart(frame_errors, "frame", "frame-errors");
}

void worst_frames(std::ostringstream& out, const Json& r) {
  const Json& models = r["models"];
  const Json& per_frame = r["per_frame"];
  // The worst frames of the first model, with their sources, so a person can look at them.
  const Json& first_errors = per_frame["models"][0]["error"];
  std::vector<size_t> order(first_errors.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  const auto error_of = [&](size_t i) { const double e = value_or_nan(first_errors[i]); return std::isfinite(e) ? e : INFINITY; };
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return error_of(a) > error_of(b); });
  order.resize(std::min<size_t>(order.size(), 20));
  out << "<h3>Frames with the largest error (first model)</h3><table><tr><th>frame</th><th>source</th>";
  for (const auto& m : models) out << "<th>" << escape(model_label(m)) << "</th>";
  out << "</tr>";
  for (size_t f : order) {
    out << "<tr><td>" << f << "</td><td>" << escape(per_frame["source"][f].get<std::string>()) << "</td>";
    for (size_t m = 0; m < models.size(); ++m) out << "<td>" << num(per_frame["models"][m]["error"][f]) << "</td>";
    out << "</tr>";
  }
  out << "</table>";
}

void episode_section(std::ostringstream& out, const Json& r) {
  out << "<h2>Episode</h2><table>"
      << "<tr><th>episode</th><td>" << escape(r.value("episode_path", std::string())) << " ("
      << escape(r.value("episode_kind", std::string())) << ")</td></tr>"
      << "<tr><th>frames</th><td>" << r["frames"].get<size_t>() << "</td></tr></table>";
  for (const auto& note : r.value("notes", std::vector<std::string>())) out << "<p class='note'>note: " << escape(note) << "</p>";

  error_tables(out, r);
  action_and_error_charts(out, r);
  worst_frames(out, r);
}

void int8_section(std::ostringstream& out, const Json& r) {
  out << "<h2>Quantization</h2><table>"
      << "<tr><th>mode</th><td>" << escape(r.value("mode", std::string())) << "</td></tr>"
      << "<tr><th>calibration method</th><td>" << escape(r.value("calibration", std::string())) << "</td></tr>"
      << "<tr><th>calibration frames</th><td>" << r.value("calibration_frames", 0) << " (" << r.value("holdout_frames", 0)
      << " more held out for the error below)</td></tr>"
      << "<tr><th>frames from</th><td>";
  for (const auto& source : r.value("calibration_sources", std::vector<std::string>())) out << escape(source) << "<br>";
  out << "</td></tr><tr><th>preprocessing</th><td>" << escape(r.value("preprocessing", std::string())) << "</td></tr>"
      << "<tr><th>attention</th><td>" << escape(r["attention"].value("precision", std::string())) << "</td></tr>"
      << "<tr><th>size</th><td>fp32 " << r.value("fp32_bytes", 0) << " bytes, int8 " << r.value("int8_bytes", 0) << " bytes</td></tr>";
  const Json& e = r["action_error"];
  out << "<tr><th>held-out error (INT8 against FP32)</th><td>normalised MSE " << num(e["mse"]) << ", max |err| " << num(e["max_abs"])
      << "; raw MSE " << num(e["mse_physical"]) << ", max |err| " << num(e["max_abs_physical"]) << "</td></tr>";
  if (r.contains("verdict")) out << "<tr><th>verdict</th><td>" << escape(r["verdict"].get<std::string>()) << "</td></tr>";
  out << "</table>";
  // Per action dimension, named when act_convert was given --action-names.
  const std::vector<double> dim_mse = e.value("per_dim_mse", std::vector<double>());
  const std::vector<std::string> names = r.value("action_names", std::vector<std::string>());
  if (!dim_mse.empty()) {
    out << "<h3>Held-out error per action dimension (INT8 against FP32)</h3><table><tr><th>action</th>"
           "<th>MSE (normalised)</th><th>max |err| (normalised)</th><th>MSE (raw)</th><th>max |err| (raw)</th></tr>";
    for (size_t a = 0; a < dim_mse.size(); ++a) {
      const auto cell = [&](const char* key) { return e.contains(key) && a < e[key].size() ? num(e[key][a]) : std::string(); };
      // (appended, not "[" + ...: GCC 12's -Wrestrict misreads the inlined insert of operator+)
      const std::string name = a < names.size() ? names[a] : std::string("[").append(std::to_string(a)).append("]");
      out << "<tr><td>" << escape(name) << "</td><td>"
          << cell("per_dim_mse") << "</td><td>" << cell("per_dim_max_abs") << "</td><td>" << cell("per_dim_mse_physical")
          << "</td><td>" << cell("per_dim_max_abs_physical") << "</td></tr>";
    }
    out << "</table>";
  }
  for (const auto& note : r.value("notes", std::vector<std::string>())) out << "<p class='note'>" << escape(note) << "</p>";

  const std::vector<std::string> float_layers = r.value("float_layers", std::vector<std::string>());
  const Json& layers = r["layers"];
  if (layers.empty()) return;
  // One bar per layer, its length the SQNR (capped at 60 dB so that exact layers do not squash the rest).
  constexpr double kMaxDb = 60;
  constexpr int kRow = 16, kLabel = 300, kBarWidth = 380;
  const int height = kRow * static_cast<int>(layers.size()) + 30;
  out << "<h2>Per-layer SQNR (dB, INT8 output against FP32; longer is better)</h2>"
      << "<div class='legend'><span><i style='background:#1f77b4'></i>int8</span><span><i style='background:#ff7f0e'></i>kept in float</span></div>"
      << "<svg class='chart sqnr' width='" << kLabel + kBarWidth + 60 << "' height='" << height << "'>";
  for (size_t i = 0; i < layers.size(); ++i) {
    const Json& layer = layers[i];
    const std::string name = layer.value("layer", std::string());
    const bool kept_float = layer.value("kept_float", false);
    const double db = value_or_nan(layer["sqnr_db"]);
    const double w = std::isfinite(db) ? std::clamp(db, 0.0, kMaxDb) / kMaxDb * kBarWidth : 0;
    const int y = static_cast<int>(i) * kRow + 4;
    char bar[200];
    std::snprintf(bar, sizeof bar, "<rect x='%d' y='%d' width='%.1f' height='%d' fill='%s'/>", kLabel, y, w, kRow - 4,
                  kept_float ? "#ff7f0e" : "#1f77b4");
    out << "<text x='" << kLabel - 6 << "' y='" << y + 10 << "' text-anchor='end' font-size='10'>" << escape(name)
        << (kept_float ? " (float)" : "") << "</text>" << bar << "<text x='" << kLabel + w + 4 << "' y='" << y + 10
        << "' font-size='10'>" << num(layer["sqnr_db"]) << "</text>";
  }
  out << "</svg>";
  if (!float_layers.empty()) {
    out << "<h3>Layers kept in float</h3><ul>";
    for (const auto& l : float_layers) out << "<li>" << escape(l) << "</li>";
    out << "</ul>";
  }
  const Json& activations = r.contains("activations") ? r["activations"] : Json::array();
  if (activations.empty()) return;
  out << "<h2>Calibrated activations</h2><table><tr><th>value</th><th>scale</th><th>zero point</th>"
         "<th>int8 range</th><th>range on the calibration frames</th></tr>";
  for (const auto& a : activations) {
    out << "<tr><td>" << escape(a.value("value", std::string())) << "</td><td>" << num(a["scale"]) << "</td><td>"
        << a.value("zero_point", 0) << "</td><td>" << num(a["quantized_range"][0]) << " .. " << num(a["quantized_range"][1])
        << "</td><td>" << num(a["observed_range"][0]) << " .. " << num(a["observed_range"][1]) << "</td></tr>";
  }
  out << "</table>";
}

}  // namespace

std::string render_html_report(const Json& report) {
  std::ostringstream out;
  const std::string title = report.value("title", std::string("actengine report"));
  out << "<!DOCTYPE html><html><head><meta charset='utf-8'><title>" << escape(title) << "</title><style>"
      << "body{font-family:sans-serif;margin:20px;max-width:1000px}table{border-collapse:collapse;margin:8px 0}"
         "td,th{border:1px solid #ccc;padding:3px 6px;font-size:13px;text-align:left}.chart{background:#fff;display:block}"
         ".legend span{margin-right:14px;font-size:12px}.legend i{display:inline-block;width:12px;height:12px;margin-right:4px}"
         ".note{color:#555;font-size:13px}"
      << "</style></head><body><h1>" << escape(title) << "</h1>";
  if (report.contains("episode")) episode_section(out, report["episode"]);
  if (report.contains("int8")) int8_section(out, report["int8"]);
  out << "</body></html>\n";
  return out.str();
}

}  // namespace act::eval
