#include "apps/executable_dir.h"

#include <system_error>

#include "actengine/status.h"

namespace act {

std::filesystem::path executable_dir() {
  std::error_code error;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", error);
  check(!error, StatusCode::kIoError, "cannot find the program's own folder (/proc/self/exe): " + error.message());
  return self.parent_path();
}

}  // namespace act
