// Observations stored in a safetensors file (act_eval's and act_bench's inputs, a calibration source),
// in the fixtures' naming:
//   input.<camera key>           F32 [N, 3, H, W] in [0, 1]     or
//   input.<camera key>.u8_nhwc   U8  [N, H, W, 3]
//   input.observation.state      [N, S]        input.<env key>   [N, E]   (when the model has them)
//   output.action                [N, T, A]     (optional: the expected raw action chunks)
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "actengine/engine.h"

namespace act {

enum class ImageSource { kAuto, kFloat, kU8 };

class ObservationBatch {
 public:
  /// Reads and checks every tensor against the model. Throws act::Error naming the tensor and the problem.
  static ObservationBatch read(const std::string& path, const ModelInfo& model, ImageSource source = ImageSource::kAuto);

  size_t size() const { return count_; }
  Observation at(size_t i) const;
  bool has_expected_actions() const { return expected_.has_value(); }
  /// Expected chunk of observation i (chunk_size x action_dim), if the file has output.action.
  const float* expected_actions(size_t i) const;
  /// Whether camera c's images were read from the .u8_nhwc tensor.
  bool uses_u8_images(size_t camera) const { return u8_.at(camera); }

 private:
  size_t count_ = 0;
  std::vector<bool> u8_;  // per camera
  ModelInfo model_;
  std::vector<std::vector<uint8_t>> images_u8_;
  std::vector<std::vector<float>> images_f32_;
  std::vector<float> state_, env_;
  std::optional<std::vector<float>> expected_;
};

}  // namespace act
