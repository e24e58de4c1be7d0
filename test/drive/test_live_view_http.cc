// act_drive --http against real HTTP clients (raw sockets, curl) with the pty fake Arduino: the e-stop
// reaches neutral on the serial line within the e-stop bound whatever other clients do (MJPEG viewers,
// slowloris, idle keep-alive, requests without a length, a 4 GB body), late commands never act, and
// the Host / Origin checks refuse what a page of another site could send.
#include <gtest/gtest.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <fstream>
#include <functional>
#include <regex>
#include <thread>

#include <nlohmann/json.hpp>

#include "drive/drive_cli_util.h"
#include "drive/drive_test_util.h"
#include "drive/fake_arduino.h"
#include "support/command.h"
#include "support/test_paths.h"

namespace act::drive::test {
namespace {

using std::chrono::milliseconds;

int connect_to(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<uint16_t>(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

bool send_all(int fd, const std::string& data) {
  for (size_t sent = 0; sent < data.size();) {
    const ssize_t n = ::send(fd, data.data() + sent, data.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) return false;
    sent += static_cast<size_t>(n);
  }
  return true;
}

// Reads until the server closes or `limit` passes (a hang detector).
std::string read_until_closed(int fd, milliseconds limit = milliseconds(5000)) {
  std::string out;
  const auto deadline = Clock::now() + limit;
  char buffer[4096];
  while (Clock::now() < deadline) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 20) <= 0) continue;
    const ssize_t n = ::recv(fd, buffer, sizeof buffer, 0);
    if (n <= 0) break;
    out.append(buffer, static_cast<size_t>(n));
  }
  return out;
}

int status_of(const std::string& response) {
  std::smatch m;
  return std::regex_search(response, m, std::regex("^HTTP/1\\.1 ([0-9]{3})")) ? std::stoi(m[1]) : 0;
}

std::string body_of(const std::string& response) {
  const size_t end = response.find("\r\n\r\n");
  return end == std::string::npos ? "" : response.substr(end + 4);
}

// One request on its own connection; the reply as text ("" when none came).
std::string round_trip(int port, const std::string& request, milliseconds limit = milliseconds(5000)) {
  const int fd = connect_to(port);
  if (fd < 0) return "";
  send_all(fd, request);
  std::string out = read_until_closed(fd, limit);
  ::close(fd);
  return out;
}

// act_drive on a video with the pty board, the live view on a free port, in manual mode (a human
// drives; nothing moves without input).
class LiveViewHttp : public ::testing::Test {
 protected:
  void SetUp() override {
    ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
    dir_ = act::test::scratch_dir();
    const std::string blob = act_tiny_blob(dir_);
    const std::string video = write_test_video(dir_ + "/v.avi", 900, 30, 128, 96);
    std::ofstream(dir_ + "/cal.json") << R"({"steering": {"left_us": 1100, "center_us": 1500, "right_us": 1900},
      "throttle": {"reverse_us": 1300, "neutral_us": 1500, "forward_us": 1800, "max_forward": 0.5}})";
    log_path_ = dir_ + "/log.txt";
    pid_ = start_act_drive({"-m", blob, "--camera", video, "--serial", board_.port_path(), "-c", dir_ + "/cal.json", "--threads",
                            "1", "--http", "127.0.0.1:0", "--mode", "manual"}, log_path_);
    ASSERT_GE(pid_, 0);
    std::smatch found;
    const std::regex announced("live view on http://127\\.0\\.0\\.1:([0-9]+)/ \\(token ([0-9a-f]+)");
    std::string log;
    ASSERT_TRUE(eventually([&] {
      log = read_text(log_path_);
      return std::regex_search(log, found, announced);
    }, std::chrono::seconds(30))) << log;
    port_ = std::stoi(found[1]);
    token_ = found[2];
    ASSERT_TRUE(eventually([&] { return !board_.commands().empty(); }, std::chrono::seconds(30))) << read_text(log_path_);
  }
  void TearDown() override {
    stop_driving();
    if (pid_ > 0) {
      ::kill(pid_, SIGINT);
      int status = 0;
      ::waitpid(pid_, &status, 0);
    }
  }

  std::string host() const { return "127.0.0.1:" + std::to_string(port_); }
  std::string manual_request(const std::string& steering, const std::string& throttle, const std::string& extra = "") const {
    return "POST /manual?steering=" + steering + "&throttle=" + throttle + " HTTP/1.1\r\nHost: " + host() +
           "\r\nX-Act-Token: " + token_ + "\r\nContent-Length: 0\r\nConnection: close\r\n" + extra + "\r\n";
  }
  // Drives full right and forward by hand (1900 / 1650 us), one request every 100 ms, until stopped.
  void start_driving() {
    driving_ = true;
    driver_ = std::thread([this] {
      while (driving_) {
        round_trip(port_, manual_request("1", "1"), milliseconds(2000));
        std::this_thread::sleep_for(milliseconds(100));
      }
    });
    ASSERT_TRUE(eventually([&] { return !board_.commands().empty() && board_.commands().back().steering_us == 1900; }))
        << read_text(log_path_);
  }
  void stop_driving() {
    driving_ = false;
    if (driver_.joinable()) driver_.join();
  }
  // ms from `sent` to the first neutral command on the serial line (-1: none within 5 s).
  double ms_to_neutral(Clock::time_point sent) {
    double result = -1;
    eventually([&] {
      for (const auto& c : board_.commands()) {
        if (c.type == 'C' && c.when >= sent && c.steering_us == 1500 && c.throttle_us == 1500) {
          result = ms(c.when - sent);
          return true;
        }
      }
      return false;
    }, std::chrono::seconds(5));
    return result;
  }
  // The e-stop as `curl -X POST URL/estop` sends it (no body, no Content-Length), timed to neutral.
  double estop_to_neutral(std::string* reply = nullptr) {
    const int fd = connect_to(port_);
    const auto sent = Clock::now();
    send_all(fd, "POST /estop HTTP/1.1\r\nHost: " + host() + "\r\nUser-Agent: curl/7.88.1\r\nAccept: */*\r\n\r\n");
    const std::string response = read_until_closed(fd);
    ::close(fd);
    if (reply) *reply = response;
    return ms_to_neutral(sent);
  }

  FakeArduino board_;
  std::string dir_, log_path_, token_;
  pid_t pid_ = -1;
  int port_ = 0;
  std::atomic<bool> driving_{false};
  std::thread driver_;
};

