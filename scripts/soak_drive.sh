#!/usr/bin/env bash
# act_drive soak: --dry-run on the act-tiny fixture for SECONDS (default 180) with its resident set
# sampled every 5 s. The camera is an image sequence of the fixture's frames, played at 30 fps with
# --loop: act_drive reopens it at its end, so the reopen path is soaked too. Fails if RSS grows after the first 30 s by more than
# ACT_SOAK_TOLERANCE_KB (default 2048), if a tick was missed, if act_drive fails, or if its last
# command is not neutral. A benchmark (docs/reliability.md), not part of CI. Needs a built tree
# ($ACT_BUILD_DIR, default build/). Arguments after SECONDS go to act_drive, e.g.
#   scripts/soak_drive.sh 180 --control-priority 50      (SCHED_FIFO control thread, as on the rover)
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
build="${ACT_BUILD_DIR:-$root/build}"
seconds="${1:-180}"
shift $(($# > 0 ? 1 : 0))  # the rest goes to act_drive (e.g. --control-priority 50, as on the rover)
tolerance_kb="${ACT_SOAK_TOLERANCE_KB:-2048}"
fixture="${ACT_SHARED_DIR:-$root/../shared}/fixtures/act-tiny"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

"$build/apps/act_convert" "$fixture" -o "$work/tiny.actb" -q
mkdir "$work/frames"
frames=("$fixture"/sample*.png)
for i in $(seq 0 299); do ln -s "${frames[$((i % ${#frames[@]}))]}" "$work/frames/$(printf %06d "$i").png"; done

"$build/apps/act_drive" -m "$work/tiny.actb" --camera "$work/frames/%06d.png" --loop --dry-run --threads 1 \
  --duration "$seconds" --stats-every 60 "$@" >"$work/commands.txt" 2>"$work/log.txt" &
pid=$!
samples=()
while kill -0 "$pid" 2>/dev/null; do
  rss=$(awk '/^VmRSS:/ {print $2}' "/proc/$pid/status" 2>/dev/null || true)
  [ -n "$rss" ] && samples+=("$SECONDS $rss")
  sleep 5
done
wait "$pid" && status=0 || status=$?

baseline="" max=0 last=0 start=${samples[0]%% *}
for s in "${samples[@]}"; do
  t=${s%% *} kb=${s##* }
  [ $((t - start)) -lt 30 ] && continue
  [ -z "$baseline" ] && baseline=$kb
  [ "$kb" -gt "$max" ] && max=$kb
  last=$kb
done
growth=$((max - ${baseline:-0}))
summary=$(grep -- '--duration reached' "$work/log.txt" || true)
last_command=$(tail -n 1 "$work/commands.txt")
echo "act_drive --dry-run for ${seconds}s: exit $status; RSS after 30 s ${baseline:-?} kB, max $max kB, at the end $last kB (growth $growth kB, tolerance $tolerance_kb kB)"
echo "$summary"
echo "last command: $last_command"
failed=0
[ "$status" -eq 0 ] || { echo "FAIL: act_drive exited with $status"; tail -n 20 "$work/log.txt"; failed=1; }
[ -n "$baseline" ] || { echo "FAIL: ran for less than 30 s"; failed=1; }
[ "$growth" -le "$tolerance_kb" ] || { echo "FAIL: RSS grew after warm-up"; failed=1; }
[[ "$summary" == *" 0 missed)"* ]] || { echo "FAIL: missed ticks (or no summary)"; failed=1; }
[[ "$last_command" == *",1500,1500*"* ]] || { echo "FAIL: the last command is not neutral"; failed=1; }
[ "$failed" -eq 0 ] && echo "OK"
exit "$failed"
