#!/usr/bin/env bash
# Fetches the arm64 OpenCV libraries that the cross-built act_drive and act_convert link against
# (scripts/build_packages.sh, scripts/run_arm64_tests.sh), into DIR/root:
#
#   scripts/fetch_arm64_opencv.sh DIR      then configure with -DACT_ARM64_OPENCV_ROOT=DIR/root
#
# Why not apt: Debian bookworm's libopencv-dev:arm64 cannot be installed next to the host's (apt
# removes the host's libopencv-dev and python3-torch to make room), and the arm64 runtime packages
# pull in arm64 FFmpeg, GDAL and GStreamer. The linker only needs the four libraries themselves, so
# their packages (the host's OpenCV version, as multiarch requires) are downloaded and unpacked here:
# about 2 MB. Headers are the host's (architecture-independent). On the Pi, apt installs the real
# runtime packages: the arm64 .deb depends on them (DIR/root/depends.txt).
# Idempotent: nothing is downloaded when DIR already holds this version.
set -euo pipefail
if [ $# -ne 1 ]; then
  echo "usage: $0 DIR" >&2
  exit 2
fi
dir="$1"
modules=(core imgproc imgcodecs videoio)  # what apps/CMakeLists.txt links

# The host's OpenCV runtime package, e.g. "libopencv-core406 4.6.0+dfsg-12".
read -r core_package version < <(dpkg-query -W -f='${Package} ${Version}\n' 'libopencv-core[0-9]*' 2>/dev/null |
  awk 'NF == 2' | head -n 1) || true
if [ -z "${version:-}" ]; then
  echo "fetch_arm64_opencv: the host's OpenCV is not installed (libopencv-dev): run scripts/install_deps.sh" >&2
  exit 1
fi
soversion="${core_package#libopencv-core}"  # 406
marker="$dir/root/.fetched-$version"
if [ -f "$marker" ]; then
  echo "fetch_arm64_opencv: arm64 OpenCV $version already in $dir/root"
  exit 0
fi

rm -rf "$dir"
mkdir -p "$dir/debs" "$dir/root"
packages=()
for m in "${modules[@]}"; do packages+=("libopencv-$m$soversion:arm64=$version"); done
echo "fetch_arm64_opencv: downloading ${packages[*]}"
# apt-get download writes into the current folder; as root it warns that its _apt user cannot.
download() { (cd "$dir/debs" && apt-get download -q "${packages[@]}" 2>&1 | grep -v "unsandboxed as root" || true); }
download
debs=("$dir"/debs/*.deb)
if [ ${#debs[@]} -ne ${#modules[@]} ] || [ ! -f "${debs[0]}" ]; then
  echo "fetch_arm64_opencv: not in apt's package lists; updating them once"
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  $SUDO apt-get update -q >/dev/null || true
  download
  debs=("$dir"/debs/*.deb)
fi
if [ ${#debs[@]} -ne ${#modules[@]} ] || [ ! -f "${debs[0]}" ]; then
  echo "fetch_arm64_opencv: could not download the arm64 packages ${packages[*]}" \
       "(is the arm64 architecture added and 'apt-get update' done? scripts/install_cross_deps.sh does both)" >&2
  exit 1
fi
for deb in "${debs[@]}"; do dpkg-deb -x "$deb" "$dir/root"; done
depends=()
for m in "${modules[@]}"; do depends+=("libopencv-$m$soversion (>= $version)"); done
(IFS=,; echo "${depends[*]}" | sed 's/,/, /g') > "$dir/root/depends.txt"
touch "$marker"
echo "fetch_arm64_opencv: arm64 OpenCV $version in $dir/root"
