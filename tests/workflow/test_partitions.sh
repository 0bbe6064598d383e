#!/usr/bin/env bash
# The workflow in partition-sized jobs, as an operator meets it on a
# nightly rebuild: color, simplify, pack and verify run a job per group of
# stores (a pack job after the simplify jobs of its neighbours' groups too,
# a verify job after the pack jobs of the groups whose nodes it reads); a
# changed county reruns only the jobs of the stores that hold it, and the
# result is byte for byte a clean build's; a new description reruns
# nothing and a new pack.tile_mb only pack and what reads the tree (render's
# previews too, unless workflow.render is false; not the frame-time
# experiment, which follows the renderer);
# --regions forces a region's jobs; a bad store fails its own jobs with its
# message on the terminal while the others finish, and the rerun after the
# fix does only what is left. Needs the 2010 tracts of DC and Rhode Island
# from ../shared/data (skips, exit 77).
#
#   tests/workflow/test_partitions.sh REPO BIN_DIR
set -uo pipefail
repo=$(cd "$1" && pwd)
bin=$(cd "$2" && pwd)
data=$repo/../shared/data/tiger/tracts2010
if [ ! -f "$data/tl_2010_11_tract10.zip" ] || [ ! -f "$data/tl_2010_44_tract10.zip" ]; then
  echo "SKIP: $data/tl_2010_{11,44}_tract10.zip are absent (../shared/data)"
  exit 77
fi
for tool in snakemake ogr2ogr; do
  if ! command -v $tool >/dev/null; then
    echo "SKIP: $tool is not installed (scripts/setup installs it)"
    exit 77
  fi
done
work=$(mktemp -d "${TMPDIR:-/tmp}/tigerlod-partitions-XXXXXX")
trap '[ -n "${KEEP:-}" ] || rm -rf "$work"' EXIT
cd "$work"
export TIGERLOD_BIN=$bin TIGERLOD_CORES=2 TIGERLOD_PROGRESS=
failures=0
fail() {
  echo "FAIL: $*"
  failures=$((failures + 1))
}
# The jobs a run's output says ran, `stage level/group` a line, sorted.
ran() { sed -n 's/^\[[0-9]*\/[0-9?]*\] \(color\|simplify\|pack\|verify\) \([^:]*\/[^:]*\):.*/\1 \2/p' "$1" | sort | tr '\n' ' '; }
# The ingest region jobs a run's output says ran (`r-11 r-44 `).
ingested() { sed -n 's/^\[[0-9]*\/[0-9?]*\] ingest \(r-[^:]*\):.*/\1/p' "$1" | sort | tr '\n' ' '; }
# The ingest read jobs a run's output says ran (`gdc gtl_2010_44_tract10 `).
readjobs() { sed -n 's/^\[[0-9]*\/[0-9?]*\] ingest read \([^:]*\):.*/\1/p' "$1" | sort | tr '\n' ' '; }
# Two versions of DC: as published, and with one tract's code changed.
ogr2ogr -f "ESRI Shapefile" dc_v1.shp.zip "/vsizip/$data/tl_2010_11_tract10.zip/tl_2010_11_tract10.shp" -nln dc
ogr2ogr -f "ESRI Shapefile" dc_v2.shp.zip "/vsizip/$data/tl_2010_11_tract10.zip/tl_2010_11_tract10.shp" -nln dc \
  -dialect SQLite -sql "SELECT Geometry, MTFCC10, INTPTLAT10, INTPTLON10, NAMELSAD10, ALAND10, AWATER10, CASE WHEN GEOID10 = '11001000100'
    THEN '11001990100' ELSE GEOID10 END AS GEOID10 FROM tl_2010_11_tract10"
cp dc_v1.shp.zip dc.shp.zip
cat >p.yaml <<EOF
name: p
description: DC and Rhode Island tracts
dataset:
  kind: polygons
  inputs: [dc.shp.zip, $data/tl_2010_44_tract10.zip]
  code_field: GEOID10
  class_field: MTFCC10
  intpt_lat_field: INTPTLAT10
  intpt_lon_field: INTPTLON10
  name_field: NAMELSAD10
  attributes: [ALAND10, AWATER10]
levels:
  - {name: nation, code: US}
  - {name: state, prefix: 2}
  - {name: county, prefix: 5}
  - {name: tract, prefix: 11}
ingest: {halo_m: 200}
simplify: {tolerances_m: [1, 16], shortcut_test: voronoi}
workflow: {job_mb: 0.001}
render: {frames: 6}
EOF
wf() { "$repo/scripts/workflow" p.yaml "$@"; }

