#!/usr/bin/env bash
# Seeded maps at the antimeridian and across a conic's cut, end to end
# (ingest, simplify, pack, verify on the ellipsoid with the CGAL checker):
# a grid of cells from 150 E to 150 W, each with random points on its
# edges (the same for the two cells that share an edge, but each side's
# own along the meridian 180, written 180 or -180 at random, as sources
# clipped there draw them); in every other row the two cells at 180 are
# one unit in two parts. A cone whose cut (lon0 + 180) falls at a random
# place inside the grid, so that cells are cut there too, and a random
# flower near the cut, which crosses it many times (each of its pieces a
# ring of its own), and a random ring round the
# south pole, closed by going once round the globe. Every seed: no problem at ingest,
# every unit there, clean on the ground, the checkers agreeing.
#   tests/world/test_globe_property.sh REPO BIN_DIR [SEEDS]
. "$(dirname "$0")/../support/script.sh" globe-property "$1" "$2"
. "$(dirname "$0")/end_to_end.sh"
seeds=${3:-1 2 3 4}
[ "${TIGERLOD_SANITIZED:-0}" = 1 ] && seeds=${3:-1}
passed=0
for seed in $seeds; do
  d=$work/$seed
  mkdir -p "$d"
  python3 - "$d" "$seed" <<'PY' || fail "seed $seed: the generator failed"
import json, math, random, sys
d, seed = sys.argv[1], int(sys.argv[2])
rnd = random.Random(seed)
E6 = 1000000
cols = list(range(150, 211, 5))  # unwrapped longitudes of the columns' edges
rows = list(range(-10, 21, 5))
def lon(x_e6, east_of_seam=False):
    # Unwrapped micro-degrees to a longitude in [-180, 180].
    if x_e6 == 180 * E6 and east_of_seam:
        return rnd.choice([180.0, -180.0])
    v = x_e6 if x_e6 <= 180 * E6 else x_e6 - 360 * E6
    return round(v / E6, 6)
def between(a, b):
    # 0 to 3 random points strictly inside (a, b), in micro-degrees, sorted.
    return sorted(rnd.sample(range(a + 1, b), rnd.randint(0, 3)))
hedge, vedge = {}, {}
for i in range(len(cols) - 1):
    for j in range(len(rows)):
        hedge[i, j] = between(cols[i] * E6, cols[i + 1] * E6)
for i in range(len(cols)):
    for j in range(len(rows) - 1):
        for side in ("w", "e"):
            vedge[i, j, side] = between(rows[j] * E6, rows[j + 1] * E6)
def cell(i, j):
    x0, x1, y0, y1 = cols[i] * E6, cols[i + 1] * E6, rows[j] * E6, rows[j + 1] * E6
    seam_l = cols[i] == 180  # the cell's west edge is the meridian 180
    seam_r = cols[i + 1] == 180
    # Two cells share a vertical edge's points, except along 180 (each its own).
    left = vedge[i, j, "e" if seam_l else "w"]
    right = vedge[i + 1, j, "w"]
    pts = [(x0, y0)] + [(x, y0) for x in hedge[i, j]] + [(x1, y0)] + [(x1, y) for y in right] + [(x1, y1)]
    pts += [(x, y1) for x in reversed(hedge[i, j + 1])] + [(x0, y1)] + [(x0, y) for y in reversed(left)]
    ring = [[lon(x, seam_l and x == x0), round(y / E6, 6)] for x, y in pts]
    return ring + [ring[0]]
features = []
seam_col = cols.index(180)
n = 0
for j in range(len(rows) - 1):
    i = 0
    while i < len(cols) - 1:
        n += 1
        code = "C%03d" % n
        parts = [cell(i, j)]
        if j % 2 == 0 and i == seam_col - 1:  # one unit in two parts, cut at 180
            parts.append(cell(i + 1, j))
            i += 1
        features.append({"type": "Feature", "properties": {"code": code},
                         "geometry": {"type": "MultiPolygon", "coordinates": [[p] for p in parts]}})
        i += 1
# The cut: inside a column, away from its edges.
k = rnd.randrange(len(cols) - 1)
cut = cols[k] + rnd.randint(5, 45) / 10 + rnd.randint(0, 99) / 1000
lon0 = cut - 180
# A flower of k petals north of the grid, its centre 2.5 to 4.5 degrees off
# the cut, so that the cut crosses it up to 2 k times. Smooth (short
# segments, petals apart): simple in the plane too, where the cone bends
# lon/lat's straight lines (a spiky star, simple in lon/lat, can cross
# itself there, and ingest rightly says so).
k = rnd.randint(3, 8)
amp, phase = rnd.uniform(1.5, 2.5), rnd.uniform(0, 2 * math.pi)
dx = rnd.choice([-1, 1]) * rnd.uniform(2.5, 4.5)  # through the petals
m = 12 * k
star = []
for i in range(m):
    a = 2 * math.pi * (i + rnd.uniform(-0.3, 0.3)) / m
    r = 4 + amp * math.sin(k * a + phase)
    star.append([lon(round((cut + dx + r * math.cos(a)) * E6)), round(37.5 + r * math.sin(a), 6)])
star.append(star[0])
n += 1
features.append({"type": "Feature", "properties": {"code": "S%03d" % n},
                 "geometry": {"type": "Polygon", "coordinates": [star]}})
# A ring round the south pole at random longitudes and latitudes, from
# -180 once round back to it (as Natural Earth closes Antarctica).
lons = sorted(rnd.sample(range(-179 * E6, 180 * E6, 1000), rnd.randint(20, 80)))
polar = [[-180.0, -70.0]] + [[round(x / E6, 6), round(rnd.uniform(-75, -65), 6)] for x in lons] + [[-180.0, -70.0]]
n += 1
features.append({"type": "Feature", "properties": {"code": "P%03d" % n},
                 "geometry": {"type": "Polygon", "coordinates": [polar]}})
json.dump({"type": "FeatureCollection", "features": features}, open(f"{d}/map.geojson", "w"))
open(f"{d}/map.yaml", "w").write(
    "name: globe-property\ndataset: {kind: polygons, inputs: [map.geojson], code_field: code}\n"
    "levels:\n  - {name: world, code: W}\n  - {name: unit, prefix: 4}\n"
    f"projection: {{kind: albers, lon0: {lon0:.3f}, lat0: 0, stdlat1: 20, stdlat2: 50, grid_m: 0.1}}\n"
    "ingest: {halo_m: 20000}\nsimplify: {tolerances_m: [100, 1000, 5000], shortcut_test: exact}\n")
open(f"{d}/units", "w").write(str(n))
PY
  units=$(cat "$d/units")
  end_to_end "seed $seed" "$d/map.yaml" "$d"
  grep -q "problems: none" "$d/ingest.log" || fail "seed $seed ingest: $(cat "$d/map.yaml" "$d/ingest.log")"
  grep -Eq "^ +unit +$units " "$d/ingest.log" || fail "seed $seed: not $units units: $(cat "$d/ingest.log")"
  passed=$((passed + 1))
done
echo "globe-property: seeds $seeds: no problem at ingest, every unit, clean on the ground, the checkers agreeing"
echo "$passed passed, 0 failed"
