#include "support/test_paths.h"

#include <cstdlib>
#include <filesystem>

namespace fs = std::filesystem;

namespace act::test {

bool running_in_ci() {
  const char* ci = std::getenv("CI");
  return ci != nullptr && std::string(ci) == "true";
}

std::string fixture_dir(const std::string& name) {
  return (fs::path(ACT_SHARED_DIR) / "fixtures" / name).string();
}

std::string generated_checkpoint_dir(const std::string& name) {
  return (fs::path(ACT_TEST_DATA_DIR) / name).string();
}

std::string scratch_dir() {
  const testing::TestInfo* info = testing::UnitTest::GetInstance()->current_test_info();
  std::string leaf = std::string(info->test_suite_name()) + "." + info->name();
  for (char& c : leaf) {
    if (c == '/') c = '_';
  }
  const char* base = std::getenv("ACT_TEST_TMP");
  fs::path dir = fs::path(base ? base : fs::temp_directory_path().string()) / "act_scratch" / leaf;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

}  // namespace act::test
