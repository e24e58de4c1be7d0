// Helpers for model-level tests: convert checkpoints into blobs, compare tensors with references.
#pragma once

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "actengine/convert.h"
#include "weights/import/safetensors.h"

namespace act::test {

/// act_convert in-process: imports `checkpoint_dir` and writes `<scratch>/<stem>.actb`; returns its path.
/// The first conversion of a checkpoint by a test binary is kept in `converted_checkpoints/` beside
/// the binary; later calls (any process) copy it while neither the checkpoint's files nor the binary change.
std::string convert_checkpoint(const std::string& checkpoint_dir, const std::string& scratch, const std::string& stem = "model");

/// INT8 options for a quick conversion in a test: 8 calibration frames and 3 held out, 2 threads, no
/// per-layer report.
Int8Options quick_int8_options(Int8Mode mode = Int8Mode::kStatic);

/// NCHW (batch 1) -> HWC, the engine's layout.
std::vector<float> nchw_to_hwc(const float* src, int channels, int height, int width);

/// Asserts |ours - ref| <= tol * (1 + |ref|) elementwise; reports the worst element.
::testing::AssertionResult all_close(const std::string& what, const float* ours, const float* ref, size_t n, double tol);

/// Writes a copy of safetensors file `src` to `dst` with every value of F32 tensor `name` from index
/// `first` on replaced by `value`.
void write_with_values_replaced(const std::string& src, const std::string& dst, const std::string& name, size_t first,
                                float value);

/// Copies a checkpoint folder into `dst` with config.json fields replaced by `config_patch` (a JSON
/// object merged into the config); big files are symlinked.
void patch_checkpoint(const std::string& src, const std::string& dst, const std::string& config_patch_json);

}  // namespace act::test
