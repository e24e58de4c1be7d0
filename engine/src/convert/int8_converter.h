// The INT8 conversion behind ImportedCheckpoint::write_int8: calibration passes over the FP32
// network, the dynamic / static / mixed blob, and the accuracy report against the FP32 model on
// held-out frames.
#pragma once

#include <string>

#include "actengine/convert.h"
#include "weights/import/lerobot_import.h"

namespace act {

/// Writes the INT8 blob of `model` at `output` (atomically: on any error, or when max_mse is
/// missed, nothing is written; intermediate blobs are unnamed files). Throws act::Error.
Int8Report convert_to_int8(const ImportedModel& model, const std::string& output, const CalibrationSet& calibration,
                           const Int8Options& options);

/// `v` as printf's `printf_format` writes it: the numbers in the converter's messages and report.
std::string format_number(double v, const char* printf_format = "%.3g");

}  // namespace act
