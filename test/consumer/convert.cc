// consumer_convert CHECKPOINT OUT_DIR: with the installed package's public headers only, converts a
// LeRobot checkpoint to FP32 and to static INT8, calibrated on frames made in memory (cv::Mat ->
// act::frame_to_model_rgb), runs both blobs with act::Engine and checks that the report's numbers
// are finite and that the INT8 actions stay close to the FP32 ones. Exits non-zero on any failure.
#include <actengine/convert.h>
#include <actengine/engine.h>
#include <actengine/vision.h>

#include <opencv2/core.hpp>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace {

int failed(const std::string& what) {
  std::fprintf(stderr, "consumer_convert: %s\n", what.c_str());
  return 1;
}

// A camera frame (BGR, twice the model's size) with smooth content that changes with `i`.
cv::Mat camera_frame(int height, int width, int i) {
  cv::Mat bgr(height * 2, width * 2, CV_8UC3);
  for (int y = 0; y < bgr.rows; ++y) {
    for (int x = 0; x < bgr.cols; ++x) {
      bgr.at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<uchar>((x * 3 + i * 17) % 256), static_cast<uchar>((y * 2 + i * 29) % 256),
                                          static_cast<uchar>((x + y + i * 41) % 256));
    }
  }
  return bgr;
}

// The chunk the blob's Engine predicts for calibration frame `f` (states zero).
bool run(const std::string& blob, const act::CalibrationFrame& f, std::vector<float>& chunk, std::string& error) {
  auto engine = act::Engine::open(blob, {.threads = 1});
  if (!engine.ok()) {
    error = engine.status().to_string();
    return false;
  }
  const act::ModelInfo& info = (*engine)->model_info();
  act::Observation obs;
  for (size_t c = 0; c < info.cameras.size(); ++c) {
    obs.images.push_back(act::ImageView::rgb_u8(f.images[c].data(), info.cameras[c].height, info.cameras[c].width));
  }
  const std::vector<float> state(static_cast<size_t>(info.state_dim), 0.0f), env(static_cast<size_t>(info.env_state_dim), 0.0f);
  obs.state = state;
  obs.env_state = env;
  chunk.resize(info.chunk_values());
  const act::Status s = (*engine)->infer(obs, chunk);
  if (!s.ok()) error = s.to_string();
  return s.ok();
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: consumer_convert CHECKPOINT OUT_DIR\n");
    return 2;
  }
  const std::string checkpoint = argv[1], out = argv[2];
  auto missing = act::import_checkpoint(out + "/no-such-checkpoint");
  if (missing.ok() || missing.status().code() != act::StatusCode::kNotFound) return failed("a missing checkpoint is not kNotFound");

  auto model = act::import_checkpoint(checkpoint);
  if (!model.ok()) return failed(model.status().to_string());
  const act::ModelInfo& info = (*model)->summary().model;
  auto fp32_bytes = (*model)->write_fp32(out + "/fp32.actb");
  if (!fp32_bytes.ok()) return failed(fp32_bytes.status().to_string());

  act::CalibrationSet calibration;
  calibration.preprocessing = act::model_preprocessing_description(info.cameras[0].height, info.cameras[0].width);
  for (int i = 0; i < 12; ++i) {
    act::CalibrationFrame f;
    for (const act::CameraInfo& cam : info.cameras) {
      f.images.emplace_back();
      const act::Status s = act::frame_to_model_rgb(camera_frame(cam.height, cam.width, i), cam.height, cam.width, f.images.back());
      if (!s.ok()) return failed(s.to_string());
    }
    calibration.frames.push_back(std::move(f));  // states left empty: sampled from the statistics
  }
  act::Int8Options options;
  options.mode = act::Int8Mode::kStatic;
  options.holdout = 3;
  options.threads = 2;
  auto report = (*model)->write_int8(out + "/int8.actb", calibration, options);
  if (!report.ok()) return failed(report.status().to_string());
  const act::ActionError& e = report->action_error;
  if (!std::isfinite(e.mse) || !std::isfinite(e.max_abs) || !std::isfinite(e.mse_physical) || report->layers.empty()) {
    return failed("the report's numbers are not finite:\n" + report->to_text());
  }
  for (const act::LayerSqnr& l : report->layers) {
    if (!std::isfinite(l.sqnr_db)) return failed("layer " + l.value + " has a non-finite SQNR");
  }
  if (report->to_json().find("\"action_error\"") == std::string::npos) return failed("the JSON report has no action_error");

  std::vector<float> fp32, int8;
  std::string error;
  if (!run(out + "/fp32.actb", calibration.frames[0], fp32, error) || !run(out + "/int8.actb", calibration.frames[0], int8, error)) {
    return failed(error);
  }
  double diff = 0, scale = 0;
  for (size_t i = 0; i < fp32.size(); ++i) {
    diff += (static_cast<double>(int8[i]) - fp32[i]) * (static_cast<double>(int8[i]) - fp32[i]);
    scale += static_cast<double>(fp32[i]) * fp32[i];
  }
  const double relative_rms = std::sqrt(diff / scale);
  std::printf("consumer_convert: fp32 %llu bytes, int8 %llu bytes, held-out MSE %g; INT8 vs FP32 actions: relative RMS %g\n",
              static_cast<unsigned long long>(*fp32_bytes), static_cast<unsigned long long>(report->int8_bytes), e.mse,
              relative_rms);
  if (!(relative_rms < 0.1)) return failed("the INT8 actions are far from the FP32 ones");
  return 0;
}
