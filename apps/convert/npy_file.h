// NumPy .npy files (format version 1.0): a magic string, a small Python-dict header giving dtype,
// order and shape, then the raw little-endian data. act_convert --export-calib writes the calibration
// frames so for compilers that calibrate on NumPy arrays (the Hailo Dataflow Compiler).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace act {

/// Writes `values` as a C-order float32 array of `shape`, atomically (nothing at `path` on failure).
/// Throws act::Error (kIoError naming the path; kInvalidArgument when the shape does not hold the values).
void write_npy_f32(const std::string& path, const std::vector<int64_t>& shape, const std::vector<float>& values);

}  // namespace act
