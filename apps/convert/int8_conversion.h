// act_convert's INT8 path: calibration on real frames, the dynamic / static / mixed blob, and the
// accuracy report against the FP32 model on held-out frames.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "apps/convert/activation_stats.h"
#include "apps/convert/calib_set.h"
#include "weights/import/lerobot_import.h"
#include "weights/blob/quant_config.h"

namespace act {

/// Reads calibration frames from files (calib_frames.h's load_calibration_frames, which needs
/// OpenCV; programs built without it pass none).
using CalibFrameLoader = CalibSet (*)(const std::vector<std::string>& sources, const ModelConfig& config,
                                      const ModelInfo& info, const ActbFile& blob, size_t max_frames, uint64_t seed);

struct Int8Options {
  QuantMode mode = QuantMode::kStatic;
  CalibrationMethod method = CalibrationMethod::kMse;
  double percentile = 99.99;
  std::vector<std::string> calib_sources;
  CalibFrameLoader frame_loader = nullptr;  ///< reads calib_sources
  size_t calib_samples = 64;           ///< frames used for calibration
  std::optional<size_t> holdout;       ///< frames kept out for the report (default: a fifth, 1..16)
  std::optional<double> target_mse;    ///< mixed: the held-out normalised MSE to meet
  std::optional<double> max_mse;       ///< fail, writing nothing, above this held-out MSE
  int threads = 0;
  bool progress = true;                ///< progress lines on stderr
  bool layer_report = true;            ///< per-layer SQNR in the report (one more pass over 4 frames)
  uint64_t seed = 1;
};

struct Int8Result {
  size_t bytes = 0;             ///< of the written blob
  nlohmann::json report;        ///< everything the text report says
  std::string text;             ///< the report for stdout
};

/// Converts the imported model into an INT8 blob at `output` (atomically: on any error, or when
/// --max-mse is missed, nothing is written). `frames`, when given, replaces the calibration sources
/// (act_bench's built-in model). Throws act::Error.
Int8Result convert_to_int8(const ImportedModel& model, const std::string& output, const Int8Options& options,
                           const CalibSet* frames = nullptr);

}  // namespace act
