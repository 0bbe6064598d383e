#!/usr/bin/env bash
# Concurrent runs on one output. Updated in place (pack's tree): two
# packs of the same tree with different --tile-mb, started together eight
# times, both exit 0 and leave exactly the tree one of them makes alone
# (its skeleton, its tiles, no other), which verifies clean. And a pack
# started while another holds the tree waits for it (the message says so)
# instead of interleaving its files. Whole runs of ingest, simplify and
# verify, two at once on one OUTPUT: it is one run's output. And the kinds
# of lock: partition jobs share OUTPUT, a --finish and a whole run's swap
# take it alone; pack's partition jobs share their parts folder.
#   tests/faults/test_races.sh REPO BIN_DIR
. "$(dirname "$0")/../support/script.sh" races "$1" "$2"
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

# Every stage's whole runs on one OUTPUT at once (--overwrite), with
# different options where a stage has them: both exit 0 and OUTPUT is
# exactly one run's output (the swap into place is under an exclusive lock
# on OUTPUT), never a mix, never missing.
two_at_once() { # NAME OUT CMD_A -- CMD_B: both run together, four times
  local name=$1 out=$2
  shift 2
  local a=() b=()
  while [ "$1" != -- ]; do a+=("$1"); shift; done
  shift
  b=("$@")
  rm -rf "$out"
  "${a[@]}" >"$work/log" 2>&1 || fail "$name alone: $(cat "$work/log")"
  canonical "$out" >"$work/want-a"
  rm -rf "$out"
  "${b[@]}" >"$work/log" 2>&1 || fail "$name alone (B): $(cat "$work/log")"
  canonical "$out" >"$work/want-b"
  for try in 1 2 3 4; do
    "${a[@]}" --overwrite >"$work/a.log" 2>&1 &
    local pa=$!
    "${b[@]}" --overwrite >"$work/b.log" 2>&1 &
    local pb=$!
    wait "$pa" || fail "$name try $try: A: $(cat "$work/a.log")"
    wait "$pb" || fail "$name try $try: B: $(cat "$work/b.log")"
    canonical "$out" >"$work/got"
    cmp -s "$work/got" "$work/want-a" || cmp -s "$work/got" "$work/want-b" ||
      fail "$name try $try: OUTPUT is neither run's alone: $(diff "$work/got" "$work/want-a" | head)"
    ls -d "$out".tmp-* "$out".old-* 2>/dev/null && fail "$name try $try: temporaries left beside OUTPUT"
  done
  echo "races: $name: 4 tries of two whole runs at once, each left one run's output"
}
sed 's/tolerances_m: \[50, 200\]/tolerances_m: [100, 400]/' "$work/map.yaml" >"$work/map2.yaml"
two_at_once ingest "$work/in2" "$bin/tigerlod-ingest" "$work/map.yaml" "$work/in2" -- \
  "$bin/tigerlod-ingest" --threads 1 "$work/map.yaml" "$work/in2"
two_at_once simplify "$work/simp2" "$bin/tigerlod-simplify" --config "$work/map.yaml" "$work/in" "$work/simp2" -- \
  "$bin/tigerlod-simplify" --config "$work/map2.yaml" "$work/in" "$work/simp2"
two_at_once verify "$work/v2" "$bin/tigerlod-verify" "$work/ref-1" "$work/in" "$work/v2" -- \
  "$bin/tigerlod-verify" "$work/ref-0.002" "$work/in" "$work/v2"

