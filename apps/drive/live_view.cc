#include "apps/drive/live_view.h"

#include <arpa/inet.h>
#include <httplib.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <charconv>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <optional>
#include <random>
#include <system_error>
#include <thread>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "actengine/status.h"
#include "actengine/vision.h"
#include "engine/media/media_io.h"

namespace act::drive {
namespace {

using std::chrono::milliseconds;

// The MJPEG stream's rate: enough to watch the road, a small share of a Pi's CPU.
constexpr milliseconds kStreamPeriod{66};
// Every connection has its own thread, so no client waits for another. Past kConnections open at
// once, a new connection may only press the e-stop (anything else gets 503); past kConnections +
// kEstopOnlyConnections it is closed unread.
constexpr size_t kConnections = 32;
constexpr size_t kEstopOnlyConnections = 96;
// Open MJPEG streams (each holds its connection while it lasts); one more gets 503.
constexpr int kMaxStreams = 4;
// A connection that sends nothing for this long is closed (before its first request and between
// keep-alive requests); a request's head and body must arrive within kRequestDeadline of its first
// byte (slowloris); a client that stops reading for kWriteTimeout is dropped.
constexpr milliseconds kIdleTimeout{300};
constexpr milliseconds kRequestDeadline{500};
constexpr milliseconds kWriteTimeout{1000};
// Request bodies: nothing here needs one, so a small bound (413 beyond); the head is bounded too.
constexpr size_t kMaxBody = 4096;
constexpr size_t kMaxHead = 16384;
constexpr int kMaxRequestsPerConnection = 1000;
// A command that moves the car and is older than this when it would act is refused (408).
constexpr milliseconds kStaleAfter{250};

// Per connection thread: set by ConnectionThreads before the connection is served.
thread_local bool t_estop_only = false;  // over kConnections: only the e-stop is served
thread_local bool t_reject = false;      // over every bound: closed unread

// One thread per connection, bounded (above); shutdown() waits for them all.
class ConnectionThreads final : public httplib::TaskQueue {
 public:
  void enqueue(std::function<void()> fn) override {
    size_t open = 0;
    {
      std::lock_guard lock(state_->mutex);
      open = state_->open;
      if (open < kConnections + kEstopOnlyConnections) ++state_->open;
    }
    if (open >= kConnections + kEstopOnlyConnections) {
      t_reject = true;  // on the listening thread: the connection is closed at once
      fn();
      t_reject = false;
      return;
    }
    const bool estop_only = open >= kConnections;
    try {
      std::thread([state = state_, fn, estop_only]() mutable {
        t_estop_only = estop_only;
        fn();
        fn = nullptr;
        std::lock_guard lock(state->mutex);
        --state->open;
        state->closed.notify_all();
      }).detach();
    } catch (const std::system_error&) {  // the OS refused a thread: this connection is closed unread
      {
        std::lock_guard lock(state_->mutex);
        --state_->open;
      }
      t_reject = true;
      fn();
      t_reject = false;
    }
  }
  void shutdown() override {
    std::unique_lock lock(state_->mutex);
    state_->closed.wait(lock, [this] { return state_->open == 0; });
  }

 private:
  struct State {
    std::mutex mutex;
    std::condition_variable closed;
    size_t open = 0;  // guarded by mutex
  };
  std::shared_ptr<State> state_ = std::make_shared<State>();
};

// A connection's socket as httplib reads and writes it, with the bounds above in milliseconds
// (httplib 0.11's own keep-alive timeout has whole seconds) and no body for a request that gives
// no length (httplib 0.11 would read one until the client closes: curl -X POST without -d).
class Connection final : public httplib::Stream {
 public:
  explicit Connection(int fd) : fd_(fd) {}

