#!/usr/bin/env bash
# Builds the parsers' libFuzzer targets (test/fuzz, clang, ASan + UBSan; only the parser sources)
# and runs each for ACT_FUZZ_SECONDS (default 60) from its seed corpus in test/fuzz/corpus/.
# Prints the executions per target; fails on any crash, leak, sanitizer report or timeout, leaving
# the input in $ACT_FUZZ_BUILD_DIR/findings/ (store it under test/fuzz/regressions/ with a test).
# Generated inputs go to a scratch corpus in the build tree; the committed seeds stay as they are.
# ACT_FUZZ_TARGETS="fuzz_actb fuzz_pickle" runs a subset.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${ACT_FUZZ_BUILD_DIR:-$root/build-fuzz}"
seconds="${ACT_FUZZ_SECONDS:-60}"
jobs="${ACT_JOBS:-2}"

if ! command -v clang++ >/dev/null; then ACT_SKIP_ARM64=1 "$root/scripts/install_deps.sh"; fi
cmake -S "$root" -B "$build" -G Ninja -DACT_FUZZ=ON -DACT_WERROR=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ >/dev/null
cmake --build "$build" -j "$jobs"

targets=(${ACT_FUZZ_TARGETS:-$(cd "$root/test/fuzz/corpus" && ls)})
mkdir -p "$build/findings"
summary=()
failed=0
for target in "${targets[@]}"; do
  corpus="$build/corpus/$target"
  mkdir -p "$corpus"
  log="$build/$target.log"
  dict=()
  [ -f "$root/test/fuzz/$target.dict" ] && dict=(-dict="$root/test/fuzz/$target.dict")
  echo "== $target: ${seconds}s =="
  # New inputs go to the scratch corpus (first folder); the seeds are read from the second.
  if ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
     "$build/test/fuzz/$target" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -max_len=65536 \
       -print_final_stats=1 "${dict[@]}" -artifact_prefix="$build/findings/$target-" \
       "$corpus" "$root/test/fuzz/corpus/$target" >"$log" 2>&1; then
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log")
    summary+=("$target: $execs executions in ${seconds}s")
  else
    failed=1
    tail -n 60 "$log"
    summary+=("$target: FAILED (log $log, input in $build/findings/)")
  fi
done
printf '%s\n' "${summary[@]}"
exit "$failed"