// Other clients holding connections open, each on its own thread; `closed_ms` gets how long the
// server kept each one (when it closes them).
struct Load {
  std::atomic<bool> stop{false};
  std::vector<std::thread> threads;
  std::mutex mutex;
  std::vector<double> closed_ms;    // guarded by mutex
  std::vector<std::string> streams;  // guarded by mutex: the start of each /stream.mjpg reply
  ~Load() {
    stop = true;
    for (auto& t : threads) t.join();
  }
  // Connects and sends `first`; then `each_100ms` every 100 ms (slowloris) or nothing, reading
  // whatever comes, until the server closes or the load stops.
  void add(int port, const std::string& first, const std::string& each_100ms = "") {
    threads.emplace_back([this, port, first, each_100ms] {
      const int fd = connect_to(port);
      const auto start = Clock::now();
      send_all(fd, first);
      std::string got;
      auto next = Clock::now() + milliseconds(100);
      char buffer[65536];
      while (!stop) {
        pollfd p{fd, POLLIN, 0};
        if (::poll(&p, 1, 10) > 0) {
          const ssize_t n = ::recv(fd, buffer, sizeof buffer, 0);
          if (n <= 0) {
            std::lock_guard lock(mutex);
            closed_ms.push_back(ms(Clock::now() - start));
            break;
          }
          if (got.empty() && first.starts_with("GET /stream.mjpg")) {
            std::lock_guard lock(mutex);
            streams.emplace_back(buffer, static_cast<size_t>(std::min<ssize_t>(n, 1024)));
          }
          got.append(buffer, 1);
        }
        if (!each_100ms.empty() && Clock::now() > next) {
          if (!send_all(fd, each_100ms)) {
            std::lock_guard lock(mutex);
            closed_ms.push_back(ms(Clock::now() - start));
            break;
          }
          next += milliseconds(100);
        }
      }
      ::close(fd);
    });
  }
};

struct LoadCase {
  const char *id, *name;
  bool streams, slowloris, idle, no_length;
};

void PrintTo(const LoadCase& c, std::ostream* os) { *os << c.name; }

class LiveViewEstopUnderLoad : public LiveViewHttp, public ::testing::WithParamInterface<LoadCase> {};

