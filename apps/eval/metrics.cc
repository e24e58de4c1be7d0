#include "apps/eval/metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace act::eval {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

}  // namespace

void ErrorStats::add(size_t dim, double error) {
  if (!std::isfinite(error)) {
    ++non_finite_;
    return;
  }
  sum_sq_[dim] += error * error;
  max_abs_[dim] = std::max(max_abs_[dim], std::fabs(error));
  ++count_[dim];
}

double ErrorStats::mse() const {
  double sum = 0;
  size_t count = 0;
  for (size_t d = 0; d < dims(); ++d) {
    sum += sum_sq_[d];
    count += count_[d];
  }
  return non_finite_ == 0 && count > 0 ? sum / static_cast<double>(count) : kNaN;
}

double ErrorStats::max_abs() const {
  return non_finite_ == 0 ? *std::max_element(max_abs_.begin(), max_abs_.end()) : kNaN;
}

double ErrorStats::dim_mse(size_t dim) const {
  return non_finite_ == 0 && count_[dim] > 0 ? sum_sq_[dim] / static_cast<double>(count_[dim]) : kNaN;
}

nlohmann::ordered_json ErrorStats::to_json(const std::vector<std::string>& names) const {
  nlohmann::ordered_json per_dim = nlohmann::ordered_json::object();
  for (size_t d = 0; d < dims(); ++d) per_dim[names[d]] = {{"mse", dim_mse(d)}, {"max_abs", dim_max_abs(d)}};
  return {{"mse", mse()}, {"max_abs", max_abs()}, {"per_dimension", per_dim}};
}

nlohmann::ordered_json ChunkComparison::to_json(const std::vector<std::string>& names) const {
  return {{"first_action", {{"raw", first_raw.to_json(names)}, {"normalised", first_normalised.to_json(names)}}},
          {"chunk", {{"raw", chunk_raw.to_json(names)}, {"normalised", chunk_normalised.to_json(names)}}}};
}

double ActionScale::half_range(size_t dim) const {
  // A model without action normalisation (or a constant action) has no scale: its raw units are used.
  const double half = dim < low.size() ? (static_cast<double>(high[dim]) - low[dim]) / 2 : 1.0;
  return half > 0 ? half : 1.0;
}

void compare_chunks(std::span<const float> ours, std::span<const float> theirs, size_t steps, const ActionScale& scale,
                    ChunkComparison& c) {
  const size_t dims = c.first_raw.dims();
  for (size_t s = 0; s < steps; ++s) {
    for (size_t d = 0; d < dims; ++d) {
      const double error = static_cast<double>(ours[s * dims + d]) - theirs[s * dims + d];
      const double normalised = error / scale.half_range(d);
      if (s == 0) {
        c.first_raw.add(d, error);
        c.first_normalised.add(d, normalised);
      }
      c.chunk_raw.add(d, error);
      c.chunk_normalised.add(d, normalised);
    }
  }
}

void EpisodeEvaluation::add_frame(const std::string& source, std::span<const float> demonstration,
                                  const std::vector<std::vector<float>>& chunks) {
  const size_t dims = action_names.size();
  add_baselines(demonstration, chunks.empty() ? demonstration.size() : chunks[0].size());
  frame_sources.push_back(source);
  demonstration_first.insert(demonstration_first.end(), demonstration.begin(), demonstration.begin() + static_cast<std::ptrdiff_t>(dims));
  for (size_t m = 0; m < models.size(); ++m) {
    ModelEvaluation& model = models[m];
    const std::vector<float>& chunk = chunks[m];
    const size_t steps = std::min(demonstration.size(), chunk.size()) / dims;
    compare_chunks(chunk, demonstration, steps, scale, model.vs_demonstration);
    if (m > 0) compare_chunks(chunk, chunks[0], chunk.size() / dims, scale, model.vs_reference);
    model.non_finite_outputs += static_cast<size_t>(std::count_if(chunk.begin(), chunk.end(), [](float v) { return !std::isfinite(v); }));
    model.first_actions.insert(model.first_actions.end(), chunk.begin(), chunk.begin() + static_cast<std::ptrdiff_t>(dims));
    double sum_sq = 0;
    for (size_t d = 0; d < dims; ++d) {
      const double e = (static_cast<double>(chunk[d]) - demonstration[d]) / scale.half_range(d);
      sum_sq += e * e;
    }
    model.frame_error.push_back(sum_sq / static_cast<double>(dims));
  }
}

