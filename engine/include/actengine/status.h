// actengine's one error vocabulary: StatusCode, Status and StatusOr, which the public API returns
// (it never throws), and act::Error, the exception the code below it throws (it holds a Status).
//
// This header depends on nothing of the project's. It is the one public header every layer may
// include: the kernels, weights/ and graph/ see it through an include root that holds only this
// file (cmake/ActLayer.cmake), and the layer check (cmake/check_layer_includes.py) refuses any other
// actengine/ header below the engine. The API boundary (engine/src) catches Error and returns its
// status(); kernels never throw.
#pragma once

#include <optional>
#include <stdexcept>
#include <string>
#include <utility>

namespace act {

enum class StatusCode {
  kOk = 0,
  kInvalidArgument,   ///< the caller passed something malformed (wrong size, NaN, bad flag)
  kNotFound,          ///< a file or a tensor that should exist does not
  kDataLoss,          ///< a file is truncated, corrupt or fails its checksum
  kUnimplemented,     ///< a valid model feature this engine does not support
  kFailedPrecondition,///< the call is not valid in the current state
  kIoError,           ///< the operating system refused a read, write or mmap
  kInternal,          ///< a bug in actengine
};

/// Short lower-case name of a code, e.g. "invalid argument".
const char* status_code_name(StatusCode code);

class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}
  static Status ok_status() { return {}; }

  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }
  /// "invalid argument: <message>", or "ok".
  std::string to_string() const;
  /// The same code with "<context>: <message>" (an ok status, or an empty context, stays as it is).
  Status with_context(const std::string& context) const {
    if (ok() || context.empty()) return *this;
    return Status(code_, context + ": " + message_);
  }

 private:
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

/// A value or the Status that explains why there is none.
template <typename T>
class [[nodiscard]] StatusOr {
 public:
  StatusOr(T value) : value_(std::move(value)) {}  // NOLINT(google-explicit-constructor)
  StatusOr(Status status) : status_(std::move(status)) {  // NOLINT(google-explicit-constructor)
    if (status_.ok()) status_ = Status(StatusCode::kInternal, "StatusOr built from an ok Status");
  }
  bool ok() const { return value_.has_value(); }
  const Status& status() const { return status_; }
  T& value() & { return *value_; }
  const T& value() const& { return *value_; }
  T&& value() && { return std::move(*value_); }
  T* operator->() { return &*value_; }
  const T* operator->() const { return &*value_; }
  T& operator*() { return *value_; }
  const T& operator*() const { return *value_; }

 private:
  Status status_;
  std::optional<T> value_;
};

/// The exception form of a failed Status, thrown below the public API (and by the apps, to unwind to
/// main()'s one catch). what() is the status's message.
class Error : public std::runtime_error {
 public:
  Error(StatusCode code, const std::string& message) : Error(Status(code, message)) {}
  explicit Error(Status status) : Error(failed(std::move(status)), 0) {}
  StatusCode code() const { return status_.code(); }
  const Status& status() const { return status_; }

 private:
  Error(Status status, int) : std::runtime_error(status.message()), status_(std::move(status)) {}
  static Status failed(Status status) {
    return status.ok() ? Status(StatusCode::kInternal, "act::Error built from an ok Status") : status;
  }
  Status status_;
};

[[noreturn]] inline void fail(StatusCode code, const std::string& message) { throw Error(code, message); }
inline void check(bool condition, StatusCode code, const std::string& message) {
  if (!condition) fail(code, message);
}

}  // namespace act
