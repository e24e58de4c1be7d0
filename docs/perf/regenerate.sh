#!/usr/bin/env bash
# Prints the numbers table of README.md and docs/performance.md from the act_bench JSON files here
# (docs/performance.md, "The current table", says how they were measured).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
exec python3 "$here/../../scripts/perf_table.py" \
  "$here/zen4.json" "$here/zen5.json" \
  --label "Intel Xeon, 2 vCPU" \
  --note "A loaded host: 2 vCPUs shared with four other engineers' builds (load average 4-7) during the runs, so these read well below the CPU's speed; \`vpdpbusd\` probe 383 GMAC/s per core, FMA 89." \
  "$here"/xeon-2vcpu/*.json \
  "$here/pi5-estimate.json"
