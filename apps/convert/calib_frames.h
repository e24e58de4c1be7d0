// Calibration and evaluation frames for act_convert, from the sources users have:
//   - a folder of images (png, jpg, jpeg, bmp; searched recursively, sorted by path);
//   - a video file (mp4, avi, mkv, mov, webm; frames sampled evenly);
//   - a LeRobot dataset folder (its videos/ per camera key, decoded with OpenCV/FFmpeg);
//   - a folder recorded by act_drive --record (its frames; states from its log when present);
//   - an observation file (.safetensors, act_eval's format) with images and states.
// Frames are converted exactly as at run time (apps/image_preprocess.h). Where a source has no robot
// state, states are sampled from the checkpoint's normalisation statistics, and a note says so.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "actengine/engine.h"
#include "weights/actb.h"
#include "weights/model_config.h"

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

/// Reads up to `max_frames` frames from the sources, spread evenly over what they hold. `blob` (an
/// FP32 blob of the model) supplies the normalisation statistics for sampled states. Throws
/// act::Error naming the source on anything unreadable or empty.
CalibSet load_calibration_frames(const std::vector<std::string>& sources, const ModelConfig& config, const ModelInfo& info,
                                 const ActbFile& blob,
                                 size_t max_frames, uint64_t seed);

/// Frames of random images (smooth noise) and sampled states: for benchmarks and for reports when
/// the user gave no frames (a note says the accuracy is then only indicative).
CalibSet synthetic_calibration_frames(const ModelConfig& config, const ActbFile& blob, size_t count, uint64_t seed);

}  // namespace act