TEST_P(LiveViewEstopUnderLoad, ReachesNeutralWithinTheBound) {
  const LoadCase& c = GetParam();
  start_driving();
  Load load;
  const std::string h = "Host: " + host() + "\r\n";
  for (int i = 0; i < 6 && c.streams; ++i) load.add(port_, "GET /stream.mjpg HTTP/1.1\r\n" + h + "\r\n");
  for (int i = 0; i < 8 && c.slowloris; ++i) load.add(port_, "GET /stats HTTP/1.1\r\n" + h, "X");
  for (int i = 0; i < 8 && c.idle; ++i) load.add(port_, "GET /stats HTTP/1.1\r\n" + h + "\r\n");  // then idle, kept alive
  for (int i = 0; i < 8 && c.no_length; ++i) load.add(port_, "PUT /stats HTTP/1.1\r\n" + h + "\r\n");
  std::this_thread::sleep_for(milliseconds(200));  // all connected and holding
  // Still driving under the load (manual input older than 500 ms would already be neutral).
  ASSERT_EQ(board_.commands().back().steering_us, 1900);
  std::string reply;
  const double to_neutral = estop_to_neutral(&reply);
  EXPECT_EQ(status_of(reply), 200) << reply;
  EXPECT_NE(body_of(reply).find("e-stop"), std::string::npos) << reply;
  ASSERT_GE(to_neutral, 0) << "no neutral on the serial line";
  EXPECT_LE(to_neutral, ms(kFaultDeadline));
  report_fault_timing(std::string("live view e-stop under ") + c.name, to_neutral);
  if (c.streams) {  // kMaxStreams viewers; the others are told why not
    EXPECT_TRUE(eventually([&] {
      std::lock_guard lock(load.mutex);
      return load.streams.size() == 6;
    }));
    std::lock_guard lock(load.mutex);
    int refused = 0, served = 0;
    for (const auto& r : load.streams) {
      if (status_of(r) == 503) ++refused;
      if (status_of(r) == 200 && r.find("multipart/x-mixed-replace") != std::string::npos) ++served;
    }
    EXPECT_EQ(refused, 2);
    EXPECT_EQ(served, 4);
    const std::string seventh = round_trip(port_, "GET /stream.mjpg HTTP/1.1\r\n" + h + "Connection: close\r\n\r\n");
    EXPECT_EQ(status_of(seventh), 503);
    EXPECT_NE(body_of(seventh).find("viewers"), std::string::npos) << seventh;
  } else {  // the server closes every one of them (a hang detector; the time is printed)
    EXPECT_TRUE(eventually([&] {
      std::lock_guard lock(load.mutex);
      return load.closed_ms.size() == load.threads.size();
    }));
    std::lock_guard lock(load.mutex);
    for (double closed : load.closed_ms) std::printf("[live view] %s connection closed by the server after %.0f ms\n", c.name, closed);
  }
}

INSTANTIATE_TEST_SUITE_P(Loads, LiveViewEstopUnderLoad,
                         ::testing::Values(LoadCase{"Streams", "6 MJPEG viewers", true, false, false, false},
                                           LoadCase{"Slowloris", "8 slowloris clients", false, true, false, false},
                                           LoadCase{"IdleKeepAlive", "8 idle keep-alive connections", false, false, true, false},
                                           LoadCase{"PutWithoutLength", "8 PUTs without Content-Length", false, false, false, true},
                                           LoadCase{"All", "all of them at once", true, true, true, true}),
                         [](const ::testing::TestParamInfo<LoadCase>& param_info) {
                           return std::string(param_info.param.id);
                         });

