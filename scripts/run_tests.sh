#!/usr/bin/env bash
# README command (2) and what CI runs (.ci/run): installs the dependencies, builds actengine and runs
# every test, in stages (each one's wall time is printed at the end):
#   1. Release (build/, only what these need): the tests of the full-size generated models, which
#      take seconds here and many minutes under ASan, the Python module's pytest suite, the host's
#      Debian packages (unpacked, run, built against) and a smoke run of act_kernel_bench;
#   2. every other test in a native build under AddressSanitizer + UndefinedBehaviorSanitizer
#      (build-asan/; -O1 with the kernels at -O2, which builds in much less time than -O2
#      everywhere while the whole-model tests stay quick; act_tests in 4 processes, not one per
#      test: ACT_TEST_SHARDS in test/CMakeLists.txt);
#   3. the core library's tests cross-compiled for aarch64 and run under qemu-user (in 4 shards too),
#      and the arm64 Debian packages (scripts/run_arm64_tests.sh; ACT_SKIP_ARM64=1 skips it);
#   4. the threaded tests under ThreadSanitizer (scripts/run_tsan.sh; ACT_SKIP_TSAN=1 skips it);
#   5. each parser's libFuzzer target for ACT_FUZZ_SECONDS (15 here, which keeps the CI run under
#      30 minutes; scripts/run_fuzz.sh alone runs 30 s each; ACT_SKIP_FUZZ=1 skips it).
# The Release build users run (scripts/build.sh) compiles the same sources; its speed is measured by
# act_bench and act_kernel_bench, never asserted by a test.
# The Release tree builds file by file, as users build; the sanitizer and aarch64 trees are unity
# builds (-DCMAKE_UNITY_BUILD=ON: each target's files compiled in batches of 8, so the headers they
# share compile once per batch; the kernels never are, kernels/CMakeLists.txt), which builds in much
# less time. So both ways are compiled here.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"
jobs="${ACT_JOBS:-$(nproc)}"
timings=()
stage_start=$SECONDS
stage_done() { timings+=("$1 $((SECONDS - stage_start))s"); stage_start=$SECONDS; }

# ctest over a build tree; when tests fail, their output is printed again at the very end, so the
# tail of a long CI log says what failed and why: first each failed test's last lines (where a test
# says why it failed), then up to 80 lines of each one's log.
run_ctest() {
  local dir="$1"
  shift
  if ctest --test-dir "$dir" --output-on-failure -j "$jobs" "$@"; then return 0; fi
  local failed failed_names=()
  if [ ! -f "$dir/Testing/Temporary/LastTestsFailed.log" ]; then  # ctest itself could not finish
    echo "ctest wrote no list of failed tests in $dir; the disk:"
    df -h "$root" /tmp
    exit 1
  fi
  while IFS=: read -r _ failed; do failed_names+=("$failed"); done < "$dir/Testing/Temporary/LastTestsFailed.log"
  test_log() {
    awk -v name="$1" '{ p = index($0, " Testing: ") } p && substr($0, p + 10) == name {on = 1}
                      on {print} on && /end time:/ {on = 0}' "$dir/Testing/Temporary/LastTest.log"
  }
  echo "== why the failed tests in $dir failed: the last lines each printed =="
  for failed in "${failed_names[@]}"; do
    echo "-- $failed:"
    test_log "$failed" | grep -v -e '^<end of output>' -e '^-----' -e '^Test time' -e '^Test Failed' -e 'end time:' | tail -n 12
  done
  echo "== output of the failed tests in $dir =="
  for failed in "${failed_names[@]}"; do test_log "$failed" | tail -n 80; done
  echo "stage times: ${timings[*]} (failed in $dir after $SECONDS s)"
  echo "disk: $(free_disk) free"
  exit 1
}

# glibc's malloc in transparent huge pages (madvise mode, as Debian ships the kernel): the tests
# convert and load models of hundreds of MB, and on a VM each 4 KB page faulted in costs about 15 us;
# the Release stage's tests ran in 92 s instead of 131. (The sanitizers' own allocators ignore it.)
export GLIBC_TUNABLES="glibc.malloc.hugetlb=1${GLIBC_TUNABLES:+:$GLIBC_TUNABLES}"

# The build trees, generated checkpoints and converted blobs of a run take about 4.5 GB (each test's
# scratch folder goes when it passes: test/support/test_paths.h); "No space left on device" is the host's.
free_disk() { df -h --output=avail "$root" | tail -n 1 | tr -d ' '; }
echo "disk: $(free_disk) free on the checkout's filesystem"

"$root/scripts/install_deps.sh"
stage_done install

# The SIMD kernel variants of every ISA level this CPU runs (kernels/common/isa.h) must really run in
# the tests (a test fails otherwise).
flags=$(grep -m1 -E '^(flags|Features)' /proc/cpuinfo || true)
has() { for f in "$@"; do [[ " $flags " == *" $f "* ]] || return 1; done; }
required=()
has avx2 fma && required+=(avx2)
has avx2 fma avx_vnni && required+=(avxvnni)
has avx2 fma avx512f avx512bw avx512vl && required+=(avx512)
has avx2 fma avx512f avx512bw avx512vl avx512_vnni && required+=(avx512vnni)
has avx2 fma avx512f avx512bw avx512vl avx512_vnni amx_tile amx_int8 && required+=(amx)
has asimd && required+=(neon)
has asimd asimddp && required+=(neondot)
ACT_TEST_REQUIRE_ISAS=$(IFS=,; echo "${required[*]}")
export ACT_TEST_REQUIRE_ISAS
echo "kernel variants required by the tests: ${ACT_TEST_REQUIRE_ISAS:-none}"

