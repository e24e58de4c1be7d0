#!/usr/bin/env bash
# Configures and builds actengine (Release) into build/ (or $ACT_BUILD_DIR). Extra arguments are
# passed to CMake's configure step (CI adds -DACT_WERROR=ON: warnings are errors there, not for users).
# A unity build: each target's sources compile in batches of up to 8 (CMake's UNITY_BUILD), so the
# headers they share (CLI11, JSON, GoogleTest, the standard library) are compiled once per batch
# instead of once per file: CI's trees build in 29-43 % less time (README "CI cost"). The kernels never
# are (kernels/CMakeLists.txt). Pass -DCMAKE_UNITY_BUILD=OFF to build file by file.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${ACT_BUILD_DIR:-$root/build}"
jobs="${ACT_JOBS:-$(nproc)}"
cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_UNITY_BUILD=ON "$@"
cmake --build "$build" -j "$jobs"
