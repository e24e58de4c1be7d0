#include "apps/image_preprocess.h"

#include <opencv2/imgproc.hpp>

#include "weights/blob/error.h"

namespace act {

void frame_to_model_rgb(const cv::Mat& frame, int height, int width, std::vector<uint8_t>& rgb) {
  if (frame.empty()) fail(ErrorCode::kInvalidArgument, "empty camera frame");
  if (frame.depth() != CV_8U) fail(ErrorCode::kInvalidArgument, "camera frame is not 8-bit");
  cv::Mat converted;
  switch (frame.channels()) {
    case 1: cv::cvtColor(frame, converted, cv::COLOR_GRAY2RGB); break;
    case 3: cv::cvtColor(frame, converted, cv::COLOR_BGR2RGB); break;
    case 4: cv::cvtColor(frame, converted, cv::COLOR_BGRA2RGB); break;
    default: fail(ErrorCode::kInvalidArgument, "camera frame has " + std::to_string(frame.channels()) + " channels");
  }
  rgb.resize(static_cast<size_t>(height) * width * 3);
  cv::Mat out(height, width, CV_8UC3, rgb.data());
  if (converted.rows == height && converted.cols == width) {
    converted.copyTo(out);
  } else {
    const bool shrinking = converted.rows * converted.cols > height * width;
    cv::resize(converted, out, cv::Size(width, height), 0, 0, shrinking ? cv::INTER_AREA : cv::INTER_LINEAR);
  }
}

std::string model_preprocessing_description(int height, int width) {
  return "decode -> RGB -> resize to " + std::to_string(height) + "x" + std::to_string(width) +
         " (OpenCV INTER_AREA when shrinking, INTER_LINEAR when enlarging; no crop) -> uint8 /255 -> the model's "
         "normalisation";
}

}  // namespace act
