// Calibration frames from the sources users have, decoded with OpenCV:
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

#include "apps/convert/calib_set.h"

namespace act {

/// Reads up to `max_frames` frames from the sources, spread evenly over what they hold. `blob` (an
/// FP32 blob of the model) supplies the normalisation statistics for sampled states. Throws
/// act::Error naming the source on anything unreadable or empty.
CalibSet load_calibration_frames(const std::vector<std::string>& sources, const ModelConfig& config, const ModelInfo& info,
                                 const ActbFile& blob, size_t max_frames, uint64_t seed);

}  // namespace act
