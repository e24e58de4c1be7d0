#include "engine/src/convert/calibration_frames.h"

#include <algorithm>
#include <cmath>

#include "actengine/status.h"
#include "weights/blob/blob_names.h"

namespace act {

namespace bn = blob_names;

std::vector<float> StateSampler::sample(const std::string& key, int dim) {
  std::vector<float> v(static_cast<size_t>(dim));
  const NormMode mode = model_.config.input_norm_mode(key);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  std::uniform_real_distribution<float> uniform(-1.0f, 1.0f);
  const auto statistic = [&](const std::string& name) {
    const NamedTensor* t = model_.find(name);
    if (t == nullptr || t->values.size() != v.size()) fail(StatusCode::kInternal, "no statistics \"" + name + "\" to sample states from");
    return t->values.data();
  };
  const float* sub = mode == NormMode::kIdentity ? nullptr : statistic(bn::norm_sub(key));
  const float* div = mode == NormMode::kIdentity ? nullptr : statistic(bn::norm_div(key));
  for (size_t i = 0; i < v.size(); ++i) {
    switch (mode) {
      case NormMode::kIdentity: v[i] = normal(rng_); break;
      case NormMode::kMeanStd: v[i] = sub[i] + div[i] * normal(rng_); break;
      case NormMode::kMinMax: v[i] = sub[i] + div[i] * (uniform(rng_) + 1.0f) * 0.5f; break;
    }
  }
  return v;
}

namespace {

void add_note(CalibrationSet& set, const std::string& note) {
  if (std::find(set.notes.begin(), set.notes.end(), note) == set.notes.end()) set.notes.push_back(note);
}

}  // namespace

void complete_calibration_frames(CalibrationSet& set, StateSampler& states) {
  const ModelConfig& config = states.config();
  for (size_t i = 0; i < set.frames.size(); ++i) {
    CalibrationFrame& f = set.frames[i];
    const std::string where = "calibration frame " + std::to_string(i) + ": ";
    if (f.images.size() != config.cameras.size()) {
      fail(StatusCode::kInvalidArgument, where + "has " + std::to_string(f.images.size()) + " images, the model has " +
           std::to_string(config.cameras.size()) + " cameras");
    }
    for (size_t c = 0; c < config.cameras.size(); ++c) {
      const CameraConfig& cam = config.cameras[c];
      const size_t bytes = static_cast<size_t>(cam.height) * cam.width * 3;
      if (f.images[c].size() != bytes) {
        fail(StatusCode::kInvalidArgument, where + "image " + std::to_string(c) + " (" + cam.key + ") has " +
             std::to_string(f.images[c].size()) + " bytes, the model's " + std::to_string(cam.height) + "x" +
             std::to_string(cam.width) + " RGB input needs " + std::to_string(bytes));
      }
    }
    const auto check_state = [&](const std::vector<float>& v, int dim, const char* what) {
      if (!v.empty() && v.size() != static_cast<size_t>(dim)) {
        fail(StatusCode::kInvalidArgument, where + "has " + std::to_string(v.size()) + " " + what + " values, the model takes " +
             std::to_string(dim));
      }
    };
    check_state(f.state, config.state_dim, "state");
    check_state(f.env_state, config.env_state_dim, "environment state");
    if (config.state_dim > 0 && f.state.empty()) {
      f.state = states.sample(config.state_key, config.state_dim);
      add_note(set, "robot states were sampled from the checkpoint's normalisation statistics (the source has none)");
    }
    if (config.env_state_dim > 0 && f.env_state.empty()) {
      f.env_state = states.sample(config.env_state_key, config.env_state_dim);
      add_note(set, "environment states were sampled from the checkpoint's normalisation statistics");
    }
  }
}

Observation calibration_observation(const CalibrationFrame& frame, const ModelConfig& config) {
  Observation obs;
  for (size_t c = 0; c < config.cameras.size(); ++c) {
    obs.images.push_back(ImageView::rgb_u8(frame.images[c].data(), config.cameras[c].height, config.cameras[c].width));
  }
  obs.state = frame.state;
  obs.env_state = frame.env_state;
  return obs;
}

CalibrationSet synthetic_calibration_frames(StateSampler& states, size_t count, uint64_t seed) {
  const ModelConfig& config = states.config();
  CalibrationSet set;
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> byte(0, 255);
  for (size_t i = 0; i < count; ++i) {
    CalibrationFrame f;
    for (const auto& cam : config.cameras) {
      // Smooth noise: a coarse random grid (1/16 of the size) upsampled bilinearly, like the
      // low-frequency content of real frames.
      const int gh = std::max(2, cam.height / 16), gw = std::max(2, cam.width / 16);
      std::vector<float> grid(static_cast<size_t>(gh) * gw * 3);
      for (float& g : grid) g = static_cast<float>(byte(rng));
      std::vector<uint8_t> image(static_cast<size_t>(cam.height) * cam.width * 3);
      for (int y = 0; y < cam.height; ++y) {
        const float gy = std::min(static_cast<float>(gh - 1), static_cast<float>(y) * (gh - 1) / std::max(1, cam.height - 1));
        const int y0 = std::min(static_cast<int>(gy), gh - 2);
        const float fy = gy - static_cast<float>(y0);
        for (int x = 0; x < cam.width; ++x) {
          const float gx = std::min(static_cast<float>(gw - 1), static_cast<float>(x) * (gw - 1) / std::max(1, cam.width - 1));
          const int x0 = std::min(static_cast<int>(gx), gw - 2);
          const float fx = gx - static_cast<float>(x0);
          for (int c = 0; c < 3; ++c) {
            const auto at = [&](int yy, int xx) { return grid[(static_cast<size_t>(yy) * gw + xx) * 3 + c]; };
            const float v = (1 - fy) * ((1 - fx) * at(y0, x0) + fx * at(y0, x0 + 1)) + fy * ((1 - fx) * at(y0 + 1, x0) + fx * at(y0 + 1, x0 + 1));
            image[(static_cast<size_t>(y) * cam.width + x) * 3 + c] = static_cast<uint8_t>(std::clamp(std::nearbyint(v), 0.0f, 255.0f));
          }
        }
      }
      f.images.push_back(std::move(image));
    }
    if (config.state_dim > 0) f.state = states.sample(config.state_key, config.state_dim);
    if (config.env_state_dim > 0) f.env_state = states.sample(config.env_state_key, config.env_state_dim);
    set.frames.push_back(std::move(f));
  }
  set.notes.push_back("synthetic frames (smooth random noise, states sampled from the statistics): accuracy is only indicative");
  set.preprocessing = "synthetic RGB uint8 at the model's input size";
  return set;
}

}  // namespace act
