// The cockpit's rules (who drives after which input) and the gamepad's event mapping. A real gamepad
// through uinput is not tested: /dev/uinput is absent on the CI machine.
#include <gtest/gtest.h>
#include <linux/input.h>

#include <fstream>
#include <sstream>

#include "actengine/status.h"
#include "apps/drive/cockpit.h"
#include "apps/drive/gamepad.h"
#include "support/test_paths.h"

namespace act::drive::test {
namespace {

TEST(Cockpit, ManualInputOverridesThePolicyUntilResumed) {
  Cockpit cockpit(DriveMode::kAi);
  const auto now = [] { return Clock::now(); };
  EXPECT_FALSE(cockpit.input(now()).manual_drives());
  cockpit.manual(0.02, -0.03);  // a stick resting off centre is no input
  EXPECT_FALSE(cockpit.input(now()).manual_drives());
  cockpit.manual(0.5, 0.25);
  PilotInput in = cockpit.input(now());
  EXPECT_TRUE(in.overridden);
  EXPECT_EQ(in.steering, 0.5);
  EXPECT_EQ(in.throttle, 0.25);
  cockpit.manual(0, 0);  // released: still overridden, holding neutral
  in = cockpit.input(now());
  EXPECT_TRUE(in.manual_drives());
  EXPECT_EQ(in.throttle, 0);
  cockpit.resume();
  EXPECT_FALSE(cockpit.input(now()).manual_drives());
}

TEST(Cockpit, StaleManualInputIsNeutralAndEstopHoldsUntilResume) {
  Cockpit cockpit(DriveMode::kManual);
  cockpit.manual(1, 1);
  EXPECT_EQ(cockpit.input(Clock::now()).throttle, 1);
  const PilotInput later = cockpit.input(Clock::now() + Cockpit::kManualTimeout + std::chrono::milliseconds(1));
  EXPECT_EQ(later.steering, 0);  // a closed page or unplugged pad stops the car
  EXPECT_EQ(later.throttle, 0);
  cockpit.estop();
  cockpit.manual(1, 1);
  EXPECT_TRUE(cockpit.input(Clock::now()).estopped);
  cockpit.resume();
  EXPECT_FALSE(cockpit.input(Clock::now()).estopped);
}

TEST(Cockpit, AiSteerTakesTheThrottleByHandAndASteeringInputOverrides) {
  Cockpit cockpit(DriveMode::kAiSteer);
  cockpit.manual(0, 0.6);
  PilotInput in = cockpit.input(Clock::now());
  EXPECT_FALSE(in.manual_drives());
  EXPECT_EQ(in.throttle, 0.6);
  cockpit.manual(-0.4, 0.6);
  EXPECT_TRUE(cockpit.input(Clock::now()).manual_drives());
  EXPECT_EQ(parse_mode("ai-steer"), DriveMode::kAiSteer);
  EXPECT_EQ(parse_mode("auto"), std::nullopt);
}

TEST(GamepadMapping, SticksAndButtons) {
  GamepadMapping pad({ABS_X, 0, 255}, {ABS_RY, -32768, 32767});
  EXPECT_EQ(pad.on_event(EV_ABS, ABS_X, 255), GamepadMapping::Action::kMoved);
  EXPECT_DOUBLE_EQ(pad.steering(), 1.0);
  pad.on_event(EV_ABS, ABS_X, 130);  // inside the dead zone around 127.5
  EXPECT_EQ(pad.steering(), 0.0);
  pad.on_event(EV_ABS, ABS_RY, -32768);  // pushed up: full forward
  EXPECT_DOUBLE_EQ(pad.throttle(), 1.0);
  EXPECT_TRUE(pad.active());
  pad.on_event(EV_ABS, ABS_RY, 0);
  EXPECT_FALSE(pad.active());
  EXPECT_EQ(pad.on_event(EV_ABS, ABS_Z, 100), GamepadMapping::Action::kNone);
  EXPECT_EQ(pad.on_event(EV_KEY, BTN_EAST, 1), GamepadMapping::Action::kEstop);
  EXPECT_EQ(pad.on_event(EV_KEY, BTN_EAST, 0), GamepadMapping::Action::kNone);  // the release does nothing
  EXPECT_EQ(pad.on_event(EV_KEY, BTN_START, 1), GamepadMapping::Action::kResume);
}

TEST(Gamepad, NamesWhatIsWrongWithTheDevice) {
  Cockpit cockpit(DriveMode::kAi);
  std::ostringstream log;
  const std::string dir = act::test::scratch_dir();
  const auto error_of = [&](const std::string& path) {
    try {
      Gamepad pad(path, cockpit, log);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error_of(dir + "/no-such-event").find("cannot open " + dir + "/no-such-event"), std::string::npos);
  std::ofstream(dir + "/plain-file") << "x";
  EXPECT_NE(error_of(dir + "/plain-file").find("is not an input device"), std::string::npos);
}

}  // namespace
}  // namespace act::drive::test
