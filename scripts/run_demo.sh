#!/usr/bin/env bash
# README command (1): installs the dependencies, builds actengine, then runs the main job: converts
# the act-tiny LeRobot fixture into an .actb blob and evaluates it against LeRobot's own outputs.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
shared="${ACT_SHARED_DIR:-$root/../shared}"
"$root/scripts/install_deps.sh"
ACT_BUILD_DIR="$root/build" "$root/scripts/build.sh"
fixture="$shared/fixtures/act-tiny"
if [ ! -d "$fixture" ]; then
  echo "run_demo: the act-tiny fixture is not at $fixture (set ACT_SHARED_DIR)" >&2
  exit 1
fi
out="$root/build/demo"
mkdir -p "$out"
"$root/build/apps/act_convert" "$fixture" -o "$out/act-tiny.actb"
"$root/build/apps/act_eval" --model "$out/act-tiny.actb" --input "$fixture/reference.safetensors" --compare \
  --output "$out/act-tiny.actions.safetensors"
