#pragma once
/// @file near_parts.hpp
/// The parts of a shortcut that the raster needs to test.
///
/// Every point x of a proximate shortcut s of chain i lies within eps_i of a
/// segment of its subchain v_0 .. v_m: the feet of the v_k on s (their
/// nearest points on s) run from one end of s to the other, so x lies
/// between the feet of some v_k and v_k+1, where the distance to segment
/// v_k v_k+1 (convex along s) is at most eps_i. This holds in any norm, so
/// in L1 and Linf too, and then x is within eps_i x l2_reach of that segment
/// as an L2 distance (1 for L1, sqrt 2 for Linf); below, eps_i stands for
/// that L2 radius. If the segment has no other chain within eps_i + every
/// other chain's reach ("clear"), x is farther than that reach from every
/// other chain, and so are the pixels the raster tests around x. So only the
/// points of s within eps_i of the subchain's blocked (not clear) segments
/// can fail, and only they are drawn: near a junction, a kilometre-long
/// shortcut is tested over its first few pixels.

#include "core/geometry.hpp"

#include <algorithm>
#include <cmath>
#include <optional>
#include <span>
#include <utility>
#include <vector>

namespace tigerlod::simplify {

/// The interval of t in [0, 1] where a + t (b - a) lies within r of segment
/// pq (L2), or nothing. In doubles; callers widen it for rounding.
struct Point2 {
    double x = 0, y = 0;
};

inline std::optional<std::pair<double, double>> capsule_interval(Point2 a, Point2 b, Point2 p, Point2 q, double r)
{
    const double dx = b.x - a.x, dy = b.y - a.y;
    const double dd = dx * dx + dy * dy;
    if (dd == 0) {
        return std::nullopt;
    }
    double lo = 2, hi = -1; // empty
    auto unite = [&](double t0, double t1) {
        if (t0 <= t1) {
            lo = std::min(lo, t0);
            hi = std::max(hi, t1);
        }
    };
    // The disks at p and q: |a - c + t d|^2 <= r^2.
    auto disk = [&](Point2 c) {
        const double ux = a.x - c.x, uy = a.y - c.y;
        const double cross = ux * dy - uy * dx;
        const double disc = dd * r * r - cross * cross; // a quarter of the discriminant
        if (disc < 0) {
            return;
        }
        const double mid = -(ux * dx + uy * dy) / dd, half = std::sqrt(disc) / dd;
        unite(mid - half, mid + half);
    };
    disk(p);
    disk(q);
    // The rectangle around pq: its projection onto pq within [0, |pq|^2],
    // its distance to pq's line within r.
    const double ex = q.x - p.x, ey = q.y - p.y;
    const double ee = ex * ex + ey * ey;
    if (ee > 0) {
        double t0 = -1e300, t1 = 1e300;
        // c0 + t c1 in [lo_bound, hi_bound]
        auto within = [&](double c0, double c1, double lo_bound, double hi_bound) {
            if (c1 == 0) {
                if (c0 < lo_bound || c0 > hi_bound) {
                    t0 = 1;
                    t1 = 0;
                }
                return;
            }
            double ta = (lo_bound - c0) / c1, tb = (hi_bound - c0) / c1;
            if (ta > tb) {
                std::swap(ta, tb);
            }
            t0 = std::max(t0, ta);
            t1 = std::min(t1, tb);
        };
        const double ux = a.x - p.x, uy = a.y - p.y;
        within(ux * ex + uy * ey, dx * ex + dy * ey, 0, ee);
        const double band = r * std::sqrt(ee);
        within(ex * uy - ey * ux, ex * dy - ey * dx, -band, band);
        unite(t0, t1);
    }
    lo = std::max(lo, 0.0);
    hi = std::min(hi, 1.0);
    if (lo > hi) {
        return std::nullopt;
    }
    return std::pair{lo, hi};
}

inline std::optional<std::pair<double, double>> capsule_interval(GridPoint a, GridPoint b, GridPoint p, GridPoint q,
                                                                 double r)
{
    auto d = [](GridPoint g) { return Point2{double(g.x), double(g.y)}; };
    return capsule_interval(d(a), d(b), d(p), d(q), r);
}

/// A blocked segment pts[k] pts[k+1] of a chain, and the part of it (as
/// parameters t0..t1 along it) that another chain comes near.
struct NearSegment {
    uint32_t k = 0;
    double t0 = 0, t1 = 1;
};

/// The parts of shortcut ab (over pts[from..to]) to draw: the points within
/// r of the near part of a segment listed in `blocked` (sorted by k) with
/// from <= k < to, each widened by `pad` grid units, merged. Empty when the
/// shortcut cannot fail: a point within eps_i of the clear part of a segment
/// is as far from other chains as the point of the proof above.
inline std::vector<std::pair<double, double>> near_parts(std::span<const GridPoint> pts, uint32_t from, uint32_t to,
                                                         const std::vector<NearSegment>& blocked, double r, double pad)
{
    std::vector<std::pair<double, double>> parts;
    const GridPoint a = pts[from], b = pts[to];
    const double len = std::hypot(double(b.x) - double(a.x), double(b.y) - double(a.y));
    if (len == 0) {
        return parts;
    }
    const double widen = pad / len + 1e-9;
    auto at = [](GridPoint p, GridPoint q, double t) {
        return Point2{p.x + t * (double(q.x) - p.x), p.y + t * (double(q.y) - p.y)};
    };
    const Point2 fa{double(a.x), double(a.y)}, fb{double(b.x), double(b.y)};
    // The parts come mostly in order along ab: `covered` is how far from 0
    // they cover ab without a gap, so far. Once that is all of ab, the union
    // is [0, 1] whatever the rest (a long shortcut at a coarse tolerance
    // passes hundreds of blocked segments, and drawing it whole is then what
    // the union says anyway).
    double covered = 0;
    bool sorted = true;
    for (auto it = std::lower_bound(blocked.begin(), blocked.end(), from,
                                    [](const NearSegment&n, uint32_t k) { return n.k < k; });
         it != blocked.end() && it->k < to; ++it) {
        const GridPoint p = pts[it->k], q = pts[it->k + 1];
        if (const auto iv = capsule_interval(fa, fb, at(p, q, it->t0), at(p, q, it->t1), r)) {
            const std::pair<double, double> part{std::max(0.0, iv->first - widen), std::min(1.0, iv->second + widen)};
            sorted = sorted && (parts.empty() || !(part < parts.back()));
            parts.push_back(part);
            if (part.first <= covered) {
                covered = std::max(covered, part.second);
                if (covered >= 1) {
                    parts.assign(1, {0.0, 1.0});
                    return parts;
                }
            }
        }
    }
    if (!sorted) {
        std::sort(parts.begin(), parts.end());
    }
    size_t n = 0;
    for (const auto& iv : parts) {
        if (n > 0 && iv.first <= parts[n - 1].second) {
            parts[n - 1].second = std::max(parts[n - 1].second, iv.second);
        } else {
            parts[n++] = iv;
        }
    }
    parts.resize(n);
    return parts;
}

} // namespace tigerlod::simplify
