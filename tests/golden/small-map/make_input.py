#!/usr/bin/env python3
"""Writes input.geojson: a hand-made map for the stage goldens (run once; the
output is checked in). Two districts (codes 1, 2), each of two units (11, 12;
21, 22), on a 2 x 2 grid of cells about 900 m wide near 80 W 37 N. Every
border is one polyline, shared vertex for vertex by the two units it
separates, with a zigzag of a few metres (simplified away at the ladder's
larger tolerances) and one deep notch (kept)."""
import json

X0, X1, X2 = -80.0, -79.99, -79.98
Y0, Y1, Y2 = 37.0, 37.008, 37.016
STEP, AMP = 0.0004, 0.00003


def line(a, b, zig):
    """From a to b in STEP pieces, every other point moved AMP sideways."""
    (ax, ay), (bx, by) = a, b
    n = max(1, round(max(abs(bx - ax), abs(by - ay)) / STEP))
    pts = []
    for k in range(n + 1):
        t = k / n
        x, y = ax + (bx - ax) * t, ay + (by - ay) * t
        if zig and 0 < k < n and k % 2:
            if ax == bx:
                x += AMP
            else:
                y += AMP
        pts.append([round(x, 6), round(y, 6)])
    return pts


def notch(pts, at, depth):
    """A deep V into the line at index `at` (a feature no tolerance removes)."""
    x, y = pts[at]
    pts[at] = [round(x + depth, 6), y] if pts[0][0] == pts[-1][0] else [x, round(y + depth, 6)]
    return pts


# Borders, each drawn once.
south_w, south_e = line((X0, Y0), (X1, Y0), False), line((X1, Y0), (X2, Y0), False)
north_w, north_e = line((X0, Y2), (X1, Y2), False), line((X1, Y2), (X2, Y2), False)
west_s, west_n = line((X0, Y0), (X0, Y1), False), line((X0, Y1), (X0, Y2), False)
east_s, east_n = line((X2, Y0), (X2, Y1), False), line((X2, Y1), (X2, Y2), False)
mid_v_s = notch(line((X1, Y0), (X1, Y1), True), 9, 0.002)  # district border, notched east
mid_v_n = line((X1, Y1), (X1, Y2), True)
mid_h_w = line((X0, Y1), (X1, Y1), True)
mid_h_e = notch(line((X1, Y1), (X2, Y1), True), 12, -0.0015)  # notched south


def ring(*parts):
    """Concatenate polylines (each given in ring order) into a closed ring."""
    pts = []
    for p in parts:
        pts += p if not pts else p[1:]
    assert pts[0] == pts[-1]
    return pts


rev = lambda p: p[::-1]
units = {
    "11": ring(south_w, mid_v_s, rev(mid_h_w), rev(west_s)),
    "12": ring(mid_h_w, mid_v_n, rev(north_w), rev(west_n)),
    "21": ring(south_e, east_s, rev(mid_h_e), rev(mid_v_s)),
    "22": ring(mid_h_e, east_n, rev(north_e), rev(mid_v_n)),
}
features = [{"type": "Feature", "properties": {"code": code}, "geometry": {"type": "Polygon", "coordinates": [pts]}}
            for code, pts in units.items()]
with open("input.geojson", "w") as f:
    json.dump({"type": "FeatureCollection", "features": features}, f, separators=(",", ":"))
    f.write("\n")
