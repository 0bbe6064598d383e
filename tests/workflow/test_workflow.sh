#!/usr/bin/env bash
# The workflow as a user meets it after a bad night: a run killed with
# SIGKILL resumes with scripts/workflow alone, a failing stage shows its
# last log lines on the terminal, a bad input file fixed recovers with the
# same command, a config the pipeline cannot expand
# says so in one line, and a synthetic nation runs from its config alone.
# Needs Floyd from ../shared/data (skips, exit 77).
#
#   tests/workflow/test_workflow.sh REPO BIN_DIR
set -uo pipefail
repo=$(cd "$1" && pwd)
bin=$(cd "$2" && pwd)
data=$repo/../shared/data/tiger
if [ ! -f "$data/tl_2020_51063_edges.zip" ]; then
  echo "SKIP: $data/tl_2020_51063_edges.zip is absent (../shared/data)"
  exit 77
fi
if ! command -v snakemake >/dev/null; then
  echo "SKIP: snakemake is not installed (scripts/setup installs it)"
  exit 77
fi
work=$(mktemp -d "${TMPDIR:-/tmp}/tigerlod-workflow-XXXXXX")
trap 'rm -rf "$work"' EXIT
cd "$work"
export TIGERLOD_BIN=$bin TIGERLOD_CORES=1
failures=0
fail() {
  echo "FAIL: $*"
  failures=$((failures + 1))
}
# The eps-Voronoi test by name (the default, auto, takes the exact rules
# where there is no GPU), so the color jobs run; 2c takes the exact rules.
sed "s#\.\./\.\./shared#$repo/../shared#; s/^name: floyd/name: wf/; s/^  tolerances_m: .*/&\n  shortcut_test: voronoi/" \
  "$repo/configs/floyd.yaml" >wf.yaml
grep -q '^  shortcut_test: voronoi$' wf.yaml || fail "the test's config does not name the eps-Voronoi test"

# 1. Killed with SIGKILL in the middle (simplify running): Snakemake's lock
# and incomplete markers stay. Before, every rerun failed until a person
# passed --unlock --rerun-incomplete.
setsid "$repo/scripts/workflow" wf.yaml >run1.out 2>&1 &
pid=$!
for _ in $(seq 1 600); do
  [ -d out/wf/logs/simplify ] && break
  kill -0 "$pid" 2>/dev/null || break
  sleep 0.05
done
if ! kill -0 "$pid" 2>/dev/null; then
  fail "the first run ended before simplify began; cannot test a kill"
  cat run1.out
fi
kill -KILL -- -"$pid" 2>/dev/null
wait "$pid" 2>/dev/null
[ -n "$(ls -A .snakemake/locks 2>/dev/null)" ] || fail "no Snakemake lock after the kill: the test did not kill a run"
if ! "$repo/scripts/workflow" wf.yaml >run2.out 2>&1; then
  fail "the rerun after a kill failed:"
  cat run2.out
fi
grep -q '"clean": true' out/wf/reports/verify-report.json || fail "the resumed run's verify report is not clean"
grep -q '^\*\*CLEAN: no violations.\*\*$' out/wf/reports/verify-summary.md ||
  fail "the reports have no clean verify summary: $(cat out/wf/reports/verify-summary.md 2>&1)"
