#!/usr/bin/env bash
# kill -9 under every stage, at several points of its run, then the same
# command again: it must exit 0 and leave exactly the bytes of a run that
# was never killed, with nothing of the dead run left beside or inside the
# output. Each stage runs with --overwrite (a nightly rebuild's command),
# pack without (it updates its tree in place: here a tree of another tile
# size, so a kill finds old tiles and new ones side by side). The kill
# times are fractions of the stage's own time on this machine; a stage that
# no kill caught alive fails the test (it would have tested nothing).
#   tests/faults/test_kills.sh REPO BIN_DIR
. "$(dirname "$0")/../support/script.sh" kills "$1" "$2"
# The fault map, larger (12 x 12 counties, 150 vertices a side): each stage
# runs for a few tenths of a second at least, long enough to be caught.
python3 "$repo/tests/faults/make_map.py" "$work" 12 150
cfg=$work/map.yaml
ref=$work/ref
mkdir -p "$ref"
stages=(
  "ingest|$bin/tigerlod-ingest --overwrite $cfg OUT"
  "color|$bin/tigerlod-color --overwrite --config $cfg $ref/ingest OUT"
  "simplify|$bin/tigerlod-simplify --overwrite --config $cfg $ref/ingest OUT"
  "pack|$bin/tigerlod-pack --tile-mb 0.002 $ref/ingest $ref/simplify OUT"
  "verify|$bin/tigerlod-verify --overwrite $ref/pack $ref/ingest OUT"
  "export|$bin/tigerlod-export --overwrite $ref/pack OUT.gpkg"
)
now_ms() { date +%s%3N; }
for entry in "${stages[@]}"; do
  name=${entry%%|*}
  cmd=${entry#*|}
  target=$ref/$name
  [ "$name" = export ] && target=$ref/$name.gpkg
  t0=$(now_ms)
  ${cmd//OUT/$ref/$name} >"$work/log" 2>&1 || fail "$name on its own: $(cat "$work/log")"
  took=$(($(now_ms) - t0))
  canonical "$target" >"$work/want-$name"
  caught=0
  for percent in 10 30 50 70 90; do
    out=$work/run/$name
    rm -rf "$work/run"
    mkdir -p "$work/run"
    if [ "$name" = pack ]; then
      "$bin/tigerlod-pack" --tile-mb 1 "$ref/ingest" "$ref/simplify" "$out" >"$work/log" 2>&1 ||
        fail "pack --tile-mb 1: $(cat "$work/log")"
    fi
    [ "$name" = export ] && out=$work/run/$name.gpkg
    # A stage is one process (its threads within it): kill -9 on its pid.
    ${cmd//OUT/$work/run/$name} >"$work/killed.log" 2>&1 &
    pid=$!
    delay=$((took * percent / 100)) # ms; bash's arithmetic, as python3 takes long to start
    sleep "$((delay / 1000)).$(printf %03d $((delay % 1000)))"
    if kill -0 "$pid" 2>/dev/null; then
      kill -KILL "$pid" 2>/dev/null && caught=$((caught + 1))
    fi
    wait "$pid" 2>/dev/null
    ${cmd//OUT/$work/run/$name} >"$work/again.log" 2>&1 ||
      fail "$name killed at $percent % of its time: the same command again failed: $(cat "$work/again.log")"
    canonical "$out" >"$work/got"
    cmp -s "$work/got" "$work/want-$name" ||
      fail "$name killed at $percent %: the run again left other bytes: $(diff "$work/want-$name" "$work/got" | head)"
    left=$(cd "$work/run" && find . -name '*.tmp-*' -o -name '*.old-*' | head -3)
    [ -z "$left" ] || fail "$name killed at $percent %: the dead run's files are left: $left"
  done
  [ "$caught" -gt 0 ] || fail "$name ($took ms): no kill caught it running; the map is too small to test it"
  echo "kills: $name ($took ms): killed $caught times of 5 mid-run; each rerun left the bytes of a clean run"
done
echo "${#stages[@]} passed, 0 failed"
