#!/usr/bin/env bash
# Installs what the aarch64 cross build and its qemu test run need (scripts/run_arm64_tests.sh):
# Debian's cross compiler and qemu-user, and through multiarch the arm64 packages that act_tests
# links and runs with: the Debian arm64 runtime (loader, libc, libstdc++, as on a Raspberry Pi OS /
# Debian bookworm board), zlib, GoogleTest and cpuinfo's library. Header-only dependencies (xsimd,
# nlohmann-json) and the cpuinfo header are architecture-independent: the host's (install_deps.sh).
# --packaging (scripts/build_packages.sh): only the cross compiler and the arm64 libraries the
# packages link, no qemu-user or GoogleTest. --projection: the cross compiler and LLVM 19's llvm-mca,
# which bench/tools/count_loop_insns.py runs to project the NEON kernels on a Cortex-A76 (its
# -mcpu=neoverse-n1 model: the A76's own name maps to the Cortex-A57 model in every LLVM of Debian).
#
# cpuinfo: libcpuinfo-dev:arm64 is NOT installed. Debian's libcpuinfo-dev is "Multi-Arch: same" but
# ships /usr/lib/cmake/cpuinfo/cpuinfo-targets-none.cmake with its own architecture's paths inside,
# so dpkg refuses the arm64 package next to the host's ("trying to overwrite shared ..., which is
# different from other instances") and stops apt half-way. libcpuinfo0:arm64 (the library) installs
# cleanly; cmake/toolchains/aarch64-linux-gnu/ stands in for the rest of the -dev package.
#
# Called by install_deps.sh. Idempotent: adds the arm64 architecture and runs apt only when
# something is missing. "Multi-Arch: same" packages must have the host's version, so apt may
# upgrade a host package to the version of its arm64 twin (seen: libssl3, krb5, e2fsprogs,
# linux-libc-dev); it must never remove one: such a transaction is refused.
set -euo pipefail

host_packages=(g++-aarch64-linux-gnu)
arm64_packages=(libc6 libstdc++6 zlib1g-dev libcpuinfo0
                libserialport-dev libevdev-dev libcpp-httplib-dev)  # act_drive (--list-ports, --gamepad, --http)
if [ "${1:-}" = "--projection" ]; then
  host_packages+=(llvm-19)
  arm64_packages=()
elif [ "${1:-}" != "--packaging" ]; then  # the tests under emulation; --packaging: only the arm64 packages' build
  host_packages+=(qemu-user debootstrap)  # debootstrap: the arm64 Python of scripts/check_arm64_wheel.sh
  arm64_packages+=(libgtest-dev libgmock-dev)
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

if ! dpkg --print-foreign-architectures | grep -qx arm64; then
  echo "install_cross_deps: adding the arm64 architecture to dpkg"
  $SUDO dpkg --add-architecture arm64
fi

installed() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"; }
missing=()
for p in "${host_packages[@]}"; do installed "$p" || missing+=("$p"); done
for p in "${arm64_packages[@]}"; do installed "$p:arm64" || missing+=("$p:arm64"); done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install_cross_deps: all ${#host_packages[@]}+${#arm64_packages[@]} packages already there"
  exit 0
fi

echo "install_cross_deps: installing ${missing[*]}"
$SUDO apt-get update
# The host build must keep working whatever the cross build needs: no removals.
plan="$($SUDO apt-get install -s --no-install-recommends "${missing[@]}")"
if grep -q '^Remv ' <<<"$plan"; then
  echo "install_cross_deps: apt would remove packages to install ${missing[*]}; refusing:" >&2
  grep '^Remv ' <<<"$plan" >&2
  exit 1
fi
apt_env=(env DEBIAN_FRONTEND=noninteractive)
if ! $SUDO "${apt_env[@]}" apt-get install -y --no-install-recommends "${missing[@]}"; then
  # Leave dpkg consistent (configure what was unpacked) rather than half-installed.
  $SUDO "${apt_env[@]}" dpkg --configure -a || true
  echo "install_cross_deps: apt-get install ${missing[*]} failed" >&2
  exit 1
fi
