// act_drive --pwm against a fake sysfs tree (fake_pwm.h): the values written, the error messages,
// neutral within 250 ms of the control loop's faults and of signals, and act_pwm_watchdog making the
// car safe when act_drive is killed (its whole process group, SIGKILL) or stopped (SIGSTOP).
#include <gtest/gtest.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <fstream>
#include <new>
#include <sstream>

#include "actengine/status.h"
#include "apps/drive/control_loop.h"
#include "apps/drive/emergency_neutral.h"
#include "apps/drive/pwm_link.h"
#include "drive/drive_test_util.h"
#include "drive/fake_pwm.h"
#include "support/command.h"
#include "support/test_paths.h"

namespace act::drive::test {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;
using act::test::q;
using act::test::run_command;


PwmLinkOptions link_options(const FakePwmTree& tree, const std::string& channels = "pwmchip0:0,1") {
  PwmLinkOptions options;
  options.channels = parse_pwm_channels(channels);
  options.sysfs_root = tree.root();
  options.neutral = kSafe;
  options.watchdog_path = ACT_PWM_WATCHDOG_BIN;
  options.export_timeout = milliseconds(100);
  return options;
}

// The message PwmSysfsLink's constructor throws, or "" when it starts.
std::string link_error(const PwmLinkOptions& options) {
  std::ostringstream log;
  try {
    PwmSysfsLink link(options, log);
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

// A process gone or a zombie nobody reaped (the watchdog's parent died; in a container pid 1 may not reap).
bool process_ended(pid_t pid, milliseconds limit) {
  const auto deadline = Clock::now() + limit;
  while (Clock::now() < deadline) {
    std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
    std::string text;
    std::getline(stat, text);
    const size_t paren = text.rfind(')');
    if (!stat || paren == std::string::npos || text.substr(paren + 2, 1) == "Z") return true;
    std::this_thread::sleep_for(milliseconds(5));
  }
  return false;
}

TEST(PwmLink, ConfiguresTheChannelsAndWritesTheCalibratedPulseWidths) {
  FakePwmTree tree(act::test::scratch_dir() + "/sys");
  const Calibration calibration = test_calibration();
  std::ostringstream log;
  pid_t watchdog = -1;
  {
    PwmSysfsLink link(link_options(tree), log);
    watchdog = link.watchdog_pid();
    for (int c = 0; c < 2; ++c) {
      EXPECT_EQ(tree.values(c, "period"), std::vector<int64_t>{20'000'000});
      EXPECT_EQ(tree.values(c, "enable"), std::vector<int64_t>{1});
      EXPECT_EQ(tree.values(c, "duty_cycle"), std::vector<int64_t>{1'500'000});
    }
    const float action[] = {0.5f, 0.8f};
    const PwmCommand mapped = calibration.map(action);
    ASSERT_EQ(mapped, kDriving);
    EXPECT_TRUE(link.send(mapped, Clock::now()));
    EXPECT_EQ(tree.values(0, "duty_cycle").back(), 1'700'000);
    EXPECT_EQ(tree.values(1, "duty_cycle").back(), 1'650'000);
    // The board's range rule: refused, neutral instead.
    EXPECT_FALSE(link.send(PwmCommand{500, 1650}, Clock::now()));
    EXPECT_EQ(tree.values(0, "duty_cycle").back(), 1'500'000);
    EXPECT_EQ(tree.values(1, "duty_cycle").back(), 1'500'000);
    EXPECT_NE(log.str().find("refused PWM command 500/1650 us"), std::string::npos) << log.str();
    EXPECT_TRUE(link.send(kDriving, Clock::now()));
  }  // destroyed: neutral, and the watchdog ends
  EXPECT_EQ(tree.values(0, "duty_cycle").back(), 1'500'000);
  EXPECT_EQ(tree.values(1, "duty_cycle").back(), 1'500'000);
  EXPECT_TRUE(process_ended(watchdog, milliseconds(1000)));
  EXPECT_EQ(tree.values(0, "enable"), std::vector<int64_t>{1});  // an ESC wants a steady neutral pulse, not none
}

TEST(PwmLink, SignalHandlersWriteTheArmedNeutral) {
  FakePwmTree tree(act::test::scratch_dir() + "/sys");
  std::ostringstream log;
  PwmSysfsLink link(link_options(tree), log);
  ASSERT_TRUE(link.send(kDriving, Clock::now()));
  emergency_neutral();  // what neutral_then_die calls
  EXPECT_EQ(tree.values(0, "duty_cycle").back(), 1'500'000);
  EXPECT_EQ(tree.values(1, "duty_cycle").back(), 1'500'000);
  link.shutdown(kSafe);
  const size_t written = tree.values(0, "duty_cycle").size();
  emergency_neutral();  // disarmed with the closed descriptors
  EXPECT_EQ(tree.values(0, "duty_cycle").size(), written);
}

TEST(PwmLink, ClearErrorsNameTheOverlayAndThePermissionFix) {
  const std::string dir = act::test::scratch_dir();
  FakePwmTree tree(dir + "/sys");
  PwmLinkOptions options = link_options(tree);
  options.sysfs_root = dir + "/nothing";
  std::string error = link_error(options);
  EXPECT_NE(error.find("no PWM chip " + dir + "/nothing/pwmchip0"), std::string::npos) << error;
  EXPECT_NE(error.find("dtoverlay=pwm-2chan"), std::string::npos) << error;
  error = link_error(link_options(tree, "pwmchip0:0,2"));
  EXPECT_NE(error.find("pwmchip0 has 2 channels (0..1), not 2"), std::string::npos) << error;
  EXPECT_NE(error.find("dtoverlay=pwm-2chan"), std::string::npos) << error;
  // An export that never makes the channel appear.
  fs::remove_all(tree.channel_dir(1));
  error = link_error(link_options(tree));
  EXPECT_NE(error.find("PWM channel " + tree.channel_dir(1) + " is not usable"), std::string::npos) << error;
  EXPECT_EQ(tree.values(0, "duty_cycle").back(), 1'500'000);  // the channel that did open was left at neutral
  std::ifstream exported(dir + "/sys/pwmchip0/export");
  int channel = -1;
  exported >> channel;
  EXPECT_EQ(channel, 1);
  for (const char* bad : {"pwmchip0", "pwmchip0:0", "pwmchip0:a,1", ":0,1", "pwmchip0:1,1"}) {
    EXPECT_THROW(parse_pwm_channels(bad), act::Error) << bad;
  }
  options = link_options(tree, "pwmchip0:0,1");
  options.watchdog_path = dir + "/no-such-watchdog";
  std::filesystem::create_directories(tree.channel_dir(1));
  for (const char* file : {"period", "duty_cycle", "enable"}) std::ofstream(tree.channel_dir(1) + "/" + file).flush();
  error = link_error(options);
  EXPECT_NE(error.find("the PWM watchdog " + dir + "/no-such-watchdog did not start"), std::string::npos) << error;
}

TEST(PwmLink, UnwritableChannelsNameTheGroupFix) {
  const std::string dir = act::test::scratch_dir();
  FakePwmTree tree(dir + "/sys");
  for (int c = 0; c < 2; ++c) fs::permissions(tree.channel_dir(c) + "/duty_cycle", fs::perms::owner_read | fs::perms::group_read | fs::perms::others_read);
  fs::permissions(dir, fs::perms::all);
  // Root writes read-only files anyway: the check runs as nobody then.
  int pipe_fds[2];
  ASSERT_EQ(::pipe(pipe_fds), 0);
  pid_t pid;
  {
    const FakePwmTree::ScanPause pause(tree);  // the child allocates before it exits
    pid = ::fork();
  }
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::close(pipe_fds[0]);
    if (::geteuid() == 0 && (::setgid(65534) != 0 || ::setuid(65534) != 0)) ::_exit(2);
    const std::string error = link_error(link_options(tree));
    const ssize_t ignored = ::write(pipe_fds[1], error.data(), error.size());
    (void)ignored;
    ::_exit(0);
  }
  ::close(pipe_fds[1]);
  std::string error;
  char buffer[512];
  for (ssize_t n; (n = ::read(pipe_fds[0], buffer, sizeof buffer)) > 0;) error.append(buffer, static_cast<size_t>(n));
  ::close(pipe_fds[0]);
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "could not switch to user nobody";
  EXPECT_NE(error.find("is not usable: permission denied"), std::string::npos) << error;
  EXPECT_NE(error.find("'gpio' group"), std::string::npos) << error;
}

TEST(PwmLink, ListsTheChipsAndTheirChannels) {
  const std::string dir = act::test::scratch_dir();
  FakePwmTree tree(dir + "/sys");
  std::ostringstream out;
  list_pwm_channels(tree.root(), out);
  EXPECT_EQ(out.str(), "pwm: " + tree.root() + "/pwmchip0: 2 channels (0..1), e.g. --pwm pwmchip0:0,1\n");
  std::ostringstream none;
  list_pwm_channels(dir + "/nothing", none);
  EXPECT_NE(none.str().find("no PWM chips under " + dir + "/nothing"), std::string::npos) << none.str();
  EXPECT_NE(none.str().find("dtoverlay=pwm-2chan"), std::string::npos) << none.str();
}

// ---- the control loop's faults, on PWM ----

struct PwmRig {
  std::string dir = act::test::scratch_dir();
  FakePwmTree tree{dir + "/sys"};
  std::shared_ptr<FakeModelControls> controls = std::make_shared<FakeModelControls>();
  Calibration calibration = test_calibration();
  ControlOptions options;
  std::ostringstream log;
  std::atomic<bool> stop{false};

  DriveSummary run(const FrameSource& frames, const std::function<void()>& during) {
    PwmSysfsLink link(link_options(tree), log);
    InferenceWorkerOptions worker_options;
    worker_options.max_frame_age = options.max_frame_age;
    InferenceWorker worker([&] { return std::make_unique<FakeModel>(fake_model_info(), controls); }, frames, worker_options, log);
    ControlLoop loop(options, calibration, frames, worker, link, nullptr, log);
    DriveSummary summary;
    std::thread control([&] { summary = loop.run(stop); });
    during();
    stop.store(true);
    control.join();
    EXPECT_TRUE(tree.wait_until_is(kSafe, milliseconds(1000))) << "not neutral at the end";
    return summary;
  }
};

// Neutral within kFaultDeadline of `fault`, reported for docs/reliability.md's fault-timing table.
void expect_neutral_after(const FakePwmTree& tree, Clock::time_point fault, const std::string& fault_name,
                          Clock::duration deadline = kFaultDeadline) {
  const auto neutral = tree.wait_for(kSafe, fault, milliseconds(1000));
  ASSERT_TRUE(neutral) << "no neutral after " << fault_name;
  report_fault_timing(fault_name + " (pwm)", ms(neutral->when - fault), "neutral duty cycles");
  EXPECT_LE(neutral->when - fault, deadline) << fault_name;
}

TEST(PwmControlLoop, NeutralWithin250msOfTheModelReturningNaN) {
  PwmRig rig;
  rig.options.max_consecutive_inference_errors = 10;
  Camera camera(CameraOptions{write_test_video(rig.dir + "/camera.avi", 150, 30), 0, 0, 0});
  std::optional<Clock::time_point> nan_at;
  rig.run(camera, [&] {
    EXPECT_TRUE(rig.tree.wait_until_not(kSafe, milliseconds(3000)));
    // Waited for, not read once: the fake reads the two channels' files one after the other, so
    // the first sample off neutral can hold the new steering beside the old throttle.
    EXPECT_TRUE(rig.tree.wait_until_is(kDriving, milliseconds(1000)));
    rig.controls->return_nan.store(true);
    std::this_thread::sleep_for(milliseconds(600));
    std::lock_guard lock(rig.controls->mutex);
    nan_at = rig.controls->first_nan_returned;
  });
  ASSERT_TRUE(nan_at.has_value());
  expect_neutral_after(rig.tree, *nan_at, "the model returns NaN");
}

TEST(PwmControlLoop, NeutralWithin250msOfTheCameraEnding) {
  PwmRig rig;
  Camera camera(CameraOptions{write_test_video(rig.dir + "/camera.avi", 30, 30), 0, 0, 0});
  rig.run(camera, [&] {
    while (camera.state() != FrameSource::State::kEnded) std::this_thread::sleep_for(milliseconds(10));
    std::this_thread::sleep_for(milliseconds(300));
  });
  const auto samples = rig.tree.samples();
  EXPECT_TRUE(std::any_of(samples.begin(), samples.end(), [](const auto& s) { return s.is(kDriving); }));
  expect_neutral_after(rig.tree, camera.latest()->captured + milliseconds(1000 / 30), "the camera ends");
}

// ---- act_pwm_watchdog ----

// A stand-in for act_drive in a process group of its own: opens the link (which starts the watchdog)
// and drives kDriving every 10 ms until it is killed, recording when each beat was sent.
struct DrivingProcess {
  pid_t pid = -1, watchdog = -1;
  std::atomic<Clock::rep>* last_beat = nullptr;  // in memory shared with the child
  Clock::time_point last_beat_time() const { return Clock::time_point(Clock::duration(last_beat->load())); }
};

// The heartbeat's shared page: mapped once per test process (never unmapped) and reused, since one
// driving process at a time is alive.
std::atomic<Clock::rep>* shared_last_beat() {
  static_assert(std::atomic<Clock::rep>::is_always_lock_free, "shared between processes");
  static std::atomic<Clock::rep>* const beat = [] {
    void* shared = ::mmap(nullptr, sizeof(std::atomic<Clock::rep>), PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
    EXPECT_NE(shared, MAP_FAILED);
    return new (shared) std::atomic<Clock::rep>(0);
  }();
  return beat;
}

DrivingProcess start_driving_process(const FakePwmTree& tree) {
  std::atomic<Clock::rep>* last_beat = shared_last_beat();
  last_beat->store(0);
  int report[2];
  EXPECT_EQ(::pipe(report), 0);
  pid_t pid;
  {
    const FakePwmTree::ScanPause pause(tree);  // the child allocates (the link, its log) as it drives
    pid = ::fork();
  }
  if (pid == 0) {
    ::setpgid(0, 0);
    ::close(report[0]);
    std::ostringstream log;
    try {
      PwmSysfsLink link(link_options(tree), log);
      const pid_t watchdog = link.watchdog_pid();
      if (::write(report[1], &watchdog, sizeof watchdog) != sizeof watchdog) ::_exit(1);
      for (;;) {
        const auto now = Clock::now();
        link.send(kDriving, now);
        last_beat->store(now.time_since_epoch().count());
        std::this_thread::sleep_for(milliseconds(10));
      }
    } catch (const std::exception&) {
      ::_exit(1);
    }
  }
  ::close(report[1]);
  pid_t watchdog = -1;
  EXPECT_EQ(::read(report[0], &watchdog, sizeof watchdog), static_cast<ssize_t>(sizeof watchdog));
  ::close(report[0]);
  return {pid, watchdog, last_beat};
}

TEST(PwmWatchdog, NeutralWithin250msOfSigkillOfTheWholeProcessGroup) {
  FakePwmTree tree(act::test::scratch_dir() + "/sys");
  std::vector<double> latencies;
  for (int kill = 0; kill < 20; ++kill) {
    const auto [pid, watchdog, last_beat] = start_driving_process(tree);
    ASSERT_GT(watchdog, 0);
    ASSERT_TRUE(tree.wait_until_not(kSafe, milliseconds(2000)));
    const auto killed = Clock::now();
    ::kill(-pid, SIGKILL);  // what a terminal's or a service manager's kill of the group does
    ::waitpid(pid, nullptr, 0);
    const auto neutral = tree.wait_for(kSafe, killed, milliseconds(1000));
    ASSERT_TRUE(neutral) << "kill " << kill << ": no neutral";
    latencies.push_back(ms(neutral->when - killed));
    EXPECT_TRUE(process_ended(watchdog, milliseconds(1000))) << "the watchdog did not exit once the car was safe";
  }
  std::sort(latencies.begin(), latencies.end());
  std::printf("[fault timing] SIGKILL of act_drive's process group, %zu kills: median %.2f ms, max %.2f ms to neutral duty cycles\n",
              latencies.size(), latencies[latencies.size() / 2], latencies.back());
  EXPECT_LE(latencies.back(), ms(kFaultDeadline));
}

TEST(PwmWatchdog, NeutralWhenActDriveStopsBeatingAndDrivingAgainWhenItResumes) {
  FakePwmTree tree(act::test::scratch_dir() + "/sys");
  const DrivingProcess driving = start_driving_process(tree);
  const pid_t pid = driving.pid;
  ASSERT_GT(driving.watchdog, 0);
  ASSERT_TRUE(tree.wait_until_not(kSafe, milliseconds(2000)));
  const auto stopped = Clock::now();
  ::kill(pid, SIGSTOP);
  const auto neutral = tree.wait_for(kSafe, stopped, milliseconds(1000));
  ASSERT_TRUE(neutral);
  report_fault_timing("SIGSTOP of act_drive (pwm, watchdog)", ms(neutral->when - stopped), "neutral duty cycles");
  // Not early: 250 ms after the last heartbeat (less the watchdog's tick), counted from that beat,
  // not from the stop (on a loaded machine the beat before the stop can come tens of ms late). Not
  // much later than the threshold: the margin is a loaded machine's scheduling of three processes,
  // and the time itself is reported above.
  EXPECT_GE(neutral->when - driving.last_beat_time(), milliseconds(200));
  EXPECT_LE(neutral->when - stopped, kFaultDeadline + milliseconds(250));
  ::kill(pid, SIGCONT);
  EXPECT_TRUE(tree.wait_until_not(kSafe, milliseconds(1000)));
  const auto killed = Clock::now();
  ::kill(-pid, SIGKILL);
  ::waitpid(pid, nullptr, 0);
  EXPECT_TRUE(process_ended(driving.watchdog, milliseconds(1000)));
  // The tree's watcher scans every 200 us: wait until it has seen the watchdog's last writes, which
  // may come just before it exits, then the car must stay safe.
  EXPECT_TRUE(tree.wait_for(kSafe, killed, milliseconds(1000)));
  EXPECT_TRUE(tree.current().is(kSafe));
}

// ---- the act_drive binary ----

TEST(ActDrivePwm, DrivesThePinsAndEndsNeutralOnSigtermSigstopAndSigkill) {
  ACT_REQUIRE_PATH(act::test::fixture_dir("act-tiny"));
  const std::string dir = act::test::scratch_dir();
  FakePwmTree tree(dir + "/sys");
  const std::string blob = dir + "/act-tiny.actb";
  const auto convert = run_command(std::string(ACT_CONVERT_BIN) + " " + q(act::test::fixture_dir("act-tiny")) + " -o " + q(blob) + " -q");
  ASSERT_EQ(convert.exit_code, 0) << convert.output;
  const std::string video = write_test_video(dir + "/v.avi", 300, 30, 128, 96);
  const auto start = [&](const std::string& log_path) {
    const pid_t pid = ::fork();
    if (pid == 0) {
      const int log = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      ::dup2(log, 1);
      ::dup2(log, 2);
      ::execl(ACT_DRIVE_BIN, ACT_DRIVE_BIN, "-m", blob.c_str(), "--camera", video.c_str(), "--pwm", "pwmchip0:0,1",
              "--pwm-sysfs-root", tree.root().c_str(), "--raw-endpoints", "--threads", "1", static_cast<char*>(nullptr));
      ::_exit(127);
    }
    return pid;
  };
  const auto read_log = [](const std::string& path) {
    std::ifstream in(path);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  };
  // act-tiny's actions through the default calibration are never exactly 1500/1500: any other value is driving.
  pid_t pid = start(dir + "/term.txt");
  ASSERT_TRUE(tree.wait_until_not(kSafe, milliseconds(20000))) << read_log(dir + "/term.txt");
  auto signalled = Clock::now();
  ::kill(pid, SIGTERM);
  int status = 0;
  ::waitpid(pid, &status, 0);
  std::string log = read_log(dir + "/term.txt");
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << log;
  EXPECT_NE(log.find("act_drive: PWM " + tree.root() + "/pwmchip0:0,1 at 50 Hz"), std::string::npos) << log;
  EXPECT_NE(log.find("stopped by a signal"), std::string::npos) << log;
  expect_neutral_after(tree, signalled, "SIGTERM");

  pid = start(dir + "/kill.txt");
  ASSERT_TRUE(tree.wait_until_not(kSafe, milliseconds(20000))) << read_log(dir + "/kill.txt");
  signalled = Clock::now();
  ::kill(pid, SIGSTOP);
  // The watchdog's 250 ms run from the last heartbeat, a tick before the stop; 50 ms for this busy machine.
  expect_neutral_after(tree, signalled, "SIGSTOP (watchdog)", kFaultDeadline + milliseconds(50));
  ::kill(pid, SIGCONT);
  ASSERT_TRUE(tree.wait_until_not(kSafe, milliseconds(5000))) << read_log(dir + "/kill.txt");
  signalled = Clock::now();
  ::kill(pid, SIGKILL);
  ::waitpid(pid, &status, 0);
  expect_neutral_after(tree, signalled, "SIGKILL (watchdog)");
  log = read_log(dir + "/kill.txt");
  EXPECT_NE(log.find("act_pwm_watchdog: no heartbeat from act_drive for"), std::string::npos) << log;
  EXPECT_NE(log.find("act_pwm_watchdog: act_drive's heartbeat is back"), std::string::npos) << log;

  const auto uncalibrated = run_command(std::string(ACT_DRIVE_BIN) + " -m " + q(blob) + " --camera " + q(video) +
                                        " --pwm pwmchip0:0,1 --pwm-sysfs-root " + q(tree.root()));
  EXPECT_EQ(uncalibrated.exit_code, 1);
  EXPECT_NE(uncalibrated.output.find("--pwm pwmchip0:0,1 without --calibration: refusing"), std::string::npos) << uncalibrated.output;
  EXPECT_NE(uncalibrated.output.find("--raw-endpoints"), std::string::npos) << uncalibrated.output;
  const auto missing = run_command(std::string(ACT_DRIVE_BIN) + " -m " + q(blob) + " --camera " + q(video) +
                                   " --pwm pwmchip3:0,1 --raw-endpoints --pwm-sysfs-root " + q(tree.root()));
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.output.find("no PWM chip " + tree.root() + "/pwmchip3"), std::string::npos) << missing.output;
  EXPECT_NE(missing.output.find("dtoverlay=pwm-2chan"), std::string::npos) << missing.output;
  const auto both = run_command(std::string(ACT_DRIVE_BIN) + " -m m.actb --camera 0 --pwm pwmchip0:0,1 --serial /dev/ttyUSB0");
  EXPECT_EQ(both.exit_code, 1);
  EXPECT_NE(both.output.find("--pwm drives the pins itself: not with --serial"), std::string::npos) << both.output;
  const auto typo = run_command(std::string(ACT_DRIVE_BIN) + " -m m.actb --camera 0 --pwm pwmchip0:0");
  EXPECT_NE(typo.output.find("--pwm 'pwmchip0:0': expected CHIP:STEERING,THROTTLE"), std::string::npos) << typo.output;
  const auto listed = run_command(std::string(ACT_DRIVE_BIN) + " --list-ports --pwm-sysfs-root " + q(tree.root()));
  EXPECT_EQ(listed.exit_code, 0);
  EXPECT_NE(listed.output.find("pwm: " + tree.root() + "/pwmchip0: 2 channels"), std::string::npos) << listed.output;
}

}  // namespace
}  // namespace act::drive::test
