// The running program's own folder, where act_drive finds act_pwm_watchdog.
#pragma once

#include <filesystem>

namespace act {

/// The folder of /proc/self/exe. Throws act::Error (kIoError) when it cannot be read.
std::filesystem::path executable_dir();

}  // namespace act