  /// Waits up to kIdleTimeout for the next request's first byte; then its deadline starts.
  bool next_request() {
    if (pos_ == buffer_.size() && !fill(Clock::now() + kIdleTimeout)) return false;
    received_ = Clock::now();
    deadline_ = received_ + kRequestDeadline;
    head_left_ = kMaxHead;
    body_left_.reset();
    headers_read_ = close_after_ = false;
    return true;
  }
  /// The request's head is in (httplib's setup_request): bound what is read of its body.
  void headers_read(const httplib::Request& req) {
    headers_read_ = true;
    const bool chunked = req.get_header_value("Transfer-Encoding").find("chunked") != std::string::npos;
    if (chunked) {
      body_left_ = kMaxBody + 1024;  // framing included; beyond it the request fails
      close_after_ = true;
    } else if (!req.has_header("Content-Length")) {
      body_left_ = 0;  // RFC 9112 6.3: no length, no body
    } else {
      const uint64_t length = req.get_header_value<uint64_t>("Content-Length");
      body_left_ = length > kMaxBody ? 0 : length;  // httplib answers 413 beyond kMaxBody
      if (length > kMaxBody) close_after_ = true;
    }
  }
  Clock::time_point received() const { return received_; }
  void close_after() { close_after_ = true; }
  /// After a request httplib refused before its headers were read (its body, if any, is unread).
  bool must_close() const { return close_after_ || broken_ || !headers_read_; }

  bool is_readable() const override { return pos_ < buffer_.size() || wait(POLLIN, deadline_); }
  bool is_writable() const override { return wait(POLLOUT, Clock::now() + kWriteTimeout); }
  ssize_t read(char* out, size_t size) override {
    size_t limit = size;
    if (body_left_) limit = std::min<uint64_t>(limit, *body_left_);
    else limit = std::min(limit, head_left_);
    if (limit == 0) {
      if (body_left_) return 0;
      broken_ = true;  // head over kMaxHead
      return -1;
    }
    if (pos_ == buffer_.size() && !fill(deadline_)) return broken_ ? -1 : 0;
    const size_t n = std::min(limit, buffer_.size() - pos_);
    std::copy_n(buffer_.data() + pos_, n, out);
    pos_ += n;
    if (body_left_) *body_left_ -= n;
    else head_left_ -= n;
    return static_cast<ssize_t>(n);
  }
  ssize_t write(const char* data, size_t size) override {
    if (!wait(POLLOUT, Clock::now() + kWriteTimeout)) {
      broken_ = true;
      return -1;
    }
    const ssize_t n = ::send(fd_, data, size, MSG_NOSIGNAL);
    if (n < 0) broken_ = true;
    return n;
  }
  void get_remote_ip_and_port(std::string& ip, int& port) const override { address(::getpeername, ip, port); }
  void get_local_ip_and_port(std::string& ip, int& port) const override { address(::getsockname, ip, port); }
  int socket() const override { return fd_; }

 private:
  bool wait(short events, Clock::time_point until) const {
    for (;;) {
      const auto left = std::chrono::duration_cast<milliseconds>(until - Clock::now()).count();
      pollfd p{fd_, events, 0};
      const int r = ::poll(&p, 1, static_cast<int>(std::max<int64_t>(left, 0)));
      if (r > 0) return true;
      if (r == 0 || errno != EINTR) return false;
    }
  }
  // Reads what is there into the buffer; false on timeout (broken), end of stream or error.
  bool fill(Clock::time_point until) {
    buffer_.clear();
    pos_ = 0;
    if (!wait(POLLIN, until)) {
      broken_ = true;
      return false;
    }
    char chunk[4096];
    const ssize_t n = ::recv(fd_, chunk, sizeof chunk, 0);
    if (n <= 0) {
      broken_ = true;
      return false;
    }
    buffer_.assign(chunk, static_cast<size_t>(n));
    return true;
  }
  template <typename Get>
  void address(Get get, std::string& ip, int& port) const {
    sockaddr_storage a{};
    socklen_t length = sizeof a;
    ip.clear();
    port = 0;
    if (get(fd_, reinterpret_cast<sockaddr*>(&a), &length) != 0) return;
    char text[INET6_ADDRSTRLEN] = "";
    if (a.ss_family == AF_INET) {
      const auto* v4 = reinterpret_cast<const sockaddr_in*>(&a);
      ::inet_ntop(AF_INET, &v4->sin_addr, text, sizeof text);
      port = ntohs(v4->sin_port);
    } else if (a.ss_family == AF_INET6) {
      const auto* v6 = reinterpret_cast<const sockaddr_in6*>(&a);
      ::inet_ntop(AF_INET6, &v6->sin6_addr, text, sizeof text);
      port = ntohs(v6->sin6_port);
    }
    ip = text;
  }

