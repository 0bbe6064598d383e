#!/usr/bin/env bash
# The operator's scripts around the workflow refuse bad arguments with one
# line naming the fault and exit 2 (bad input files: 1), before they start
# anything: scripts/fuzz, scripts/cluster-estimate, pipeline/merge-reports,
# scripts/bench-workflow, scripts/bench-gl, scripts/bench-partitions and scripts/test-slurm (which
# would otherwise install and start Slurm first). And merge-reports sums two
# shares as the whole run writes them.
#
#   tests/workflow/test_scripts.sh REPO
set -uo pipefail
repo=$(cd "$1" && pwd)
work=$(mktemp -d "${TMPDIR:-/tmp}/tigerlod-scripts-XXXXXX")
trap 'rm -rf "$work"' EXIT
failures=0

# expect RC PATTERN CMD...: CMD exits RC and its stderr matches PATTERN, in
# one line, with no Python traceback.
expect() {
  local rc=$1 pattern=$2
  shift 2
  "$@" >"$work/out" 2>"$work/err"
  local got=$?
  if [ "$got" != "$rc" ] || ! grep -Eq -- "$pattern" "$work/err" || grep -q Traceback "$work/err"; then
    echo "FAIL: $* exited $got (want $rc), stderr:"
    sed 's/^/  /' "$work/err"
    failures=$((failures + 1))
  else
    echo "ok: $* -> $rc: $(head -n 1 "$work/err")"
  fi
}

mkdir -p "$work/run/benchmarks/color/tract" "$work/run/benchmarks/simplify/tract"
printf 's\th:m:s\tmax_rss\n12.5\t0:00:12\t100\n' >"$work/run/benchmarks/ingest.tsv"
printf 's\th:m:s\tmax_rss\n3.0\t0:00:03\t100\n' >"$work/run/benchmarks/color/tract/g1.tsv"
printf 's\th:m:s\tmax_rss\n5.0\t0:00:05\t100\n' >"$work/run/benchmarks/simplify/tract/g1.tsv"
expect 2 "fuzz: SECONDS must be a whole number >= 1, not 'x'" "$repo/scripts/fuzz" x
expect 2 "fuzz: TIGERLOD_FUZZ_JOBS must be a whole number >= 1, not '0'" env TIGERLOD_FUZZ_JOBS=0 "$repo/scripts/fuzz" 5
expect 2 "usage: scripts/bench-gl" "$repo/scripts/bench-gl"
expect 2 "not a tigerlod-ingest output" "$repo/scripts/bench-gl" "$work/none" 1,4
expect 2 "required: out, workers" "$repo/scripts/cluster-estimate"
expect 2 "no benchmark files" "$repo/scripts/cluster-estimate" "$work/none" 8
expect 2 "not a number: 'x'" "$repo/scripts/cluster-estimate" "$work/run" x
expect 2 "0 must be >= 1" "$repo/scripts/cluster-estimate" "$work/run" 0
expect 2 "-3 must be >= 0" "$repo/scripts/cluster-estimate" "$work/run" 8 --overhead -3
expect 2 "0 must be > 0" "$repo/scripts/cluster-estimate" "$work/run" 8 --scale 0
if ! "$repo/scripts/cluster-estimate" "$work/run" 1 2 >"$work/est" 2>&1 || ! grep -q "^| 2 | " "$work/est"; then
  echo "FAIL: cluster-estimate on a good folder:"
  cat "$work/est"
  failures=$((failures + 1))
fi

mkdir -p "$work/jobs/tract"
echo '{"tolerances": [{"eps_m": 1.0, "stores": 2, "tiles": 4, "classes_max": 7, "classes_mean": 5.0}]}' \
  >"$work/jobs/tract/a.json"
echo '{"tolerances": [{"eps_m": 1.0, "stores": 1, "tiles": 1, "classes_max": 9, "classes_mean": 10.0}]}' \
  >"$work/jobs/tract/b.json"
