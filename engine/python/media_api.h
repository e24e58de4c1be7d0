// What actengine._media (media_module.cc) gives actengine._actengine: the calibration readers of
// actengine/calibration_files.h, through a capsule. They live in an extension of their own so that
// `import actengine` loads no OpenCV: _actengine imports _media on the first convert() whose calib
// holds paths, and a build without OpenCV has no _media (convert() then says so). Both extensions are
// built together, by one compiler, from one tree; kMediaApiVersion guards against a stale copy.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "actengine/convert.h"
#include "actengine/status.h"

namespace act::python {

inline constexpr const char* kMediaModule = "actengine._media";
inline constexpr const char* kMediaApiAttribute = "calibration_files_api";
inline constexpr const char* kMediaApiCapsule = "actengine._media.calibration_files_api";
inline constexpr int kMediaApiVersion = 1;

struct MediaApi {
  int version;
  /// load_calibration_frames: the frames of `sources` into `set`, how many the sources hold in
  /// `given`; its act::Error as the Status returned (no exception crosses the extensions).
  Status (*load_calibration_frames)(const std::vector<std::string>& sources, const ModelInfo& model, size_t max_frames,
                                    CalibrationSet& set, size_t& given);
};

}  // namespace act::python
