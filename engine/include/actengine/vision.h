// actengine public API, vision helper (libactengine_vision, over OpenCV): the one conversion from a
// decoded camera frame to a model input image. Calibration (act_convert) and the control loop
// (act_drive) both use it, so a C++ program that feeds an Engine through it sees the pixels the
// INT8 calibration saw.
//
//   std::vector<uint8_t> rgb;
//   act::Status s = act::frame_to_model_rgb(frame, cam.height, cam.width, rgb);   // frame: cv::Mat, BGR
//   obs.images = {act::ImageView::rgb_u8(rgb.data(), cam.height, cam.width)};
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "actengine/status.h"

namespace act {

/// Frame (OpenCV BGR, BGRA or grayscale, 8-bit) -> RGB uint8 HWC of height x width: colour
/// converted, then resized with INTER_AREA when shrinking and INTER_LINEAR when enlarging (no crop,
/// no letterbox). kInvalidArgument on an empty or non-8-bit frame, or a size that is not positive.
Status frame_to_model_rgb(const cv::Mat& frame, int height, int width, std::vector<uint8_t>& rgb);

/// One line describing frame_to_model_rgb, for reports (CalibrationSet::preprocessing).
std::string model_preprocessing_description(int height, int width);

}  // namespace act