  int fd_;
  std::string buffer_;
  size_t pos_ = 0;
  Clock::time_point received_{}, deadline_{};
  size_t head_left_ = kMaxHead;
  std::optional<uint64_t> body_left_;  // set once the head is read
  bool headers_read_ = false, close_after_ = false, broken_ = false;
};

thread_local Connection* t_connection = nullptr;  // the request being served on this thread

// httplib's server with our connection handling (Connection, ConnectionThreads).
class HttpServer final : public httplib::Server {
 public:
  HttpServer() {
    new_task_queue = [] { return new ConnectionThreads; };
    set_payload_max_length(kMaxBody);
  }
  std::atomic<bool> stopping{false};

 private:
  bool process_and_close_socket(socket_t sock) override {
    bool ok = true;
    if (!t_reject) {
      Connection connection(sock);
      t_connection = &connection;
      for (int served = 0; svr_sock_ != INVALID_SOCKET && !stopping.load() && connection.next_request(); ++served) {
        const bool last = t_estop_only || served + 1 >= kMaxRequestsPerConnection;
        bool closed = false;
        ok = process_request(connection, last, closed, [&connection](httplib::Request& req) { connection.headers_read(req); });
        if (!ok || closed || last || connection.must_close()) break;
      }
      t_connection = nullptr;
      // Close gently: what the client still sends (a body never read) is drained for a moment, so
      // that our reply is not lost to a reset.
      ::shutdown(sock, SHUT_WR);
      const auto until = Clock::now() + milliseconds(100);
      char sink[4096];
      for (size_t drained = 0; drained < (1u << 20) && Clock::now() < until;) {
        pollfd p{sock, POLLIN, 0};
        if (::poll(&p, 1, 20) <= 0) continue;
        const ssize_t n = ::recv(sock, sink, sizeof sink, 0);
        if (n <= 0) break;
        drained += static_cast<size_t>(n);
      }
    }
    ::close(sock);
    return ok;
  }
};

std::string random_token() {
  std::random_device device;
  char text[17];
  std::snprintf(text, sizeof text, "%08x%08x", device(), device());
  return text;
}

nlohmann::ordered_json status_json(const LiveStatus& s) {
  return {{"tick", s.tick},
          {"time_s", s.time_s},
          {"mode", mode_name(s.pilot.mode)},
          {"estopped", s.pilot.estopped},
          {"overridden", s.pilot.overridden},
          {"driver", s.driver},
          {"source", s.source},
          {"fault", s.fault},
          {"steering_us", s.command.steering_us},
          {"throttle_us", s.command.throttle_us},
          {"steering", s.steering},
          {"throttle", s.throttle},
          {"steering_ahead", s.steering_ahead},
          {"throttle_ahead", s.throttle_ahead},
          {"capture_age_ms", s.capture_age_ms},
          {"preprocess_ms", s.preprocess_ms},
          {"infer_ms", s.infer_ms},
          {"jitter_ms", s.jitter_ms},
          {"ticks", s.ticks},
          {"inferences", s.inferences},
          {"overruns", s.overruns},
          {"frame_index", s.frame_index},
          {"control_hz", s.control_hz}};
}

void reply_json(httplib::Response& res, int status, const nlohmann::ordered_json& body) {
  res.status = status;
  res.set_content(body.dump(), "application/json");
}

std::string lower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return std::tolower(c); });
  return text;
}

// The host part of a Host header ("name:port", "[v6]:port"), lower case.
std::string host_name(const std::string& host) {
  if (!host.empty() && host[0] == '[') return lower(host.substr(0, host.find(']') + 1));
  const size_t colon = host.find(':');
  return lower(colon != std::string::npos && host.find(':', colon + 1) == std::string::npos ? host.substr(0, colon) : host);
}

bool is_ip_literal(const std::string& host) {
  unsigned char address[sizeof(in6_addr)];
  if (host.size() > 2 && host.front() == '[' && host.back() == ']') {
    return ::inet_pton(AF_INET6, host.substr(1, host.size() - 2).c_str(), address) == 1;
  }
  return ::inet_pton(AF_INET, host.c_str(), address) == 1;
}

// -1..1, all of the text (no "1,5", no NaN); nullopt otherwise.
std::optional<double> parse_position(const std::string& text) {
  double value = 0;
  const char* end = text.data() + text.size();
  const auto [stop, error] = std::from_chars(text.data(), end, value);
  if (text.empty() || error != std::errc() || stop != end || !std::isfinite(value) || value < -1 || value > 1) return std::nullopt;
  return value;
}