// issue 54: a scripted e-stop, `curl -X POST URL/estop`, no -d. The e-stop bound on that request is
// asserted where the request's bytes are sent from this process (estop_to_neutral sends curl's
// exact request, LiveViewEstopUnderLoad): here the time also holds curl's own start, a fork and
// exec of this process that took over 100 ms under ASan on a loaded machine, so it is reported,
// and the rover must have gone neutral.
TEST_F(LiveViewHttp, CurlEstopWithoutABodyWorks) {
  start_driving();  // and on driving: only the e-stop brings neutral
  const auto sent = Clock::now();
  const auto r = act::test::run_command("curl -sS -i -X POST http://" + host() + "/estop");
  const double to_neutral = ms_to_neutral(sent);
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(status_of(r.output), 200) << r.output;
  EXPECT_NE(r.output.find("neutral until resumed"), std::string::npos) << r.output;
  ASSERT_GE(to_neutral, 0) << "no neutral command on the wire within 5 s of the e-stop";
  report_fault_timing("live view e-stop by curl -X POST without a body (curl's start included)", to_neutral);
  // Every refusal says why: an unknown page, a PUT without a length.
  const std::string missing = round_trip(port_, "GET /nope HTTP/1.1\r\nHost: " + host() + "\r\nConnection: close\r\n\r\n");
  EXPECT_EQ(status_of(missing), 404);
  EXPECT_NE(body_of(missing).find("no GET /nope"), std::string::npos) << missing;
}

// A 4 GB body to the e-stop (which needs no token): neutral at once, and nothing is buffered.
TEST_F(LiveViewHttp, HugeBodyIsNeverBufferedAndTheEstopActsAtOnce) {
  const auto rss_kb = [this] {
    std::smatch m;
    const std::string status = read_text("/proc/" + std::to_string(pid_) + "/status");
    return std::regex_search(status, m, std::regex("VmRSS:\\s+([0-9]+) kB")) ? std::stol(m[1]) : -1L;
  };
  start_driving();
  const long before = rss_kb();
  const int fd = connect_to(port_);
  const auto sent = Clock::now();
  send_all(fd, "POST /estop HTTP/1.1\r\nHost: " + host() + "\r\nContent-Length: 4000000000\r\n\r\n");
  const std::string megabyte(1 << 20, 'x');
  size_t sent_mb = 0;
  while (sent_mb < 256 && send_all(fd, megabyte)) ++sent_mb;  // until the server closes
  ::close(fd);
  const double to_neutral = ms_to_neutral(sent);
  const long after = rss_kb();
  ASSERT_GE(to_neutral, 0);
  EXPECT_LE(to_neutral, ms(kFaultDeadline));
  report_fault_timing("live view e-stop with a 4 GB body", to_neutral);
  EXPECT_LT(sent_mb, 256u) << "the server read the whole body";
  EXPECT_LT(after - before, 32 * 1024) << before << " kB -> " << after << " kB after " << sent_mb << " MB sent";
  // A body over the bound anywhere else: 413, with the reason.
  const std::string big = round_trip(port_, "POST /resume HTTP/1.1\r\nHost: " + host() + "\r\nX-Act-Token: " + token_ +
                                               "\r\nContent-Length: 100000\r\n\r\n" + std::string(100000, 'x'));
  EXPECT_EQ(status_of(big), 413) << big;
  EXPECT_NE(body_of(big).find("body over"), std::string::npos) << big;
}

// A command that reaches the server late (its request took 350 ms to arrive) never moves the car.
TEST_F(LiveViewHttp, LateCommandsAreRefusedAndNeverAct) {
  const int fd = connect_to(port_);
  const std::string request = manual_request("1", "1");
  const size_t split = request.find("Content-Length");
  send_all(fd, request.substr(0, split));
  std::this_thread::sleep_for(milliseconds(350));
  const auto completed = Clock::now();
  send_all(fd, request.substr(split));
  const std::string late = read_until_closed(fd);
  ::close(fd);
  EXPECT_EQ(status_of(late), 408) << late;
  EXPECT_NE(body_of(late).find("reached this server"), std::string::npos) << late;
  std::this_thread::sleep_for(milliseconds(300));
  for (const auto& c : board_.commands()) {
    if (c.type == 'C' && c.when > completed) {
      EXPECT_EQ(c.steering_us, 1500) << "the late command drove";
    }
  }
  // Issued 1 s ago on the server's clock (as the page stamps it: a command that waited in the
  // network), or ahead of it: refused, and nothing moves.
  const auto server_ms = [&] {
    return nlohmann::json::parse(body_of(round_trip(port_, "GET /stats HTTP/1.1\r\nHost: " + host() + "\r\nConnection: close\r\n\r\n")))
        ["server_ms"].get<double>();
  };
  const auto issued_at = [&](double at) { return manual_request("1", "1", "X-Act-Issued: " + std::to_string(at) + "\r\n"); };
  const std::string old_issue = round_trip(port_, issued_at(server_ms() - 1000));
  EXPECT_EQ(status_of(old_issue), 408) << old_issue;
  EXPECT_NE(body_of(old_issue).find("was issued"), std::string::npos) << old_issue;
  const std::string ahead = round_trip(port_, issued_at(server_ms() + 5000));
  EXPECT_EQ(status_of(ahead), 408) << ahead;
  EXPECT_NE(body_of(ahead).find("ahead"), std::string::npos) << ahead;
  EXPECT_EQ(status_of(round_trip(port_, manual_request("1", "1", "X-Act-Issued: soon\r\n"))), 400);
  std::this_thread::sleep_for(milliseconds(300));
  for (const auto& c : board_.commands()) {
    if (c.type == 'C' && c.when > completed) {
      EXPECT_EQ(c.steering_us, 1500) << "a late command drove";
    }
  }
  // The same request on time drives, with or without the time it was issued.
  EXPECT_EQ(status_of(round_trip(port_, issued_at(server_ms()))), 200);
  EXPECT_TRUE(eventually([&] { return board_.commands().back().steering_us == 1900; }));
  EXPECT_EQ(status_of(round_trip(port_, request)), 200);
}

