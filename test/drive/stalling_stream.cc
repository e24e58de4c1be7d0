#include "drive/stalling_stream.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <iterator>
#include <stdexcept>

namespace act::drive::test {

namespace {

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("stalling stream server: cannot read " + path);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

}  // namespace

StallingStreamServer::StallingStreamServer(const std::string& video, std::chrono::milliseconds spread)
    : bytes_(read_bytes(video)), spread_(spread) {
  listener_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  address.sin_port = 0;  // any free port
  socklen_t length = sizeof address;
  if (listener_ < 0 || ::bind(listener_, reinterpret_cast<sockaddr*>(&address), sizeof address) != 0 ||
      ::listen(listener_, 4) != 0 || ::getsockname(listener_, reinterpret_cast<sockaddr*>(&address), &length) != 0) {
    throw std::runtime_error(std::string("stalling stream server: ") + std::strerror(errno));
  }
  url_ = "tcp://127.0.0.1:" + std::to_string(ntohs(address.sin_port));
  thread_ = std::thread([this] { serve(); });
}

StallingStreamServer::~StallingStreamServer() {
  stop_.store(true);
  ::shutdown(listener_, SHUT_RDWR);  // wakes accept()
  thread_.join();
  ::close(listener_);
  for (int client : clients_) ::close(client);
}

void StallingStreamServer::serve() {
  while (!stop_.load()) {
    const int client = ::accept4(listener_, nullptr, nullptr, SOCK_CLOEXEC);
    if (client < 0) return;
    {
      std::lock_guard lock(mutex_);
      clients_.push_back(client);
    }
    if (connections_.fetch_add(1) == 0) stream_to(client);
  }
}

void StallingStreamServer::stream_to(int client) {
  constexpr auto kPieceEvery = std::chrono::milliseconds(20);
  const size_t pieces = std::max<size_t>(1, static_cast<size_t>(spread_ / kPieceEvery));
  const size_t piece = (bytes_.size() + pieces - 1) / pieces;
  for (size_t offset = 0; offset < bytes_.size() && !stop_.load(); offset += piece) {
    const size_t n = std::min(piece, bytes_.size() - offset);
    if (::send(client, bytes_.data() + offset, n, MSG_NOSIGNAL) != static_cast<ssize_t>(n)) return;
    if (pieces > 1) std::this_thread::sleep_for(kPieceEvery);
  }
}

}  // namespace act::drive::test
