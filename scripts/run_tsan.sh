#!/usr/bin/env bash
# ThreadSanitizer stage: a narrow build (-DACT_SANITIZE=thread; only the act_thread_tests target:
# the core library, act_drive's pieces and the tests that run threads) and a run of it: the thread
# pool, Engines side by side, opened concurrently and handed between threads, every thread count of
# the same model, and act_drive's control loop (camera, inference, serial link, recorder threads).
# -O1 (the kernels -O2, kernels/CMakeLists.txt) with line tables only (-g1): -O2 everywhere and full
# debug info each double the build time, and line tables are all a race report needs.
# ACT_TSAN_FILTER replaces the gtest filter.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${ACT_TSAN_BUILD_DIR:-$root/build-tsan}"
jobs="${ACT_JOBS:-2}"
# The tests of act_thread_tests that start threads (the rest only come along with their files).
threaded="ThreadPool.*:PeakTogether.*:EngineApiTest.SameResultForAnyThreadCountAndMemoryPlan:EngineApiTest.TwoEnginesRunSideBySide"
threaded+=":EngineApiTest.OneEngineHandedFromThreadToThread:EngineApiTest.EnginesOpenAndRunConcurrently"
threaded+=":EngineApiTest.ProfilerTimesEveryOpAndTracesEveryThread:ControlLoop.*:Recorder.*"
# Left out: it counts the frames recorded in 1.2 s of wall time, which TSan's slowdown can miss (its
# threads ran race-free when tried; the count assertion was what failed).
threaded+=":-ControlLoop.RecordWritesFramesObservationsAndTicks"

cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" \
  -DACT_WERROR=ON -DACT_SANITIZE=thread -DACT_BUILD_BENCH=OFF -DCMAKE_UNITY_BUILD=ON >/dev/null
cmake --build "$build" -j "$jobs" --target act_thread_tests
# halt_on_error: the first race fails the stage (a report alone would not change the exit code).
TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1 suppressions=$root/test/tsan.supp ${TSAN_OPTIONS:-}" \
  ACT_TEST_TMP="$build/tmp" "$build/test/act_thread_tests" --gtest_filter="${ACT_TSAN_FILTER:-$threaded}"
