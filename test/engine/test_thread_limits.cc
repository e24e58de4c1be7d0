// Thread counts: a documented limit (act::kMaxThreads) refused with a clear error, and a thread the
// OS refuses (RLIMIT_NPROC in a child run as an unprivileged user: root ignores the limit) is an error
// from ThreadPool and Engine::open, never std::terminate or a hang, with no thread left behind.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>

#include "actengine/engine.h"
#include "graph/thread_pool.h"
#include "support/act_test_util.h"
#include "support/test_paths.h"
#include "actengine/status.h"

namespace act {
namespace {

namespace fs = std::filesystem;

TEST(ThreadLimits, ThreadPoolRefusesCountsOutsideTheLimit) {
  EXPECT_EQ(kMaxThreads, 256);
  for (const int threads : {kMaxThreads + 1, 2000, 100000, -1}) {
    try {
      ThreadPool pool(threads);
      ADD_FAILURE() << threads << " threads accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), StatusCode::kInvalidArgument);
      const std::string expected = threads < 0 ? "threads must be >= 0" : "is above the limit of 256";
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
    }
  }
  EXPECT_LE(ThreadPool::checked_threads(0), kMaxThreads);
  EXPECT_EQ(ThreadPool(3).threads(), 3);
}

TEST(ThreadLimits, EngineOpenRefusesTooManyThreads) {
  const std::string fixture = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(fixture);
  const std::string blob = test::convert_checkpoint(fixture, test::scratch_dir());
  const auto opened = Engine::open(blob, {.threads = 2000});
  ASSERT_FALSE(opened.ok());
  EXPECT_EQ(opened.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(opened.status().message().find("threads = 2000 is above the limit of 256"), std::string::npos)
      << opened.status().to_string();
}

// Threads of this process (the child's), from /proc.
size_t own_threads() {
  size_t n = 0;
  for (const auto& entry : fs::directory_iterator("/proc/self/task")) n += entry.is_directory() ? 1 : 0;
  return n;
}

// True when the child is back to `before` threads within a second. Under qemu-user a joined thread
// can linger in /proc for a moment: the emulator wakes its joiner before the host thread has exited.
bool threads_back_to(size_t before) {
  for (int i = 0; i < 100 && own_threads() != before; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  return own_threads() == before;
}

// In a child: become nobody with RLIMIT_NPROC 3 (the child and two more threads), then run `body`,
// whose exit code the parent gets (or -1 when it hung 30 s, -2 when it died by a signal).
int as_nobody_with_few_threads(const std::function<int()>& body) {
  const pid_t pid = fork();
  if (pid == 0) {
    const rlimit few{3, 3};
    if (::setgid(65534) != 0 || ::setuid(65534) != 0 || ::setrlimit(RLIMIT_NPROC, &few) != 0) ::_exit(100);
    ::_exit(body());
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  int status = 0;
  while (::waitpid(pid, &status, WNOHANG) == 0) {
    if (std::chrono::steady_clock::now() > deadline) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      return -1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -2;
}

TEST(ThreadLimits, AThreadTheOsRefusesIsAnErrorNotATerminateOrAHang) {
  if (::geteuid() != 0) GTEST_SKIP() << "needs root, to run a child as nobody (RLIMIT_NPROC does not bind root)";
  // Threads left running are counted against the child's own before the pool: under qemu-user the
  // emulator has threads of its own.
  const int pool = as_nobody_with_few_threads([] {
    const size_t before = own_threads();
    try {
      ThreadPool p(16);
      return 2;  // every thread started: the limit did not bind
    } catch (const Error& e) {
      const std::string what = e.what();
      if (e.code() != StatusCode::kIoError || what.find(" of 16: the operating system refused it") == std::string::npos ||
          what.find("use fewer threads") == std::string::npos) {
        return 3;
      }
    }
    return threads_back_to(before) ? 0 : 4;  // the workers that had started were joined
  });
  EXPECT_EQ(pool, 0) << "2: no thread refused, 3: wrong error, 4: threads left running, 100: setuid failed, "
                        "-1: hung, -2: died by a signal (std::terminate)";

  // Engine::open turns it into a failed Status. The blob is copied where nobody can read it.
  const std::string fixture = test::fixture_dir("act-tiny");
  ACT_REQUIRE_PATH(fixture);
  char dir_template[] = "/tmp/act_nproc_XXXXXX";
  ASSERT_NE(::mkdtemp(dir_template), nullptr);
  const std::string dir = dir_template;
  ::chmod(dir.c_str(), 0755);
  const std::string blob = test::convert_checkpoint(fixture, dir);
  ::chmod(blob.c_str(), 0644);
  const int engine = as_nobody_with_few_threads([&] {
    const size_t before = own_threads();
    const auto opened = Engine::open(blob, {.threads = 16});
    if (opened.ok()) return 2;
    if (opened.status().message().find("the operating system refused it") == std::string::npos) return 3;
    return threads_back_to(before) ? 0 : 4;
  });
  fs::remove_all(dir);
  EXPECT_EQ(engine, 0) << "2: opened, 3: wrong error, 4: threads left running, -1: hung, -2: died by a signal";
}

}  // namespace
}  // namespace act
