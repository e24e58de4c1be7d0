// act_eval's arithmetic: how far each model's action chunks are from the demonstration and from
// the first model's (the reference, typically FP32), in raw units and in the network's normalised
// units (raw - centre) / half-range, the range being ModelInfo::action_low..action_high.
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace act::eval {

/// Squared and absolute errors of one comparison in one unit, overall and per action dimension.
/// A non-finite error makes the MSE NaN (a maximum alone would hide it).
class ErrorStats {
 public:
  explicit ErrorStats(size_t dims) : sum_sq_(dims), max_abs_(dims), count_(dims) {}
  void add(size_t dim, double error);
  double mse() const;
  double max_abs() const;
  double dim_mse(size_t dim) const;
  double dim_max_abs(size_t dim) const { return max_abs_[dim]; }
  size_t dims() const { return sum_sq_.size(); }
  nlohmann::ordered_json to_json(const std::vector<std::string>& names) const;

 private:
  std::vector<double> sum_sq_, max_abs_;
  std::vector<size_t> count_;
  size_t non_finite_ = 0;
};

/// One comparison (a model against the demonstration, or against the reference model): the first
/// action of each chunk, and every step of the chunk both sides have.
struct ChunkComparison {
  explicit ChunkComparison(size_t dims) : first_raw(dims), first_normalised(dims), chunk_raw(dims), chunk_normalised(dims) {}
  ErrorStats first_raw, first_normalised, chunk_raw, chunk_normalised;
  nlohmann::ordered_json to_json(const std::vector<std::string>& names) const;
};

/// The action scale: half_range[d] raw units are one normalised unit.
struct ActionScale {
  std::vector<float> low, high;
  double half_range(size_t dim) const;
};

/// Adds `steps` steps of `ours` against `theirs` (both steps x dims, row-major) to `c`.
void compare_chunks(std::span<const float> ours, std::span<const float> theirs, size_t steps, const ActionScale& scale,
                    ChunkComparison& c);

/// A chunk made without the policy, a bar it should clear: the last demonstrated action held, the
/// training mean action (the centre of the action scale) or zero, repeated over the chunk.
struct BaselineEvaluation {
  BaselineEvaluation(std::string baseline_name, std::string what, size_t dims)
      : name(std::move(baseline_name)), description(std::move(what)), vs_demonstration(dims) {}
  std::string name;         ///< "hold last action", "mean action", "zero"
  std::string description;  ///< what it does, for a verdict ("repeats the last demonstrated action")
  ChunkComparison vs_demonstration;
};

struct ModelEvaluation {
  ModelEvaluation(std::string model_path, std::string model_precision, size_t dims)
      : path(std::move(model_path)), precision(std::move(model_precision)), vs_demonstration(dims), vs_reference(dims) {}
  std::string path, precision;
  ChunkComparison vs_demonstration;
  ChunkComparison vs_reference;     ///< against the first model (unused for the first model itself)
  size_t non_finite_outputs = 0;    ///< output values that were NaN or infinite
  std::vector<float> first_actions;           ///< frames x dims: each frame's first predicted action (raw)
  std::vector<double> frame_error;            ///< per frame: first-action MSE against the demonstration, normalised
  double seconds = 0;                         ///< inference time over the episode
};

/// Everything act_eval measured on one episode.
struct EpisodeEvaluation {
  std::vector<std::string> action_names;
  ActionScale scale;
  std::vector<std::string> frame_sources;
  std::vector<float> demonstration_first;  ///< frames x dims: each frame's demonstrated action (raw)
  std::vector<ModelEvaluation> models;     ///< the first is the reference
  /// Hold last action, mean action, zero against the demonstration, over the steps model 1's chunks
  /// are compared on (filled by add_frame; the first frame's "last action" is the mean action).
  std::vector<BaselineEvaluation> baselines;

  /// One frame: the demonstration from it on (steps x dims) and each model's chunk, in `models` order.
  void add_frame(const std::string& source, std::span<const float> demonstration,
                 const std::vector<std::vector<float>>& chunks);

  /// The baselines' chunks for one frame (add_frame calls it): `chunk_values` is model 1's chunk size.
  void add_baselines(std::span<const float> demonstration, size_t chunk_values);
  /// The error model m adds to the reference, as a fraction of the reference's own error: whole-chunk
  /// normalised MSE of m against the reference over the reference's against the demonstration.
  double added_error(size_t m) const;
  nlohmann::ordered_json to_json() const;
};

}  // namespace act::eval