// A MJPEG stream's place among kMaxStreams, held while the stream lasts.
struct StreamSlot {
  explicit StreamSlot(std::atomic<int>& open) : open_(open) {}
  ~StreamSlot() { open_.fetch_sub(1); }
  StreamSlot(const StreamSlot&) = delete;
  StreamSlot& operator=(const StreamSlot&) = delete;
  std::atomic<int>& open_;
};

// Names this server answers to besides IP literals and localhost: the configured address and this
// machine's name (also as NAME.local). Anything else in Host is a DNS-rebinding page's name.
std::vector<std::string> own_host_names(const std::string& address) {
  std::vector<std::string> names{lower(address)};
  char hostname[256] = "";
  if (::gethostname(hostname, sizeof hostname - 1) == 0 && hostname[0] != '\0') {
    names.push_back(lower(hostname));
    names.push_back(lower(hostname) + ".local");
  }
  return names;
}

// May this command act? It needs the run's token, and it must not be late.
bool command_allowed(const std::string& token, Clock::time_point started, const httplib::Request& req,
                     httplib::Response& res) {
  const std::string given = req.has_header("X-Act-Token") ? req.get_header_value("X-Act-Token") : req.get_param_value("token");
  if (given != token) {
    reply_json(res, 403, {{"error", "this moves the car: it needs the token act_drive printed at start-up"}});
    return false;
  }
  // A command that is served late never acts: timed from when its first byte reached this server
  // and, when it says when it was issued (X-Act-Issued, the page: ms on this server's clock as
  // /stats gives it in server_ms), from then, so a command that waited in the network is late too.
  const auto now = Clock::now();
  double age_ms = t_connection ? ms_between(t_connection->received(), now) : 0;
  std::string since = "reached this server";
  if (req.has_header("X-Act-Issued")) {
    const std::string text = req.get_header_value("X-Act-Issued");
    double issued = 0;
    const auto [stop, error] = std::from_chars(text.data(), text.data() + text.size(), issued);
    if (error != std::errc() || stop != text.data() + text.size() || !std::isfinite(issued)) {
      reply_json(res, 400, {{"error", "X-Act-Issued '" + text + "' is not a time in ms on this server's clock (server_ms in /stats)"}});
      return false;
    }
    const double issued_age = ms_between(started, now) - issued;
    if (issued_age < -static_cast<double>(kStaleAfter.count())) {
      reply_json(res, 408, {{"error", "X-Act-Issued is " + std::to_string(std::lround(-issued_age)) + " ms ahead of this server's "
                                      "clock (a page from before act_drive restarted? reload it): refused"}});
      return false;
    }
    if (issued_age > age_ms) {
      age_ms = issued_age;
      since = "was issued";
    }
  }
  if (age_ms > static_cast<double>(kStaleAfter.count())) {
    reply_json(res, 408, {{"error", "this request " + since + " " + std::to_string(std::lround(age_ms)) + " ms ago (over " +
                                    std::to_string(kStaleAfter.count()) + " ms): refused, it would move the car late"}});
    return false;
  }
  return true;
}

}  // namespace

struct LiveView::Server {
  Clock::time_point started = Clock::now();  // server_ms in /stats counts from here
  HttpServer http;
  std::thread thread;
  std::atomic<int> streams{0};
};

void parse_http_address(const std::string& text, LiveViewOptions& options) {
  const size_t colon = text.rfind(':');
  const std::string port = colon == std::string::npos ? text : text.substr(colon + 1);
  if (colon != std::string::npos) options.address = text.substr(0, colon);
  size_t used = 0;
  int value = -1;
  try {
    value = std::stoi(port, &used);
  } catch (const std::exception&) {
  }
  if (used != port.size() || value < 0 || value > 65535 || options.address.empty()) {
    fail(StatusCode::kInvalidArgument, "--http '" + text + "': expected [ADDR:]PORT, e.g. 8887 or 0.0.0.0:8887");
  }
  options.port = value;
}

LiveView::LiveView(LiveViewOptions options, Cockpit& cockpit, const FrameSource& frames)
    : options_(std::move(options)), token_(random_token()), server_(std::make_unique<Server>()) {
  add_guards(cockpit);
  add_view_routes(cockpit, frames);
  add_control_routes(cockpit);
  listen();
}

