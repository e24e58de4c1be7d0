#!/usr/bin/env bash
# Same-process A/B of one gemm_s8 ISA file: the file as it is at a git revision (A, default HEAD)
# against the working tree's (B), both compiled with this build's flags for it into one harness
# (gemm_s8_ab_main.cc) and timed in alternating rounds there. For kernel changes of a few percent,
# which a shared host's noise between processes (5-15 %) hides; an A/A run (no change) shows the
# harness's own floor (about 1-2 %).
#
#   bench/tools/gemm_s8_ab.sh [--rev REV] [--build DIR] FILE [--rounds N] SHAPE...
#     FILE   an ISA file of kernels/gemm_s8/, e.g. kernels/gemm_s8/gemm_s8_avx512vnni.cc
#     SHAPE  MxNxK[:s8|:f32|:s32][+zp], e.g. 302x3200x512:f32+zp (the FFN's hidden layer), or a
#            conv as the network runs it: conv:HxWxC:OUT:KERNEL:STRIDE, e.g. conv:120x160x64:64:3:1
#   taskset -c 1 bench/tools/gemm_s8_ab.sh kernels/gemm_s8/gemm_s8_avx512vnni.cc 1200x256x2304 302x1536x512:f32
#
# A is compiled against the revision's kernels/ headers (its driver and common code), B against the
# working tree's; both link this build's library (build first). The two must pack weights the same
# way (the harness packs once).
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
die() { echo "gemm_s8_ab: $*" >&2; exit 2; }
rev=HEAD
build="$root/build"
while [ $# -gt 0 ]; do
  case "$1" in
    --rev) rev="$2"; shift 2 ;;
    --build) build="$2"; shift 2 ;;
    -h|--help) sed -n '2,19p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) break ;;
  esac
done
[ $# -ge 2 ] || die "usage: $0 [--rev REV] [--build DIR] FILE [--rounds N] SHAPE... (--help)"
file="${1#"$root"/}"
shift
[ -f "$root/$file" ] || die "no file $file"
lib="$build/engine/libactengine.a"
probes="$build/bench/probes/libact_bench_probes.a"  # thread_cpu_seconds (kernels/peak)
if [ ! -f "$lib" ] || [ ! -f "$probes" ] || [ ! -f "$build/build.ninja" ]; then
  die "no built library in $build (build it first: ninja -C $build)"
fi
# The compile flags this build gives the file (its ISA's -m options included).
flags="$(awk -v obj="/$(basename "$file").o:" '$1 == "build" && index($2, obj) {found = 1; next}
  found && $1 == "FLAGS" {sub(/^[ \t]*FLAGS = /, ""); print; exit}' "$build/build.ninja")"
[ -n "$flags" ] || die "$build/build.ninja does not compile $file"
# The file's exported kernels and its table, renamed per copy so both link into one program.
mapfile -t names < <(grep -oE '^(void|const GemmS8Kernels\*) gemm_s8[a-z0-9_]*\(' "$root/$file" | sed -E 's/.* (gemm_s8[a-z0-9_]*)\(/\1/')
table="$(printf '%s\n' "${names[@]}" | grep -m1 '^gemm_s8_table_')" || die "$file defines no gemm_s8_table_*()"

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/a_root"
git -C "$root" archive "$rev" kernels | tar -x -C "$work/a_root" || die "no kernels/ at revision $rev"
[ -f "$work/a_root/$file" ] || die "$file is not in revision $rev"
renames() { for n in "${names[@]}"; do printf -- '-D%s=%s_ab_%s ' "$n" "$n" "$1"; done; }
echo "gemm_s8_ab: A = $file at $(git -C "$root" rev-parse --short "$rev"), B = the working tree's; compiling..." >&2
# shellcheck disable=SC2046,SC2086
g++ $flags -I"$work/a_root" -I"$root" $(renames A) -c "$work/a_root/$file" -o "$work/a.o" &
compile_a=$!
# shellcheck disable=SC2046,SC2086
g++ $flags -I"$root" $(renames B) -c "$root/$file" -o "$work/b.o" &
compile_b=$!
wait "$compile_a" || die "compiling A ($rev) failed"
wait "$compile_b" || die "compiling B (the working tree) failed"
g++ -O2 -std=c++20 -I"$root" -DACT_AB_TABLE_A="${table}_ab_A" -DACT_AB_TABLE_B="${table}_ab_B" \
  "$root/bench/tools/gemm_s8_ab_main.cc" "$work/a.o" "$work/b.o" "$probes" "$lib" -lcpuinfo -lpthread -o "$work/gemm_s8_ab"
"$work/gemm_s8_ab" "$@"