# 1. A clean build: a job per store here (job_mb is tiny), each stage's
# folder as a whole run of the stage writes it.
wf >r1.out 2>&1 || fail "the first run failed: $(tail -30 r1.out)"
all="color county/g11 color county/g44 color nation/gall color state/gUS color tract/g11001 color tract/g44001 "
all+="color tract/g44003 color tract/g44005 color tract/g44007 color tract/g44009 "
[ "$(ran r1.out)" = "$all${all//color/pack}${all//color/simplify}${all//color/verify}" ] ||
  fail "the first run's group jobs: $(ran r1.out)"
# Ingest too: a plan, a job per state (region), a finish; the folder is a whole run's.
[ "$(ingested r1.out)" = "r-11 r-44 " ] || fail "the first run's ingest jobs: $(ingested r1.out)"
# ... and a read job per input file here (job_mb is tiny).
[ "$(readjobs r1.out)" = "gdc gtl_2010_44_tract10 " ] || fail "the first run's read jobs: $(readjobs r1.out)"
"$bin/tigerlod-ingest" p.yaml whole-ingest >/dev/null 2>&1 || fail "tigerlod-ingest whole failed"
diff -r -x '*-timings.json' whole-ingest out/p/ingest >/dev/null || fail "ingest by jobs differs from a whole run"
"$bin/tigerlod-color" --config p.yaml out/p/ingest whole-color >/dev/null || fail "tigerlod-color whole failed"
"$bin/tigerlod-simplify" --config p.yaml --colors whole-color out/p/ingest whole-simp >/dev/null ||
  fail "tigerlod-simplify whole failed"
diff -r -x '*-report.json' whole-color out/p/color >/dev/null || fail "color by jobs differs from a whole run"
diff -r -x '*-report.json' whole-simp out/p/simplified >/dev/null || fail "simplify by jobs differs from a whole run"
"$bin/tigerlod-pack" --config p.yaml out/p/ingest whole-simp whole-tree >/dev/null || fail "tigerlod-pack whole failed"
diff -r -x '*-report.json' whole-tree out/p/tree >/dev/null || fail "pack by jobs differs from a whole run"
# The names and attributes came through the jobs: DC's tracts in its county node.
dc_units=$("$bin/tigerlod-dump" out/p/tree --node 11001)
grep -q '^unit 11001000100 point=.* name=Census Tract 1 ALAND10=[1-9][0-9]* AWATER10=' <<<"$dc_units" ||
  fail "the tree's units lack the names and attributes: $(grep '^unit' <<<"$dc_units" | head -3)"
"$bin/tigerlod-verify" --config p.yaml out/p/tree out/p/ingest whole-verify >/dev/null || fail "a whole verify failed"
same_report() { python3 - "$1" "$2" <<'PY'
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:3])
for r in (a, b):
    r.pop("seconds"); r.pop("segments_per_second"); r.pop("ground_seconds")
sys.exit(a != b)
PY
}
same_report whole-verify/verify-report.json out/p/verify/verify-report.json ||
  fail "verify by jobs reports other than a whole verify"
grep -q "summary of out/p" r1.out || fail "no summary at the end: $(tail r1.out)"
grep -q "verify: CLEAN" r1.out || fail "the summary does not say verify was clean: $(tail r1.out)"

# 2. Nothing changed: nothing runs. A new description: nothing runs.
wf >r2.out 2>&1 || fail "a rerun failed"
grep -q "Nothing to be done" r2.out || fail "a rerun with nothing changed ran jobs: $(cat r2.out)"
sed -i 's/^description: .*/description: the same tracts, described again/' p.yaml
wf >r3.out 2>&1 || fail "a rerun with a new description failed"
grep -q "Nothing to be done" r3.out || fail "a new description ran jobs: $(cat r3.out)"

# A workflow section the pipeline cannot use: one line, exit 2.
sed 's/job_mb: 0.001/job_mb: lots/' p.yaml >badwf.yaml
"$repo/scripts/workflow" badwf.yaml >badwf.out 2>&1
[ $? = 2 ] || fail "a word for workflow.job_mb did not exit 2"
grep -q "'workflow.job_mb' must be a number > 0, not 'lots'" badwf.out || fail "no message for job_mb: $(cat badwf.out)"

