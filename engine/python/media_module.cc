// actengine._media: the calibration readers (actengine/calibration_files.h: image folders, videos,
// LeRobot datasets, act_drive recordings, observation files) for actengine.convert(calib=paths), as
// act_convert --calib reads them. Built where OpenCV is; media_api.h says why it is an extension of
// its own. Its image and video decoding comes from libact_media_io.so in the same folder, loaded on
// first use (engine/media/media_io.h).
#include <pybind11/pybind11.h>

#include <utility>

#include "actengine/calibration_files.h"
#include "media_api.h"

namespace act::python {
namespace {

Status load(const std::vector<std::string>& sources, const ModelInfo& model, size_t max_frames, CalibrationSet& set,
            size_t& given) {
  StatusOr<CalibrationSet> read = load_calibration_frames(sources, model, max_frames, &given);
  if (!read.ok()) return read.status();
  set = std::move(read).value();
  return Status();
}

const MediaApi kApi{kMediaApiVersion, &load};

}  // namespace
}  // namespace act::python

PYBIND11_MODULE(_media, m) {
  m.doc() = "actengine's calibration readers (frame folders, videos, LeRobot datasets, recordings), for actengine.convert";
  m.attr(act::python::kMediaApiAttribute) =
      pybind11::capsule(const_cast<act::python::MediaApi*>(&act::python::kApi), act::python::kMediaApiCapsule);
}
