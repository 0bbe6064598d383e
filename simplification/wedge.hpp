#pragma once
/// @file wedge.hpp
/// The pieces the candidate scans share (candidates.cpp, hull_scan.cpp):
/// the exact test of one shortcut, and the wedge of directions from a start
/// in which a segment can still pass near every vertex seen. Private to
/// the simplification library.

#include "core/geometry.hpp"
#include "core/metric.hpp"

#include <cmath>
#include <cstdint>
#include <span>

namespace tigerlod::simplify::detail {

/// Brute-force check of shortcut (j, k): every vertex between within tol.
inline bool proximate_exact(std::span<const GridPoint> pts, uint32_t j, uint32_t k, const Tolerance& tol) noexcept
{
    for (uint32_t i = j + 1; i < k; ++i) {
        if (!within(pts[i], pts[j], pts[k], tol)) {
            return false;
        }
    }
    return true;
}

/// The directions from A counter-clockwise to B, an arc of less than pi;
/// vectors need not be unit.
struct Arc {
    double ax = 0, ay = 0, bx = 0, by = 0;
    /// v within the arc, its edges included (or excluded when `strict`).
    bool holds(double x, double y, bool strict = false) const noexcept
    {
        const double c1 = ax * y - ay * x, c2 = x * by - y * bx;
        return strict ? (c1 > 0 && c2 > 0) : (c1 >= 0 && c2 >= 0);
    }
    /// v inside the arc with an angle whose squared sine is at least `sin2`
    /// from both edges; `len2` = |v|^2.
    bool deep_inside(double x, double y, double len2, double sin2) const noexcept
    {
        const double c1 = ax * y - ay * x, c2 = x * by - y * bx;
        return c1 > 0 && c2 > 0 && c1 * c1 >= sin2 * (ax * ax + ay * ay) * len2 &&
               c2 * c2 >= sin2 * (bx * bx + by * by) * len2;
    }
    /// This arc narrowed to its intersection with `o` (both under pi); false if empty.
    bool intersect(const Arc& o) noexcept
    {
        // Each edge of the intersection: ours if o holds it, else o's if we hold that.
        auto edge = [&](double x, double y, double ox, double oy, double& rx, double& ry) {
            if (o.holds(x, y)) {
                rx = x;
                ry = y;
            } else if (holds(ox, oy)) {
                rx = ox;
                ry = oy;
            } else {
                return false;
            }
            return true;
        };
        Arc r;
        if (!edge(ax, ay, o.ax, o.ay, r.ax, r.ay) || !edge(bx, by, o.bx, o.by, r.bx, r.by)) {
            return false;
        }
        *this = r;
        return true;
    }
};

/// Directions narrowed arc by arc: open (no arc yet), an arc, or empty.
struct Wedge {
    enum State { open, set, empty } state = open;
    Arc arc;
    /// Intersects with `a`; false once empty.
    bool narrow(const Arc& a) noexcept
    {
        if (state == open) {
            arc = a;
            state = set;
        } else if (state == set && !arc.intersect(a)) {
            state = empty;
        }
        return state != empty;
    }
};

/// The arc of directions within half-angle h of direction (ux, uy), given
/// sin h and cos h times the same positive factor as |u| (h < pi / 2).
inline Arc arc_around(double ux, double uy, double sin_h, double cos_h) noexcept
{
    return {ux * cos_h + uy * sin_h, uy * cos_h - ux * sin_h, ux * cos_h - uy * sin_h, uy * cos_h + ux * sin_h};
}

/// The constants of the wedge, for both scans (scan<> and scan_lanes must
/// compute alike). One wedge, without trigonometry: every constraint's
/// half-angle widened by `slack` (outside it: surely not proximate; empty:
/// stop). An end at least 2 x slack inside it is inside every exact
/// constraint (its neighbourhood of that angle lies in the wedge, so in
/// every widened arc): with no vertex beyond it, proximate without the exact test.
struct WedgeConstants {
    static constexpr double slack = 1e-9; // radians; far above the double error of the rotations
    explicit WedgeConstants(int128 reps2) : r_eps(std::sqrt(double(reps2))) {}
    double r_eps; ///< the L2 radius of the metric's ball
    double cos_s = std::cos(slack), sin_s = std::sin(slack);
    double deep2 = std::pow(std::sin(2 * slack), 2); ///< squared sine of 2 x slack
};

} // namespace tigerlod::simplify::detail
