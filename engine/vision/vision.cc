#include "actengine/vision.h"

#include <opencv2/imgproc.hpp>

namespace act {

Status frame_to_model_rgb(const cv::Mat& frame, int height, int width, std::vector<uint8_t>& rgb) {
  if (frame.empty()) return Status(StatusCode::kInvalidArgument, "empty camera frame");
  if (frame.depth() != CV_8U) return Status(StatusCode::kInvalidArgument, "camera frame is not 8-bit");
  if (height <= 0 || width <= 0) {
    return Status(StatusCode::kInvalidArgument,
                  "model input size " + std::to_string(height) + "x" + std::to_string(width) + " is not positive");
  }
  cv::Mat converted;
  switch (frame.channels()) {
    case 1: cv::cvtColor(frame, converted, cv::COLOR_GRAY2RGB); break;
    case 3: cv::cvtColor(frame, converted, cv::COLOR_BGR2RGB); break;
    case 4: cv::cvtColor(frame, converted, cv::COLOR_BGRA2RGB); break;
    default:
      return Status(StatusCode::kInvalidArgument, "camera frame has " + std::to_string(frame.channels()) + " channels");
  }
  rgb.resize(static_cast<size_t>(height) * width * 3);
  cv::Mat out(height, width, CV_8UC3, rgb.data());
  if (converted.rows == height && converted.cols == width) {
    converted.copyTo(out);
  } else {
    const bool shrinking = converted.rows * converted.cols > height * width;
    cv::resize(converted, out, cv::Size(width, height), 0, 0, shrinking ? cv::INTER_AREA : cv::INTER_LINEAR);
  }
  return Status();
}

std::string model_preprocessing_description(int height, int width) {
  return "decode -> RGB -> resize to " + std::to_string(height) + "x" + std::to_string(width) +
         " (OpenCV INTER_AREA when shrinking, INTER_LINEAR when enlarging; no crop) -> uint8 /255 -> the model's "
         "normalisation";
}

}  // namespace act
