#!/usr/bin/env bash
# Generates every make_test_checkpoint.py preset into OUT_DIR/<preset>/ (run by ctest before the
# tests that read them).  A preset is skipped when its folder's .stamp matches the current hashes of
# the generator and of the shared reference tools, so re-running ctest costs nothing; any change to
# either regenerates.  Presets run in parallel, one per core (ACT_GEN_JOBS overrides).
#
#   test/tools/generate_test_checkpoints.sh OUT_DIR [SHARED_DIR]   (SHARED_DIR: <repo>/../shared)
set -euo pipefail

if [ $# -lt 1 ] || [ $# -gt 2 ]; then
  echo "usage: $0 OUT_DIR [SHARED_DIR]" >&2
  exit 2
fi
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
out_dir=$1
shared_dir=${2:-$here/../../../shared}
python=${PYTHON:-/usr/bin/python3}
generator=$here/make_test_checkpoint.py
tools=$shared_dir/tools/act_reference

if [ ! -f "$tools/spec_forward.py" ] || [ ! -f "$tools/act_harness/stio.py" ]; then
  echo "error: shared reference tools not found in '$tools'" \
       "(pass SHARED_DIR, the shared/ folder)" >&2
  exit 1
fi
if ! "$python" -c 'import torch, numpy' 2>/dev/null; then
  echo "error: $python cannot import torch and numpy; install python3-torch and python3-numpy" \
       "(scripts/install_deps.sh does)" >&2
  exit 1
fi

stamp=$(cat "$generator" "$tools/spec_forward.py" "$tools/act_harness/stio.py" | sha256sum)
stamp=${stamp%% *}
mkdir -p "$out_dir"
out_dir=$(cd "$out_dir" && pwd)

todo=()
for preset in $("$python" "$generator" --list | cut -d' ' -f1); do
  if [ "$(cat "$out_dir/$preset/.stamp" 2>/dev/null)" = "$stamp" ]; then
    echo "$preset: up to date"
  else
    todo+=("$preset")
  fi
done
[ ${#todo[@]} -eq 0 ] && exit 0

# One preset: generate (the generator replaces the folder atomically and self-checks it), stamp.
generate_one() {
  local preset=$1 log="$out_dir/$1.log" start=$SECONDS
  if "$python" "$generator" --preset "$preset" --out "$out_dir/$preset" --shared "$shared_dir" \
       >"$log" 2>&1; then
    echo "$stamp" >"$out_dir/$preset/.stamp"
    echo "$preset: generated in $((SECONDS - start)) s"
  else
    echo "$preset: FAILED after $((SECONDS - start)) s; last lines of $log:" >&2
    tail -n 20 "$log" >&2
    return 1
  fi
}
export -f generate_one
export python generator shared_dir out_dir stamp

jobs=${ACT_GEN_JOBS:-$(nproc)}
# The float64 references allocate and free tensors of megabytes per layer: glibc would hand each back
# to the kernel and fault it in again (a third of the run in page faults); keeping them in the heap
# makes the 480x640 preset about a quarter faster, at the same peak memory; in transparent huge pages
# (hugetlb=1) the presets took 20 s instead of 31 (2 cores).
export GLIBC_TUNABLES=glibc.malloc.hugetlb=1:glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=8589934592:glibc.malloc.top_pad=268435456
# shellcheck disable=SC2016  # $1 is expanded by the inner bash, on purpose
if ! printf '%s\n' "${todo[@]}" \
     | OMP_NUM_THREADS=1 xargs -P "$jobs" -I{} bash -c 'generate_one "$1"' _ {}; then
  echo "error: some test checkpoints failed to generate (see the .log files in $out_dir)" >&2
  exit 1
fi
