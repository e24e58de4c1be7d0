#!/usr/bin/env bash
# Builds the parsers' libFuzzer targets (test/fuzz, clang, ASan + UBSan; only the parser sources)
# and runs each for ACT_FUZZ_SECONDS (default 30) from its seed corpus in test/fuzz/corpus/, ACT_JOBS
# (default 2) targets at a time.
# Prints the executions per target; fails on any crash, leak, sanitizer report or timeout, leaving
# the input in $ACT_FUZZ_BUILD_DIR/findings/ (store it under test/fuzz/regressions/ with a test).
# Generated inputs go to a scratch corpus in the build tree; the committed seeds stay as they are.
# ACT_FUZZ_TARGETS="fuzz_actb fuzz_pickle" runs a subset.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${ACT_FUZZ_BUILD_DIR:-$root/build-fuzz}"
seconds="${ACT_FUZZ_SECONDS:-30}"
jobs="${ACT_JOBS:-2}"

if ! command -v clang++ >/dev/null; then ACT_SKIP_ARM64=1 "$root/scripts/install_deps.sh"; fi
cmake -S "$root" -B "$build" -G Ninja -DACT_FUZZ=ON -DACT_WERROR=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ >/dev/null
cmake --build "$build" -j "$jobs"

targets=(${ACT_FUZZ_TARGETS:-$(cd "$root/test/fuzz/corpus" && ls)})
mkdir -p "$build/findings"

# Runs one target; its result line goes to $build/<target>.result. Each fuzzer is one process, so
# $jobs of them run side by side.
fuzz_one() {
  local target="$1" corpus="$build/corpus/$1" log="$build/$1.log" dict=()
  mkdir -p "$corpus"
  [ -f "$root/test/fuzz/$target.dict" ] && dict=(-dict="$root/test/fuzz/$target.dict")
  # New inputs go to the scratch corpus (first folder); the seeds are read from the second.
  if ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
     "$build/test/fuzz/$target" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -max_len=65536 \
       -print_final_stats=1 "${dict[@]}" -artifact_prefix="$build/findings/$target-" \
       "$corpus" "$root/test/fuzz/corpus/$target" >"$log" 2>&1; then
    echo "$target: $(sed -n 's/^stat::number_of_executed_units: *//p' "$log") executions in ${seconds}s" >"$build/$target.result"
  else
    echo "$target: FAILED (log $log, input in $build/findings/)" >"$build/$target.result"
  fi
}

echo "== ${#targets[@]} fuzz targets, ${seconds}s each, $jobs at a time =="
running=0
for target in "${targets[@]}"; do
  fuzz_one "$target" &
  running=$((running + 1))
  if [ "$running" -ge "$jobs" ]; then
    wait -n
    running=$((running - 1))
  fi
done
wait
failed=0
for target in "${targets[@]}"; do
  cat "$build/$target.result"
  if grep -q FAILED "$build/$target.result"; then
    failed=1
    tail -n 60 "$build/$target.log"
  fi
done
exit "$failed"
