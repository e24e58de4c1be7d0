#!/usr/bin/env bash
# run_package_test.sh BUILD_DIR SOURCE_DIR WORK_DIR BLOB CHECKPOINT
# The host's Debian packages as a user gets them: made with CPack from BUILD_DIR (its libraries and
# apps must be built), unpacked with dpkg -x into a scratch root, then
#  - exactly libactengine0, libactengine-dev and actengine-tools, with computed dependencies;
#  - every program and shared library stripped, and none needing a library ldd cannot find;
#  - each tool's --help runs from the unpacked files, and act_convert reads CHECKPOINT's images through
#    the image and video module (libact_media_io.so, found from /usr/bin in /usr/lib/<multiarch>/actengine);
#  - test/consumer builds against the unpacked -dev package with CMake (CMAKE_PREFIX_PATH) and its
#    main.cc with pkg-config (actengine.pc), and both run BLOB (the CMake one also converts CHECKPOINT).
set -euo pipefail
if [ $# -ne 5 ]; then
  echo "usage: $0 BUILD_DIR SOURCE_DIR WORK_DIR BLOB CHECKPOINT" >&2
  exit 2
fi
build="$1" source="$2" work="$3" blob="$4" checkpoint="$5"
fail() { echo "run_package_test: $*" >&2; exit 1; }
# Any other command that fails names itself (set -e alone exits without a word when the command is quiet).
trap 'status=$?; echo "run_package_test: line $LINENO: \"$BASH_COMMAND\" failed with exit code $status" >&2' ERR

rm -rf "$work"
mkdir -p "$work/debs" "$work/root"
(cd "$work" && cpack --config "$build/CPackConfig.cmake" -G DEB -B "$work/debs" >"$work/cpack.log") ||
  { cat "$work/cpack.log"; fail "cpack failed"; }
version="$(sed -n 's/^set(CPACK_PACKAGE_VERSION "\(.*\)")$/\1/p' "$build/CPackConfig.cmake")"
arch="$(dpkg --print-architecture)"
for package in libactengine0 libactengine-dev actengine-tools; do
  deb="$work/debs/${package}_${version}_${arch}.deb"
  [ -f "$deb" ] || fail "no $package package: $(ls "$work/debs")"
  echo "$package: $(dpkg-deb -f "$deb" Depends)"
  dpkg -x "$deb" "$work/root"
done
[ "$(ls "$work"/debs/*.deb | wc -l)" -eq 3 ] || fail "expected three packages: $(ls "$work/debs")"
dev_depends="$(dpkg-deb -f "$work/debs/libactengine-dev_${version}_${arch}.deb" Depends)"
[[ "$dev_depends" == *"libactengine0 (= $version)"* ]] || fail "libactengine-dev does not depend on libactengine0 (= $version)"
tools_depends="$(dpkg-deb -f "$work/debs/actengine-tools_${version}_${arch}.deb" Depends)"
[[ "$tools_depends" == *libopencv-videoio* && "$tools_depends" == *libc6* ]] ||
  fail "actengine-tools' dependencies were not computed from its programs: $tools_depends"

multiarch="$(dpkg-architecture -qDEB_HOST_MULTIARCH)"
libdir="$work/root/usr/lib/$multiarch"
[ -f "$libdir/libactengine.so.0" ] || fail "libactengine.so.0 is not in /usr/lib/$multiarch"
export LD_LIBRARY_PATH="$libdir${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
# Outputs are read whole before they are matched: under pipefail `ldd X | grep -q Y` fails when grep
# stops at its match and ldd, still writing, dies of SIGPIPE (the pkg-config check below failed that
# way one full ctest run in two here, and the checks in this loop could pass without looking).
unstripped=' \.(symtab|debug_info) '
[ -f "$libdir/actengine/libact_media_io.so" ] || fail "libact_media_io.so is not in /usr/lib/$multiarch/actengine"
for binary in "$work"/root/usr/bin/* "$libdir"/lib*.so.*.* "$libdir/actengine/libact_media_io.so"; do
  sections="$(readelf -S "$binary")"
  libraries="$(ldd "$binary")"
  if [[ "$sections" =~ $unstripped ]]; then fail "$binary is not stripped"; fi
  if [[ "$libraries" == *"not found"* ]]; then echo "$libraries"; fail "$binary needs a library that is not found"; fi
done
for tool in act_convert act_eval act_bench act_drive; do
  "$work/root/usr/bin/$tool" --help >"$work/$tool.help" || fail "$tool --help failed"
  head -n 1 "$work/$tool.help"
done
# CHECKPOINT's folder holds its sample images: INT8 calibrated on them.
"$work/root/usr/bin/act_convert" "$checkpoint" -o "$work/calibrated.actb" --precision int8 --calib "$checkpoint" \
  >"$work/calibrated.log" 2>&1 || { cat "$work/calibrated.log"; fail "the packaged act_convert could not calibrate on images"; }

# The consumer project against the unpacked package, with CMake...
cmake -S "$source/test/consumer" -B "$work/consumer" -DCMAKE_PREFIX_PATH="$work/root/usr" -DCMAKE_BUILD_TYPE=Release \
  >"$work/consumer.log" || { cat "$work/consumer.log"; fail "configuring test/consumer failed"; }
cmake --build "$work/consumer" --target consumer consumer_convert >>"$work/consumer.log" ||
  { cat "$work/consumer.log"; fail "building test/consumer failed"; }
# ...its shared libraries must be the package's, not the build tree's.
[[ "$(ldd "$work/consumer/consumer")" == *"$libdir/libactengine.so.0"* ]] || fail "consumer does not use the package's libactengine"
"$work/consumer/consumer" "$blob"
mkdir -p "$work/convert"
"$work/consumer/consumer_convert" "$checkpoint" "$work/convert"

# ...and with pkg-config.
export PKG_CONFIG_PATH="$libdir/pkgconfig"
[ "$(pkg-config --modversion actengine)" = "$version" ] || fail "pkg-config does not find actengine $version"
# shellcheck disable=SC2046  # the flags are words
c++ -std=c++20 -O1 "$source/test/consumer/main.cc" -o "$work/consumer_pkgconfig" $(pkg-config --cflags --libs actengine)
[[ "$(ldd "$work/consumer_pkgconfig")" == *"$libdir/libactengine.so.0"* ]] || fail "the pkg-config consumer does not use the package's libactengine"
"$work/consumer_pkgconfig" "$blob"
echo "run_package_test: the packages install, run and build consumers (CMake and pkg-config)"
