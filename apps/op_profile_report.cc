#include "apps/op_profile_report.h"

#include <algorithm>
#include <map>

namespace act {
namespace {

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : (v[n / 2 - 1] + v[n / 2]) / 2;
}

void set_rates(OpProfileRow& row, double total_ms, double peak_gmacs_per_s) {
  row.percent = total_ms > 0 ? 100.0 * row.mean_ms / total_ms : 0.0;
  row.gmacs_per_s = row.p50_ms > 0 ? row.macs / (row.p50_ms * 1e6) : 0.0;
  row.percent_of_peak = peak_gmacs_per_s > 0 ? 100.0 * row.gmacs_per_s / peak_gmacs_per_s : 0.0;
}

void print_rows(std::FILE* out, const char* title, const std::vector<OpProfileRow>& rows, bool by_kind) {
  std::fprintf(out, "\n%s\n%-44s %-18s %8s %8s %7s %9s %8s %7s  %s\n", title, by_kind ? "kind" : "op",
               by_kind ? "ops" : "kind", "mean ms", "p50 ms", "%", "MMAC", "GMAC/s", "% peak", by_kind ? "" : "kernel");
  for (const OpProfileRow& r : rows) {
    const std::string first = by_kind ? r.kind : r.name;
    const std::string second = by_kind ? std::to_string(r.ops) : r.kind;
    std::fprintf(out, "%-44s %-18s %8.3f %8.3f %7.2f %9.1f %8.1f %7.1f  %s\n", first.c_str(), second.c_str(), r.mean_ms,
                 r.p50_ms, r.percent, r.macs / 1e6, r.gmacs_per_s, r.percent_of_peak, by_kind ? "" : r.kernel.c_str());
  }
}

nlohmann::ordered_json row_json(const OpProfileRow& r) {
  return {{"name", r.name},         {"kind", r.kind},     {"kernel", r.kernel},           {"stage", r.stage},
          {"ops", r.ops},           {"runs", r.runs},     {"mean_ms", r.mean_ms},         {"p50_ms", r.p50_ms},
          {"percent", r.percent},
          {"macs", r.macs},         {"gmac_per_s", r.gmacs_per_s}, {"percent_of_peak", r.percent_of_peak}};
}

}  // namespace

OpProfileTable OpProfileTable::make(std::span<const OpProfile> profile, double peak_gmacs_per_s,
                                    const std::vector<std::vector<double>>& run_ms) {
  OpProfileTable t;
  std::map<std::string, OpProfileRow> kinds;
  for (size_t op = 0; op < profile.size(); ++op) {
    const OpProfile& p = profile[op];
    const double mean = p.runs > 0 ? p.total_ms / static_cast<double>(p.runs) : 0.0;
    const bool have_runs = op < run_ms.size() && !run_ms[op].empty();
    OpProfileRow row{p.name, p.kind, p.kernel, p.stage, 1, p.runs, mean, have_runs ? median(run_ms[op]) : mean, 0, p.macs, 0, 0};
    t.total_ms += row.mean_ms;
    t.ops.push_back(row);
    auto [it, fresh] = kinds.try_emplace(p.kind, OpProfileRow{p.kind, p.kind, "", "", 0, p.runs, 0, 0, 0, 0, 0, 0});
    it->second.ops += 1;
    it->second.mean_ms += row.mean_ms;
    it->second.p50_ms += row.p50_ms;  // a kind's: the sum of its ops' medians
    it->second.macs += row.macs;
  }
  for (OpProfileRow& r : t.ops) set_rates(r, t.total_ms, peak_gmacs_per_s);
  for (auto& [kind, row] : kinds) {
    set_rates(row, t.total_ms, peak_gmacs_per_s);
    t.kinds.push_back(row);
  }
  std::stable_sort(t.kinds.begin(), t.kinds.end(), [](const auto& a, const auto& b) { return a.mean_ms > b.mean_ms; });
  return t;
}

std::vector<OpProfileRow> OpProfileTable::top(size_t n) const {
  std::vector<OpProfileRow> rows = ops;
  std::stable_sort(rows.begin(), rows.end(), [](const auto& a, const auto& b) { return a.p50_ms > b.p50_ms; });
  rows.resize(std::min(n, rows.size()));
  return rows;
}

void OpProfileTable::print(std::FILE* out, size_t top_n) const {
  print_rows(out, "op profile (every op in the order it runs; mean per inference)", ops, false);
  print_rows(out, ("top " + std::to_string(std::min(top_n, ops.size())) + " ops by median time").c_str(), top(top_n), false);
  print_rows(out, "by kind", kinds, true);
  std::fprintf(out, "\nops total    %.3f ms per inference (%zu ops)\n", total_ms, ops.size());
}

nlohmann::ordered_json OpProfileTable::to_json() const {
  nlohmann::ordered_json j;
  j["total_ms"] = total_ms;
  j["ops"] = nlohmann::ordered_json::array();
  for (const auto& r : ops) j["ops"].push_back(row_json(r));
  j["kinds"] = nlohmann::ordered_json::array();
  for (const auto& r : kinds) j["kinds"].push_back(row_json(r));
  return j;
}

}  // namespace act
