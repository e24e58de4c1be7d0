#!/usr/bin/env bash
# Builds the Debian packages libactengine0, libactengine-dev and actengine-tools (cmake/ActPackaging.cmake)
# for amd64 (native) and arm64 (cross-compiled with Debian's aarch64 toolchain against the arm64
# multiarch libraries, for the Raspberry Pi 5), Release, no tests or benchmarks, into build-packages/.
# Installs only what that needs (install_deps.sh --packaging). Install the tools on the Pi with
#   sudo apt install ./libactengine0_<version>_arm64.deb ./actengine-tools_<version>_arm64.deb
# ACT_PACKAGE_ARCHS="arm64" (or "amd64") builds only one. Extra arguments go to CMake's configure step.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
out="${ACT_PACKAGE_DIR:-$root/build-packages}"
jobs="${ACT_JOBS:-$(nproc)}"
archs="${ACT_PACKAGE_ARCHS:-amd64 arm64}"

"$root/scripts/install_deps.sh" --packaging
mkdir -p "$out"
for arch in $archs; do
  build="$out/build-$arch"
  configure=(-G Ninja -DCMAKE_BUILD_TYPE=Release -DACT_WERROR=ON -DACT_BUILD_TESTS=OFF -DACT_BUILD_BENCH=OFF)
  case "$arch" in
    amd64) ;;
    # Debian's arm64 OpenCV cannot be installed next to the host's: act_convert and act_drive link
    # the arm64 libraries unpacked by fetch_arm64_opencv.sh (the package depends on their runtime packages).
    arm64)
      "$root/scripts/fetch_arm64_opencv.sh" "$out/opencv-arm64"
      configure+=(--toolchain "$root/cmake/toolchains/aarch64-linux-gnu.cmake" -DACT_ARM64_OPENCV_ROOT="$out/opencv-arm64/root") ;;
    *) echo "build_packages: unknown architecture '$arch' (amd64, arm64)" >&2; exit 2 ;;
  esac
  echo "== actengine package for $arch =="
  cmake -S "$root" -B "$build" "${configure[@]}" "$@"
  cmake --build "$build" -j "$jobs"
  (cd "$build" && cpack -G DEB)
  cp "$build"/*_"$arch".deb "$out/"
done
ls -l "$out"/*.deb
