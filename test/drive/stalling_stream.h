// A network camera that stalls: a TCP server, read by FFmpeg as tcp://127.0.0.1:<port>, that streams
// a video file to its first client and then sends nothing more while it keeps the connection
// open. Later clients (the camera reopening) are accepted and get nothing either.
#pragma once

#include <atomic>
#include <chrono>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace act::drive::test {

class StallingStreamServer {
 public:
  /// Streams the file `video` spread evenly over `spread` (0: all at once), then stalls.
  StallingStreamServer(const std::string& video, std::chrono::milliseconds spread);
  ~StallingStreamServer();
  StallingStreamServer(const StallingStreamServer&) = delete;
  StallingStreamServer& operator=(const StallingStreamServer&) = delete;

  /// The camera source, tcp://127.0.0.1:<port>.
  std::string url() const { return url_; }
  /// Clients accepted so far: 2 once a camera has reopened the stream after the stall.
  int connections() const { return connections_.load(); }

 private:
  void serve();
  void stream_to(int client);

  const std::string bytes_;
  const std::chrono::milliseconds spread_;
  int listener_ = -1;
  std::string url_;
  std::atomic<int> connections_{0};
  std::atomic<bool> stop_{false};
  std::mutex mutex_;
  std::vector<int> clients_;  // guarded by mutex_; held open until the server ends
  std::thread thread_;
};

}  // namespace act::drive::test
