#include "apps/deploy_package.h"

#include <filesystem>
#include <sstream>

#include <nlohmann/json.hpp>

#include "weights/error.h"
#include "weights/file_util.h"

namespace act {

namespace {

namespace fs = std::filesystem;

void write_text(const fs::path& path, const std::string& text) {
  detail::AtomicFileWriter out(path.string());
  out.write(text.data(), text.size());
  out.commit();
}

// One entry per action dimension: how a raw action value becomes an actuator command. The values
// are placeholders to measure on the robot (act_drive reads the file; see its --help).
std::string calibration_template(const ModelConfig& m) {
  nlohmann::ordered_json j;
  j["_comment"] = "Template written by act_convert --package: fill in the values measured on your robot. "
                  "Each action dimension maps linearly to an actuator command: command = clamp(action * scale + offset, min, max).";
  j["model"] = kPackageBlobName;
  j["control_hz"] = 30;
  j["n_action_steps"] = m.n_action_steps;
  nlohmann::ordered_json actions = nlohmann::ordered_json::array();
  for (int i = 0; i < m.action_dim; ++i) {
    const char* name = m.action_dim == 2 ? (i == 0 ? "steering" : "throttle") : "";
    actions.push_back({{"index", i}, {"name", name[0] ? name : ("action" + std::to_string(i))}, {"output", "pwm"},
                       {"channel", i}, {"scale", 1.0}, {"offset", 0.0}, {"min", -1.0}, {"max", 1.0},
                       {"pulse_us", {{"min", 1000}, {"center", 1500}, {"max", 2000}}}});
  }
  j["actions"] = actions;
  nlohmann::ordered_json cameras = nlohmann::ordered_json::array();
  for (size_t i = 0; i < m.cameras.size(); ++i) {
    const auto& c = m.cameras[i];
    cameras.push_back({{"key", c.key}, {"device", "/dev/video" + std::to_string(i)}, {"width", c.width}, {"height", c.height}});
  }
  j["cameras"] = cameras;
  if (m.state_dim > 0) {
    j["state"] = {{"key", m.state_key}, {"dim", m.state_dim}, {"_comment", "where each state value comes from (e.g. the last command sent)"}};
  }
  j["safety"] = {{"stop_if_no_frame_ms", 200}, {"max_throttle", 0.3}};
  return j.dump(2) + "\n";
}

std::string readme(const ModelConfig& m, const std::string& source) {
  std::ostringstream r;
  r << "# ACT model for the robot\n\n"
    << "Converted by `act_convert` from `" << source << "`.\n\n"
    << "- `" << kPackageBlobName << "`: the model (" << m.summary() << ")\n"
    << "- `drive_calibration.json`: how actions become actuator commands; a template, fill in your robot's values\n\n"
    << "## On the desktop\n\n"
    << "Build the Debian packages (amd64 and, cross-compiled, arm64 for the Raspberry Pi 5) from the actengine\n"
    << "checkout:\n\n"
    << "    ./scripts/build_packages.sh          # -> build-packages/actengine_<version>_arm64.deb (and _amd64)\n\n"
    << "Copy the arm64 package and this folder to the Pi:\n\n"
    << "    scp build-packages/actengine_*_arm64.deb pi@rover.local:\n"
    << "    scp -r THIS_FOLDER pi@rover.local:model\n\n"
    << "## On the Raspberry Pi (64-bit Raspberry Pi OS / Debian bookworm)\n\n"
    << "    sudo apt install ./actengine_*_arm64.deb\n"
    << "    act_bench --model model/" << kPackageBlobName << " --threads 4      # speed and memory on this board\n"
    << "    act_drive --model model/" << kPackageBlobName << " --calibration model/drive_calibration.json\n\n"
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

void write_deploy_package(const std::string& dir, const ModelConfig& model, const std::string& source) {
  const fs::path calibration = fs::path(dir) / "drive_calibration.json";
  if (!fs::exists(calibration)) write_text(calibration, calibration_template(model));
  write_text(fs::path(dir) / "README.md", readme(model, source));
}

}  // namespace act
