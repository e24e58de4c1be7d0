// act_drive --calibrate: find the servo and ESC endpoints by hand over the serial link, or (without a
// port) write a calibration file to edit to -c FILE (print it without -c).
#pragma once

#include <atomic>
#include <istream>
#include <ostream>
#include <string>

namespace act::drive {

struct CalibrateOptions {
  std::string serial;       ///< empty: write (or print) a template instead of talking to the board
  int baud = 115200;
  std::string output_path;  ///< the file edited: its values are the start, "save" writes it (default calibration.json)
};

/// Reads commands from `in` (one per line, "help" lists them) until "quit", end of input or `stop`.
/// Returns the process exit code.
int run_calibration(const CalibrateOptions& options, const std::atomic<bool>& stop, std::istream& in, std::ostream& out,
                    std::ostream& log);

}  // namespace act::drive
