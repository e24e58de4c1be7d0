// The tools' --version: "act_convert 0.1.0", the project version from the top CMakeLists.txt (a
// compile definition of version.cc, the same one the library's act::version() gets).
#pragma once

#include <string>

namespace act {

/// "<tool> <version>", what every tool's --version prints.
std::string version_line(const std::string& tool);

}  // namespace act