// What a page of another site could send: a cross-origin form POST carrying the token, reads through
// DNS rebinding (a Host that is not this machine's), and /manual values that are not numbers.
TEST_F(LiveViewHttp, OriginHostAndStrictManualParsing) {
  std::string reply;
  estop_to_neutral(&reply);
  ASSERT_EQ(status_of(reply), 200) << reply;
  const std::string h = "Host: " + host() + "\r\n";
  const std::string form = "token=" + token_;
  const auto resume_form = [&](const std::string& origin) {
    return round_trip(port_, "POST /resume HTTP/1.1\r\n" + h + "Origin: " + origin +
                               "\r\nContent-Type: application/x-www-form-urlencoded\r\nContent-Length: " +
                               std::to_string(form.size()) + "\r\nConnection: close\r\n\r\n" + form);
  };
  const std::string cross = resume_form("http://evil.example");
  EXPECT_EQ(status_of(cross), 403) << cross;
  EXPECT_NE(body_of(cross).find("cross-origin"), std::string::npos) << cross;
  const auto stats = [&](const std::string& host_header) {
    const std::string r = round_trip(port_, "GET /stats HTTP/1.1\r\nHost: " + host_header + "\r\nConnection: close\r\n\r\n");
    return std::make_pair(status_of(r), body_of(r));
  };
  EXPECT_TRUE(nlohmann::json::parse(stats(host()).second)["estopped"].get<bool>());  // still e-stopped
  // DNS rebinding: a name that is not this machine's, for /stats and /frame.jpg.
  const auto rebound = stats("evil.example:" + std::to_string(port_));
  EXPECT_EQ(rebound.first, 403);
  EXPECT_NE(rebound.second.find("DNS"), std::string::npos) << rebound.second;
  const std::string frame = round_trip(port_, "GET /frame.jpg HTTP/1.1\r\nHost: evil.example\r\nConnection: close\r\n\r\n");
  EXPECT_EQ(status_of(frame), 403) << frame.substr(0, 200);
  EXPECT_EQ(stats("localhost:" + std::to_string(port_)).first, 200);
  // The page's own origin resumes.
  EXPECT_EQ(status_of(resume_form("http://" + host())), 200);
  EXPECT_TRUE(eventually([&] { return !nlohmann::json::parse(stats(host()).second)["estopped"].get<bool>(); }));  // at the next tick
  // /manual: all of each value, finite, -1..1.
  for (const auto& [steering, throttle] : std::vector<std::pair<std::string, std::string>>{
           {"1,5", "0"}, {"NaN", "0"}, {"0", "nan"}, {"0", "inf"}, {"2", "0"}, {"", "0"}, {"0.5x", "0"}}) {
    const std::string r = round_trip(port_, manual_request(steering, throttle));
    EXPECT_EQ(status_of(r), 400) << steering << " " << throttle << ": " << r;
    EXPECT_NE(body_of(r).find("-1..1"), std::string::npos) << r;
  }
  EXPECT_EQ(status_of(round_trip(port_, manual_request("-0.25", "0"))), 200);
  EXPECT_TRUE(eventually([&] { return board_.commands().back().steering_us == 1400; }));
}

}  // namespace
}  // namespace act::drive::test