# Both native trees share the generated test checkpoints (generating them takes minutes).
checkpoints="$root/build/test-checkpoints"
# Tests of the full-size generated models (Presets/...: FP32 against float64 references, INT8
# calibration and accuracy at 480x640; Onnx...: the ONNX export in ONNX Runtime through Node): seconds
# each in Release, many minutes under ASan.
full_size='^(Presets/|Onnx)'
# The host's Debian packages from the Release tree (test/consumer/run_package_test.sh): its libraries
# and apps are built for it; the ASan stage's would not run outside their sanitizer runtime.
packages='^debian_packages$'
# The web pages in headless chromium (Node; Release only, like the ONNX Runtime tests): the HTML
# reports, and act_drive's live view (run alone, below).
report_pages='^html_report_pages$'
live_view='^ActDriveLiveView\.'

echo "== Release build of the full-size model tests, the kernel benchmarks and the packaged libraries and apps (-Werror) =="
cmake -S "$root" -B "$root/build" -G Ninja -DCMAKE_BUILD_TYPE=Release -DACT_WERROR=ON \
  -DACT_GENERATED_CHECKPOINTS_DIR="$checkpoints" >/dev/null
cmake --build "$root/build" -j "$jobs" --target act_model_tests act_kernel_bench \
  actengine actengine_convert actengine_vision act_convert act_eval act_bench act_drive act_drive_browser_tests
stage_done release-build
echo "== Release: full-size model tests, the Debian packages, the web pages =="
run_ctest "$root/build" -R "$full_size|$packages|$report_pages"
# The live view's e-stop must reach the serial line within 250 ms: timed in a browser, alone, not
# beside a full-size model test that takes the other core.
jobs=1 run_ctest "$root/build" -R "$live_view"
stage_done release-tests
# The kernel benchmarks' smoke run (one thread) beside the Python module's build (one file) and
# pytest (one process), which leave the other core idle.
echo "== kernel benchmarks (smoke run; the numbers are not judged), and the Python module and LeRobot plugin (engine/python, pytest) =="
"$root/build/bench/act_kernel_bench" --benchmark_min_time=0.01 >"$root/build/kernel_bench.txt" 2>&1 &
kernel_bench=$!
cmake -S "$root" -B "$root/build" -DACT_BUILD_PYTHON=ON >/dev/null  # a missing pybind11 fails here, not skips
cmake --build "$root/build" -j "$jobs" --target actengine_python act_convert act_eval
run_ctest "$root/build" -R '^python_(module|lerobot_plugin)$'
# The wheel, built by pip for Debian's Python and for pyenv's 3.11 (when the machine has it), one at a time.
jobs=1 run_ctest "$root/build" -R '^python_wheel_(debian|pyenv)$'
wait "$kernel_bench" || { tail -n 40 "$root/build/kernel_bench.txt"; echo "act_kernel_bench failed" >&2; exit 1; }
echo "$(grep -c 'GMAC/s=' "$root/build/kernel_bench.txt") benchmarks ran (build/kernel_bench.txt)"
stage_done python-tests+kernel-bench-smoke

echo "== ASan + UBSan build (-Werror) =="
# -g1 (line tables) is all the sanitizer reports need, and builds much faster than -g.
ACT_BUILD_DIR="$root/build-asan" "$root/scripts/build.sh" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" -DACT_SANITIZE=ON -DACT_WERROR=ON -DACT_BUILD_BENCH=OFF \
  -DCMAKE_UNITY_BUILD=ON -DACT_TEST_SHARDS=4 -DACT_GENERATED_CHECKPOINTS_DIR="$checkpoints"
stage_done asan-build
echo "== ASan + UBSan: every other test =="
ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
  run_ctest "$root/build-asan" -E "$full_size|$packages|$report_pages|$live_view"
stage_done asan-tests

if [ "${ACT_SKIP_ARM64:-0}" != "1" ]; then
  ACT_JOBS="$jobs" "$root/scripts/run_arm64_tests.sh"
  stage_done aarch64-build+qemu-tests+package
fi
if [ "${ACT_SKIP_TSAN:-0}" != "1" ]; then
  echo "== ThreadSanitizer: threaded tests =="
  ACT_JOBS="$jobs" "$root/scripts/run_tsan.sh"
  stage_done tsan-build+tests
fi
if [ "${ACT_SKIP_FUZZ:-0}" != "1" ]; then
  echo "== libFuzzer: every parser of outside data =="
  ACT_JOBS="$jobs" ACT_FUZZ_SECONDS="${ACT_FUZZ_SECONDS:-15}" "$root/scripts/run_fuzz.sh"
  stage_done fuzz-build+runs
fi
echo "stage times: ${timings[*]} (total $SECONDS s)"
echo "disk: the build trees take $(du -sch "$root"/build* | tail -n 1 | cut -f1), $(free_disk) free"
echo "all tests passed"
