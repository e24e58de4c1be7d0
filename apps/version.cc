#include "apps/version.h"

#ifndef ACT_VERSION
#error "ACT_VERSION (the project version) must be defined: apps/CMakeLists.txt passes it"
#endif

namespace act {

std::string version_line(const std::string& tool) { return tool + " " + ACT_VERSION; }

}  // namespace act
