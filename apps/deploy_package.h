// `act_convert --package DIR`: everything the robot needs beside the installed actengine .deb, and
// what LeRobot's commands need to load DIR as --policy.path.
#pragma once

#include <string>

#include "actengine/engine.h"

namespace act {

/// The blob's file name inside a package folder.
inline constexpr const char* kPackageBlobName = "model.actb";

/// Creates the package folder if needed and returns the blob's path in it. Throws act::Error(kIoError).
std::string prepare_package_dir(const std::string& dir);

/// Writes DIR/drive_calibration.json (a template for this model's actions and cameras) and
/// DIR/README.md (how to install and run on the Raspberry Pi); the blob DIR/model.actb is written
/// by the caller. `source` names the converted checkpoint. Existing calibration files are kept (they
/// hold a robot's measured values); the README is rewritten. Throws act::Error(kIoError).
void write_deploy_package(const std::string& dir, const ModelInfo& model, const std::string& source);

/// Writes what LeRobot's `--policy.path DIR` loads beside the blob (write_deploy_package calls it):
/// DIR/config.json of policy type "actengine" (the plugin engine/python/lerobot_policy_actengine) with
/// the model's input and output features, and DIR/policy_preprocessor.json / policy_postprocessor.json
/// without normalising steps (the blob normalises). Rewritten each time. Throws act::Error(kIoError).
void write_lerobot_files(const std::string& dir, const ModelInfo& model);

}  // namespace act