# 3. A new pack.tile_mb: pack, verify and render only.
echo "pack: {tile_mb: 2}" >>p.yaml
wf >r4.out 2>&1 || fail "a rerun with a new tile_mb failed"
[ -z "$(ran r4.out)" ] || fail "a new tile_mb ran group jobs: $(ran r4.out)"
grep -q "\] ingest:" r4.out && fail "a new tile_mb ran ingest"
grep -q "\] pack:" r4.out || fail "a new tile_mb did not run pack: $(cat r4.out)"
# The new tree's previews are drawn again; the frame-time experiment, which
# measures the renderer, is not: its summary names the tree it drew.
grep -q "\] render:" r4.out || fail "a new tree did not draw its previews: $(cat r4.out)"
grep -q "\] frame times:" r4.out && fail "a new tree reran the frame-time experiment"
grep -q "frame times at the p95 (an earlier tree)" r4.out || fail "the summary does not say the experiment's tree is older"
[ -f out/p/render/overview.png ] && [ -f out/p/frame-times/frame-times.png ] || fail "no previews or frame-time plot"
# A new render section reruns both.
sed -i 's/^render: {frames: 6}/render: {frames: 8}/' p.yaml
wf >r4r.out 2>&1 || fail "a rerun with new render settings failed: $(tail -30 r4r.out)"
grep -q "\] frame times:" r4r.out && grep -q "\] render:" r4r.out || fail "new render settings ran: $(cat r4r.out)"
grep -q "frame times at the p95: " r4r.out || fail "the summary does not give the frame times: $(cat r4r.out)"

# workflow.render: false, for rebuilds that need the tree verified and
# nothing drawn: turning it off runs nothing; a new tile_mb then runs pack
# and verify, not render. A word for it: exit 2, one line.
sed -i 's/^workflow: {job_mb: 0.001}/workflow: {job_mb: 0.001, render: false}/' p.yaml
wf >r4b.out 2>&1 || fail "a rerun with render off failed: $(tail -30 r4b.out)"
grep -q "Nothing to be done" r4b.out || fail "turning render off ran jobs: $(cat r4b.out)"
sed -i 's/^pack: {tile_mb: 2}/pack: {tile_mb: 3}/' p.yaml
wf >r4c.out 2>&1 || fail "a new tile_mb with render off failed: $(tail -30 r4c.out)"
grep -q "\] verify:" r4c.out || fail "a new tile_mb with render off did not run verify: $(cat r4c.out)"
grep -q "\] render:" r4c.out && fail "render ran with workflow.render false"
sed 's/render: false/render: sometimes/' p.yaml >badrender.yaml
"$repo/scripts/workflow" badrender.yaml >badrender.out 2>&1
[ $? = 2 ] || fail "a word for workflow.render did not exit 2"
grep -q "'workflow.render' must be true or false, not 'sometimes'" badrender.out ||
  fail "no message for workflow.render: $(cat badrender.out)"
sed 's/render: false/frame_times: nightly/' p.yaml >badframes.yaml
"$repo/scripts/workflow" badframes.yaml >badframes.out 2>&1
[ $? = 2 ] || fail "a word for workflow.frame_times did not exit 2"
grep -q "'workflow.frame_times' must be renderer or tree, not 'nightly'" badframes.out ||
  fail "no message for workflow.frame_times: $(cat badframes.out)"

# 4. One county's input changed: ingest, then only that county's jobs.
cp dc_v2.shp.zip dc.shp.zip
wf >r5.out 2>&1 || fail "the rebuild after a change failed: $(tail -30 r5.out)"
[ "$(ran r5.out)" = "color tract/g11001 pack tract/g11001 simplify tract/g11001 verify tract/g11001 " ] ||
  fail "a changed DC tract code reran: $(ran r5.out)"
[ "$(ingested r5.out)" = "r-11 " ] || fail "a changed DC tract code reran the ingest jobs: $(ingested r5.out)"
[ "$(readjobs r5.out)" = "gdc " ] || fail "a changed DC tract code reran the read jobs: $(readjobs r5.out)"
# ... and the result is a clean build's, byte for byte.
mkdir clean && cp p.yaml dc.shp.zip clean/ && (cd clean && "$repo/scripts/workflow" p.yaml >run.out 2>&1) ||
  fail "the clean build failed"
for d in ingest color simplified tree; do
  diff -r -x '*-report.json' -x '*-timings.json' -x '.snakemake_timestamp' "out/p/$d" "clean/out/p/$d" >/dev/null ||
    fail "out/p/$d after the rebuild differs from a clean build's"
done

