#include "stages/simplify/candidates.hpp"

#include <algorithm>
#include <cmath>

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
Arc arc_around(double ux, double uy, double sin_h, double cos_h) noexcept
{
    return {ux * cos_h + uy * sin_h, uy * cos_h - ux * sin_h, ux * cos_h - uy * sin_h, uy * cos_h + ux * sin_h};
}

} // namespace

void Candidates::finish(uint32_t n)
{
    m_runs.shrink_to_fit();
    m_base.assign(m_runs.size() + 1, 0);
    for (size_t r = 0; r < m_runs.size(); ++r) {
        m_base[r + 1] = m_base[r] + (m_runs[r].hi - m_runs[r].lo + 1);
    }
    m_run_first.clear();
    if (m_runs.empty()) {
        return;
    }
    m_run_first.assign(size_t{n} + 1, 0);
    for (const Run& r : m_runs) {
        ++m_run_first[r.from + 1];
    }
    for (uint32_t v = 0; v < n; ++v) {
        m_run_first[v + 1] += m_run_first[v];
    }
}

Shortcut Candidates::at(uint32_t id) const noexcept
{
    const auto r = static_cast<size_t>(std::upper_bound(m_base.begin(), m_base.end(), id) - m_base.begin()) - 1;
    return {m_runs[r].from, m_runs[r].lo + (id - m_base[r])};
}

std::vector<Shortcut> Candidates::list() const
{
    std::vector<Shortcut> out;
    out.reserve(size());
    for (const Run& r : m_runs) {
        for (uint32_t k = r.lo; k <= r.hi; ++k) {
            out.push_back({r.from, k});
        }
    }
    return out;
}

namespace {

/// The scan of proximate_shortcuts with squared lengths in `Wide`: int64_t
/// when every coordinate difference of the chain is under 2^31 (so a
/// squared length fits; 21,000 km on a 1 cm grid), int128 otherwise. The
/// conversions to double round the same way, so both give the same answer.
template <class Wide>
void scan(std::span<const GridPoint> pts, const Tolerance& tol, uint32_t max_reach, int128 reps2, Candidates& out)
{
    const auto n = static_cast<uint32_t>(pts.size());
    const auto wide_reps2 = static_cast<Wide>(reps2); // fits: checked by the caller
    const double r_eps = std::sqrt(double(reps2));
    // One wedge, without trigonometry: every constraint's half-angle widened
    // by `slack` (outside it: surely not proximate; empty: stop). An end at
    // least 2 x slack inside it is inside every exact constraint (its
    // neighbourhood of that angle lies in the wedge, so in every widened
    // arc): with no vertex beyond it, proximate without the exact test.
    constexpr double slack = 1e-9; // radians; far above the double error of the rotations
    const double cos_s = std::cos(slack), sin_s = std::sin(slack);
    const double deep2 = std::pow(std::sin(2 * slack), 2);
    for (uint32_t j = 0; j + 2 < n; ++j) {
        const GridPoint a = pts[j];
        Wedge wide;
        bool complete = true; // every constraint is in the wedge (none left out near pi / 2)
        double far2 = 0;      // max squared distance of an intermediate vertex from a
        const auto last = static_cast<uint32_t>(max_reach ? std::min<uint64_t>(n - 1, uint64_t{j} + max_reach) : n - 1);
        // Each vertex's squared distance from a and its root are taken one
        // step ahead, so the root's latency overlaps the step before.
        auto dist = [&](GridPoint q, Wide& r2, double& c) {
            const int64_t qx = int64_t{q.x} - a.x, qy = int64_t{q.y} - a.y;
            r2 = Wide{qx} * qx + Wide{qy} * qy;
            c = std::sqrt(std::fabs(double(r2 - wide_reps2))); // used only when r2 > reps2
        };
        Wide r2_next;
        double c_next;
        dist(pts[j + 1], r2_next, c_next);
        for (uint32_t k = j + 2; k <= last; ++k) {
            // Vertex k - 1 becomes an intermediate vertex: narrow the wedge.
            const GridPoint q = pts[k - 1];
            const int64_t qx = int64_t{q.x} - a.x, qy = int64_t{q.y} - a.y;
            const Wide r2 = r2_next;
            const double c = c_next;
            dist(pts[k], r2_next, c_next);
            far2 = std::max(far2, double(r2));
            if (r2 > wide_reps2) {
                // The arc of directions within h of q, sin h = r_eps / |q|,
                // as vectors scaled by |q|: c = |q| cos h, exact under the
                // root (integers), so no division and one square root.
                // h + slack; a half-angle this close to pi / 2 is left out
                // of the wedge (wider is safe; |q| <= c + r_eps).
                const double sin_w = r_eps * cos_s + c * sin_s, cos_w = c * cos_s - r_eps * sin_s;
                if (cos_w <= 1e-6 * (c + r_eps)) {
                    complete = false;
                } else if (!wide.narrow(arc_around(double(qx), double(qy), sin_w, cos_w))) {
                    break; // no segment from a can pass near every vertex seen
                }
            }
            const GridPoint b = pts[k];
            if (b == a) {
                continue;
            }
            const double bx = double(b.x) - a.x, by = double(b.y) - a.y;
            if (wide.state == Wedge::set && !wide.arc.holds(bx, by)) {
                continue; // the ray through b misses a vertex: not proximate
            }
            const double len2 = bx * bx + by * by;
            // Clearly inside every constraint and no vertex beyond b: every
            // intermediate vertex projects onto the segment within eps (L2).
            const bool sure = tol.metric == Metric::l2 && complete && far2 * (1 + 1e-12) < len2 &&
                              (wide.state == Wedge::open || wide.arc.deep_inside(bx, by, len2, deep2));
            if (sure || proximate_exact(pts, j, k, tol)) {
                out.add(j, k);
            }
        }
    }
}

} // namespace

