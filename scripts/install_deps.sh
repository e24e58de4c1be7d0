#!/usr/bin/env bash
# Installs every build, test and tool dependency of actengine from Debian packages; with --packaging
# only what building the library and apps and packaging them needs (scripts/build_packages.sh).
# Idempotent: packages already present are left alone; safe to run again.
# Then scripts/install_cross_deps.sh adds the aarch64 cross build's packages (skipped with ACT_SKIP_ARM64=1).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
mode="${1:-}"

packages=(  # the library, the apps and their Debian packages (dpkg-shlibdeps, file)
  build-essential cmake ninja-build pkg-config
  libxsimd-dev nlohmann-json3-dev libcli11-dev libcpuinfo-dev zlib1g-dev
  libopencv-dev
  libcpp-httplib-dev libserialport-dev libevdev-dev  # act_drive: live view server, port listing, gamepads
  libonnx-dev libprotobuf-dev  # act_convert --export-onnx: ONNX's protobuf classes, checker, shape inference
  dpkg-dev file
)
if [ "$mode" != "--packaging" ]; then
  packages+=(  # tests, benchmarks, test-checkpoint generation, the sketch, fuzzing
    git libgtest-dev libgmock-dev libbenchmark-dev
    gcc-avr avr-libc arduino-core-avr
    python3 python3-numpy python3-torch
    libopenblas0-serial       # their BLAS: the test checkpoints' float64 references 3x faster than netlib's
    python3-pil               # act_drive's recording_to_lerobot.py and its test
    python3-dev pybind11-dev python3-pybind11 python3-pytest  # the Python module (engine/python) and its tests
    python3-setuptools python3-wheel python3-pip python3-venv  # pip install . / pip wheel . offline (pyproject.toml)
    python3-torchvision python3-tqdm  # LeRobot's ACTPolicy in ../shared/tools/lerobot (the LeRobot plugin's tests)
    clang libclang-rt-14-dev  # libFuzzer and the sanitizer runtimes for scripts/run_fuzz.sh
    nodejs                    # ONNX Runtime (npm's onnxruntime-node) in the export tests
    chromium                  # the web-page tests (HTML reports, act_drive's live view), headless
  )
fi

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install_deps: all ${#packages[@]} packages already installed"
else
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  echo "install_deps: installing ${missing[*]}"
  $SUDO apt-get update
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y --no-install-recommends "${missing[@]}"
fi

# ONNX Runtime and the browser driver for the tests, from the npm registry into test/*/node_modules.
if [ "$mode" != "--packaging" ]; then "$root/scripts/install_node_deps.sh"; fi

if [ "${ACT_SKIP_ARM64:-0}" != "1" ]; then
  "$root/scripts/install_cross_deps.sh" ${mode:+"$mode"}
fi
