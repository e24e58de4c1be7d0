// Runs a program the way a user does, for command-line tests.
#pragma once

#include <string>

namespace act::test {

struct CommandResult {
  int exit_code = -1;   ///< -1 when the program did not exit normally
  std::string output;  ///< stdout and stderr together
};

/// Runs `command` through the shell and captures its output.
CommandResult run_command(const std::string& command);

/// Single-quotes a path for the shell.
std::string q(const std::string& s);

}  // namespace act::test
