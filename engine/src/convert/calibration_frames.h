// Calibration frames as the INT8 conversion uses them: the states a frame lacks, sampled from the
// model's normalisation statistics, and synthetic frames for when the caller has none.
#pragma once

#include <cstdint>
#include <random>
#include <string>

#include "actengine/convert.h"
#include "weights/import/lerobot_import.h"

namespace act {

/// Samples raw state vectors from a model's normalisation statistics: the inverse of the engine's normalisation applied to N(0, 1) for MEAN_STD, U(-1, 1)
/// for MIN_MAX, and N(0, 1) itself for IDENTITY.
class StateSampler {
 public:
  StateSampler(const ImportedModel& model, uint64_t seed) : model_(model), rng_(seed) {}
  std::vector<float> sample(const std::string& key, int dim);
  const ModelConfig& config() const { return model_.config; }

 private:
  const ImportedModel& model_;
  std::mt19937_64 rng_;
};

/// Checks every frame against the model (image count and size, state lengths; throws
/// kInvalidArgument naming the frame) and fills the states a frame leaves empty from `states`,
/// frame by frame, noting it in set.notes.
void complete_calibration_frames(CalibrationSet& set, StateSampler& states);

/// The frame as an engine observation (views into the frame's storage).
Observation calibration_observation(const CalibrationFrame& frame, const ModelConfig& config);

/// Frames of random images (smooth noise) and sampled states, for reports when the caller gave no
/// frames (a note says the accuracy is then only indicative).
CalibrationSet synthetic_calibration_frames(StateSampler& states, size_t count, uint64_t seed);

}  // namespace act
