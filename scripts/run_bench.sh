#!/usr/bin/env bash
# README command (1): installs the dependencies, builds actengine, then runs the main job: act_bench
# on the built-in synthetic copy of LeRobot's default ACT (one 480x640 camera) with every core.
# Extra arguments go to act_bench (e.g. --config rover, --num_runs 20, --json out.json).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
"$root/scripts/install_deps.sh"
ACT_BUILD_DIR="$root/build" "$root/scripts/build.sh"
"$root/build/apps/act_bench" --threads "$(nproc)" "$@"
