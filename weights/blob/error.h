// Internal error type. Code below the public API throws act::Error; the API boundary (engine/src)
// catches it and returns the act::Status of the same code. Kernels never throw.
//
// This header depends on nothing of the project's, so every layer may use it; the public
// StatusCode mirrors ErrorCode value for value (checked where the engine converts one into the other).
#pragma once

#include <stdexcept>
#include <string>

namespace act {

enum class ErrorCode {
  kInvalidArgument = 1,  ///< the caller passed something malformed (wrong size, NaN, bad flag)
  kNotFound,             ///< a file or a tensor that should exist does not
  kDataLoss,             ///< a file is truncated, corrupt or fails its checksum
  kUnimplemented,        ///< a valid model feature this engine does not support
  kFailedPrecondition,   ///< the call is not valid in the current state
  kIoError,              ///< the operating system refused a read, write or mmap
  kInternal,             ///< a bug in actengine
};

class Error : public std::runtime_error {
 public:
  Error(ErrorCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
  ErrorCode code() const { return code_; }

 private:
  ErrorCode code_;
};

[[noreturn]] inline void fail(ErrorCode code, const std::string& message) { throw Error(code, message); }
inline void check(bool condition, ErrorCode code, const std::string& message) {
  if (!condition) fail(code, message);
}

}  // namespace act
