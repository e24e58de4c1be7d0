// The apps report every failure through one catch of act::Error in main(); this turns a failed Status
// of the public API into that error (the codes mirror each other value for value).
#pragma once

#include <string>

#include "actengine/status.h"
#include "weights/blob/error.h"

namespace act {

/// Throws act::Error with the status's code and "<context>: <message>" (or the message alone).
inline void throw_if_failed(const Status& status, const std::string& context = "") {
  if (status.ok()) return;
  fail(static_cast<ErrorCode>(status.code()), context.empty() ? status.message() : context + ": " + status.message());
}

}  // namespace act
