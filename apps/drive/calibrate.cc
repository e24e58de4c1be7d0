#include "apps/drive/calibrate.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <sstream>
#include <thread>

#include "actengine/status.h"
#include "apps/drive/calibration.h"
#include "apps/drive/serial_link.h"

namespace act::drive {
namespace {

constexpr const char* kHelp =
    "commands (one per line):\n"
    "  s <us>        steering pulse width, e.g. s 1400       t <us>   throttle pulse width (wheels off the ground!)\n"
    "  left | center | right        store the current steering pulse as that endpoint\n"
    "  reverse | neutral | forward  store the current throttle pulse as that endpoint\n"
    "  invert-steering | invert-throttle   toggle the direction flags\n"
    "  show          print the calibration so far      save   write it to the output file\n"
    "  quit          send neutral and exit\n";

constexpr const char* kTemplateNotes =
    "Edit the pulse widths (microseconds) for your servo and ESC:\n"
    "  steering.left_us / center_us / right_us     where the wheels point full left, straight, full right\n"
    "  throttle.reverse_us / neutral_us / forward_us  full reverse, stopped, full forward\n"
    "  invert          true if the model's +1 should mean left / reverse on this car\n"
    "  max_forward / max_reverse   throttle cap as a fraction of full (0.3 here: raise it slowly)\n"
    "  rate_limit_us_per_s         largest pulse change per second (0 = unlimited)\n"
    "  action_index    which action value drives the channel; action_units: normalized (-1..1) or microseconds\n"
    "Or run: act_drive --calibrate --serial /dev/ttyUSB0 -c calibration.json to find them interactively.\n";

// Sends the current command several times a second so the board's 250 ms watchdog stays quiet.
class CommandKeeper {
 public:
  explicit CommandKeeper(SerialLink& link) : link_(link), thread_([this] { run(); }) {}
  ~CommandKeeper() {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    thread_.join();
  }
  void set(PwmCommand command) {
    std::lock_guard lock(mutex_);
    command_ = command;
  }

 private:
  void run() {
    for (;;) {
      PwmCommand command;
      {
        std::lock_guard lock(mutex_);
        if (stop_) return;
        command = command_;
      }
      link_.send(command, Clock::now());
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  }
  SerialLink& link_;
  std::mutex mutex_;
  PwmCommand command_;  // guarded by mutex_
  bool stop_ = false;   // guarded by mutex_
  std::thread thread_;
};

// Without a port: the template (or the file being edited) printed, or with -c FILE written to FILE
// when there is none yet (an existing file is left as it is: it may hold measured values).
int print_or_write_template(const Calibration& calibration, const std::string& path, bool existed, std::ostream& out,
                            std::ostream& log) {
  if (path.empty()) {
    out << calibration.to_json().dump(2) << "\n";
    log << kTemplateNotes;
    return 0;
  }
  if (existed) {
    log << "act_drive --calibrate: " << path << " exists: left as it is (edit it, or measure the endpoints with "
        << "act_drive --calibrate --serial PORT -c " << path << "; act_drive --list-ports lists the ports)\n";
    return 0;
  }
  std::ofstream file(path);
  file << calibration.to_json().dump(2) << "\n";
  file.close();
  if (!file) fail(StatusCode::kIoError, "--calibrate: cannot write " + path);
  log << "act_drive --calibrate: wrote a calibration template to " << path << "\n" << kTemplateNotes;
  return 0;
}

}  // namespace

int run_calibration(const CalibrateOptions& options, const std::atomic<bool>& stop, std::istream& in, std::ostream& out,
                    std::ostream& log) {
  const std::string output = options.output_path.empty() ? "calibration.json" : options.output_path;
  // Start from the file being edited, so one channel can be re-measured without losing the other.
  const bool existed = std::filesystem::exists(output);
  Calibration calibration = existed ? Calibration::load(output) : Calibration::starting_template();
  if (options.serial.empty()) return print_or_write_template(calibration, options.output_path, existed, out, log);
  SerialLinkOptions serial_options;
  serial_options.path = options.serial;
  serial_options.baud = options.baud;
  serial_options.failsafe = calibration.safe_command();
  SerialLink link(serial_options, log);
  link.connect();
  PwmCommand current = calibration.safe_command();
  {
    CommandKeeper keeper(link);
    out << "act_drive --calibrate: board ready on " << options.serial << "; holding " << current.steering_us << " / "
        << current.throttle_us << " us\n" << kHelp;
    std::string line;
    while (!stop.load() && out << "> " << std::flush && std::getline(in, line)) {
      std::istringstream words(line);
      std::string command;
      int value = 0;
      words >> command;
      if (command.empty()) continue;
      if (command == "quit" || command == "q") break;
      if (command == "help") {
        out << kHelp;
      } else if ((command == "s" || command == "t") && words >> value) {
        const uint16_t us = static_cast<uint16_t>(std::clamp(value, ROVER_PWM_MIN_US, ROVER_PWM_MAX_US));
        (command == "s" ? current.steering_us : current.throttle_us) = us;
        keeper.set(current);
        out << (command == "s" ? "steering " : "throttle ") << us << " us\n";
      } else if (command == "left" || command == "center" || command == "right") {
        ChannelCalibration& ch = calibration.steering;
        (command == "left" ? ch.low_us : command == "center" ? ch.mid_us : ch.high_us) = current.steering_us;
        out << "steering " << command << " = " << current.steering_us << " us\n";
      } else if (command == "reverse" || command == "neutral" || command == "forward") {
        ChannelCalibration& ch = calibration.throttle;
        (command == "reverse" ? ch.low_us : command == "neutral" ? ch.mid_us : ch.high_us) = current.throttle_us;
        out << "throttle " << command << " = " << current.throttle_us << " us\n";
      } else if (command == "invert-steering" || command == "invert-throttle") {
        bool& flag = command == "invert-steering" ? calibration.steering.invert : calibration.throttle.invert;
        flag = !flag;
        out << command << " = " << (flag ? "true" : "false") << "\n";
      } else if (command == "show") {
        out << calibration.to_json().dump(2) << "\n";
      } else if (command == "save") {
        try {
          Calibration::from_json(calibration.to_json(), "being saved");  // the same checks act_drive applies
          std::ofstream file(output);
          file << calibration.to_json().dump(2) << "\n";
          if (!file) fail(StatusCode::kIoError, "cannot write " + output);
          out << "saved " << output << "\n";
        } catch (const Error& e) {
          out << "not saved: " << e.what() << "\n";
        }
      } else {
        out << "unknown command '" << line << "'\n" << kHelp;
      }
    }
  }
  link.shutdown(calibration.safe_command());
  return 0;
}

}  // namespace act::drive
