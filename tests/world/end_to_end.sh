# Sourced by tests/world's scripts after tests/support/script.sh (which
# sets bin and fail).
# end_to_end NAME CONFIG DIR: ingest (its log in DIR, checked by the
# caller), simplify, pack, and verify with the CGAL checker; clean, the
# checkers agreeing, and measured on the ellipsoid.
end_to_end() {
  local name=$1 cfg=$2 d=$3
  mkdir -p "$d"
  "$bin/tigerlod-ingest" "$cfg" "$d/in" >"$d/ingest.log" 2>&1 || fail "$name ingest: $(cat "$d/ingest.log")"
  "$bin/tigerlod-simplify" --config "$cfg" "$d/in" "$d/simp" >"$d/simp.log" 2>&1 ||
    fail "$name simplify: $(cat "$d/simp.log")"
  "$bin/tigerlod-pack" "$d/in" "$d/simp" "$d/tree" >"$d/pack.log" 2>&1 || fail "$name pack: $(cat "$d/pack.log")"
  "$bin/tigerlod-verify" --cgal "$d/tree" "$d/in" "$d/verify" >"$d/verify.log" 2>&1 ||
    fail "$name verify: $(cat "$d/verify.log")"
  grep -q "CLEAN: no violations" "$d/verify.log" || fail "$name verify: $(cat "$d/verify.log")"
  grep -q "CGAL check: agrees" "$d/verify.log" || fail "$name CGAL: $(cat "$d/verify.log")"
  grep -q "on the ellipsoid: skipped vertices at most 0\." "$d/verify.log" || fail "$name ground: $(cat "$d/verify.log")"
}
