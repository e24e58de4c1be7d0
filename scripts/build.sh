#!/usr/bin/env bash
# Configures and builds actengine (Release) into build/ (or $ACT_BUILD_DIR). Extra arguments are
# passed to CMake's configure step (CI adds -DACT_WERROR=ON: warnings are errors there, not for users).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${ACT_BUILD_DIR:-$root/build}"
jobs="${ACT_JOBS:-$(nproc)}"
cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release "$@"
cmake --build "$build" -j "$jobs"