void LiveView::add_guards(Cockpit& cockpit) {
  HttpServer& http = server_->http;
  const std::vector<std::string> names = own_host_names(options_.address);
  const auto host_allowed = [names](const std::string& host) {
    return is_ip_literal(host) || host == "localhost" || (host.size() > 10 && host.ends_with(".localhost")) ||
           std::find(names.begin(), names.end(), host) != names.end();
  };
  const std::string known_names = names.size() > 1 ? names[1] + ", " + names[2] : options_.address;
  // The e-stop, refusals and bounds come before routing, so before any body is read: the e-stop acts
  // on its request line and headers alone, from anyone, whatever follows.
  http.set_pre_routing_handler([&cockpit, host_allowed, known_names](const httplib::Request& req, httplib::Response& res) {
    using Handled = httplib::Server::HandlerResponse;
    const auto refuse = [&res](int status, const std::string& why) {
      reply_json(res, status, {{"error", why}});
      res.set_header("Connection", "close");
      if (t_connection) t_connection->close_after();  // the body, if any, is never read
      return Handled::Handled;
    };
    if (req.method == "POST" && req.path == "/estop") {
      cockpit.estop();
      reply_json(res, 200, {{"ok", "e-stop: neutral until resumed"}});
      res.set_header("Connection", "close");
      if (t_connection) t_connection->close_after();
      return Handled::Handled;
    }
    if (t_estop_only) return refuse(503, "too many connections open: only POST /estop is served until some close");
    const std::string host = host_name(req.get_header_value("Host"));
    if (!host_allowed(host)) {
      return refuse(403, "Host '" + req.get_header_value("Host") + "' is not this machine's (a page of another site, through DNS "
                         "rebinding?): open the live view by its IP address, localhost or " + known_names);
    }
    if (req.method != "GET" && req.method != "HEAD") {
      const std::string origin = req.get_header_value("Origin"), site = req.get_header_value("Sec-Fetch-Site");
      if (req.has_header("Origin") && lower(origin) != "http://" + lower(req.get_header_value("Host"))) {
        return refuse(403, "cross-origin request refused: Origin '" + origin + "' is not this page's (http://" +
                               req.get_header_value("Host") + ")");
      }
      if (!site.empty() && site != "same-origin" && site != "none") {
        return refuse(403, "cross-origin request refused (Sec-Fetch-Site: " + site + ")");
      }
    }
    return Handled::Unhandled;
  });
  // httplib's own refusals (unknown path, malformed or oversized request) say why, too.
  http.set_error_handler(httplib::Server::HandlerWithResponse([](const httplib::Request& req, httplib::Response& res) {
    using Handled = httplib::Server::HandlerResponse;
    if (!res.body.empty()) return Handled::Unhandled;
    std::string why;
    switch (res.status) {
      case 404: why = "no " + req.method + " " + req.path + " here: GET /, /stats, /stream.mjpg, /frame.jpg; POST /estop, /resume, /mode, /manual"; break;
      case 413: why = "request body over " + std::to_string(kMaxBody) + " bytes (nothing here needs one)"; break;
      case 414: why = "request line too long"; break;
      case 400: why = "malformed request, or head and body not in within " + std::to_string(kRequestDeadline.count()) + " ms"; break;
      default: why = "refused (HTTP " + std::to_string(res.status) + ")"; break;
    }
    reply_json(res, res.status, {{"error", why}});
    return Handled::Handled;
  }));
}

