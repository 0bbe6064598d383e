"""tests/faults/make_map.py DIR [N [STEPS]]: the fault tests' hand-made map
in DIR: map.geojson (N x N counties, default 6, in 2 states, wavy borders,
STEPS vertices a side, default 40) and map.yaml (a state and a county level, a 50 and 200 m ladder with the
exact rules, a 4-frame 64 x 64 render)."""
import json, math, sys
d = sys.argv[1]
n = int(sys.argv[2]) if len(sys.argv) > 2 else 6
steps = int(sys.argv[3]) if len(sys.argv) > 3 else 40
size, wave = 0.5, 0.01
def x(i, j): return -100 + i * size + (wave * math.sin(j * 7.3 + i) if 0 < i < n else 0)
def y(i, j): return 40 + j * size + (wave * math.cos(i * 5.1 + j) if 0 < j < n else 0)
def edge(a, b):
    return [(a[0] + (b[0] - a[0]) * t / steps, a[1] + (b[1] - a[1]) * t / steps) for t in range(steps)]
feats = []
for i in range(n):
    for j in range(n):
        c = [(x(i, j), y(i, j)), (x(i + 1, j), y(i + 1, j)), (x(i + 1, j + 1), y(i + 1, j + 1)), (x(i, j + 1), y(i, j + 1))]
        ring = []
        for k in range(4):
            ring += edge(c[k], c[(k + 1) % 4])
        ring.append(ring[0])
        code = ("01" if i < n // 2 else "02") + "%03d" % (i * n + j)
        feats.append({"type": "Feature", "properties": {"code": code},
                      "geometry": {"type": "Polygon", "coordinates": [[list(p) for p in ring]]}})
json.dump({"type": "FeatureCollection", "features": feats}, open(f"{d}/map.geojson", "w"))
open(f"{d}/map.yaml", "w").write(
    "name: disk\ndataset: {kind: polygons, inputs: [map.geojson], code_field: code}\n"
    "levels:\n  - {name: state, prefix: 2}\n  - {name: county, prefix: 5}\n"
    "simplify: {tolerances_m: [50, 200], shortcut_test: exact}\n"
    "render: {frames: 4, size: 64x64}\n")
