#!/usr/bin/env bash
# Cross-compiles the core library (kernels, weights, graph, engine) and act_tests for aarch64 (the
# Raspberry Pi 5) with Debian's g++-aarch64-linux-gnu, warnings as errors, into build-aarch64/ (or
# $ACT_ARM64_BUILD_DIR), then runs the tests through ctest under qemu-user (`qemu-aarch64 -cpu max`:
# NEON, dotprod, SVE...), so the ARM code paths really execute. Exits non-zero on any failure.
# Called by scripts/run_tests.sh (CI), which skips it with ACT_SKIP_ARM64=1. Extra arguments go to
# CMake's configure step.
#
# Then the arm64 Debian package from the same tree (the apps are built too, not their tests): built
# with CPack, unpacked, and its act_bench run under qemu (`--help`), so the package CI ships starts.
#
# Which tests: all of act_tests except the few end-to-end tests listed below, which repeat
# whole-model inference many times or run the full-size model: under emulation each takes minutes,
# and the native Release and sanitizer stages run them anyway. Everything else runs, so new kernel
# tests run here with no change to this script. ACT_ARM64_TESTS=all runs everything (~10 min of
# tests on 2 cores instead of ~2.5).
# ACT_QEMU_CPU=cortex-a76 (the Pi 5's exact features) or cortex-a72 (no dotprod) picks the emulated
# CPU (with a fresh ACT_ARM64_BUILD_DIR: the emulator is fixed when the tree is configured).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${ACT_ARM64_BUILD_DIR:-$root/build-aarch64}"
jobs="${ACT_JOBS:-$(nproc)}"

# Under qemu on 2 cores each of these took 1.5-3.5 minutes; the other 182 tests 2.5 minutes in all.
slow_tests=(
  'Fixtures/FixtureTest\.ActionChunksMatchLeRobotForEverySampleAndImageFormat/.*'
  'Fixtures/FixtureTest\.TemporalEnsemblingMatchesLeRobot/.*'
  'EngineApiTest\.TwoEnginesRunSideBySide'
  'EngineApiTest\.SameResultForAnyThreadCountAndMemoryPlan'
  'SyntheticModel\.ActivationsStayWellScaled'  # one inference of the full-size rover model
)
exclude="^($(IFS='|'; echo "${slow_tests[*]}"))\$"

"$root/scripts/install_cross_deps.sh"

echo "== aarch64 cross build (core library + act_tests, -Werror) =="
configure=(--toolchain "$root/cmake/toolchains/aarch64-linux-gnu.cmake" -DACT_CORE_ONLY=ON -DACT_PACKAGE_APPS=ON -DACT_WITH_OPENCV=OFF)
if [ -n "${ACT_SHARED_DIR:-}" ]; then configure+=(-DACT_SHARED_DIR="$ACT_SHARED_DIR"); fi
ACT_BUILD_DIR="$build" "$root/scripts/build.sh" "${configure[@]}" "$@"

# The emulator command as ctest runs it (gtest_discover_tests writes it at build time).
emulator="$(grep -o -m1 '[^ ]*qemu-aarch64[^ ]* -cpu [^ ]*' "$build"/test/act_tests*_tests.cmake \
  || true)"
if [ -z "$emulator" ]; then
  echo "run_arm64_tests: act_tests in $build is not set up to run under qemu-aarch64" >&2
  exit 1
fi
# The emulated CPU's SIMD variants must really run (the host's requirement does not apply here).
case "$emulator" in
  *cortex-a72*) export ACT_TEST_REQUIRE_ISAS="" ;;
  *) export ACT_TEST_REQUIRE_ISAS=neondot ;;
esac
echo "kernel variants required under emulation: ${ACT_TEST_REQUIRE_ISAS:-none}"
count() { ctest --test-dir "$build" -N "$@" | sed -n 's/^Total Tests: //p'; }
ctest_args=(--test-dir "$build" --output-on-failure --no-tests=error -j "$jobs" --timeout 600)
if [ "${ACT_ARM64_TESTS:-quick}" = "all" ]; then
  echo "== aarch64 tests under $emulator: all $(count) =="
else
  echo "== aarch64 tests under $emulator: $(count -E "$exclude") of $(count) =="
  echo "not run under emulation (slow; the native stages run them; ACT_ARM64_TESTS=all runs them):"
  ctest --test-dir "$build" -N -R "$exclude" | sed -n 's/^ *Test *#[0-9]*: \([^ ]*\).*/  \1/p'
  ctest_args+=(-E "$exclude")
fi
ctest "${ctest_args[@]}"

echo "== arm64 Debian package =="
(cd "$build" && cpack -G DEB >/dev/null)
deb="$(ls "$build"/actengine_*_arm64.deb)"
dpkg-deb -f "$deb" Package Version Architecture Depends
unpacked="$build/package-check"
rm -rf "$unpacked"
dpkg-deb -x "$deb" "$unpacked"
# The dynamic loader and libraries come from the multiarch arm64 runtime, as for the tests.
read -r -a qemu <<<"$emulator"
help="$("${qemu[@]}" "$unpacked/usr/bin/act_bench" --help)"
echo "${help%%$'\n'*}"
echo "arm64 package OK: $deb"