# The locks' kinds, held by hand with flock(1): partition jobs of one run
# share OUTPUT (a job does not wait for another), a --finish or a whole
# run's swap waits for them, and a job waits for a --finish.
waits() { # EXPECT(yes|no) HOLD(-s|-x) OUT CMD...: does CMD wait for the holder?
  local expect=$1 mode=$2 out=$3
  shift 3
  mkdir -p "$out"
  flock "$mode" "$out" sleep 2 &
  local holder=$!
  sleep 0.3
  local t0
  t0=$(date +%s.%N)
  "$@" >"$work/w.log" 2>&1 || fail "$*: $(cat "$work/w.log")"
  local long
  long=$(python3 -c "import sys; print(float(sys.argv[2]) - float(sys.argv[1]) >= 1.5)" "$t0" "$(date +%s.%N)")
  wait "$holder"
  if [ "$expect" = yes ]; then
    [ "$long" = True ] && grep -q "another run is updating $out; waiting for it" "$work/w.log" ||
      fail "did not wait for a $mode holder of $out: $* ($(cat "$work/w.log"))"
  else
    [ "$long" = False ] || fail "waited for a $mode holder of $out: $*"
  fi
}
s=$work/simp2
"$bin/tigerlod-simplify" --config "$work/map.yaml" "$work/in" "$s" --overwrite >"$work/log" 2>&1 || fail "$(cat "$work/log")"
waits no -s "$s" "$bin/tigerlod-simplify" --config "$work/map.yaml" --partitions 'county/01*' "$work/in" "$s"
waits yes -x "$s" "$bin/tigerlod-simplify" --config "$work/map.yaml" --partitions 'county/02*' "$work/in" "$s"
waits yes -s "$s" "$bin/tigerlod-simplify" --config "$work/map.yaml" --finish "$work/in" "$s"
waits yes -s "$s" "$bin/tigerlod-simplify" --config "$work/map.yaml" --overwrite "$work/in" "$s"
waits yes -s "$work/in2" "$bin/tigerlod-ingest" --overwrite "$work/map.yaml" "$work/in2"
parts=$work/parts
"$bin/tigerlod-ingest" --list --parts "$parts" "$work/map.yaml" "$work/in3" >"$work/log" 2>&1 &&
  "$bin/tigerlod-ingest" --plan --parts "$parts" "$work/map.yaml" "$work/in3" >"$work/log" 2>&1 ||
  fail "ingest --list/--plan: $(cat "$work/log")"
waits no -s "$work/in3" "$bin/tigerlod-ingest" --region whole --parts "$parts" "$work/map.yaml" "$work/in3"
waits yes -s "$work/in3" "$bin/tigerlod-ingest" --finish --parts "$parts" "$work/map.yaml" "$work/in3"
waits yes -x "$work/in3" "$bin/tigerlod-ingest" --region whole --parts "$parts" "$work/map.yaml" "$work/in3"
echo "races: partition jobs share OUTPUT; a --finish, a whole run's swap and a job behind a --finish wait"
# Pack's parts folder: its partition jobs share it, its --plan and its
# --finish (which prunes parts) take it alone.
pp=$work/packparts
"$bin/tigerlod-pack" --plan --parts "$pp" "$work/in" "$work/simp" "$work/tree4" >"$work/log" 2>&1 ||
  fail "pack --plan: $(cat "$work/log")"
pack_job=("$bin/tigerlod-pack" --parts "$pp" --partitions 'county/*' --report "$work/share.json" "$work/in" "$work/simp" "$work/tree4")
waits yes -s "$pp" "$bin/tigerlod-pack" --plan --parts "$pp" "$work/in" "$work/simp" "$work/tree4"
waits no -s "$pp" "${pack_job[@]}"
waits yes -x "$pp" "${pack_job[@]}"
"$bin/tigerlod-pack" --parts "$pp" --partitions 'state/*' "$work/in" "$work/simp" "$work/tree4" >"$work/log" 2>&1 ||
  fail "pack's state jobs: $(cat "$work/log")"
waits yes -s "$pp" "$bin/tigerlod-pack" --finish --parts "$pp" "$work/in" "$work/simp" "$work/tree4"
"$bin/tigerlod-verify" "$work/tree4" "$work/in" "$work/v4" >"$work/log" 2>&1 || fail "verify of the parts' tree: $(cat "$work/log")"
echo "races: pack's partition jobs share their parts folder; its --plan and --finish wait for them"
echo "6 passed, 0 failed"
