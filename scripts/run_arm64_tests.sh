#!/usr/bin/env bash
# Cross-compiles the core library (kernels, weights, graph, engine) and act_tests for aarch64 (the
# Raspberry Pi 5) with Debian's g++-aarch64-linux-gnu, warnings as errors, into build-aarch64/ (or
# $ACT_ARM64_BUILD_DIR), then runs the tests through ctest under qemu-user (`qemu-aarch64 -cpu max`:
# NEON, dotprod, SVE...), so the ARM code paths really execute. Exits non-zero on any failure.
# Called by scripts/run_tests.sh (CI), which skips it with ACT_SKIP_ARM64=1. Extra arguments go to
# CMake's configure step.
#
# Then the arm64 Debian packages from the same tree (the apps are built too, not their tests; act_convert
# and act_drive against the arm64 OpenCV of scripts/fetch_arm64_opencv.sh): built with CPack,
# unpacked, the library checked to be in /usr/lib/aarch64-linux-gnu, every app (and the image and
# video module, apps/media) to be a stripped aarch64 program whose OpenCV libraries actengine-tools
# depends on, and its act_bench run under qemu (`--help`, then one run that must say it is emulated),
# so the packages CI ships start. (act_drive itself cannot start under qemu here: the arm64
# dependencies of OpenCV's core, TBB, BLAS, LAPACK and GLX among them, are not installed.)
#
# Which tests: all of act_tests except the few end-to-end tests listed below, which repeat
# whole-model inference many times or run the full-size model: under emulation each takes 15 s or more,
# and the native sanitizer stage runs them anyway. Everything else runs, so new kernel
# tests run here with no change to this script. ACT_ARM64_TESTS=all runs everything (~10 min of
# tests on 2 cores instead of ~1).
# ACT_QEMU_CPU=cortex-a76 (the Pi 5's exact features) or cortex-a72 (no dotprod) picks the emulated
# CPU (with a fresh ACT_ARM64_BUILD_DIR: the emulator is fixed when the tree is configured).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${ACT_ARM64_BUILD_DIR:-$root/build-aarch64}"
jobs="${ACT_JOBS:-$(nproc)}"

# Under qemu on 2 cores each of these took 15 s to 3.5 minutes (the kernel tests take seconds): they
# repeat whole-model inference (thread hand-offs, select_action over many steps, several seeds). The
# native stages run them; here every fixture still runs end to end once (EveryIntermediateMatchesLeRobot).
slow_tests=(
  'Fixtures/FixtureTest.ActionChunksMatchLeRobotForEverySampleAndImageFormat/*'
  'Fixtures/FixtureTest.TemporalEnsemblingMatchesLeRobot/*'
  'Fixtures/FixtureTest.SelectActionQueueMatchesLeRobot/*'
  'EngineApiTest.TwoEnginesRunSideBySide'
  'EngineApiTest.SameResultForAnyThreadCountAndMemoryPlan'
  'EngineApiTest.OneEngineHandedFromThreadToThread'
  'EngineApiTest.EnginesOpenAndRunConcurrently'
  'EngineApiTest.ProfilingReportsEveryStage'
  'EngineApiTest.RowStrideIsHonoured'
  'SyntheticModel.ActivationsStayWellScaled'  # one inference of the full-size rover model
  'SyntheticModel.DeterministicForASeed'
  'SplitEngine.Int8StaticBlobRunsTheRestExactlyAsTheWholeEngine'  # an INT8 calibration, then two engines
  # INT8 conversions (each evaluates its held-out frames with and without int8 attention): 12-140 s
  # here; the int8 attention's NEON path runs in OpsPerIsa.AttentionS8* within a second.
  'ConvertApi.AttentionPrecisionIsChosenByHeldOutErrorAndRunsAsChosen'
  'ConvertApi.LinearInputCodesAreChosenByHeldOutErrorAndRunAsChosen'
  'ConvertApi.ReportStructMatchesItsJson'
  'ConvertApi.MissedMaxMseWritesNothing'
  'SharedPackedWeights.*'  # three or four engines of act-tiny's 45 MB each; the sharing does not depend on the ISA
  'Modes/SchedulerVsPolicy.ZeroLatencyOnRawChunksMatchesPolicySelectAction/TemporalEnsembling'  # 83 s
  'Modes/SchedulerVsPolicy.ZeroLatencyOnRawChunksMatchesPolicySelectAction/Queue'  # 29 s
  # Whole-model inference repeated for the profiler and the blob's mapping (18-21 s each here): no
  # kernel of their own; the NEON variants run in EveryIsaThisCpuRunsGivesTheSameActions.
  'EngineApiTest.ProfilerTimesEveryOpAndTracesEveryThread'
  'EngineApiTest.TheRunningModelCannotChangeUnderIt'
)
# gtest filter patterns (* any text): ACT_TEST_SHARDS below runs act_tests in 4 processes, and
# GTEST_FILTER leaves these out of them.

