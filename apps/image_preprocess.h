// The one conversion from a decoded camera frame to a model input image, shared by calibration
// (act_convert) and the control loop (act_drive) so both see the same pixels.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace act {

/// Frame (OpenCV BGR, BGRA or grayscale, 8-bit) -> RGB uint8 HWC of height x width: colour
/// converted, then resized with INTER_AREA when shrinking and INTER_LINEAR when enlarging (no crop,
/// no letterbox). Throws act::Error(kInvalidArgument) on an empty or non-8-bit frame.
void frame_to_model_rgb(const cv::Mat& frame, int height, int width, std::vector<uint8_t>& rgb);

/// One line describing frame_to_model_rgb for reports.
std::string model_preprocessing_description(int height, int width);

}  // namespace act