Candidates proximate_shortcuts(std::span<const GridPoint> pts, const Tolerance& tol, uint32_t max_reach)
{
    Candidates out;
    const auto n = static_cast<uint32_t>(pts.size());
    // The L2 disc that holds the metric's ball: a vertex must be within this
    // radius of the ray from v_j, so the wedge is a necessary condition.
    // Its square is an integer: threshold (L2), threshold^2 (L1), 2 threshold^2 (Linf).
    const int128 reps2 = std::max<int128>(0, tol.metric == Metric::l2   ? tol.threshold
                                             : tol.metric == Metric::l1 ? tol.threshold * tol.threshold
                                                                        : 2 * tol.threshold * tol.threshold);
    GridBox box;
    for (const GridPoint p : pts) {
        box.extend(p);
    }
    constexpr int64_t limit = int64_t{1} << 31;
    if (!pts.empty() && box.max_x - box.min_x < limit && box.max_y - box.min_y < limit && reps2 < int128{limit}) {
        scan<int64_t>(pts, tol, max_reach, reps2, out);
    } else {
        scan<int128>(pts, tol, max_reach, reps2, out);
    }
    out.finish(n);
    return out;
}

std::vector<uint32_t> cull_by_points(std::span<const GridPoint> pts, const Candidates& cand,
                                     std::span<const GridPoint> points)
{
    std::vector<uint32_t> bad;
    if (points.empty() || cand.empty()) {
        return bad;
    }
    const auto runs = cand.runs();
    size_t begin = 0;
    while (begin < runs.size()) {
        const uint32_t j = runs[begin].from;
        size_t end = begin;
        while (end < runs.size() && runs[end].from == j) {
            ++end;
        }
        const uint32_t reach = runs[end - 1].hi;
        // Box of the subchain j..reach: a point outside it is outside every region.
        GridBox box;
        for (uint32_t i = j; i <= reach; ++i) {
            box.extend(pts[i]);
        }
        const size_t first_bad = bad.size();
        for (const GridPoint p : points) {
            if (p.x < box.min_x || p.x > box.max_x || p.y < box.min_y || p.y > box.max_y) {
                continue;
            }
            // Even-odd state of p against the subchain j..k, extended one edge
            // at a time; closing it with edge k -> j gives the region's test.
            PointInPolygon acc(p);
            size_t r = begin;
            for (uint32_t k = j + 1; k <= reach && r < end; ++k) {
                acc.add_segment(pts[k - 1], pts[k]);
                if (k < runs[r].lo) {
                    continue;
                }
                PointInPolygon closed = acc;
                closed.add_segment(pts[k], pts[j]);
                if (closed.location() != PointLocation::outside) {
                    bad.push_back(cand.run_id(r) + (k - runs[r].lo));
                }
                if (k == runs[r].hi) {
                    ++r;
                }
            }
        }
        // Several points can cull the same shortcut.
        std::sort(bad.begin() + static_cast<std::ptrdiff_t>(first_bad), bad.end());
        bad.erase(std::unique(bad.begin() + static_cast<std::ptrdiff_t>(first_bad), bad.end()), bad.end());
        begin = end;
    }
    return bad;
}

} // namespace tigerlod::simplify