grep -q "releasing the lock of a run that died" run2.out || fail "the rerun did not say it released a dead run's lock"
ls -d out/wf/*.tmp-* 2>/dev/null && fail "temporaries of the killed run are left"

# 2. A rerun with nothing changed does nothing and succeeds.
"$repo/scripts/workflow" wf.yaml >run3.out 2>&1 || fail "a rerun with nothing changed failed: $(cat run3.out)"
grep -q "Nothing to be done" run3.out || fail "a rerun with nothing changed ran jobs: $(cat run3.out)"

# 2b. A new ladder in the config reruns color and what follows, with the
# stages reading the config themselves (--config), and not ingest: the
# pipeline reruns a job when the config sections it reads change.
before=$(stat -c %Y out/wf/ingest/manifest.json)
sed -i 's/tolerances_m: \[1, 4, 16, 64\]/tolerances_m: [2, 8, 32]\n  class_scale: {S1400: 0.5}/' wf.yaml
"$repo/scripts/workflow" wf.yaml >run4.out 2>&1 || fail "a rerun with a new ladder failed: $(cat run4.out)"
[ "$(stat -c %Y out/wf/ingest/manifest.json)" = "$before" ] || fail "a new ladder reran ingest"
python3 - out/wf/tree/manifest.json out/wf/reports/verify-report.json <<'PY' || fail "the tree is not the new ladder's"
import json, sys
tree = json.load(open(sys.argv[1]))["simplify"]
report = json.load(open(sys.argv[2]))
assert tree["tolerances_m"] == [2, 8, 32], tree["tolerances_m"]
assert tree["class_scale"] == {"S1400": 0.5}, tree["class_scale"]
assert report["clean"] and report["contract"]["class_scale"] == {"S1400": 0.5}, report["contract"]
PY

# 2c. simplify.shortcut_test: exact reruns simplify and what follows with the
# exact rules alone: no color job runs, the tree verifies clean, and a
# region rebuild forces the groups' simplify jobs (there are no colour jobs).
rm -rf out/wf/jobs/color
sed -i 's/shortcut_test: voronoi/shortcut_test: exact/' wf.yaml
"$repo/scripts/workflow" wf.yaml >run5.out 2>&1 || fail "a rerun with the exact rules failed: $(cat run5.out)"
[ "$(stat -c %Y out/wf/ingest/manifest.json)" = "$before" ] || fail "the exact rules reran ingest"
[ -e out/wf/jobs/color ] && fail "color jobs ran for the exact rules"
python3 - out/wf/tree/manifest.json out/wf/reports/verify-report.json out/wf/reports/simplify-report.json <<'PY' ||
import json, sys
tree = json.load(open(sys.argv[1]))["simplify"]
report = json.load(open(sys.argv[2]))
simp = json.load(open(sys.argv[3]))
assert tree["shortcut_test"] == "exact", tree
assert report["clean"], report["violations"]
assert all(t["drawn_segments"] == 0 for t in simp["tolerances"]), simp["tolerances"]
PY
  fail "the exact rules' tree is not what the config asked for"
python3 "$repo/pipeline/regions.py" wf.yaml 51063 >forced.out 2>/dev/null || fail "regions.py failed"
grep -q '^out/wf/jobs/simplify/' forced.out || fail "a region rebuild forces no simplify job: $(cat forced.out)"
grep -q '/jobs/color/' forced.out && fail "a region rebuild forces color jobs that do not exist: $(cat forced.out)"

# 2d. simplify.shortcut_test left out: auto, decided once by the pipeline
# for every job and said on its output; the tree says which test ran.
sed -i '/^  shortcut_test: exact$/d' wf.yaml
if [ -e /dev/nvidiactl ] || compgen -G '/dev/dri/renderD*' >/dev/null; then want=voronoi; else want=exact; fi
"$repo/scripts/workflow" wf.yaml >run5b.out 2>&1 || fail "a rerun with shortcut_test auto failed: $(cat run5b.out)"
grep -q "pipeline: simplify.shortcut_test $want (auto: " run5b.out ||
  fail "the pipeline did not say that auto took $want: $(head -5 run5b.out)"
python3 - out/wf/tree/manifest.json out/wf/reports/simplify-report.json "$want" <<'PY' ||
import json, sys
tree = json.load(open(sys.argv[1]))["simplify"]
simp = json.load(open(sys.argv[2]))
assert tree["shortcut_test"] == sys.argv[3], tree
assert simp["options"]["shortcut_test"] == sys.argv[3], simp["options"]
PY
  fail "the tree made under shortcut_test auto does not say $want ran"

# 3. A failing stage: its message on the terminal, not only in its log.
sed "s/^name: wf/name: bad/; s#tl_2020_51063_faces.zip#tl_2020_51063_edges.zip#" wf.yaml >bad.yaml
if "$repo/scripts/workflow" bad.yaml >bad.out 2>&1; then
  fail "a run with EDGES given as FACES succeeded"
fi
# (One county's file: ingest is one job, `whole`, that reads it.)
grep -q "pipeline: ingest:whole failed (exit [0-9]); the last lines of out/bad/logs/ingest/whole.log:" bad.out ||
  fail "no log tail on the terminal: $(cat bad.out)"
grep -q "tigerlod-ingest: .*tl_2020_51063_edges.zip" bad.out || fail "the stage's own message is not on the terminal"

# 3b. A bad input file, then the file fixed: the same command recovers,
# twice over (issue 54: a one-file dataset's plan kept the bad file's
# digest, and its job refused the fixed file until --plan was run by hand).
mkdir fix && python3 "$repo/tests/faults/make_map.py" fix && sed -i 's/^name: disk/name: fix/' fix/map.yaml
cp fix/map.geojson fix/good.geojson
for round in 1 2; do
  head -c 1000 fix/good.geojson >fix/map.geojson
  (cd fix && "$repo/scripts/workflow" map.yaml >"bad$round.out" 2>&1) && fail "round $round: a cut-off input file ran"
  grep -q "tigerlod-ingest: map.geojson: " "fix/bad$round.out" || fail "round $round: no message naming the file: $(cat "fix/bad$round.out")"
  cp fix/good.geojson fix/map.geojson
  if ! (cd fix && "$repo/scripts/workflow" map.yaml >"fixed$round.out" 2>&1); then
    fail "round $round: the run after the file was fixed failed: $(tail -20 "fix/fixed$round.out")"
  fi
  grep -q '"clean": true' fix/out/fix/reports/verify-report.json || fail "round $round: the fixed run's tree is not clean"
done
touch fix/map.geojson
(cd fix && "$repo/scripts/workflow" map.yaml >touched.out 2>&1) || fail "a run after a touch failed: $(tail -20 fix/touched.out)"

# 4. Configs the pipeline cannot expand: one line each, no traceback.
grep -v '^name:' wf.yaml >noname.yaml
"$repo/scripts/workflow" noname.yaml >noname.out 2>&1
rc=$?
[ "$rc" = 2 ] || fail "a config without a name exited $rc, not 2"
grep -q "pipeline: noname.yaml: 'name' is required" noname.out || fail "no message for a missing name: $(cat noname.out)"
grep -qi "traceback\|KeyError\|File \"" noname.out && fail "a traceback for a missing name: $(cat noname.out)"
sed 's/^name: wf/name: str/; s/tolerances_m: \[[^]]*\]/tolerances_m: [1, "x", 4]/' wf.yaml >str.yaml
"$repo/scripts/workflow" str.yaml >str.out 2>&1 && fail "a string in tolerances_m ran"
grep -q "'simplify.tolerances_m' must be a list of numbers" str.out || fail "no message for a string tolerance: $(cat str.out)"
[ -e out/str/simplified ] && fail "simplify ran with a string tolerance"

"$repo/scripts/workflow" nothere.yaml >missing.out 2>&1
rc=$?
[ "$rc" = 2 ] || fail "a config that does not exist exited $rc, not 2"
grep -q "workflow: nothere.yaml: no such config file" missing.out || fail "no message for a missing config: $(cat missing.out)"

# 5. A synthetic nation (a config with a synth section): tigerlod-synth
# runs first, ingest reads its files by pattern, and the tree verifies
# clean; a new seed reruns synth and what follows.
cat >sy.yaml <<'EOF'
name: sy
synth: {seed: 1, states: 1, counties_per_state: 2, target_vertices: 20000}
dataset:
  kind: tiger
  edges: [out/sy/synth/tl_2020_*_edges.zip]
  faces: [out/sy/synth/tl_2020_*_faces.zip]
simplify: {tolerances_m: [4, 16]}
render: {frames: 6}
EOF
"$repo/scripts/workflow" sy.yaml >sy1.out 2>&1 || fail "the synthetic nation's run failed: $(tail -20 sy1.out)"
grep -q '"clean": true' out/sy/reports/verify-report.json || fail "the synthetic nation's tree is not clean"
[ -f out/sy/synth/tl_2020_01001_edges.zip ] || fail "no EDGES file of the synthetic nation"
first=$(sha256sum <out/sy/synth/manifest.json)
sed -i 's/seed: 1,/seed: 2,/' sy.yaml
"$repo/scripts/workflow" sy.yaml >sy2.out 2>&1 || fail "a new seed's run failed: $(tail -20 sy2.out)"
[ "$(sha256sum <out/sy/synth/manifest.json)" != "$first" ] || fail "a new seed did not rerun synth"
grep -q '"clean": true' out/sy/reports/verify-report.json || fail "the new seed's tree is not clean"

if [ "$failures" -gt 0 ]; then
  echo "$failures failure(s)"
  exit 1
fi
echo "workflow: all checks passed"
