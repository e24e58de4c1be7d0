// Nothing partial left behind when a conversion is killed: temporary files and folders registered
// here are removed if the process gets SIGINT, SIGTERM or SIGHUP, and the signal then does what it
// would have done. The handler only calls unlink()/rmdir() on preformatted paths, which is
// async-signal-safe. Normal exits and exceptions are handled by each owner's destructor.
#pragma once

#include <string>

namespace act {

/// Installs the handlers (once; later calls do nothing). Programs that write files call it first.
void install_signal_cleanup();

/// Registers `path` (a file, or an empty-at-the-end folder when `is_dir`) for removal on a signal,
/// for the lifetime of this object. Paths are removed newest first, so files registered after their
/// folder go before it. Silently does nothing for paths longer than PATH_MAX or when all slots are used.
class SignalCleanup {
 public:
  explicit SignalCleanup(const std::string& path, bool is_dir = false);
  ~SignalCleanup();
  SignalCleanup(const SignalCleanup&) = delete;
  SignalCleanup& operator=(const SignalCleanup&) = delete;
  /// The path is no longer ours to remove (e.g. renamed into place).
  void release();

 private:
  int slot_ = -1;
};

}  // namespace act
