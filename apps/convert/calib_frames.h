// Calibration frames from the sources users have, decoded with OpenCV:
//   - a folder of images (png, jpg, jpeg, bmp; searched recursively, sorted by path);
//   - a video file (mp4, avi, mkv, mov, webm; frames sampled evenly);
//   - a LeRobot dataset folder (its videos/ per camera key, decoded with OpenCV/FFmpeg);
//   - a folder recorded by act_drive --record (its frames; states from its log when present);
//   - an observation file (.safetensors, act_eval's format) with images and states.
// Frames are converted exactly as at run time (actengine/vision.h). Where a source has no robot
// state the frame's state is left empty: the conversion samples it from the checkpoint's
// normalisation statistics, and its report says so.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "actengine/convert.h"

namespace act {

/// Image files (png, jpg, jpeg, bmp) and videos (mp4, avi, mkv, mov, webm), by extension in any case:
/// what act_convert and act_eval read.
bool is_image_file(const std::filesystem::path& p);
bool is_video_file(const std::filesystem::path& p);
/// The files of a folder and its subfolders that `pick` accepts, sorted by path.
std::vector<std::filesystem::path> files_in(const std::filesystem::path& dir, bool (*pick)(const std::filesystem::path&));

/// Reads up to `max_frames` frames from the sources, spread evenly over what they hold, at the
/// model's input size; `given` (if not null) gets how many frames the sources hold in all. A
/// warning note says when frames are stretched to another aspect ratio or upscaled 2x or more.
/// Throws act::Error naming the source on anything unreadable or empty.
CalibrationSet load_calibration_frames(const std::vector<std::string>& sources, const ModelInfo& model, size_t max_frames,
                                       size_t* given = nullptr);

}  // namespace act