"$root/scripts/install_cross_deps.sh"

echo "== aarch64 cross build (core library + act_tests, -Werror) =="
"$root/scripts/fetch_arm64_opencv.sh" "$build/opencv-arm64"
# A unity build, as CI's sanitizer trees (scripts/run_tests.sh says why).
configure=(--toolchain "$root/cmake/toolchains/aarch64-linux-gnu.cmake" -DACT_WERROR=ON -DACT_CORE_ONLY=ON -DACT_PACKAGE_APPS=ON
           -DCMAKE_UNITY_BUILD=ON -DACT_TEST_SHARDS=4 -DACT_ARM64_OPENCV_ROOT="$build/opencv-arm64/root")
if [ -n "${ACT_SHARED_DIR:-}" ]; then configure+=(-DACT_SHARED_DIR="$ACT_SHARED_DIR"); fi
ACT_BUILD_DIR="$build" "$root/scripts/build.sh" "${configure[@]}" "$@"

# The emulator command as ctest runs it (CMAKE_CROSSCOMPILING_EMULATOR, in each shard's command).
emulator="$(sed -n 's/^add_test(\[=\[act_tests_shard_0_of_[0-9]*\]=\] "\([^"]*qemu-aarch64\)" "-cpu" "\([^"]*\)".*/\1 -cpu \2/p' \
  "$build/test/CTestTestfile.cmake")"
if [ -z "$emulator" ]; then
  echo "run_arm64_tests: act_tests in $build is not set up to run under qemu-aarch64 in shards" >&2
  exit 1
fi
# The emulated CPU's SIMD variants must really run (the host's requirement does not apply here).
case "$emulator" in
  *cortex-a72*) export ACT_TEST_REQUIRE_ISAS=neon ;;
  *) export ACT_TEST_REQUIRE_ISAS=neon,neondot ;;
esac
echo "kernel variants required under emulation: ${ACT_TEST_REQUIRE_ISAS:-none}"
read -r -a qemu <<<"$emulator"
# The tests a gtest filter selects, one per line.
list_tests() {
  "${qemu[@]}" "$build/test/act_tests" --gtest_list_tests --gtest_filter="$1" |
    awk '/^[^ ]/ {suite = $1} /^  / {print suite $1}'
}
if [ "${ACT_ARM64_TESTS:-quick}" = "all" ]; then
  export GTEST_FILTER='*'
  echo "== aarch64 tests under $emulator: all $(list_tests '*' | wc -l) =="
else
  slow_filter="$(IFS=':'; echo "${slow_tests[*]}")"
  export GTEST_FILTER="-$slow_filter"
  echo "== aarch64 tests under $emulator: $(list_tests "$GTEST_FILTER" | wc -l) of $(list_tests '*' | wc -l) =="
  echo "not run under emulation (slow; the native stages run them; ACT_ARM64_TESTS=all runs them):"
  list_tests "$slow_filter" | sed 's/^/  /'
