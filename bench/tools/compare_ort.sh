#!/usr/bin/env bash
# act_bench against ONNX Runtime on the same model, on the same machine, in the same run: the
# built-in model act_bench benchmarks is saved once as a blob (act_bench --save-model) and exported
# once as ONNX (act_convert --export-onnx; an INT8 blob exports QDQ), then ROUNDS rounds alternate
# act_bench -m BLOB and ort_bench.js (onnxruntime-node) with the same thread count, and one table
# prints each round's p50 and the ratio ORT / ours (above 1: ours is faster).
#
#   bench/tools/compare_ort.sh [--build DIR] [-n RUNS] [-w WARMUP] [--keep DIR] [--profile] MODEL PRECISION THREADS ROUNDS
#     MODEL      default (480x640) or rover (360x640), act_bench --config (or HxW)
#     PRECISION  int8 or fp32
#     -n RUNS    timed runs per round and runtime (default 20); -w WARMUP untimed runs before (default 2)
#     --keep DIR write the blob, the ONNX model and each round's JSON there (default: a temp dir, removed)
#     --profile  after the rounds, ONNX Runtime's time per run by op type (ort_bench.js --profile)
#   taskset -c 0,1 bench/tools/compare_ort.sh default int8 2 3
#
# Needs a build with act_bench and act_convert (ONNX export on: libonnx-dev) and
# scripts/install_node_deps.sh's onnxruntime-node.
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
die() { echo "compare_ort: $*" >&2; exit 2; }
build="$root/build"
runs=20
warmup=2
keep=""
profile=0
while [ $# -gt 0 ]; do
  case "$1" in
    --build) build="$2"; shift 2 ;;
    -n) runs="$2"; shift 2 ;;
    -w) warmup="$2"; shift 2 ;;
    --keep) keep="$2"; shift 2 ;;
    --profile) profile=1; shift ;;
    -h|--help) sed -n '2,18p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    -*) die "unknown option $1 (--help)" ;;
    *) break ;;
  esac
done
[ $# -eq 4 ] || die "usage: $0 [--build DIR] [-n RUNS] [-w WARMUP] [--keep DIR] [--profile] MODEL PRECISION THREADS ROUNDS (--help)"
model="$1" precision="$2" threads="$3" rounds="$4"
case "$precision" in int8|fp32) ;; *) die "PRECISION is int8 or fp32, not \"$precision\"" ;; esac
for n in "$threads" "$rounds" "$runs" "$warmup"; do
  [[ "$n" =~ ^[0-9]+$ ]] || die "THREADS, ROUNDS, -n and -w are whole numbers, not \"$n\""
done
if [ "$threads" -lt 1 ] || [ "$rounds" -lt 1 ] || [ "$runs" -lt 1 ]; then die "THREADS, ROUNDS and -n are at least 1"; fi
bench="$build/apps/act_bench"
convert="$build/apps/act_convert"
ort_bench="$root/bench/tools/ort_bench.js"
if [ ! -x "$bench" ] || [ ! -x "$convert" ]; then die "no act_bench and act_convert in $build/apps (build them: cmake --build $build --target act_bench act_convert)"; fi
command -v node >/dev/null || die "node is not installed (scripts/install_deps.sh)"

if [ -n "$keep" ]; then
  mkdir -p "$keep"
  work="$(cd "$keep" && pwd)"
else
  work="$(mktemp -d)"
  trap 'rm -rf "$work"' EXIT
fi
"$bench" --config "$model" --precision "$precision" -t "$threads" --save-model "$work/model.actb" >&2
"$convert" "$work/model.actb" --export-onnx "$work/model.onnx" -q

for ((r = 1; r <= rounds; ++r)); do
  echo "compare_ort: round $r/$rounds: act_bench" >&2
  "$bench" -m "$work/model.actb" -t "$threads" -n "$runs" -w "$warmup" --json "$work/ours_$r.json" >/dev/null
  echo "compare_ort: round $r/$rounds: onnxruntime" >&2
  node "$ort_bench" "$work/model.onnx" --threads "$threads" --runs "$runs" --warmup "$warmup" --json "$work/ort_$r.json" >/dev/null
done

node - "$work" "$rounds" "$model" "$precision" "$threads" "$runs" <<'EOF'
const fs = require('fs');
const [work, rounds, model, precision, threads, runs] = process.argv.slice(2);
const read = (f) => JSON.parse(fs.readFileSync(`${work}/${f}`, 'utf8'));
const first = read('ours_1.json');
const ortVersion = read('ort_1.json').ort_version;
console.log(`model ${model} ${precision} (${first.model.precision}), ${threads} threads, ${runs} runs per round`);
const exported = precision === 'int8' ? 'QDQ' : 'FP32';
console.log(`machine ${first.machine.cpu_model}, ${first.machine.online_cores} cores; ONNX Runtime ${ortVersion} on the ${exported} export`);
console.log('round   ours p50 ms   ORT p50 ms   ORT/ours');
for (let r = 1; r <= Number(rounds); ++r) {
  const ours = read(`ours_${r}.json`).latency_ms.total.p50;
  const ort = read(`ort_${r}.json`).latency_ms.p50;
  console.log(`${String(r).padStart(5)}   ${ours.toFixed(2).padStart(11)}   ${ort.toFixed(2).padStart(10)}   ${(ort / ours).toFixed(2).padStart(7)}x`);
}
EOF
if [ "$profile" = 1 ]; then
  node "$ort_bench" "$work/model.onnx" --threads "$threads" --runs 1 --warmup 0 --profile | sed -n '/^op types/,$p'
fi
