#!/usr/bin/env bash
# ThreadSanitizer stage: a narrow build (the core library and act_tests only, -DACT_SANITIZE=thread
# -DACT_CORE_ONLY=ON) and the tests that run threads: the thread pool, Engines side by side, opened
# concurrently and handed between threads, and every thread count of the same model.
# ACT_TSAN_FILTER replaces the gtest filter.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${ACT_TSAN_BUILD_DIR:-$root/build-tsan}"
jobs="${ACT_JOBS:-2}"
filter="${ACT_TSAN_FILTER:-ThreadPool.*:EngineApiTest.TwoEnginesRunSideBySide:EngineApiTest.OneEngineHandedFromThreadToThread:EngineApiTest.EnginesOpenAndRunConcurrently:EngineApiTest.SameResultForAnyThreadCountAndMemoryPlan}"

cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DACT_WERROR=ON -DACT_SANITIZE=thread \
  -DACT_CORE_ONLY=ON >/dev/null
cmake --build "$build" -j "$jobs" --target act_tests
# halt_on_error: the first race fails the stage (a report alone would not change the exit code).
TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1 ${TSAN_OPTIONS:-}" \
  ACT_TEST_TMP="$build/tmp" "$build/test/act_tests" --gtest_filter="$filter"