void EpisodeEvaluation::add_baselines(std::span<const float> demonstration, size_t chunk_values) {
  const size_t dims = action_names.size();
  if (baselines.empty()) {
    baselines.emplace_back("hold last action", "repeats the last demonstrated action", dims);
    baselines.emplace_back("mean action", "always gives the training mean action", dims);
    baselines.emplace_back("zero", "always gives zero", dims);
  }
  std::vector<float> mean(dims, 0.0f), last(dims), zero(dims, 0.0f);
  for (size_t d = 0; d < dims && d < scale.low.size() && d < scale.high.size(); ++d) mean[d] = (scale.low[d] + scale.high[d]) / 2;
  // The previous frame's demonstrated action (this frame's is not in demonstration_first yet).
  if (demonstration_first.size() >= dims) {
    last.assign(demonstration_first.end() - static_cast<std::ptrdiff_t>(dims), demonstration_first.end());
  } else {
    last = mean;
  }
  const size_t steps = std::min(demonstration.size(), chunk_values) / dims;
  const std::vector<float>* actions[] = {&last, &mean, &zero};
  for (size_t b = 0; b < baselines.size(); ++b) {
    std::vector<float> chunk;
    for (size_t s = 0; s < steps; ++s) chunk.insert(chunk.end(), actions[b]->begin(), actions[b]->end());
    compare_chunks(chunk, demonstration, steps, scale, baselines[b].vs_demonstration);
  }
}

double EpisodeEvaluation::added_error(size_t m) const {
  const double own = models[0].vs_demonstration.chunk_normalised.mse();
  const double added = models[m].vs_reference.chunk_normalised.mse();
  if (!std::isfinite(own) || !std::isfinite(added)) return kNaN;
  return own > 0 ? added / own : (added > 0 ? std::numeric_limits<double>::infinity() : 0.0);
}

nlohmann::ordered_json EpisodeEvaluation::to_json() const {
  const size_t dims = action_names.size();
  const auto rows = [dims](const std::vector<float>& values) {
    nlohmann::ordered_json out = nlohmann::ordered_json::array();
    for (size_t i = 0; i + dims <= values.size(); i += dims) {
      out.push_back(std::vector<float>(values.begin() + static_cast<std::ptrdiff_t>(i), values.begin() + static_cast<std::ptrdiff_t>(i + dims)));
    }
    return out;
  };
  nlohmann::ordered_json j;
  j["action_names"] = action_names;
  j["action_low"] = scale.low;
  j["action_high"] = scale.high;
  j["frames"] = frame_sources.size();
  j["models"] = nlohmann::ordered_json::array();
  for (size_t m = 0; m < models.size(); ++m) {
    const ModelEvaluation& model = models[m];
    nlohmann::ordered_json mj = {{"path", model.path},
                                 {"precision", model.precision},
                                 {"non_finite_outputs", model.non_finite_outputs},
                                 {"seconds", model.seconds},
                                 {"vs_demonstration", model.vs_demonstration.to_json(action_names)}};
    if (m > 0) {
      mj["vs_reference"] = model.vs_reference.to_json(action_names);
      mj["added_error_fraction"] = added_error(m);
      mj["added_error_percent"] = 100 * added_error(m);
    }
    j["models"].push_back(std::move(mj));
  }
  j["baselines"] = nlohmann::ordered_json::array();
  for (const auto& b : baselines) {
    j["baselines"].push_back({{"name", b.name}, {"description", b.description},
                              {"vs_demonstration", b.vs_demonstration.to_json(action_names)}});
  }
  nlohmann::ordered_json per_frame = {{"source", frame_sources}, {"demonstration", rows(demonstration_first)}};
  per_frame["models"] = nlohmann::ordered_json::array();
  for (const auto& model : models) {
    per_frame["models"].push_back({{"first_action", rows(model.first_actions)}, {"error", model.frame_error}});
  }
  j["per_frame"] = std::move(per_frame);
  return j;
}

}  // namespace act::eval
