// Python observation dicts (LeRobot feature names -> arrays) to the public API's act::Observation and
// act::CalibrationFrame. Arrays come from numpy, anything with __array__, or DLPack (a torch tensor is
// read without importing torch); a non-contiguous array is copied, a wrong key, shape or dtype raises
// ValueError naming the key and what the model expects. Needs the GIL.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <vector>

#include "actengine/convert.h"
#include "actengine/engine.h"

namespace act::python {

/// LeRobot's key of the robot state (ModelInfo names the cameras and the environment state only).
inline constexpr const char* kStateKey = "observation.state";

/// An Observation whose views point into arrays it keeps alive.
class HeldObservation {
 public:
  const Observation& view() const { return observation_; }

 private:
  friend HeldObservation observation_from_dict(const ModelInfo& info, const pybind11::dict& observation);
  std::vector<pybind11::array> arrays_;
  Observation observation_;
};

/// Reads an observation for `info`'s model: every camera key and the state keys it takes, no others.
/// Images uint8 HxWx3 (RGB) or float32 3xHxW in [0, 1], states floating-point vectors; each may carry
/// a leading batch dimension of 1 (LeRobot adds one).
HeldObservation observation_from_dict(const ModelInfo& info, const pybind11::dict& observation);

/// One calibration frame from an observation dict: uint8 HxWx3 images at the model's input size
/// (calibration sees the pixels the robot's camera gives); states optional (sampled when absent).
CalibrationFrame calibration_frame_from_dict(const ModelInfo& info, const pybind11::dict& observation);

/// `value` as a C-contiguous float32 array of shape (rows, cols), for `what` in error messages.
pybind11::array_t<float> float_matrix(const pybind11::handle& value, const std::string& what, size_t rows, size_t cols);

}  // namespace act::python
