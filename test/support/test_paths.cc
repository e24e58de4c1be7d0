#include "support/test_paths.h"

#include <cstdlib>
#include <filesystem>
#include <string>
#include <utility>

namespace fs = std::filesystem;

namespace act::test {

namespace {

bool env_equals(const char* name, const std::string& value) {
  const char* set = std::getenv(name);
  return set != nullptr && set == value;
}

}  // namespace

bool running_in_ci() { return env_equals("CI", "true"); }

std::filesystem::path this_executable() {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path() : exe;
}

std::string fixture_dir(const std::string& name) {
  return (fs::path(ACT_SHARED_DIR) / "fixtures" / name).string();
}

std::string fixture_image(int i) {
  return fixture_dir("act-tiny") + "/sample" + std::to_string(i) + ".observation.images.front.png";
}

std::string generated_checkpoint_dir(const std::string& name) {
  return (fs::path(ACT_TEST_DATA_DIR) / name).string();
}

namespace {

// Removes a test's scratch folder when the test ends unless it failed: a CI run's tests write about
// 15 GB of blobs, ONNX files and recordings, more than a CI machine's disk may have free. A failed
// test's folder stays for inspection (ACT_KEEP_SCRATCH=1 keeps every folder).
class RemoveScratchOfPassedTests : public testing::EmptyTestEventListener {
 public:
  void OnTestEnd(const testing::TestInfo& info) override {
    if (current_.empty()) return;
    const fs::path dir = std::exchange(current_, {});
    if (info.result()->Failed() || env_equals("ACT_KEEP_SCRATCH", "1")) return;
    std::error_code ec;  // best effort: a folder the test left busy only costs disk
    fs::remove_all(dir, ec);
  }
  void set_current(const fs::path& dir) { current_ = dir; }

 private:
  fs::path current_;
};

RemoveScratchOfPassedTests& scratch_remover() {
  // Owned by gtest's listener list once appended (it deletes its listeners at exit).
  static RemoveScratchOfPassedTests* remover = [] {
    auto* r = new RemoveScratchOfPassedTests;
    testing::UnitTest::GetInstance()->listeners().Append(r);
    return r;
  }();
  return *remover;
}

}  // namespace

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
  scratch_remover().set_current(dir);
  return dir.string();
}

}  // namespace act::test
