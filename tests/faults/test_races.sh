#!/usr/bin/env bash
# Concurrent runs on one output that is updated in place (pack's tree): two
# packs of the same tree with different --tile-mb, started together eight
# times, both exit 0 and leave exactly the tree one of them makes alone
# (its skeleton, its tiles, no other), which verifies clean. And a pack
# started while another holds the tree waits for it (the message says so)
# instead of interleaving its files.
#   tests/faults/test_races.sh REPO BIN_DIR
set -uo pipefail
repo=$(cd "$1" && pwd)
bin=$(cd "$2" && pwd)
work=$(mktemp -d "${TMPDIR:-/tmp}/tigerlod-races-XXXXXX")
trap 'rm -rf "$work"' EXIT
fail() {
  echo "races: FAILED: $*"
  exit 1
}
python3 "$repo/tests/faults/make_map.py" "$work"
"$bin/tigerlod-ingest" "$work/map.yaml" "$work/in" >"$work/log" 2>&1 || fail "ingest: $(cat "$work/log")"
"$bin/tigerlod-simplify" --config "$work/map.yaml" "$work/in" "$work/simp" >"$work/log" 2>&1 ||
  fail "simplify: $(cat "$work/log")"
# What a tree is: its skeleton's and tiles' digests, by name.
tree_text() { (cd "$1" && sha256sum skeleton.tls tiles/* | LC_ALL=C sort -k2); }
for mb in 0.002 1; do
  "$bin/tigerlod-pack" --tile-mb "$mb" "$work/in" "$work/simp" "$work/ref-$mb" >"$work/log" 2>&1 ||
    fail "pack --tile-mb $mb: $(cat "$work/log")"
  tree_text "$work/ref-$mb" >"$work/want-$mb"
done
cmp -s "$work/want-0.002" "$work/want-1" && fail "the two tile sizes give one tree: the test would not see a mix"
for try in 1 2 3 4 5 6 7 8; do
  t=$work/tree
  [ $((try % 2)) = 0 ] && rm -rf "$t" # half the tries on a new tree, half updating the last one
  "$bin/tigerlod-pack" --tile-mb 0.002 "$work/in" "$work/simp" "$t" >"$work/a.log" 2>&1 &
  a=$!
  "$bin/tigerlod-pack" --tile-mb 1 "$work/in" "$work/simp" "$t" >"$work/b.log" 2>&1 &
  b=$!
  wait "$a" || fail "try $try: pack A: $(cat "$work/a.log")"
  wait "$b" || fail "try $try: pack B: $(cat "$work/b.log")"
  got=$(tree_text "$t")
  [ "$got" = "$(cat "$work/want-0.002")" ] || [ "$got" = "$(cat "$work/want-1")" ] ||
    fail "try $try: the tree is neither pack's alone: $got"
  rm -rf "$work/v"
  "$bin/tigerlod-verify" "$t" "$work/in" "$work/v" >"$work/v.log" 2>&1 || fail "try $try: verify: $(cat "$work/v.log")"
done
echo "races: 8 tries of two packs at once: each left one pack's tree, verified clean"
# A pack that finds the tree held waits for it, then does its work.
flock "$work/tree" sleep 2 &
holder=$!
sleep 0.3
start=$(date +%s.%N)
"$bin/tigerlod-pack" --tile-mb 0.002 "$work/in" "$work/simp" "$work/tree" >"$work/w.log" 2>&1 ||
  fail "the waiting pack: $(cat "$work/w.log")"
waited=$(python3 -c "import sys; print(float(sys.argv[2]) - float(sys.argv[1]) >= 1.5)" "$start" "$(date +%s.%N)")
wait "$holder"
grep -q "another run is updating $work/tree; waiting for it" "$work/w.log" || fail "no waiting message: $(cat "$work/w.log")"
[ "$waited" = True ] || fail "the pack did not wait for the lock's holder"
[ "$(tree_text "$work/tree")" = "$(cat "$work/want-0.002")" ] || fail "the waiting pack's tree is not its own"
echo "races: a pack waits for the run that holds its tree, then writes its own"
echo "2 passed, 0 failed"
