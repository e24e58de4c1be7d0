// The internals behind the public conversion API's handles (actengine/convert.h).
#pragma once

#include "actengine/convert.h"
#include "weights/import/config_inference.h"
#include "weights/import/lerobot_import.h"

namespace act {

class PthPlan::Impl {
 public:
  PyTorchConversion plan;
};

class ImportedCheckpoint::Impl {
 public:
  ImportedModel model;
};

}  // namespace act