void LiveView::add_view_routes(Cockpit& cockpit, const FrameSource& frames) {
  HttpServer& http = server_->http;
  // The newest frame as the model sees it (after preprocessing), JPEG-encoded; empty before the first.
  const auto model_view_jpeg = [this, &frames] {
    std::vector<uchar> jpeg;
    const auto frame = frames.latest();
    std::vector<uint8_t> rgb;
    if (!frame || !frame_to_model_rgb(frame->bgr, options_.image_height, options_.image_width, rgb).ok()) return jpeg;
    cv::Mat bgr;
    cv::cvtColor(cv::Mat(options_.image_height, options_.image_width, CV_8UC3, rgb.data()), bgr, cv::COLOR_RGB2BGR);
    media::encode_image(".jpg", bgr, jpeg);
    return jpeg;
  };

  http.Get("/", [](const httplib::Request&, httplib::Response& res) { res.set_content(kLiveViewPage, "text/html"); });
  http.Get("/stats", [this, &cockpit](const httplib::Request&, httplib::Response& res) {
    nlohmann::ordered_json status = status_json(cockpit.status());
    status["server_ms"] = std::round(ms_between(server_->started, Clock::now()) * 10) / 10;
    reply_json(res, 200, status);
  });
  http.Get("/frame.jpg", [model_view_jpeg](const httplib::Request&, httplib::Response& res) {
    const std::vector<uchar> jpeg = model_view_jpeg();
    if (jpeg.empty()) return reply_json(res, 503, {{"error", "no frame yet"}});
    res.set_content(reinterpret_cast<const char*>(jpeg.data()), jpeg.size(), "image/jpeg");
  });
  http.Get("/stream.mjpg", [this, model_view_jpeg](const httplib::Request&, httplib::Response& res) {
    if (server_->streams.fetch_add(1) >= kMaxStreams) {
      server_->streams.fetch_sub(1);
      return reply_json(res, 503, {{"error", std::to_string(kMaxStreams) + " viewers already watch /stream.mjpg: close one, or "
                                             "poll /frame.jpg"}});
    }
    const auto slot = std::make_shared<StreamSlot>(server_->streams);
    res.set_header("Cache-Control", "no-store");
    res.set_chunked_content_provider("multipart/x-mixed-replace; boundary=frame",
                                     [this, model_view_jpeg, slot](size_t, httplib::DataSink& sink) {
      if (server_->http.stopping.load()) return false;
      const std::vector<uchar> jpeg = model_view_jpeg();
      if (!jpeg.empty()) {
        const std::string head = "--frame\r\nContent-Type: image/jpeg\r\nContent-Length: " + std::to_string(jpeg.size()) + "\r\n\r\n";
        if (!sink.write(head.data(), head.size()) || !sink.write(reinterpret_cast<const char*>(jpeg.data()), jpeg.size()) ||
            !sink.write("\r\n", 2)) {
          return false;
        }
      }
      std::this_thread::sleep_for(kStreamPeriod);
      return true;
    });
  });
}

void LiveView::add_control_routes(Cockpit& cockpit) {
  HttpServer& http = server_->http;
  // POST /estop: the pre-routing handler above.
  http.Post("/resume", [this, &cockpit](const httplib::Request& req, httplib::Response& res) {
    if (!command_allowed(token_, server_->started, req, res)) return;
    cockpit.resume();
    reply_json(res, 200, {{"ok", "resumed"}});
  });
  http.Post("/mode", [this, &cockpit](const httplib::Request& req, httplib::Response& res) {
    if (!command_allowed(token_, server_->started, req, res)) return;
    const std::optional<DriveMode> mode = parse_mode(req.get_param_value("mode"));
    if (!mode) return reply_json(res, 400, {{"error", "mode must be ai, manual or ai-steer"}});
    cockpit.set_mode(*mode);
    reply_json(res, 200, {{"ok", std::string("mode ") + mode_name(*mode)}});
  });
  http.Post("/manual", [this, &cockpit](const httplib::Request& req, httplib::Response& res) {
    if (!command_allowed(token_, server_->started, req, res)) return;
    const std::optional<double> steering = parse_position(req.get_param_value("steering"));
    const std::optional<double> throttle = parse_position(req.get_param_value("throttle"));
    if (!steering || !throttle) {
      return reply_json(res, 400, {{"error", "steering '" + req.get_param_value("steering") + "' and throttle '" +
                                             req.get_param_value("throttle") + "' must both be numbers in -1..1 (a dot for "
                                             "decimals: 0.5)"}});
    }
    cockpit.manual(*steering, *throttle);
    reply_json(res, 200, {{"ok", "manual"}});
  });
}

void LiveView::listen() {
  HttpServer& http = server_->http;
  if (options_.port == 0) {
    port_ = http.bind_to_any_port(options_.address);
  } else {
    port_ = http.bind_to_port(options_.address, options_.port) ? options_.port : -1;
  }
  if (port_ <= 0) {
    fail(StatusCode::kIoError, "--http: cannot listen on " + options_.address + ":" + std::to_string(options_.port) +
                                   " (in use, or not an address of this machine)");
  }
  server_->thread = std::thread([this] { server_->http.listen_after_bind(); });
}

LiveView::~LiveView() {
  server_->http.stopping.store(true);
  server_->http.stop();
  if (server_->thread.joinable()) server_->thread.join();
}

std::string LiveView::url() const { return "http://" + options_.address + ":" + std::to_string(port_) + "/"; }

}  // namespace act::drive