echo 'not json' >"$work/jobs/tract/bad.json"
expect 2 "usage: merge-reports" "$repo/pipeline/merge-reports" "$work/jobs"
expect 1 "$work/jobs/tract/missing.json: not a job's report share" "$repo/pipeline/merge-reports" "$work/jobs" \
  "$work/merged.json" "$work/jobs/tract/a.json" "$work/jobs/tract/missing.json"
expect 1 "bad.json: not a job's report share" "$repo/pipeline/merge-reports" "$work/jobs" "$work/merged.json" \
  "$work/jobs/tract/a.json" "$work/jobs/tract/bad.json"
if [ -e "$work/merged.json" ] || [ ! -e "$work/jobs/tract/bad.json" ]; then
  echo "FAIL: a refused merge wrote its destination or removed a share"
  failures=$((failures + 1))
fi
"$repo/pipeline/merge-reports" "$work/jobs" "$work/merged.json" "$work/jobs/tract/a.json" "$work/jobs/tract/b.json"
merged=$(python3 -c "import json; t = json.load(open('$work/merged.json'))['tolerances'][0]; \
print(t['eps_m'], t['stores'], t['tiles'], t['classes_max'], t['classes_mean'])")
if [ "$merged" != "1.0 3 5 9 6.0" ] || [ -e "$work/jobs/tract/bad.json" ]; then
  echo "FAIL: merge-reports summed to '$merged' (want '1.0 3 5 9 6.0': counts added, maxima, mean by tiles)" \
    "and removes the shares not given"
  failures=$((failures + 1))
fi

# scripts/workflow on a bad config: one line naming the file (and line), exit 2, before Snakemake.
printf 'name: a\ndataset: {kind: polygons, inputs: [x.shp]}\nname: b\n' >"$work/dup.yaml"
printf -- '- name: a\n' >"$work/list.yaml"
printf 'name: [\n' >"$work/bad.yaml"
cd "$work" || exit 1
expect 2 "dup.yaml:3: duplicate key 'name' \(first at line 1\)" "$repo/scripts/workflow" "$work/dup.yaml"
expect 2 "list.yaml: the config must be a mapping of keys .*, not a list" "$repo/scripts/workflow" "$work/list.yaml"
expect 2 "bad.yaml:2: not valid YAML" "$repo/scripts/workflow" "$work/bad.yaml"
cd - >/dev/null || exit 1
expect 2 "usage: scripts/bench-partitions" "$repo/scripts/bench-partitions"
expect 2 "must be a finished scripts/workflow output" "$repo/scripts/bench-partitions" "$work/none"
expect 2 "THREADS must be an integer >= 1, not '0'" "$repo/scripts/bench-partitions" "$work/none" 0
expect 2 "no such config" "$repo/scripts/bench-workflow" "$work/none.yaml"
expect 2 "two-digit state code, not '4x'" "$repo/scripts/bench-workflow" "$repo/configs/tracts2010.yaml" 4x
expect 2 "names no input file of state 99" "$repo/scripts/bench-workflow" "$repo/configs/tracts2010.yaml" 99
expect 2 "none.yaml: no such config" "$repo/scripts/test-slurm" "$work/none.yaml"

# The workflow's bar never goes back when a checkpoint adds jobs (75 % of 4
# jobs, then 4 of 10): pipeline/progress.py shows the largest fraction so far.
shown=$(cd "$repo/pipeline" && python3 -c "
import progress
print(' '.join(f'{progress.bar_fraction(d, t):.2f}' for d, t in [(1, 4), (3, 4), (4, 10), (7, 10), (9, 10), (10, 10)]))")
if [ "$shown" != "0.25 0.75 0.75 0.75 0.90 1.00" ]; then
  echo "FAIL: the workflow bar's fractions were '$shown' (want 0.25 0.75 0.75 0.75 0.90 1.00)"
  failures=$((failures + 1))
fi

[ "$failures" = 0 ] || {
  echo "$failures failures"
  exit 1
}
echo "all scripts refuse bad arguments"
