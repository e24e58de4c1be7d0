// actengine public API: Status and StatusOr. The public API never throws; every call that can fail
// returns one of these, with a message that names what is wrong.
#pragma once

#include <optional>
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

}  // namespace act
