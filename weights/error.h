// Internal error type. Code below the public API throws act::Error; the API boundary
// (engine/src) catches it and returns the equivalent act::Status. Kernels never throw.
#pragma once

#include <stdexcept>
#include <string>

#include "actengine/status.h"

namespace act {

class Error : public std::runtime_error {
 public:
  Error(StatusCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
  StatusCode code() const { return code_; }
  Status status() const { return Status(code_, what()); }

 private:
  StatusCode code_;
};

[[noreturn]] inline void fail(StatusCode code, const std::string& message) { throw Error(code, message); }
inline void check(bool condition, StatusCode code, const std::string& message) {
  if (!condition) fail(code, message);
}

}  // namespace act
