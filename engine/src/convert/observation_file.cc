#include "engine/src/convert/observation_file.h"

#include <cmath>
#include <cstring>

#include "actengine/status.h"
#include "weights/blob/file_kind.h"
#include "weights/import/safetensors.h"

namespace act {

namespace {

void expect_shape(const SafetensorsTensor& t, const std::vector<int64_t>& shape, const std::string& file) {
  if (t.shape != shape) {
    fail(StatusCode::kInvalidArgument,
         file + ": \"" + t.name + "\" has shape " + shape_string(t.shape) + ", expected " + shape_string(shape));
  }
}

}  // namespace

ObservationBatch ObservationBatch::read(const std::string& path, const ModelInfo& model, ImageSource source) {
  // The wrong kind of input (an image, a blob, a folder) says what it is instead of failing to parse.
  if (const FileKind kind = file_kind(path); kind != FileKind::kSafetensors && kind != FileKind::kMissing &&
                                             kind != FileKind::kOther) {
    fail(StatusCode::kInvalidArgument, wrong_kind_message(path, kind, "an observation file (a .safetensors file of "
                                                       "input.<feature key> tensors, as in the LeRobot fixtures)"));
  }
  const SafetensorsFile file = SafetensorsFile::open(path);
  ObservationBatch b;
  b.model_ = model;

  // The batch size comes from the state (or the first camera).
  const std::string state_name = "input.observation.state";
  const std::string first_cam = "input." + model.cameras.at(0).key;
  const SafetensorsTensor* lead = model.state_dim > 0 ? file.find(state_name) : nullptr;
  if (!lead) lead = file.find(first_cam);
  if (!lead) lead = file.find(first_cam + ".u8_nhwc");
  if (!lead) {
    fail(StatusCode::kNotFound, path + ": no \"" + (model.state_dim > 0 ? state_name : first_cam) +
         "\" tensor (observations are named input.<feature key>)");
  }
  if (lead->shape.empty() || lead->shape[0] < 1) fail(StatusCode::kInvalidArgument, path + ": \"" + lead->name + "\" has no batch axis");
  const int64_t n = lead->shape[0];
  b.count_ = static_cast<size_t>(n);

  for (const auto& cam : model.cameras) {
    const std::string fname = "input." + cam.key;
    const SafetensorsTensor* f = file.find(fname);
    const SafetensorsTensor* u = file.find(fname + ".u8_nhwc");
    const bool use_u8 = source == ImageSource::kU8 || (source == ImageSource::kAuto && !f && u);
    if (use_u8) {
      if (!u) fail(StatusCode::kNotFound, path + ": missing \"" + fname + ".u8_nhwc\"");
      if (u->dtype != DType::kU8) fail(StatusCode::kInvalidArgument, path + ": \"" + u->name + "\" must be U8");
      expect_shape(*u, {n, cam.height, cam.width, 3}, path);
      b.images_u8_.emplace_back(u->data, u->data + u->nbytes);
      b.images_f32_.emplace_back();
      b.u8_.push_back(true);
    } else {
      if (!f) fail(StatusCode::kNotFound, path + ": missing \"" + fname + "\" (or its .u8_nhwc twin)");
      expect_shape(*f, {n, 3, cam.height, cam.width}, path);
      b.images_f32_.push_back(f->to_f32());
      b.images_u8_.emplace_back();
      b.u8_.push_back(false);
    }
  }
  if (model.state_dim > 0) {
    const SafetensorsTensor& s = file.get(state_name);
    expect_shape(s, {n, model.state_dim}, path);
    b.state_ = s.to_f32();
  }
  if (model.env_state_dim > 0) {
    const std::string env_name = "input." + model.env_state_key;
    const SafetensorsTensor& e = file.get(env_name);
    expect_shape(e, {n, model.env_state_dim}, path);
    b.env_ = e.to_f32();
  }
  if (const SafetensorsTensor* a = file.find("output.action")) {
    expect_shape(*a, {n, model.chunk_size, model.action_dim}, path);
    b.expected_ = a->to_f32();
  }
  return b;
}

Observation ObservationBatch::at(size_t i) const {
  Observation obs;
  for (size_t c = 0; c < model_.cameras.size(); ++c) {
    const auto& cam = model_.cameras[c];
    const size_t per = static_cast<size_t>(cam.height) * cam.width * 3;
    if (u8_[c]) {
      obs.images.push_back(ImageView::rgb_u8(images_u8_[c].data() + i * per, cam.height, cam.width));
    } else {
      obs.images.push_back(ImageView::rgb_f32_chw(images_f32_[c].data() + i * per, cam.height, cam.width));
    }
  }
  const size_t s = static_cast<size_t>(model_.state_dim), e = static_cast<size_t>(model_.env_state_dim);
  if (s > 0) obs.state = std::span<const float>(state_.data() + i * s, s);
  if (e > 0) obs.env_state = std::span<const float>(env_.data() + i * e, e);
  return obs;
}

const float* ObservationBatch::expected_actions(size_t i) const {
  return expected_ ? expected_->data() + i * model_.chunk_values() : nullptr;
}

}  // namespace act
