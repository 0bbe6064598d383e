#!/usr/bin/env bash
# A full disk under every stage and export format: each stage writes its
# output onto a small tmpfs, at sizes from a few pages to nine tenths of
# what the output needs, and must then exit 3 naming a path on that disk
# with nothing left there (no temporary, no half-written output), or, where
# the output fit, exit 0 with exactly the bytes of a run on a roomy disk.
# Each stage must fail at one size at least and pass on a roomy tmpfs, so
# the test cannot pass without running into the fault. Needs mount(8) for
# tmpfs (root); skips (77) with a reason without it.
#   tests/faults/test_full_disk.sh REPO BIN_DIR
. "$(dirname "$0")/../support/script.sh" "full disk" "$1" "$2"
mnt=$work/disk
mkdir -p "$mnt"
on_exit() { mountpoint -q "$mnt" && umount "$mnt"; }
if ! mount -t tmpfs -o size=64k tmpfs "$mnt" 2>/dev/null; then
  echo "full disk: skipped: cannot mount a tmpfs here (needs root and mount(8))"
  exit 77
fi
umount "$mnt"
# A hand-made map: 6 x 6 counties in 2 states, wavy borders.
python3 "$repo/tests/faults/make_map.py" "$work"
cfg=$work/map.yaml
ref=$work/ref
mkdir -p "$ref"
# The stages as "NAME|COMMAND" with OUT where the output goes; each reads
# the reference run's outputs of the stages before it.
stages=(
  "ingest|$bin/tigerlod-ingest $cfg OUT"
  "color|$bin/tigerlod-color --config $cfg $ref/ingest OUT"
  "simplify|$bin/tigerlod-simplify --config $cfg $ref/ingest OUT"
  "pack|$bin/tigerlod-pack $ref/ingest $ref/simplify OUT"
  "verify|$bin/tigerlod-verify $ref/pack $ref/ingest OUT"
  "export.gpkg|$bin/tigerlod-export $ref/pack OUT"
  "export.geojson|$bin/tigerlod-export --layer chains $ref/pack OUT"
  "render|$bin/tigerlod-render --config $cfg --mode none $ref/pack OUT"
)
# What of an output must match the roomy run: canonical (tests/support/
# script.sh): every file's bytes, a GeoPackage's too (its last_change is
# fixed), except the files that hold measured times.
out_name() { # the output's name: a file for export
  case "$1" in
  export.gpkg) echo "out.gpkg" ;;
  export.geojson) echo "out.geojson" ;;
  *) echo "out" ;;
  esac
}
passed=0
for entry in "${stages[@]}"; do
  name=${entry%%|*}
  cmd=${entry#*|}
  o=$(out_name "$name")
  # The roomy run: the reference.
  ${cmd//OUT/$ref/$o} >"$work/$name.log" 2>&1 || fail "$name on a roomy disk: $(cat "$work/$name.log")"
  [ "$o" = out ] && mv "$ref/out" "$ref/$name" || mv "$ref/$o" "$ref/$name-$o"
  refout=$ref/$name
  [ "$o" = out ] || refout=$ref/$name-$o
  want=$(canonical "$refout")
  need=$(du -sb "$refout" | cut -f1)
  failed_once=0
  for size in 4096 $((need / 10)) $((need * 3 / 10)) $((need * 6 / 10)) $((need * 9 / 10)) $((need * 4 + 1048576)); do
    [ "$size" -ge 4096 ] || size=4096
    mount -t tmpfs -o "size=$size" tmpfs "$mnt" || fail "cannot mount a tmpfs of $size bytes"
    ${cmd//OUT/$mnt/$o} >"$work/run.log" 2>&1
    rc=$?
    if [ "$rc" = 0 ]; then
      [ "$(canonical "$mnt/$o")" = "$want" ] ||
        fail "$name on $size bytes: exit 0 but not the roomy run's output: $(cat "$work/run.log")"
      left=$(cd "$mnt" && find . -mindepth 1 -maxdepth 1 ! -name "$o")
      [ -z "$left" ] || fail "$name on $size bytes: exit 0 but left beside the output: $left"
    else
      [ "$rc" = 3 ] || fail "$name on $size bytes: exit $rc, not 3: $(cat "$work/run.log")"
      grep -q "$mnt" "$work/run.log" || fail "$name on $size bytes: the message names no path on the full disk: $(cat "$work/run.log")"
      left=$(cd "$mnt" && find . -mindepth 1)
      [ -z "$left" ] || fail "$name on $size bytes: exit 3 but left: $left ($(cat "$work/run.log"))"
      failed_once=1
    fi
    umount "$mnt"
  done
  [ "$rc" = 0 ] || fail "$name: failed on a tmpfs four times its output's size"
  [ "$failed_once" = 1 ] || fail "$name: never met the full disk (the test did not test it)"
  echo "full disk: $name: exit 3 and nothing left where it did not fit, the same bytes where it did"
  passed=$((passed + 1))
done
echo "$passed passed, 0 failed"
