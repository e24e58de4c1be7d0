// Calibration and evaluation frames as the INT8 conversion uses them (no media decoding here: see
// calib_frames.h for reading image folders, videos and datasets with OpenCV).
#pragma once

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "actengine/engine.h"
#include "weights/blob/actb.h"
#include "weights/blob/model_config.h"

namespace act {

struct CalibFrame {
  std::vector<std::vector<uint8_t>> images;  ///< per camera, RGB uint8 HWC at the model's size
  std::vector<float> state, env_state;       ///< raw (un-normalised) values
  std::string origin;                        ///< file (and frame index) it came from
};

struct CalibSet {
  std::vector<CalibFrame> frames;
  std::vector<std::string> notes;  ///< e.g. "states sampled from the normalisation statistics"
  std::string preprocessing;       ///< how images were converted

  /// The frame as an engine observation (views into the frame's storage).
  static Observation observation(const CalibFrame& frame, const ModelConfig& config);
};

/// Samples raw state vectors from a model's normalisation statistics (in `blob`, an FP32 blob of
/// the model): the inverse of the engine's normalisation applied to N(0, 1) for MEAN_STD, U(-1, 1)
/// for MIN_MAX, and N(0, 1) itself for IDENTITY.
class StateSampler {
 public:
  StateSampler(const ModelConfig& config, const ActbFile& blob, uint64_t seed) : config_(config), blob_(blob), rng_(seed) {}
  std::vector<float> sample(const std::string& key, int dim);

 private:
  const ModelConfig& config_;
  const ActbFile& blob_;
  std::mt19937_64 rng_;
};

/// Frames of random images (smooth noise) and sampled states: for benchmarks and for reports when
/// the user gave no frames (a note says the accuracy is then only indicative).
CalibSet synthetic_calibration_frames(const ModelConfig& config, const ActbFile& blob, size_t count, uint64_t seed);

}  // namespace act
