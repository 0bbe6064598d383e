#include "stages/simplify/candidates.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace tigerlod::simplify {

namespace {

/// Brute-force check of shortcut (j, k): every vertex between within tol.
bool proximate_exact(std::span<const GridPoint> pts, uint32_t j, uint32_t k, const Tolerance& tol) noexcept
{
    for (uint32_t i = j + 1; i < k; ++i) {
        if (!within(pts[i], pts[j], pts[k], tol)) {
            return false;
        }
    }
    return true;
}

double wrap(double a) noexcept
{
    while (a > std::numbers::pi) {
        a -= 2 * std::numbers::pi;
    }
    while (a <= -std::numbers::pi) {
        a += 2 * std::numbers::pi;
    }
    return a;
}

} // namespace

std::vector<Shortcut> proximate_shortcuts(std::span<const GridPoint> pts, const Tolerance& tol, uint32_t max_reach)
{
    std::vector<Shortcut> out;
    const auto n = static_cast<uint32_t>(pts.size());
    // The L2 disc that holds the metric's ball: a vertex must be within this
    // radius of the ray from v_j, so the wedge is a necessary condition.
    const double r_eps =
        std::sqrt(std::max(0.0, double(tol.metric == Metric::l2 ? tol.threshold : tol.threshold * tol.threshold))) *
        l2_reach(tol.metric);
    constexpr double slack = 1e-9; // radians; far above the double error of atan2/asin
    for (uint32_t j = 0; j + 2 < n; ++j) {
        const GridPoint a = pts[j];
        bool constrained = false;       // any vertex farther than r_eps seen yet
        double ref = 0, lo = 0, hi = 0; // wedge [ref + lo, ref + hi]
        double far2 = 0;                // max squared distance of an intermediate vertex from a
        const auto last = static_cast<uint32_t>(max_reach ? std::min<uint64_t>(n - 1, uint64_t{j} + max_reach) : n - 1);
        for (uint32_t k = j + 2; k <= last; ++k) {
            // Vertex k - 1 becomes an intermediate vertex: narrow the wedge.
            const GridPoint q = pts[k - 1];
            const double qx = double(q.x) - a.x, qy = double(q.y) - a.y;
            const double r2 = qx * qx + qy * qy;
            far2 = std::max(far2, r2);
            if (r2 > r_eps * r_eps) {
                const double phi = std::atan2(qy, qx);
                const double half = std::asin(std::min(1.0, r_eps / std::sqrt(r2)));
                if (!constrained) {
                    constrained = true;
                    ref = phi;
                    lo = -half;
                    hi = half;
                } else {
                    const double c = wrap(phi - ref);
                    lo = std::max(lo, c - half);
                    hi = std::min(hi, c + half);
                }
                if (lo > hi + 2 * slack) {
                    break; // no segment from a can pass near every vertex seen
                }
            }
            const GridPoint b = pts[k];
            if (b == a) {
                continue;
            }
            const double bx = double(b.x) - a.x, by = double(b.y) - a.y;
            const double len2 = bx * bx + by * by;
            bool inside_clearly = true;
            if (constrained) {
                const double t = wrap(std::atan2(by, bx) - ref);
                if (t < lo - slack || t > hi + slack) {
                    continue; // the ray through b misses a vertex: not proximate
                }
                inside_clearly = t > lo + slack && t < hi - slack;
            }
            // Clearly inside the wedge and no vertex beyond b: every
            // intermediate vertex projects onto the segment within eps (L2).
            const bool sure = tol.metric == Metric::l2 && inside_clearly && far2 * (1 + 1e-12) < len2;
            if (sure || proximate_exact(pts, j, k, tol)) {
                out.push_back({j, k});
            }
        }
    }
    return out;
}

size_t cull_by_points(std::span<const GridPoint> pts, std::vector<Shortcut>& shortcuts,
                      std::span<const GridPoint> points)
{
    if (points.empty() || shortcuts.empty()) {
        return 0;
    }
    std::vector<uint8_t> bad(shortcuts.size(), 0);
    size_t begin = 0;
    while (begin < shortcuts.size()) {
        const uint32_t j = shortcuts[begin].from;
        size_t end = begin;
        while (end < shortcuts.size() && shortcuts[end].from == j) {
            ++end;
        }
        const uint32_t reach = shortcuts[end - 1].to;
        // Box of the subchain j..reach: a point outside it is outside every region.
        GridBox box;
        for (uint32_t i = j; i <= reach; ++i) {
            box.extend(pts[i]);
        }
        for (const GridPoint p : points) {
            if (p.x < box.min_x || p.x > box.max_x || p.y < box.min_y || p.y > box.max_y) {
                continue;
            }
            // Even-odd state of p against the subchain j..k, extended one edge
            // at a time; closing it with edge k -> j gives the region's test.
            PointInPolygon acc(p);
            size_t s = begin;
            for (uint32_t k = j + 1; k <= reach && s < end; ++k) {
                acc.add_segment(pts[k - 1], pts[k]);
                if (shortcuts[s].to != k) {
                    continue;
                }
                PointInPolygon closed = acc;
                closed.add_segment(pts[k], pts[j]);
                if (closed.location() != PointLocation::outside) {
                    bad[s] = 1;
                }
                ++s;
            }
        }
        begin = end;
    }
    size_t w = 0, removed = 0;
    for (size_t i = 0; i < shortcuts.size(); ++i) {
        if (bad[i]) {
            ++removed;
        } else {
            shortcuts[w++] = shortcuts[i];
        }
    }
    shortcuts.resize(w);
    return removed;
}

} // namespace tigerlod::simplify
