#!/usr/bin/env bash
# README command (1): installs the dependencies, builds actengine, then runs the main job: act_bench
# on the built-in synthetic copy of LeRobot's default ACT (one 480x640 camera) with every core, in
# INT8 with the FP32 model interleaved run by run (--compare: both latencies, the speed ratio and
# the action difference). Extra arguments go to act_bench (e.g. --config rover, --num_runs 20,
# --json out.json; --precision fp32 to time FP32 first).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
"$root/scripts/install_deps.sh"
ACT_BUILD_DIR="$root/build" "$root/scripts/build.sh"
"$root/build/apps/act_bench" --threads "$(nproc)" --precision int8 --compare --num_runs 20 "$@"
