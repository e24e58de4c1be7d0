// actengine public API, calibration files (libactengine_media, over OpenCV; act_convert --calib and
// Python's actengine.convert(calib=...) read them): calibration frames from the sources users have:
//   - a folder of images (png, jpg, jpeg, bmp; searched recursively, sorted by path);
//   - a video file (mp4, avi, mkv, mov, webm; frames sampled evenly);
//   - a LeRobot dataset folder (its videos/ per camera key, decoded with OpenCV/FFmpeg);
//   - a folder recorded by act_drive --record (its frames; states from its log when present);
//   - an observation file (.safetensors, act_eval's format) with images and states.
// Frames are converted exactly as at run time (actengine/vision.h). Where a source has no robot
// state the frame's state is left empty: the conversion samples it from the checkpoint's
// normalisation statistics, and its report says so. Images and video are decoded by OpenCV's
// imgcodecs and videoio, loaded on first use (libact_media_io.so: engine/media/media_io.h).
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "actengine/convert.h"
#include "actengine/status.h"

namespace act {

/// Reads up to `max_frames` frames from the sources, spread evenly over what they hold, at the
/// model's input size; `given` (if not null) gets how many frames the sources hold in all. A
/// warning note says when frames are stretched to another aspect ratio or upscaled 2x or more.
/// An error names the source on anything missing (kNotFound), of another kind (kInvalidArgument),
/// unreadable or empty.
StatusOr<CalibrationSet> load_calibration_frames(const std::vector<std::string>& sources, const ModelInfo& model, size_t max_frames,
                                       size_t* given = nullptr);

}  // namespace act
