#include "observation.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace act::python {

namespace py = pybind11;

namespace {

std::string shape_text(const py::array& array) {
  std::string text = "(";
  for (py::ssize_t d = 0; d < array.ndim(); ++d) {
    if (d > 0) text += ", ";
    text += std::to_string(array.shape(d));
  }
  return text + (array.ndim() == 1 ? ",)" : ")");
}

std::string describe(const py::array& array) {
  return py::str(array.dtype()).cast<std::string>() + " array of shape " + shape_text(array);
}

// numpy arrays as they are; DLPack exporters (torch tensors, ...) through numpy.from_dlpack, which
// shares their memory; anything else through numpy.asarray (__array__, sequences).
py::array to_numpy(const std::string& key, const py::handle& value) {
  if (py::isinstance<py::array>(value)) return py::reinterpret_borrow<py::array>(value);
  const py::module_ numpy = py::module_::import("numpy");
  try {
    if (py::hasattr(value, "__dlpack__")) return numpy.attr("from_dlpack")(value);
    return numpy.attr("asarray")(value);
  } catch (py::error_already_set& e) {
    throw py::value_error(key + ": cannot be read as an array: " + std::string(e.what()));
  }
}

// Drops LeRobot's leading batch dimension of 1 from an array that has one dimension too many.
py::array without_batch(py::array array, py::ssize_t ndim) {
  if (array.ndim() == ndim + 1 && array.shape(0) == 1) return array.attr("squeeze")(0);
  return array;
}

bool has_shape(const py::array& array, std::initializer_list<py::ssize_t> shape) {
  if (array.ndim() != static_cast<py::ssize_t>(shape.size())) return false;
  py::ssize_t d = 0;
  for (const py::ssize_t size : shape) {
    if (array.shape(d++) != size) return false;
  }
  return true;
}

std::string image_expectation(const CameraInfo& cam, bool allow_float) {
  const std::string h = std::to_string(cam.height), w = std::to_string(cam.width);
  std::string text = "uint8 " + h + "x" + w + "x3 (RGB, height x width x channels)";
  if (allow_float) text += " or float32 3x" + h + "x" + w + " (RGB channel-first, values in [0, 1])";
  return text;
}

std::string vector_expectation(size_t size) {
  return "a float vector of " + std::to_string(size) + " values";
}

// The image as a C-contiguous array of the format it has (a copy only when it is not contiguous).
py::array image_array(const std::string& key, const py::handle& value, const CameraInfo& cam, bool allow_float,
                      ImageView::Format& format) {
  py::array array = without_batch(to_numpy(key, value), 3);
  if (py::isinstance<py::array_t<uint8_t>>(array) && has_shape(array, {cam.height, cam.width, 3})) {
    format = ImageView::Format::kRgbU8Hwc;
    return py::array_t<uint8_t, py::array::c_style>::ensure(array);
  }
  if (allow_float && py::isinstance<py::array_t<float>>(array) && has_shape(array, {3, cam.height, cam.width})) {
    format = ImageView::Format::kRgbF32Chw;
    return py::array_t<float, py::array::c_style>::ensure(array);
  }
  throw py::value_error(key + ": expected " + image_expectation(cam, allow_float) + ", got " + describe(array));
}

// A floating-point vector of `size` values as contiguous float32, every value finite.
py::array_t<float> float_vector(const std::string& key, const py::handle& value, size_t size) {
  const py::array array = without_batch(to_numpy(key, value), 1);
  if (array.dtype().kind() != 'f' || !has_shape(array, {static_cast<py::ssize_t>(size)})) {
    throw py::value_error(key + ": expected " + vector_expectation(size) + ", got " + describe(array));
  }
  auto values = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(array);
  const float* data = values.data();
  for (size_t i = 0; i < size; ++i) {
    if (!std::isfinite(data[i])) {
      throw py::value_error(key + "[" + std::to_string(i) + "] is " + std::to_string(data[i]) +
                            ": every value must be finite");
    }
  }
  return values;
}

// The keys of `observation`, checked against the model's: each must be one of them.
void check_keys(const ModelInfo& info, const py::dict& observation) {
  std::vector<std::string> known;
  for (const CameraInfo& cam : info.cameras) known.push_back(cam.key);
  if (info.state_dim > 0) known.push_back(kStateKey);
  if (info.env_state_dim > 0) known.push_back(info.env_state_key);
  std::string known_text;
  for (const std::string& key : known) known_text += (known_text.empty() ? "" : ", ") + key;
  for (const auto& item : observation) {
    if (!py::isinstance<py::str>(item.first)) {
      throw py::value_error("observation keys are LeRobot feature names (str), got " +
                            py::repr(item.first).cast<std::string>());
    }
    const auto key = item.first.cast<std::string>();
    if (std::find(known.begin(), known.end(), key) == known.end()) {
      throw py::value_error("unknown observation key '" + key + "': the model takes " + known_text);
    }
  }
}

py::handle required(const py::dict& observation, const std::string& key, const std::string& expectation) {
  if (!observation.contains(key)) throw py::value_error("missing observation key '" + key + "': " + expectation);
  return observation[key.c_str()];
}

}  // namespace