fi
# act_tests in 4 processes (ACT_TEST_SHARDS): a process per test spent most of its time starting
# the emulator and the program (117 s for 352 tests on two cores; the 4 shards ran them in 85 s).
ctest --test-dir "$build" --output-on-failure --no-tests=error -j "$jobs"

echo "== arm64 Debian packages =="
rm -f "$build"/*.deb
(cd "$build" && cpack -G DEB >/dev/null)
unpacked="$build/package-check"
rm -rf "$unpacked"
for package in libactengine0 libactengine-dev actengine-tools; do
  deb="$(ls "$build/${package}"_*_arm64.deb)"
  dpkg-deb -f "$deb" Package Version Architecture Depends
  dpkg-deb -x "$deb" "$unpacked"
done
if [ ! -f "$unpacked/usr/lib/aarch64-linux-gnu/libactengine.so.0" ]; then
  echo "run_arm64_tests: libactengine0 has no /usr/lib/aarch64-linux-gnu/libactengine.so.0" >&2
  exit 1
fi
depends="$(dpkg-deb -f "$(ls "$build"/actengine-tools_*_arm64.deb)" Depends)"
unstripped=' \.(symtab|debug_info) '
# The apps, and the image and video module act_convert, act_eval and act_drive load on first use.
for program in "$unpacked"/usr/bin/{act_bench,act_eval,act_convert,act_drive,act_pwm_watchdog} \
               "$unpacked/usr/lib/aarch64-linux-gnu/actengine/libact_media_io.so"; do
  app="$(basename "$program")"
  if [ ! -f "$program" ]; then
    echo "run_arm64_tests: the arm64 packages have no $program" >&2
    exit 1
  fi
  # Outputs read whole before they are matched (under pipefail, `readelf | grep -q` fails when grep
  # stops early and readelf dies of SIGPIPE).
  header="$(readelf -h "$program" 2>/dev/null || true)"
  if [[ ! "$header" =~ Machine:\ *AArch64 ]]; then
    echo "run_arm64_tests: the arm64 package has no aarch64 $app" >&2
    exit 1
  fi
  sections="$(readelf -S "$program")"
  if [[ "$sections" =~ $unstripped ]]; then
    echo "run_arm64_tests: $app in the arm64 package is not stripped" >&2
    exit 1
  fi
  # Each OpenCV library the program needs (libopencv_videoio.so.406) -> its package (libopencv-videoio406).
  for lib in $(readelf -d "$program" | sed -n 's/.*NEEDED.*\[\(libopencv_[a-z]*\)\.so\.\([0-9]*\)\]/\1\2/p'); do
    package="$(echo "$lib" | tr _ -)"
    if [[ "$depends" != *"$package "* ]]; then
      echo "run_arm64_tests: $app needs $lib but actengine-tools does not depend on $package" >&2
      exit 1
    fi
  done
done
# The dynamic loader and libraries come from the multiarch arm64 runtime, as for the tests.
help="$("${qemu[@]}" "$unpacked/usr/bin/act_bench" --help)"
echo "${help%%$'\n'*}"
# A run under qemu says that its timings are the emulator's, in the text and the JSON.
bench="$("${qemu[@]}" "$unpacked/usr/bin/act_bench" --config 64x64 --num_runs 1 --warmup_runs 0 --threads 1 \
  --json "$build/emulated_bench.json" 2>&1)"
if ! grep -q '^EMULATED ' <<<"$bench" || ! grep -q '"emulated": true' "$build/emulated_bench.json"; then
  echo "$bench"
  echo "run_arm64_tests: act_bench under qemu does not say that it is emulated" >&2
  exit 1
fi
grep '^EMULATED ' <<<"$bench"
echo "arm64 packages OK: $(ls "$build"/*_arm64.deb | tr '\n' ' ')"
