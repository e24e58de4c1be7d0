#!/usr/bin/env bash
# The aarch64 wheel (Raspberry Pi OS / Debian bookworm, Python 3.11), cross-built and run under
# qemu-user, offline once the arm64 Python is there:
#   1. an arm64 Debian bookworm Python (python3, python3-numpy, libpython3.11-dev; libcpuinfo0 and
#      zlib1g, which the module links) in
#      build-arm64-python/rootfs, by `debootstrap --foreign` (downloads once; its packages are only
#      unpacked: nothing runs as root in it);
#   2. the core and the module cross-compiled (cmake/toolchains/aarch64-linux-gnu.cmake) for that
#      Python: its headers, and its own interpreter under qemu for what CMake asks it (EXT_SUFFIX);
#   3. the wheel: the host wheel's pure-Python files and metadata with the aarch64 extension, tagged
#      cp311-cp311-linux_aarch64 (`python3 -m wheel pack`), in build-arm64-python/dist;
#   4. installed into that arm64 Python (unzipped into its dist-packages, as pip does), and act-tiny
#      converted and run by it under qemu-aarch64: import, __version__, convert, 10 actions against
#      the fixture's LeRobot reference.
# Not part of run_tests.sh (CI): run it when the packaging changes. Needs install_cross_deps.sh's
# packages (qemu-user, debootstrap, the cross compiler). Set CMAKE_ARGS for ccache, as setup.py says.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
work="$root/build-arm64-python"
rootfs="$work/rootfs"
cmake_dir="$root/build-arm64-wheel"  # one level deep like build-aarch64/: ccache reuses its objects
shared="${ACT_SHARED_DIR:-$root/../shared}"
fixture="$shared/fixtures/act-tiny"
mirror="${ACT_DEBIAN_MIRROR:-http://deb.debian.org/debian}"
[ -d "$fixture" ] || { echo "check_arm64_wheel: fixture missing: $fixture" >&2; exit 1; }
mkdir -p "$work"

if ! ls "$rootfs"/var/cache/apt/archives/libcpuinfo0_*_arm64.deb >/dev/null 2>&1; then
  echo "== arm64 Python: debootstrap --foreign bookworm into $rootfs"
  rm -rf "$rootfs"
  debootstrap --foreign --arch=arm64 --variant=minbase --include=python3,python3-numpy,libpython3.11-dev,libcpuinfo0,zlib1g \
    bookworm "$rootfs" "$mirror" >"$work/debootstrap.log"
fi
if [ ! -x "$rootfs/usr/bin/python3.11" ]; then
  # --foreign unpacks only the required set: unpack the rest of what it fetched (no maintainer scripts).
  for deb in "$rootfs"/var/cache/apt/archives/*.deb; do dpkg-deb -x "$deb" "$rootfs"; done
fi
for lib in blas lapack; do  # what update-alternatives would link for numpy (reference BLAS and LAPACK)
  [ -e "$rootfs/usr/lib/aarch64-linux-gnu/lib$lib.so.3" ] || ln -s "$lib/lib$lib.so.3" "$rootfs/usr/lib/aarch64-linux-gnu/lib$lib.so.3"
done
python_arm64=(qemu-aarch64 -L "$rootfs" "$rootfs/usr/bin/python3.11")
echo "== $("${python_arm64[@]}" -c 'import sys, platform, numpy; print("Python", sys.version.split()[0], platform.machine(), "numpy", numpy.__version__)')"

# CMake runs the target's interpreter (FindPython, pybind11's EXT_SUFFIX query) through this wrapper.
cat >"$work/python3" <<WRAP
#!/bin/sh
exec qemu-aarch64 -L "$rootfs" "$rootfs/usr/bin/python3.11" "\$@"
WRAP
chmod +x "$work/python3"
# Debian's pyconfig.h includes <aarch64-linux-gnu/python3.11/pyconfig.h>: only that folder, not
# the arm64 root's whole /usr/include (the cross compiler has its own libc headers).
mkdir -p "$work/include/aarch64-linux-gnu"
ln -sfn "$rootfs/usr/include/aarch64-linux-gnu/python3.11" "$work/include/aarch64-linux-gnu/python3.11"

echo "== cross build of the module ($cmake_dir)"
start=$SECONDS
# shellcheck disable=SC2086
cmake -S "$root" -B "$cmake_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  --toolchain "$root/cmake/toolchains/aarch64-linux-gnu.cmake" \
  -DACT_CORE_ONLY=ON -DACT_BUILD_TESTS=OFF -DACT_BUILD_PYTHON=ON \
  -DPython3_EXECUTABLE="$work/python3" -DPython3_INCLUDE_DIR="$rootfs/usr/include/python3.11" \
  -Dpybind11_DIR=/usr/lib/cmake/pybind11 -DCMAKE_CXX_FLAGS="-isystem $work/include" \
  ${CMAKE_ARGS:-} >"$work/cmake-configure.log"
cmake --build "$cmake_dir" --target _actengine -j "${ACT_JOBS:-$(nproc)}" >"$work/cmake-build.log"
suffix="$("${python_arm64[@]}" -c 'import sysconfig; print(sysconfig.get_config_var("EXT_SUFFIX"))')"
module="$cmake_dir/python/actengine/_actengine$suffix"
aarch64-linux-gnu-strip --strip-unneeded -o "$work/_actengine$suffix" "$module"
file -b "$work/_actengine$suffix" | grep -q "ARM aarch64" || { echo "check_arm64_wheel: $module is not aarch64" >&2; exit 1; }
echo "built     _actengine$suffix in $((SECONDS - start)) s"

echo "== the wheel"
rm -rf "$work/host-dist" "$work/unpacked" "$work/dist"
# The host wheel gives the pure-Python files and the metadata (one version: CMakeLists.txt's).
(cd "$root" && /usr/bin/python3 -m pip wheel -q --no-index --no-deps --no-build-isolation --disable-pip-version-check \
   -w "$work/host-dist" .)
/usr/bin/python3 -m wheel unpack -d "$work/unpacked" "$work/host-dist"/actengine-*.whl >/dev/null
unpacked="$(ls -d "$work"/unpacked/actengine-*)"
rm -f "$unpacked"/actengine/_actengine*.so
cp "$work/_actengine$suffix" "$unpacked/actengine/"
sed -i 's/^Tag: .*/Tag: cp311-cp311-linux_aarch64/' "$unpacked"/actengine-*.dist-info/WHEEL
mkdir -p "$work/dist"
/usr/bin/python3 -m wheel pack -d "$work/dist" "$unpacked" >/dev/null
wheel="$(ls "$work"/dist/actengine-*-cp311-cp311-linux_aarch64.whl)"
echo "wheel     $(basename "$wheel"): $(du -k "$wheel" | cut -f1) KiB"

