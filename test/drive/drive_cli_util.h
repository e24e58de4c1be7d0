// Helpers of the tests that run the act_drive binary (act_drive_tests only: they need the built
// act_convert and act_drive).
#pragma once

#include <sys/resource.h>
#include <fcntl.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "support/command.h"
#include "support/test_paths.h"

namespace act::drive::test {

// act-tiny (one 96x128 camera, state 2, action 2, chunk 10) converted into `dir`.
inline std::string act_tiny_blob(const std::string& dir) {
  const std::string blob = (std::filesystem::path(dir) / "act-tiny.actb").string();
  const auto r = act::test::run_command(std::string(ACT_CONVERT_BIN) + " " + act::test::q(act::test::fixture_dir("act-tiny")) +
                                        " -o " + act::test::q(blob) + " -q");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  return blob;
}

inline std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Starts act_drive with `args` in the background, its stdout and stderr into `log_path` (no core
// dump: some tests end it with signals whose default action writes one). Returns its pid.
inline pid_t start_act_drive(const std::vector<std::string>& args, const std::string& log_path) {
  const pid_t pid = fork();
  if (pid != 0) return pid;
  const int log = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  ::dup2(log, 1);
  ::dup2(log, 2);
  const rlimit no_core_dump{0, 0};
  ::setrlimit(RLIMIT_CORE, &no_core_dump);
  std::vector<char*> argv{const_cast<char*>(ACT_DRIVE_BIN)};
  for (const std::string& arg : args) argv.push_back(const_cast<char*>(arg.c_str()));
  argv.push_back(nullptr);
  ::execv(ACT_DRIVE_BIN, argv.data());
  ::_exit(127);
}

}  // namespace act::drive::test
