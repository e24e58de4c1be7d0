#include "apps/drive/devices.h"

#include <libserialport.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "actengine/status.h"

namespace act::drive {
namespace {

namespace fs = std::filesystem;

std::string text_or(const char* text, const char* fallback) { return text && *text ? text : fallback ? fallback : ""; }

}  // namespace

void list_cameras(std::ostream& out) {
  std::vector<std::pair<std::string, std::string>> cameras;  // device, driver's name
  std::error_code ec;
  for (const fs::directory_entry& entry : fs::directory_iterator("/sys/class/video4linux", ec)) {
    const std::string device = entry.path().filename().string();
    if (device.rfind("video", 0) != 0) continue;
    std::string name;
    std::getline(std::ifstream(entry.path() / "name"), name);
    cameras.emplace_back("/dev/" + device, name);
  }
  std::sort(cameras.begin(), cameras.end());
  if (cameras.empty()) out << "no V4L2 cameras (/sys/class/video4linux is empty); a video file, an image sequence, a URL "
                              "or a GStreamer pipeline also work as --camera\n";
  for (const auto& [device, name] : cameras) out << device << "  " << text_or(name.c_str(), "(no name)") << "\n";
}

void list_ports(std::ostream& out) {
  sp_port** ports = nullptr;
  if (sp_list_ports(&ports) != SP_OK) {
    char* message = sp_last_error_message();
    const std::string why = text_or(message, "unknown error");
    sp_free_error_message(message);
    fail(StatusCode::kIoError, "--list-ports: cannot list serial ports: " + why);
  }
  int count = 0;
  for (sp_port** port = ports; *port; ++port, ++count) {
    out << sp_get_port_name(*port) << "  ";
    if (sp_get_port_transport(*port) == SP_TRANSPORT_USB) {
      int vid = 0, pid = 0;
      char id[16] = "";
      if (sp_get_port_usb_vid_pid(*port, &vid, &pid) == SP_OK) std::snprintf(id, sizeof id, "%04x:%04x ", vid, pid);
      out << "USB " << id << text_or(sp_get_port_usb_manufacturer(*port), "") << " "
          << text_or(sp_get_port_usb_product(*port), sp_get_port_description(*port)) << "\n";
    } else {
      out << text_or(sp_get_port_description(*port), "") << "\n";
    }
  }
  sp_free_port_list(ports);
  if (count == 0) out << "no serial ports found (is the board plugged in? an Arduino is /dev/ttyUSB* or /dev/ttyACM*)\n";
}

}  // namespace act::drive
