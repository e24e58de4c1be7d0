#!/usr/bin/env bash
# Prints the numbers table of README.md and docs/performance.md from the act_bench JSON files here
# (docs/performance.md, "The current table", says how they were measured). With --write, replaces
# the generated block (between its two marker comments) in both files instead. With --pi5 ACT_BENCH,
# first rewrites pi5-estimate.json from that act_bench's --target pi5 estimate of the built-in
# default and rover models (INT8, nothing timed: docs/arm.md).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$here/../.."
if [[ "${1:-}" == "--pi5" ]]; then
  bench="${2:?--pi5 needs the act_bench to run, e.g. build/apps/act_bench}"
  work="$(mktemp -d)"
  trap 'rm -rf "$work"' EXIT
  for config in default rover; do "$bench" --target pi5 --config "$config" --json "$work/$config.json" >/dev/null; done
  python3 - "$here/pi5-estimate.json" "$work/default.json" "$work/rover.json" <<'PY'
import json, sys
records = [json.load(open(path)) for path in sys.argv[2:]]
with open(sys.argv[1], "w") as f:
    json.dump(records, f, indent=1)
    f.write("\n")
PY
  shift 2
fi
table() {
  python3 "$root/scripts/perf_table.py" \
    "$here/zen4.json" \
    --label "AMD EPYC Zen 5, 2 vCPU" \
    --note "A shared host. INT8 rows: quiet during the runs, \`vpdpbusd\` probe 519-536 GMAC/s per core. FP32 rows: with the 3x3 stride-1 convs as Winograd F(2x2,3x3), whose shares count the direct convs' MACs (so they can pass 100 %), on a busier host, FMA probe 121-122 GMAC/s per core (the probes' readings move with the host's load)." \
    "$here"/zen5-2vcpu/*.json \
    --label "Intel Xeon, 2 vCPU" \
    --note "A loaded host: 2 vCPUs shared with four other engineers' builds (load average 4-7) during the runs, so these read well below the CPU's speed; \`vpdpbusd\` probe 383 GMAC/s per core, FMA 89." \
    "$here"/xeon-2vcpu/*.json \
    "$here/pi5-estimate.json"
}
if [[ "${1:-}" != "--write" ]]; then
  table
  exit 0
fi
table > "$here/.table.md"
python3 - "$here/.table.md" "$root/README.md" "$root/docs/performance.md" <<'PY'
import re, sys
table = open(sys.argv[1]).read().rstrip("\n")
for path in sys.argv[2:]:
    text = open(path).read()
    new, n = re.subn(r"(do not edit by hand -->\n).*?(\n<!-- end of generated table -->)",
                     lambda m: m.group(1) + table + m.group(2), text, flags=re.S)
    if n != 1:
        sys.exit("%s: expected one generated block, found %d" % (path, n))
    open(path, "w").write(new)
PY
rm -f "$here/.table.md"
