#pragma once
/// @file cell_cover.hpp
/// The cells of a square grid that a thick segment touches.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>

namespace tigerlod::simplify {

/// One 64-bit key for cell (x, y), ordered by x then y; for cell coordinates
/// within +-2^31.
inline uint64_t cell_key(int64_t x, int64_t y) noexcept
{
    return (static_cast<uint64_t>(x + (int64_t{1} << 31)) << 32) | static_cast<uint32_t>(y + (int64_t{1} << 31));
}

/// Calls f(x, y) for every cell of a grid (side `cell`, origin ox, oy) that
/// the r-neighbourhood of segment (ax, ay)-(bx, by) touches, row by row: the
/// part of the segment within the row's band widened by r, widened by r.
/// Conservative, and proportional to the segment's length in cells, not to
/// its bounding box (a long diagonal border at a small cell size covers
/// millions of cells of its box but thousands of its own).
template <class F>
void cover_cells(double ax, double ay, double bx, double by, double r, double cell, double ox, double oy, F&& f)
{
    ax -= ox;
    bx -= ox;
    ay -= oy;
    by -= oy;
    const auto y0 = static_cast<int64_t>(std::floor((std::min(ay, by) - r) / cell));
    const auto y1 = static_cast<int64_t>(std::floor((std::max(ay, by) + r) / cell));
    for (int64_t y = y0; y <= y1; ++y) {
        const double lo = double(y) * cell - r, hi = double(y + 1) * cell + r;
        double t0 = 0, t1 = 1;
        const double dy = by - ay;
        if (dy != 0) {
            double ta = (lo - ay) / dy, tb = (hi - ay) / dy;
            if (ta > tb) {
                std::swap(ta, tb);
            }
            t0 = std::max(t0, ta);
            t1 = std::min(t1, tb);
        }
        if (t0 > t1) {
            t0 = t1 = std::clamp(t0, 0.0, 1.0); // rounding at a band's edge: keep one point
        }
        const double xa = ax + t0 * (bx - ax), xb = ax + t1 * (bx - ax);
        const auto x0 = static_cast<int64_t>(std::floor((std::min(xa, xb) - r) / cell));
        const auto x1 = static_cast<int64_t>(std::floor((std::max(xa, xb) + r) / cell));
        for (int64_t x = x0; x <= x1; ++x) {
            f(x, y);
        }
    }
}

} // namespace tigerlod::simplify