# 5. --regions forces a region's jobs (and its state's and the nation's
# maps) with nothing changed; a region that names no store is refused.
wf --regions 44003 >r6.out 2>&1 || fail "a region rebuild failed: $(tail -30 r6.out)"
# A pack job also follows the simplify jobs of the groups its stores'
# neighbours are in (the plan): Kent County's borders are in the tract maps
# of Newport, Providence and Washington.
want="color county/g44 color nation/gall color state/gUS color tract/g44003 "
packs="pack county/g44 pack nation/gall pack state/gUS pack tract/g44003 pack tract/g44005 pack tract/g44007 "
packs+="pack tract/g44009 "
# A verify job follows the pack jobs of the groups of the nodes it decodes
# (the plan's near): Bristol's halo holds Kent's chains.
verifies="verify county/g44 verify nation/gall verify state/gUS verify tract/g44001 verify tract/g44003 "
verifies+="verify tract/g44005 verify tract/g44007 verify tract/g44009 "
[ "$(ran r6.out)" = "$want$packs${want//color/simplify}$verifies" ] || fail "--regions 44003 ran: $(ran r6.out)"
for n in 44005 44007 44009; do
  python3 -c "import json,sys; sys.exit('tract/44003' not in json.load(open('out/p/pack-parts/plan.json'))['reads']['tract/$n'])" ||
    fail "the plan does not say tract/$n reads tract/44003"
done
wf --regions 99 >r7.out 2>&1
[ $? = 2 ] || fail "a region that matches no store did not exit 2"
grep -q "region 99 matches no store" r7.out || fail "no message for an unknown region: $(cat r7.out)"

# 6. A bad store fails its own jobs, with its message on the terminal; the
# other stores' jobs finish; the rerun after the fix does the rest.
# (Rhode Island's other tract groups forced, so that their jobs run beside
# it: --regions 44 would also run the state's ingest job, which writes the
# damaged store again.)
head -c 100 out/p/ingest/tract/44005.tlc >bad && cat bad >out/p/ingest/tract/44005.tlc
if wf --forcerun out/p/jobs/color/tract/g440{01,03,07,09}.json >r8.out 2>&1; then
  fail "a run with a corrupt store succeeded"
fi
grep -q "pipeline: color:tract/g44005 failed (exit 1)" r8.out || fail "no failure line for the bad store: $(cat r8.out)"
grep -q "tigerlod-color: .*44005.tlc" r8.out || fail "the stage's message is not on the terminal: $(cat r8.out)"
for g in 44001 44003 44007 44009; do
  grep -q "\] simplify tract/g$g:" r8.out || fail "tract/g$g did not finish beside the failed store"
done
touch dc.shp.zip # the fix: ingest's plan finds the store changed since its job wrote it; the job writes it again
wf >r9.out 2>&1 || fail "the rerun after the fix failed: $(tail -30 r9.out)"
[ "$(ingested r9.out)" = "r-44 " ] || fail "the fix reran the ingest jobs: $(ingested r9.out)"
want="color tract/g44005 pack tract/g44005 pack tract/g44009 simplify tract/g44005 "
want+="verify tract/g44001 verify tract/g44003 verify tract/g44005 verify tract/g44009 "
[ "$(ran r9.out)" = "$want" ] ||
  fail "the rerun after the fix ran: $(ran r9.out)"
grep -q "verify: CLEAN" r9.out || fail "the tree after the fix is not clean"
# ... and after it, nothing is left to do.
wf >r10.out 2>&1 || fail "a run after the fix failed"
grep -q "Nothing to be done" r10.out || fail "a run after the fix ran jobs again: $(cat r10.out)"

# 7. An input with other bytes and the same map (a column ingest does not
# read added): ingest runs and no store changes, so no group job runs; the
# stages' manifests follow ingest's new one, so pack and verify take them.
ogr2ogr -f "ESRI Shapefile" dc_again.shp.zip "/vsizip/dc.shp.zip" -nln dc -sql "SELECT *, 'x' AS NOTE FROM dc" \
  >/dev/null && mv dc_again.shp.zip dc.shp.zip
wf >r11.out 2>&1 || fail "a run after a rezipped input failed: $(tail -30 r11.out)"
[ -z "$(ran r11.out)" ] || fail "a rezipped input reran group jobs: $(ran r11.out)"
grep -q "verify: CLEAN" r11.out || fail "the tree after a rezipped input is not clean"
wf >r12.out 2>&1 || fail "a run after the rezipped input failed"
grep -q "Nothing to be done" r12.out || fail "a run after the rezipped input ran jobs again: $(cat r12.out)"

