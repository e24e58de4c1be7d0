#!/usr/bin/env bash
# The HTML reports of act_eval --episode and act_convert --report FILE.html, rendered in headless
# chromium by report_page.js: charts drawn, nothing external. Made from the act-tiny fixture:
#   run_report_pages.sh ACT_CONVERT ACT_EVAL SHARED_DIR WORK_DIR
# Exit 77 (skipped) when node's packages or the fixture are missing, except under CI=true (fails).
set -euo pipefail
convert="$1" eval_bin="$2" shared="$3" work="$4"
here="$(cd "$(dirname "$0")" && pwd)"
fixture="$shared/fixtures/act-tiny"
missing() {
  echo "missing: $1"
  if [ "${CI:-}" = "true" ]; then exit 1; fi
  exit 77
}
[ -f "$here/node_modules/playwright-core/package.json" ] || missing "$here/node_modules (scripts/install_node_deps.sh)"
[ -d "$fixture" ] || missing "$fixture"

rm -rf "$work" && mkdir -p "$work/frames"
flags=(--precision int8 --calib "$fixture" --calib-samples 3 --holdout 1)
"$convert" "$fixture" -o "$work/fp32.actb" -q
"$convert" "$fixture" -o "$work/int8.actb" -q "${flags[@]}" --keep-float backbone.conv1.weight --report "$work/convert.html"

# Four frames, their states and a demonstration of two named actions.
printf 'frame,state_a,state_b\n' >"$work/states.csv"
printf 'frame,steer,throttle\n' >"$work/actions.csv"
for i in 0 1 2 3; do
  cp "$fixture/sample$i.observation.images.front.png" "$work/frames/$i.png"
  printf '%s.png,0.%s,-0.%s\n' "$i" "$i" "$i" >>"$work/states.csv"
  printf '%s.png,0.%s,0.%s\n' "$i" "$((i + 1))" "$((3 - i))" >>"$work/actions.csv"
done
"$eval_bin" --episode "$work/frames" --actions "$work/actions.csv" --states "$work/states.csv" \
  -m "$work/fp32.actb" -m "$work/int8.actb" --report "$work/eval.html" >/dev/null

for page in eval convert; do
  echo "== $page.html"
  node "$here/report_page.js" "$work/$page.html" "$work/$page.png"
done
