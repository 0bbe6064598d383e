#!/usr/bin/env bash
# The world map end to end (configs/world.yaml: Natural Earth countries from
# world-atlas, an Albers cone around the globe at a 0.1 m grid): ingest
# (the five features without a code left out and named), simplify at the
# config's ladder, pack, and verify on the ellipsoid with the CGAL checker
# beside it: clean. And the same map at the default 0.01 m grid: refused
# by --validate naming projection.grid_m. Skips (exit 77) without the
# package, which scripts/test fetches.
#   tests/world/test_world.sh REPO BIN_DIR
set -uo pipefail
repo=$(cd "$1" && pwd)
bin=$(cd "$2" && pwd)
if [ ! -f "$repo/.cache/npm/world-atlas-2.0.2/countries-50m.json" ]; then
  echo "world: skipped: .cache/npm/world-atlas-2.0.2 is absent (scripts/fetch-npm world-atlas@2.0.2 .cache/npm/world-atlas-2.0.2)"
  exit 77
fi
work=$(mktemp -d "${TMPDIR:-/tmp}/tigerlod-world-XXXXXX")
trap 'rm -rf "$work"' EXIT
fail() {
  echo "world: FAILED: $*"
  exit 1
}
cfg=$repo/configs/world.yaml
"$bin/tigerlod-ingest" "$cfg" "$work/in" >"$work/ingest.log" 2>&1 || fail "ingest: $(cat "$work/ingest.log")"
grep -q "5 features with an empty 'id' (feature 58 'Somaliland'" "$work/ingest.log" ||
  fail "ingest did not name the features without a code: $(cat "$work/ingest.log")"
"$bin/tigerlod-simplify" --config "$cfg" "$work/in" "$work/simp" >"$work/simp.log" 2>&1 ||
  fail "simplify: $(cat "$work/simp.log")"
"$bin/tigerlod-pack" "$work/in" "$work/simp" "$work/tree" >"$work/pack.log" 2>&1 || fail "pack: $(cat "$work/pack.log")"
"$bin/tigerlod-verify" --cgal "$work/tree" "$work/in" "$work/verify" >"$work/verify.log" 2>&1 ||
  fail "verify: $(cat "$work/verify.log")"
grep -q "CLEAN: no violations" "$work/verify.log" || fail "verify: $(cat "$work/verify.log")"
grep -q "CGAL check: agrees" "$work/verify.log" || fail "CGAL: $(cat "$work/verify.log")"
grep -q "on the ellipsoid: skipped vertices at most 0\." "$work/verify.log" || fail "ground: $(cat "$work/verify.log")"
# At the default grid the world is wider than a node: --validate says which key.
sed -e 's/, grid_m: 0.1}/}/' -e "s|\.\./\.cache/|$repo/.cache/|g" "$cfg" >"$work/world-fine.yaml"
"$bin/tigerlod-ingest" --validate "$work/world-fine.yaml" "$work/x" >"$work/validate.log" 2>&1
rc=$?
[ "$rc" = 2 ] || fail "--validate at 0.01 m: exit $rc, not 2: $(cat "$work/validate.log")"
grep -q "set projection.grid_m to 0.02 or more" "$work/validate.log" || fail "--validate: $(cat "$work/validate.log")"
echo "world: ingest, simplify, pack and verify clean on the ground, CGAL agreeing; 0.01 m refused naming projection.grid_m"
echo "1 passed, 0 failed"
