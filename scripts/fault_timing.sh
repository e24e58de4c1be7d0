#!/usr/bin/env bash
# Measures how long each fault act_drive handles takes to reach neutral on the wire, or in the duty
# cycles with --pwm (docs/reliability.md's fault-timing table, docs/rover.md's "On the Pi's own
# PWM pins"): runs the fault tests of an existing build (default build/, or $ACT_BUILD_DIR) against the
# pseudo-terminal Arduino and the fake PWM sysfs tree and prints their "[fault timing]" lines.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${ACT_BUILD_DIR:-$root/build}"
cmake --build "$build" --target act_drive_tests act_drive -j "${ACT_JOBS:-$(nproc)}" >/dev/null
"$build/test/act_drive_tests" \
  --gtest_filter='ControlLoop.Neutral*:ControlLoop.SerialHangUp*:ControlLoop.AfterAStall*:ActDriveCli.AfterSigstop*:SerialLink.*:Signals/*:PwmControlLoop.*:PwmWatchdog.*:ActDrivePwm.*:LiveViewHttp.*:Loads/LiveViewEstopUnderLoad.*' | grep -F '[fault timing]'
