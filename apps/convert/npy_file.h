// NumPy .npy files (format version 1.0): a magic string, a small Python-dict header giving dtype,
// order and shape, then the raw little-endian data. act_convert --export-calib writes the calibration
// frames so for compilers that calibrate on NumPy arrays (the Hailo Dataflow Compiler).
#pragma once

#include <cstdint>
#include <vector>

#include "weights/blob/file_util.h"

namespace act {

/// Writes `values` as a C-order float32 array of `shape` into `out` (the caller commits it, so that
/// several files appear together or not at all). Throws act::Error (kIoError naming the path;
/// kInvalidArgument when the shape does not hold the values).
void write_npy_f32(detail::AtomicFileWriter& out, const std::vector<int64_t>& shape, const std::vector<float>& values);

}  // namespace act
