#include "apps/deploy_package.h"

#include <filesystem>
#include <sstream>

#include <nlohmann/json.hpp>

#include "actengine/status.h"
#include "apps/drive/calibration.h"
#include "weights/blob/file_util.h"

namespace act {

namespace {

namespace fs = std::filesystem;

void write_text(const fs::path& path, const std::string& text) {
  detail::AtomicFileWriter out(path.string());
  out.write(text.data(), text.size());
  out.commit();
}

// act_drive's calibration file (apps/drive/calibration.h) with placeholder endpoints and a low
// throttle cap, plus comments on what to measure and which act_drive flags set the rest.
std::string calibration_template(const ModelInfo& m) {
  const drive::Calibration calibration = drive::Calibration::starting_template();
  nlohmann::ordered_json j;
  j["_comment"] = "Written by act_convert --package: act_drive's calibration file (README, act_drive). The pulse "
                  "widths are placeholders: measure your servo and ESC with act_drive --calibrate --serial PORT -c "
                  "drive_calibration.json. Keep the throttle cap low for the first runs.";
  std::string model = "action_dim " + std::to_string(m.action_dim) + " (steering = action " +
                      std::to_string(calibration.steering.action_index) + ", throttle = action " +
                      std::to_string(calibration.throttle.action_index) + "), n_action_steps " +
                      std::to_string(m.n_action_steps);
  for (const CameraInfo& camera : m.cameras) {
    const std::string size = std::to_string(camera.height) + "x" + std::to_string(camera.width);  // HxW, as everywhere
    model += ", camera " + camera.key + " " + size + " (act_drive --camera-size " + size + ")";
  }
  j["_model"] = model;
  const nlohmann::ordered_json fields = calibration.to_json();
  for (const auto& [key, value] : fields.items()) j[key] = value;
  return j.dump(2) + "\n";
}

nlohmann::ordered_json feature(const char* type, std::initializer_list<int> shape) {
  return {{"type", type}, {"shape", nlohmann::ordered_json(shape)}};
}

// config.json of LeRobot's policy type "actengine" (the lerobot_policy_actengine plugin,
// engine/python/lerobot_policy_actengine): PreTrainedConfig's fields with the checkpoint's input and
// output features, so LeRobot checks them against the robot's and the dataset's as for its own ACT,
// plus the blob's chunking (the plugin checks it against the blob) and where normalisation happens.
std::string lerobot_config(const ModelInfo& m) {
  nlohmann::ordered_json inputs = nlohmann::ordered_json::object();
  if (m.state_dim > 0) inputs["observation.state"] = feature("STATE", {m.state_dim});
  if (m.env_state_dim > 0) inputs[m.env_state_key] = feature("ENV", {m.env_state_dim});
  for (const CameraInfo& camera : m.cameras) inputs[camera.key] = feature("VISUAL", {3, camera.height, camera.width});
  nlohmann::ordered_json j;
  j["type"] = "actengine";
  j["n_obs_steps"] = 1;
  j["input_features"] = inputs;
  j["output_features"] = {{"action", feature("ACTION", {m.action_dim})}};
  j["device"] = "cpu";
  j["use_amp"] = false;
  j["use_peft"] = false;
  j["push_to_hub"] = false;
  for (const char* unset : {"repo_id", "private", "tags", "license", "pretrained_path", "pretrained_revision"}) j[unset] = nullptr;
  j["chunk_size"] = m.chunk_size;
  j["n_action_steps"] = m.n_action_steps;
  j["temporal_ensemble_coeff"] = m.temporal_ensembling ? nlohmann::ordered_json(m.temporal_ensemble_coeff) : nullptr;
  j["blob"] = kPackageBlobName;
  j["normalization"] = "blob";  // the blob normalises: the processors below do not
  j["threads"] = 0;
  j["isa"] = "auto";
  return j.dump(4) + "\n";
}

nlohmann::ordered_json device_step() {
  return {{"registry_name", "device_processor"}, {"config", {{"device", "cpu"}, {"float_dtype", nullptr}}}};
}

// The processors make_pre_post_processors loads: those of LeRobot's ACT without the normaliser and
// the unnormaliser (the blob normalises), so they hold no statistics and need no state files.
std::string lerobot_preprocessor() {
  nlohmann::ordered_json steps = nlohmann::ordered_json::array();
  steps.push_back({{"registry_name", "rename_observations_processor"}, {"config", {{"rename_map", nlohmann::ordered_json::object()}}}});
  steps.push_back({{"registry_name", "to_batch_processor"}, {"config", nlohmann::ordered_json::object()}});
  steps.push_back(device_step());
  return nlohmann::ordered_json{{"name", "policy_preprocessor"}, {"steps", steps}}.dump(2) + "\n";
}

std::string lerobot_postprocessor() {
  return nlohmann::ordered_json{{"name", "policy_postprocessor"}, {"steps", {device_step()}}}.dump(2) + "\n";
}

std::string readme(const ModelInfo& m, const std::string& source) {
  std::ostringstream r;
  r << "# ACT model for the robot\n\n"
    << "Converted by `act_convert` from `" << source << "`.\n\n"
    << "- `" << kPackageBlobName << "`: the model (" << m.summary << ")\n"
    << "- `drive_calibration.json`: how actions become actuator commands; a template, fill in your robot's values\n"
    << "- `config.json`, `policy_preprocessor.json`, `policy_postprocessor.json`: this folder as LeRobot's\n"
    << "  `--policy.path` (policy type `actengine`; needs `pip install actengine lerobot_policy_actengine`)\n\n"
    << "## With LeRobot\n\n"
    << "In the Python environment LeRobot runs in, install the wheel and the plugin built from the actengine\n"
    << "checkout (`pip install ./actengine-checkout ./actengine-checkout/engine/python/lerobot_policy_actengine`), then\n"
    << "give LeRobot's commands this folder: `lerobot-record ... --policy.path=THIS_FOLDER`.\n\n"
    << "## On the desktop\n\n"
    << "Build the Debian packages (amd64 and, cross-compiled, arm64 for the Raspberry Pi 5) from the actengine\n"
    << "checkout:\n\n"
    << "    ./scripts/build_packages.sh   # -> build-packages/{libactengine0,actengine-tools,libactengine-dev}_<version>_arm64.deb (and _amd64)\n\n"
    << "Copy the arm64 tools package (the apps; they link libactengine statically) and this folder to the Pi:\n\n"
    << "    scp build-packages/actengine-tools_*_arm64.deb pi@rover.local:\n"
    << "    scp -r THIS_FOLDER pi@rover.local:model\n\n"
    << "## On the Raspberry Pi (64-bit Raspberry Pi OS / Debian bookworm)\n\n"
    << "    sudo apt install ./actengine-tools_*_arm64.deb\n"
    << "    act_bench --model model/" << kPackageBlobName << " --threads 4      # speed and memory on this board\n"
    << "    act_drive --calibrate --serial /dev/ttyUSB0 -c model/drive_calibration.json   # measure the endpoints\n"
    << "    act_drive --model model/" << kPackageBlobName << " --calibration model/drive_calibration.json --camera 0 "
       "--serial /dev/ttyUSB0\n\n"
    << "Run `act_bench` first: it tells you the inference time per chunk, which bounds the control rate\n"
    << "(`control_hz` x `n_action_steps`). Check `act_drive --help` for its options. Keep the wheels off the\n"
    << "ground for the first run of `act_drive`.\n";
  return r.str();
}

}  // namespace

std::string prepare_package_dir(const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) fail(StatusCode::kIoError, "cannot create package folder " + dir + ": " + ec.message());
  return (fs::path(dir) / kPackageBlobName).string();
}

void write_deploy_package(const std::string& dir, const ModelInfo& model, const std::string& source) {
  const fs::path calibration = fs::path(dir) / "drive_calibration.json";
  if (!fs::exists(calibration)) write_text(calibration, calibration_template(model));
  write_text(fs::path(dir) / "README.md", readme(model, source));
  write_lerobot_files(dir, model);
}

void write_lerobot_files(const std::string& dir, const ModelInfo& model) {
  write_text(fs::path(dir) / "config.json", lerobot_config(model));
  write_text(fs::path(dir) / "policy_preprocessor.json", lerobot_preprocessor());
  write_text(fs::path(dir) / "policy_postprocessor.json", lerobot_postprocessor());
}

}  // namespace act
