#!/usr/bin/env bash
# The world map end to end (configs/world.yaml: Natural Earth countries from
# world-atlas, an Albers cone around the globe at a 0.1 m grid): ingest
# (the five features without a code left out and named), simplify at the
# config's ladder, pack, and verify on the ellipsoid with the CGAL checker
# beside it: clean. And the same map at the default 0.01 m grid: refused
# by --validate naming projection.grid_m; without dataset.empty_code:
# skip, the features without a code refused, all counted and three named;
# a halo below the ladder's need refused by --validate. Skips (exit 77) without the
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
# Features without a code stop ingest by default, all counted, three named, nothing written.
sed -e '/empty_code: skip/d' -e "s|\.\./\.cache/|$repo/.cache/|g" "$cfg" >"$work/world-strict.yaml"
"$bin/tigerlod-ingest" "$work/world-strict.yaml" "$work/strict" >"$work/strict.log" 2>&1
rc=$?
[ "$rc" = 1 ] || fail "empty codes: exit $rc, not 1: $(cat "$work/strict.log")"
grep -q "countries-50m.json: 5 features with an empty 'id' (feature 58 'Somaliland', feature 130 'Kosovo', feature 185 'N. Cyprus', ...): give each a code, or set dataset.empty_code: skip" "$work/strict.log" ||
  fail "empty codes: $(cat "$work/strict.log")"
[ ! -e "$work/strict" ] || fail "empty codes: ingest left $work/strict"
# The halo rule for the config's own ladder, at --validate: 10 km in Linf needs 28.3 km.
sed -e 's/halo_m: 20000/halo_m: 25000/' -e 's/shortcut_test: exact/shortcut_test: exact\n  metric: linf/' \
  -e "s|\.\./\.cache/|$repo/.cache/|g" "$cfg" >"$work/world-halo.yaml"
"$bin/tigerlod-ingest" --validate "$work/world-halo.yaml" "$work/x" >"$work/halo.log" 2>&1
rc=$?
[ "$rc" = 2 ] || fail "halo rule: exit $rc, not 2: $(cat "$work/halo.log")"
grep -q "'ingest.halo_m' (25000 m) is below the 28284.3 m that simplify.tolerances_m's largest, 10000 m, needs" "$work/halo.log" ||
  fail "halo rule: $(cat "$work/halo.log")"
echo "world: ingest, simplify, pack and verify clean on the ground, CGAL agreeing; 0.01 m refused naming projection.grid_m;"
echo "  empty codes refused by default, counted and named; the halo rule checked at --validate"
echo "1 passed, 0 failed"