# 8. A bad input in one state fails that state's ingest job, with its
# message on the terminal; the other state's job finishes and keeps its
# stores; the rerun after the fix runs the fixed state's job alone. (Here
# a tract code in two counties: the tract level built from the fields
# STATEFP10 + TRACTCE10 does not nest in the counties.)
ogr2ogr -f "ESRI Shapefile" ri_bad.shp.zip "/vsizip/$data/tl_2010_44_tract10.zip/tl_2010_44_tract10.shp" -nln ri \
  -dialect SQLite -sql "SELECT Geometry, MTFCC10, INTPTLAT10, INTPTLON10, NAMELSAD10, ALAND10, AWATER10, GEOID10,
    STATEFP10, COUNTYFP10,
    CASE WHEN GEOID10 = '44005041300' THEN '017800' ELSE TRACTCE10 END AS TRACTCE10 FROM tl_2010_44_tract10"
ogr2ogr -f "ESRI Shapefile" ri_good.shp.zip "/vsizip/$data/tl_2010_44_tract10.zip/tl_2010_44_tract10.shp" -nln ri
cp ri_bad.shp.zip ri.shp.zip
sed -e 's/^name: p/name: q/' -e "s|inputs: \[dc.shp.zip, .*\]|inputs: [$data/tl_2010_11_tract10.zip, ri.shp.zip]|" \
  -e 's/{name: state, prefix: 2}/{name: state, fields: [STATEFP10]}/' \
  -e 's/{name: county, prefix: 5}/{name: county, fields: [STATEFP10, COUNTYFP10]}/' \
  -e 's/{name: tract, prefix: 11}/{name: tract, fields: [STATEFP10, TRACTCE10]}/' p.yaml >q.yaml
if "$repo/scripts/workflow" q.yaml >q1.out 2>&1; then
  fail "a run with a tract in two counties succeeded"
fi
grep -q "pipeline: ingest:r-44 failed (exit 1)" q1.out || fail "no failure line for the bad state: $(cat q1.out)"
grep -q "tigerlod-ingest: level 'tract' does not nest in level 'county'.*ri.shp.zip" q1.out ||
  fail "the ingest job's message is not on the terminal: $(cat q1.out)"
[ "$(ingested q1.out)" = "r-11 " ] || fail "the other state's ingest job did not finish: $(ingested q1.out)"
[ -f out/q/ingest/tract/11001.tlc ] || fail "the other state's stores are not there"
[ -z "$(ran q1.out)" ] || fail "group jobs ran on a failed ingest: $(ran q1.out)"
cp ri_good.shp.zip ri.shp.zip
"$repo/scripts/workflow" q.yaml >q2.out 2>&1 || fail "the rerun after the fix failed: $(tail -30 q2.out)"
[ "$(ingested q2.out)" = "r-44 " ] || fail "the rerun after the fix ran the ingest jobs: $(ingested q2.out)"
grep -q "verify: CLEAN" q2.out || fail "the tree after the fix is not clean"

# 9. An input that cannot be read fails its read job, with its message on
# the terminal, and nothing after it runs: the last run's outputs stay as
# they were. The rerun after the fix reads that file alone; its part's
# bytes are the ones planned before, so no region job runs.
yes "not a zip" | head -c 20000 >ri.shp.zip
if "$repo/scripts/workflow" q.yaml >q3.out 2>&1; then
  fail "a run with an unreadable input succeeded"
fi
grep -q "pipeline: ingest:read:gri failed (exit 1)" q3.out || fail "no failure line for the unreadable file: $(cat q3.out)"
grep -q "tigerlod-ingest: .*ri.shp.zip" q3.out || fail "the read job's message does not name the file: $(cat q3.out)"
[ -z "$(ingested q3.out)$(ran q3.out)" ] || fail "jobs ran after a failed read: $(ingested q3.out)$(ran q3.out)"
[ -f out/q/ingest/tract/44001.tlc ] && [ -f out/q/ingest/tract/11001.tlc ] || fail "the last run's stores are gone"
cp ri_good.shp.zip ri.shp.zip
"$repo/scripts/workflow" q.yaml >q4.out 2>&1 || fail "the rerun after the unreadable file failed: $(tail -30 q4.out)"
[ "$(readjobs q4.out)" = "gri " ] || fail "the rerun after the unreadable file read: $(readjobs q4.out)"
[ -z "$(ingested q4.out)$(ran q4.out)" ] || fail "the same part ran jobs again: $(ingested q4.out)$(ran q4.out)"

if [ "$failures" -gt 0 ]; then
  echo "$failures failure(s)"
  exit 1
fi
echo "partitions: all checks passed"
