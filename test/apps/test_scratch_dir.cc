// The tests' scratch folders (support/test_paths.h): a passed test's folder is removed when the test
// ends, a failed test's folder stays for inspection. Checked on a child run of this very program
// with two helper tests (disabled, so they run only there): one passes, one fails on purpose.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "support/command.h"
#include "support/test_paths.h"

namespace fs = std::filesystem;

namespace {

void write_a_file_in_scratch() { std::ofstream(fs::path(act::test::scratch_dir()) / "output.bin") << "data"; }

TEST(ScratchDirHelper, DISABLED_Passes) { write_a_file_in_scratch(); }

TEST(ScratchDirHelper, DISABLED_Fails) {
  write_a_file_in_scratch();
  ADD_FAILURE() << "deliberate failure: this helper's scratch folder must be kept";
}

TEST(ScratchDir, PassedTestsFolderIsRemovedAFailedOnesKept) {
  const fs::path base = act::test::scratch_dir();
  const fs::path self = act::test::this_executable();
  ASSERT_FALSE(self.empty());
  for (const std::string keep : {"", "1"}) {
    const fs::path tmp = base / ("keep" + keep);
    const auto run = act::test::run_command("ACT_KEEP_SCRATCH=" + keep + " ACT_TEST_TMP=" + act::test::q(tmp.string()) + " " +
                                            act::test::q(self.string()) +
                                            " --gtest_also_run_disabled_tests --gtest_filter='ScratchDirHelper.*'");
    EXPECT_NE(run.exit_code, 0) << run.output;  // the helper that fails on purpose
    EXPECT_NE(run.output.find("1 FAILED TEST"), std::string::npos) << run.output;
    EXPECT_EQ(fs::exists(tmp / "act_scratch" / "ScratchDirHelper.DISABLED_Passes"), keep == "1") << "ACT_KEEP_SCRATCH=" << keep;
    EXPECT_TRUE(fs::exists(tmp / "act_scratch" / "ScratchDirHelper.DISABLED_Fails" / "output.bin")) << "ACT_KEEP_SCRATCH=" << keep;
  }
}

}  // namespace
