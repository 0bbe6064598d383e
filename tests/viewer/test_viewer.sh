#!/usr/bin/env bash
# The viewer in a real browser: Debian's chromium, headless, driven by
# playwright-core from npm (fetched into .cache/npm like us-atlas), against
# tigerlod-serve on a tree of the default dataset (us-atlas counties, three
# states, through ingest, simplify and pack). test_viewer.mjs says what it
# checks. Skips (exit 77) with the reason when chromium, playwright-core or
# us-atlas cannot be had.
#   tests/viewer/test_viewer.sh REPO BIN_DIR
set -euo pipefail
repo=$(cd "$1" && pwd)
bin=$(cd "$2" && pwd)
chromium=$(command -v chromium || true)
if [ -z "$chromium" ]; then
  echo "SKIP viewer: no chromium (scripts/setup installs Debian's)"
  exit 77
fi
pw=$repo/.cache/npm/playwright-core-1.64.1
atlas=$repo/.cache/npm/us-atlas-3.0.1
for spec in playwright-core@1.64.1:$pw us-atlas@3.0.1:$atlas; do
  if ! "$repo/scripts/fetch-npm" "${spec%%:*}" "${spec#*:}" >/dev/null 2>&1; then
    echo "SKIP viewer: cannot fetch ${spec%%:*} from the npm registry"
    exit 77
  fi
done
work=$(mktemp -d "${TMPDIR:-/tmp}/tigerlod-viewer-XXXXXX")
server=
cleanup() {
  [ -n "$server" ] && kill "$server" 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
cd "$work"
cat >v.yaml <<YAML
name: v
dataset:
  kind: polygons
  inputs: [$atlas/counties-10m.json]
  layer: counties
  code_field: id
  name_field: name
  where: "id LIKE '51%' OR id LIKE '54%' OR id LIKE '21%'"
levels:
  - {name: nation, code: US}
  - {name: state, prefix: 2}
  - {name: county, prefix: 5}
ingest: {halo_m: 5000}
YAML
"$bin/tigerlod-ingest" v.yaml orig >ingest.log 2>&1 || { cat ingest.log; exit 1; }
"$bin/tigerlod-simplify" --shortcut-test exact --tolerances 250,500,1000,2000 orig simp >simp.log 2>&1 ||
  { cat simp.log; exit 1; }
"$bin/tigerlod-pack" orig simp tree >pack.log 2>&1 || { cat pack.log; exit 1; }
# tigerlod-render's PNGs of views on its zoom path, to hold the page's drawing against.
"$bin/tigerlod-render" --mode ooc-noprefetch --path zoom --frames 40 --png-every 10 --size 900x600 --fps 0 \
  --disk-latency-ms 0 --disk-mbps 0 tree render >render.log 2>&1 || { cat render.log; exit 1; }
echo '{"items": []}' >report.json # test_viewer.mjs writes its own items (the server reads it per request)
"$bin/tigerlod-serve" --port 0 --viewer "$repo/viewer" --verify report.json tree >serve.out 2>&1 &
server=$!
port=
for _ in $(seq 100); do
  port=$(sed -n 's|^serving http://127.0.0.1:\([0-9]*\)/$|\1|p' serve.out)
  [ -n "$port" ] && break
  sleep 0.1
done
[ -n "$port" ] || { echo "FAIL: tigerlod-serve did not start: $(cat serve.out)"; exit 1; }
status=0
node "$repo/tests/viewer/test_viewer.mjs" "$pw" "$chromium" "http://127.0.0.1:$port" "$work" || status=$?
# TIGERLOD_VIEWER_SHOTS=DIR keeps the screenshots of the views there, and
# tigerlod-render's PNGs the page was held against.
if [ -n "${TIGERLOD_VIEWER_SHOTS:-}" ]; then
  mkdir -p "$TIGERLOD_VIEWER_SHOTS" && cp view-*.png render/frames/*.png "$TIGERLOD_VIEWER_SHOTS"/ 2>/dev/null || true
fi
exit "$status"