echo "== installed into the arm64 Python, act-tiny under qemu-aarch64"
site="$rootfs/usr/local/lib/python3.11/dist-packages"
rm -rf "$site/actengine" "$site"/actengine-*.dist-info
mkdir -p "$site"
/usr/bin/python3 -c 'import sys, zipfile; zipfile.ZipFile(sys.argv[1]).extractall(sys.argv[2])' "$wheel" "$site"
mkdir -p "$work/run"
cp "$fixture/reference.safetensors" "$work/run/"
cp -r "$shared/tools/lerobot/lerobot_harness" "$work/run/"  # its stio.py: the reference reader (numpy)
version="$(sed -n 's/^project(actengine VERSION \([0-9.]*\).*/\1/p' "$root/CMakeLists.txt")"
start=$SECONDS
cat >"$work/run/check.py" <<'PY'
import os, platform, sys
import numpy as np
import actengine
from lerobot_harness import stio

assert platform.machine() == "aarch64", platform.machine()
from actengine import _actengine
# qemu -L shows the arm64 root's files under their host path
assert actengine.__file__.endswith("/usr/local/lib/python3.11/dist-packages/actengine/__init__.py"), actengine.__file__
assert _actengine.__file__.endswith("_actengine.cpython-311-aarch64-linux-gnu.so"), _actengine.__file__
assert actengine.__version__ == os.environ["ACT_VERSION"], actengine.__version__
actengine.convert(os.environ["ACT_FIXTURE"], "act-tiny.actb", "fp32")
ref = stio.load_file_numpy("reference.safetensors")
engine = actengine.Engine("act-tiny.actb", threads=1)
policy = actengine.Policy(engine)
observation = {"observation.images.front": ref["input.observation.images.front.u8_nhwc"][0],
               "observation.state": ref["input.observation.state"][0]}
actions = np.array([policy.select_action(observation) for _ in range(10)])
np.testing.assert_allclose(actions, ref["select_action.queue_sample0"], rtol=1e-4, atol=1e-4)
print(f"checked   actengine {actengine.__version__} on {platform.machine()} Python {sys.version.split()[0]} "
      f"({engine.model_info.isa}): import, convert, 10 actions of act-tiny match LeRobot "
      f"(max |diff| {np.abs(actions - ref['select_action.queue_sample0']).max():.1e})")
PY
(cd "$work/run" && ACT_VERSION="$version" ACT_FIXTURE="$fixture" "${python_arm64[@]}" check.py)
echo "ran       under qemu in $((SECONDS - start)) s"
echo "check_arm64_wheel: OK ($wheel)"