HeldObservation observation_from_dict(const ModelInfo& info, const py::dict& observation) {
  check_keys(info, observation);
  HeldObservation held;
  for (const CameraInfo& cam : info.cameras) {
    ImageView::Format format{};
    py::array image = image_array(cam.key, required(observation, cam.key, image_expectation(cam, true)), cam, true, format);
    held.observation_.images.push_back(format == ImageView::Format::kRgbU8Hwc
        ? ImageView::rgb_u8(static_cast<const uint8_t*>(image.data()), cam.height, cam.width)
        : ImageView::rgb_f32_chw(static_cast<const float*>(image.data()), cam.height, cam.width));
    held.arrays_.push_back(std::move(image));
  }
  const auto add_vector = [&](const std::string& key, int size, std::span<const float>& span) {
    if (size == 0) return;
    const auto n = static_cast<size_t>(size);
    py::array_t<float> values = float_vector(key, required(observation, key, vector_expectation(n)), n);
    span = {values.data(), n};
    held.arrays_.push_back(std::move(values));
  };
  add_vector(kStateKey, info.state_dim, held.observation_.state);
  add_vector(info.env_state_key, info.env_state_dim, held.observation_.env_state);
  return held;
}

CalibrationFrame calibration_frame_from_dict(const ModelInfo& info, const py::dict& observation) {
  check_keys(info, observation);
  CalibrationFrame frame;
  for (const CameraInfo& cam : info.cameras) {
    ImageView::Format format{};
    const py::array image =
        image_array(cam.key, required(observation, cam.key, image_expectation(cam, false)), cam, false, format);
    const auto* pixels = static_cast<const uint8_t*>(image.data());
    frame.images.emplace_back(pixels, pixels + image.size());
  }
  const auto read_vector = [&](const std::string& key, int size, std::vector<float>& out) {
    if (size == 0 || !observation.contains(key)) return;  // absent: sampled from the statistics
    const py::array_t<float> values = float_vector(key, observation[key.c_str()], static_cast<size_t>(size));
    out.assign(values.data(), values.data() + values.size());
  };
  read_vector(kStateKey, info.state_dim, frame.state);
  read_vector(info.env_state_key, info.env_state_dim, frame.env_state);
  return frame;
}

py::array_t<float> float_matrix(const py::handle& value, const std::string& what, size_t rows, size_t cols) {
  const py::array array = to_numpy(what, value);
  if (array.dtype().kind() != 'f' ||
      !has_shape(array, {static_cast<py::ssize_t>(rows), static_cast<py::ssize_t>(cols)})) {
    throw py::value_error(what + ": expected a float array of shape (" + std::to_string(rows) + ", " +
                          std::to_string(cols) + "), got " + describe(array));
  }
  return py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(array);
}

}  // namespace act::python
