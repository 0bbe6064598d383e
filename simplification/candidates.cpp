#include "simplification/candidates.hpp"

#include "simplification/hull_scan.hpp"
#include "simplification/wedge.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

#if defined(__x86_64__)
#include <immintrin.h>
#endif

namespace tigerlod::simplify {

using namespace detail;

namespace {

/// The exact test of the ends of one start a that the wedge leaves unsure,
/// made cheap where a chain meanders far out and back (coarse tolerances:
/// a coastline at 2000 m left most ends of a start unsure, each an O(w)
/// test, O(n w^2) for the chain). Two facts, both exact:
/// - an intermediate vertex farther from a than |ab| + r (r the L2 radius
///   of the metric's ball) is farther than r from every point of ab: b is
///   not proximate, whatever the rest;
/// - for an end deep inside a complete wedge, the ray from a meets every
///   intermediate vertex's ball no farther than |q| + r_ball (r_ball = 0
///   in L2, where the ray passes within eps of q and a vertex projecting
///   past b is farther from a than b), so only the vertices with |q| >=
///   |ab| - r_ball can miss the segment.
/// So the vertices within 2 r (and a margin) of the farthest one so far are
/// kept in a list in order of distance, built on the first unsure end and
/// extended as the ends go on: a deep end tests the list's vertices beyond
/// its bound, and stops at the first nearer one. And a third fact: the
/// vertices an end found proximate (its anchor) tested lie within their
/// largest distance d of it, so within d + |b - anchor| of a later end b;
/// while that stays inside the disc in the ball, b tests only the vertices
/// the anchor did not (added since, or nearer than its bound). Ends near the
/// wedge's edges take the whole test. The answers are those of
/// proximate_exact; only their cost changes.
class UnsureEnds {
  public:
    /// r_eps: the L2 radius of the metric's ball; r_in: of the disc inside it.
    UnsureEnds(const Tolerance& tol, double r_eps, double r_in)
        : m_tol(tol), m_r_eps(r_eps), m_r_in(r_in), m_l2(tol.metric == Metric::l2)
    {
    }

    /// Start over for start j.
    void reset(uint32_t j) noexcept
    {
        m_j = j;
        m_to = j + 1;
        m_far2 = 0;
        m_keep2_stale = true;
        m_far.clear();
        m_recent.clear();
        m_begin = 0;
        m_anchored = false;
    }

    /// Whether shortcut (j, k) is proximate; `deep`: end k is deep inside a
    /// complete wedge (every constraint in it). b != a.
    bool proximate(std::span<const GridPoint> pts, uint32_t k, bool deep)
    {
        const GridPoint a = pts[m_j], b = pts[k];
        extend(pts, k);
        const double bx = double(b.x) - a.x, by = double(b.y) - a.y;
        const double len = std::sqrt(bx * bx + by * by);
        if (std::sqrt(m_far2) > (len + m_r_eps) * (1 + 1e-9) + 1) {
            return false; // a vertex farther than eps from all of ab
        }
        if (!deep) {
            return proximate_exact(pts, m_j, k, m_tol);
        }
        // |q| below lim: the ray meets q's ball before b (shrunk for rounding).
        const double lim = len / (1 + 1e-12) - (m_l2 ? 0.0 : m_r_eps);
        const double safe2 = lim > 0 ? lim * lim * (1 - 1e-9) : -1;
        // Near the anchor (an end found proximate before), the vertices it
        // covered lie within m_anchor_d of it, so within m_anchor_d + the
        // step of b: inside the disc in the ball, within eps, untested.
        auto dist = [](GridPoint p, GridPoint q) {
            const double dx = double(p.x) - q.x, dy = double(p.y) - q.y;
            return std::sqrt(dx * dx + dy * dy); // below 2^33 each: no overflow, and hypot's care is slow here
        };
        const double step = dist(b, m_anchor);
        double max_d = 0;
        auto test = [&](uint32_t i) {
            if (!within(pts[i], a, b, m_tol)) {
                return false;
            }
            max_d = std::max(max_d, dist(pts[i], b));
            return true;
        };
        if (m_anchored && (m_anchor_d + step) * (1 + 1e-9) <= m_r_in * (1 - 1e-9) - 1) {
            // The vertices added since the anchor, beyond b's bound.
            size_t tested = 0;
            for (size_t e = m_anchor_pos; e < m_recent.size(); ++e) {
                if (m_recent[e].second >= safe2) {
                    ++tested;
                    if (!test(m_recent[e].first)) {
                        return false;
                    }
                }
            }
            // Those before it that its bound left out and b's takes in.
            if (safe2 < m_anchor_safe2) {
                const auto lo = std::lower_bound(m_far.begin() + static_cast<std::ptrdiff_t>(m_begin), m_far.end(),
                                                 std::pair{safe2, uint32_t{0}});
                for (auto it = lo; it != m_far.end() && it->first < m_anchor_safe2; ++it) {
                    if (it->second < m_anchor_k && !test(it->second)) {
                        return false;
                    }
                }
            }
            if (tested >= 8) {
                anchor(b, k, safe2, std::max(max_d, m_anchor_d + step));
            }
            return true;
        }
        for (size_t e = m_far.size(); e > m_begin; --e) { // farthest first
            const auto [r2, i] = m_far[e - 1];
            if (r2 < safe2) {
                break;
            }
            if (!test(i)) {
                return false;
            }
        }
        anchor(b, k, safe2, max_d);
        return true;
    }

  private:
    /// End k at b, found proximate, covers the vertices before it at least
    /// sqrt(safe2) from a, all within d of b.
    void anchor(GridPoint b, uint32_t k, double safe2, double d) noexcept
    {
        m_anchored = true;
        m_anchor = b;
        m_anchor_k = k;
        m_anchor_pos = m_recent.size();
        m_anchor_safe2 = safe2;
        m_anchor_d = d * (1 + 1e-9) + 1e-6;
    }

    /// The vertices before k into the lists (those near the farthest so far).
    void extend(std::span<const GridPoint> pts, uint32_t k)
    {
        const GridPoint a = pts[m_j];
        for (; m_to < k; ++m_to) {
            const double qx = double(pts[m_to].x) - a.x, qy = double(pts[m_to].y) - a.y;
            const double r2 = qx * qx + qy * qy;
            // keep2() follows m_far2, so it is worked out again only after
            // m_far2 grew; a new farthest vertex is kept without it (keep2
            // is below m_far2).
            bool keep = true;
            if (r2 >= m_far2) {
                m_far2 = r2;
                m_keep2_stale = true;
            } else {
                if (m_keep2_stale) {
                    m_keep2 = keep2();
                    m_keep2_stale = false;
                }
                keep = r2 >= m_keep2;
            }
            if (keep) {
                // Mostly the farthest yet (a chain going out): at the end.
                const std::pair<double, uint32_t> e{r2, m_to};
                if (m_far.size() == m_begin || !(e < m_far.back())) {
                    m_far.push_back(e); // where upper_bound would put it, without the search
                } else {
                    m_far.insert(std::upper_bound(m_far.begin() + static_cast<std::ptrdiff_t>(m_begin), m_far.end(), e),
                                 e);
                }
                m_recent.emplace_back(m_to, r2);
            }
        }
        const double keep = keep2();
        while (m_begin < m_far.size() && m_far[m_begin].first < keep) {
            ++m_begin;
        }
        if (m_begin > 64 && 2 * m_begin > m_far.size()) {
            m_far.erase(m_far.begin(), m_far.begin() + static_cast<std::ptrdiff_t>(m_begin));
            m_begin = 0;
        }
    }
    /// The squared distance from a below which a vertex is never tested:
    /// 2 r (and a margin) inside the farthest, since an end that is not
    /// rejected lies at most r (and rounding) inside it, and tests the
    /// vertices at most r_ball inside itself.
    double keep2() const noexcept
    {
        const double lim = std::sqrt(m_far2) * (1 - 1e-8) - 2 * m_r_eps - 4;
        return lim > 0 ? lim * lim : -1;
    }

    const Tolerance& m_tol;
    double m_r_eps, m_r_in;
    bool m_l2;
    uint32_t m_j = 0, m_to = 1;
    double m_far2 = 0;
    double m_keep2 = -1; ///< keep2() when m_keep2_stale is false
    bool m_keep2_stale = true;
    /// (squared distance from a, vertex) of the vertices near the farthest,
    /// nearest first, from m_begin on (those before it fell out of the band).
    std::vector<std::pair<double, uint32_t>> m_far;
    size_t m_begin = 0;
    /// The same vertices in the order they came (vertex, squared distance).
    std::vector<std::pair<uint32_t, double>> m_recent;
    /// The anchor: an end found proximate; the vertices before it (the first
    /// m_anchor_pos of m_recent) at least sqrt(m_anchor_safe2) from a lie
    /// within m_anchor_d of it (rounding included).
    bool m_anchored = false;
    GridPoint m_anchor;
    uint32_t m_anchor_k = 0;
    size_t m_anchor_pos = 0;
    double m_anchor_safe2 = 0, m_anchor_d = 0;
};

} // namespace

uint64_t Candidates::count() const noexcept
{
    uint64_t total = 0;
    for (const Run& r : m_runs) {
        total += r.hi - r.lo + 1;
    }
    return total;
}

void Candidates::finish(uint32_t n)
{
    m_runs.shrink_to_fit();
    m_base.assign(m_runs.size() + 1, 0);
    uint64_t total = 0;
    for (size_t r = 0; r < m_runs.size(); ++r) {
        total += m_runs[r].hi - m_runs[r].lo + 1;
        if (total > max_ids) {
            throw std::length_error("a chain of " + std::to_string(n) + " vertices has " + std::to_string(count()) +
                                    " proximate shortcuts, more than a 32-bit id can number");
        }
        m_base[r + 1] = static_cast<uint32_t>(total);
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

void Candidates::append(const Candidates& later)
{
    for (const Run& r : later.m_runs) {
        add_run(r.from, r.lo, r.hi);
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

/// L1 and Linf: narrows `wide` to the directions from the origin that meet
/// the metric's ball of radius t around q (its corners' cone, widened by
/// the slack). No constraint when the origin is in the ball (every segment
/// from it passes within t of q); a cone this close to a half-plane is left
/// out (wider is safe) and clears `complete`. False once `wide` is empty.
bool metric_cone(int64_t qx, int64_t qy, int64_t t, bool l1, double cos_s, double sin_s, Wedge& wide,
                 bool& complete) noexcept
{
    const int64_t ax = qx < 0 ? -qx : qx, ay = qy < 0 ? -qy : qy;
    if (l1 ? ax + ay <= t : std::max(ax, ay) <= t) {
        return true;
    }
    using V = std::array<int64_t, 2>;
    const std::array<V, 4> corners =
        l1 ? std::array<V, 4>{{{qx + t, qy}, {qx, qy + t}, {qx - t, qy}, {qx, qy - t}}}
           : std::array<V, 4>{{{qx + t, qy + t}, {qx - t, qy + t}, {qx - t, qy - t}, {qx + t, qy - t}}};
    // The corners lie in an open half-plane through the origin (it is
    // outside the ball), so "counter-clockwise of" orders them: exactly, in
    // integers (|coordinates| < 2^33).
    auto ccw = [](const V& u, const V& v) { return int128{u[0]} * v[1] - int128{u[1]} * v[0] > 0; };
    V lo = corners[0], hi = corners[0];
    for (size_t i = 1; i < corners.size(); ++i) {
        if (ccw(corners[i], lo)) {
            lo = corners[i];
        }
        if (ccw(hi, corners[i])) {
            hi = corners[i];
        }
    }
    const double lx = double(lo[0]), ly = double(lo[1]), hx = double(hi[0]), hy = double(hi[1]);
    const Arc arc{lx * cos_s + ly * sin_s, ly * cos_s - lx * sin_s, hx * cos_s - hy * sin_s, hy * cos_s + hx * sin_s};
    const double cross = arc.ax * arc.by - arc.ay * arc.bx, dot = arc.ax * arc.bx + arc.ay * arc.by;
    if (cross <= 0 || (dot < 0 && cross <= 1e-6 * std::hypot(arc.ax, arc.ay) * std::hypot(arc.bx, arc.by))) {
        complete = false;
        return true;
    }
    return wide.narrow(arc);
}

/// The scan of proximate_shortcuts with squared lengths in `Wide`: int64_t
/// when every coordinate difference of the chain is under 2^31 (so a
/// squared length fits; 21,000 km on a 1 cm grid), int128 otherwise. The
/// conversions to double round the same way, so both give the same answer.
///
/// In L1 and Linf each vertex's arc is the exact cone of directions from a
/// that meet the metric's ball around it (a diamond or a square: the
/// directions of its four corners span it), widened by the slack; an end
/// deep inside the wedge is sure when it lies beyond every point of every
/// intermediate vertex's ball (|q| + the ball's L2 radius), since the ray
/// enters each ball before it. As that is far for an end a segment or two
/// past the last vertex, a second wedge on the L2 disc inside the ball
/// (its squared radius `rin2`, rounded down) makes an end sure as the one
/// wedge does in L2: deep inside it and beyond every intermediate vertex,
/// each vertex is within that disc of the segment, so within eps in the
/// metric. The other ends in the wedge take the exact test.
template <class Wide>
void scan(std::span<const GridPoint> pts, const Tolerance& tol, uint32_t max_reach, int128 reps2, uint32_t starts_lo,
          uint32_t starts_hi, Candidates& out)
{
    const auto n = static_cast<uint32_t>(pts.size());
    const auto wide_reps2 = static_cast<Wide>(reps2); // fits: checked by the caller
    const bool l2 = tol.metric == Metric::l2, l1 = tol.metric == Metric::l1;
    const int128 rin2 = l2 ? reps2 : reps2 / 2; // t^2 / 2 (L1) or t^2 (Linf), rounded down
    // The disc whose arcs the scan takes: the metric's ball (L2), the inner disc (L1, Linf).
    const auto disc2 = static_cast<Wide>(rin2);
    const double r_in = std::sqrt(double(rin2));
    const auto t = static_cast<int64_t>(tol.threshold); // L1, Linf: floor(eps), the ball's radius
    const WedgeConstants wc(reps2);
    const double r_eps = wc.r_eps, cos_s = wc.cos_s, sin_s = wc.sin_s, deep2 = wc.deep2;
    UnsureEnds unsure(tol, r_eps, r_in);
    for (uint32_t j = starts_lo; j + 2 < n && j < starts_hi; ++j) {
        const GridPoint a = pts[j];
        unsure.reset(j);
        Wedge wide, inner;
        bool complete = true;  // every constraint is in the wedge (none left out near pi / 2)
        bool inner_sure = !l2; // the inner wedge can still make an end sure (L1, Linf)
        double far2 = 0;       // max squared distance of an intermediate vertex from a
        const auto last = static_cast<uint32_t>(max_reach ? std::min<uint64_t>(n - 1, uint64_t{j} + max_reach) : n - 1);
        // Each vertex's squared distance from a and its root are taken one
        // step ahead, so the root's latency overlaps the step before.
        auto dist = [&](GridPoint q, Wide& r2, double& c) {
            const int64_t qx = int64_t{q.x} - a.x, qy = int64_t{q.y} - a.y;
            r2 = Wide{qx} * qx + Wide{qy} * qy;
            c = std::sqrt(std::fabs(double(r2 - disc2))); // used only when r2 > disc2
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
            if (!l2) {
                if (!metric_cone(qx, qy, t, l1, cos_s, sin_s, wide, complete)) {
                    break; // no segment from a can pass near every vertex seen
                }
                if (inner_sure && r2 > disc2) {
                    // The arc on the inner disc, with h - slack: narrower is
                    // safe here. One under the slack, or one this close to a
                    // half-plane, makes nothing sure from here on.
                    const double sin_i = r_in * cos_s - c * sin_s, cos_i = c * cos_s + r_in * sin_s;
                    inner_sure = sin_i > 0 && cos_i > 1e-6 * (c + r_in) &&
                                 inner.narrow(arc_around(double(qx), double(qy), sin_i, cos_i));
                }
            } else if (r2 > wide_reps2) {
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
            // (L1, Linf: beyond every intermediate vertex's ball, whose L2
            // radius is at most r_eps.)
            const double beyond2 = l2 ? far2 : (std::sqrt(far2) + r_eps) * (std::sqrt(far2) + r_eps);
            const bool deep = complete && (wide.state == Wedge::open || wide.arc.deep_inside(bx, by, len2, deep2));
            const bool sure = (deep && beyond2 * (1 + 1e-12) < len2) ||
                              (inner_sure && far2 * (1 + 1e-12) < len2 &&
                               (inner.state == Wedge::open || inner.arc.deep_inside(bx, by, len2, deep2)));
            if (sure || unsure.proximate(pts, k, deep)) {
                out.add(j, k);
            }
        }
    }
}

#if defined(__x86_64__)
#define TIGERLOD_SCAN_LANES 1

/// Steps of the scan worked out ahead, per block (see scan_lanes).
constexpr int block_steps = 8;

bool has_avx2() noexcept
{
    static const bool yes = __builtin_cpu_supports("avx2");
    return yes;
}

bool has_avx512() noexcept
{
    static const bool yes = __builtin_cpu_supports("avx512f");
    return yes;
}

// The lanes kernel twice (scan_lanes.ipp): four starts at once for AVX2 and
// eight for AVX-512, each built for its instruction set alone and run only
// where the processor has it (GCC's target pragma; Clang's attribute pragma
// for the sanitizer build).
#if defined(__clang__)
#pragma clang attribute push(__attribute__((target("avx2"))), apply_to = function)
#else
#pragma GCC push_options
#pragma GCC target("avx2")
#endif
namespace avx2 {

using V = double __attribute__((vector_size(32)));
using M = int64_t __attribute__((vector_size(32)));
constexpr int lanes = 4;
inline int bits(M m) noexcept
{
    return _mm256_movemask_pd(reinterpret_cast<__m256d>(m));
}
inline V root(V v) noexcept
{
    return reinterpret_cast<V>(_mm256_sqrt_pd(reinterpret_cast<__m256d>(v)));
}
inline V iota() noexcept
{
    return V{0, 1, 2, 3};
}

#include "simplification/scan_lanes.ipp"

} // namespace avx2
#if defined(__clang__)
#pragma clang attribute pop
#else
#pragma GCC pop_options
#endif

#if defined(__clang__)
#pragma clang attribute push(__attribute__((target("avx512f"))), apply_to = function)
#else
#pragma GCC push_options
#pragma GCC target("avx512f")
#endif
namespace avx512 {

using V = double __attribute__((vector_size(64)));
using M = int64_t __attribute__((vector_size(64)));
constexpr int lanes = 8;
inline int bits(M m) noexcept
{
    return _mm512_test_epi64_mask(reinterpret_cast<__m512i>(m), reinterpret_cast<__m512i>(m));
}
inline V root(V v) noexcept
{
    // (_mm512_sqrt_pd's _mm512_undefined_pd trips GCC 12's -Wmaybe-uninitialized.)
    return reinterpret_cast<V>(_mm512_maskz_sqrt_pd(__mmask8{0xFF}, reinterpret_cast<__m512d>(v)));
}
inline V iota() noexcept
{
    return V{0, 1, 2, 3, 4, 5, 6, 7};
}

#include "simplification/scan_lanes.ipp"

} // namespace avx512
#if defined(__clang__)
#pragma clang attribute pop
#else
#pragma GCC pop_options
#endif
#endif

} // namespace

const char* fastest_scan_kernel() noexcept
{
#if TIGERLOD_SCAN_LANES
    if (has_avx512()) {
        return "avx512";
    }
    if (has_avx2()) {
        return "avx2";
    }
#endif
    return "scalar";
}

Candidates proximate_shortcuts(std::span<const GridPoint> pts, const Tolerance& tol, uint32_t max_reach)
{
    return proximate_shortcuts(pts, tol, max_reach, ScanKernel::fastest);
}

Candidates proximate_shortcuts(std::span<const GridPoint> pts, const Tolerance& tol, uint32_t max_reach,
                               ScanKernel kernel)
{
    Candidates out = proximate_shortcuts_from(pts, tol, max_reach, 0, static_cast<uint32_t>(pts.size()), kernel);
    out.finish(static_cast<uint32_t>(pts.size()));
    return out;
}

Candidates proximate_shortcuts_from(std::span<const GridPoint> pts, const Tolerance& tol, uint32_t max_reach,
                                    uint32_t first, uint32_t last, ScanKernel kernel, uint32_t end_sample)
{
    Candidates out;
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
    // The hull scan: squared lengths in int64. The lanes: exact in doubles.
    const bool l2 = tol.metric == Metric::l2 && !pts.empty();
    const bool in_int64 =
        l2 && box.max_x - box.min_x < limit && box.max_y - box.min_y < limit && reps2 < int128{1} << 62;
    constexpr int64_t exact_limit = int64_t{1} << 26;
    const bool exact_in_doubles =
        l2 && box.max_x - box.min_x < exact_limit && box.max_y - box.min_y < exact_limit && reps2 < int128{1} << 52;
    if (in_int64 && (kernel == ScanKernel::hulls || (kernel == ScanKernel::fastest && hull_scan_pays(pts, reps2)))) {
        const std::vector<uint8_t> ends = end_sample > 0 && kernel == ScanKernel::fastest
                                              ? greedy_fit_vertices(pts, std::sqrt(double(reps2)) / double(end_sample))
                                              : std::vector<uint8_t>{};
        scan_hulls(pts, tol, max_reach, reps2, first, last, out, ends);
        return out;
    }
    const bool scalar_int64 =
        !pts.empty() && box.max_x - box.min_x < limit && box.max_y - box.min_y < limit && reps2 < int128{limit};
    auto scalar = [&](uint32_t lo, uint32_t hi) {
        if (scalar_int64) {
            scan<int64_t>(pts, tol, max_reach, reps2, lo, hi, out);
        } else {
            scan<int128>(pts, tol, max_reach, reps2, lo, hi, out);
        }
    };
#if TIGERLOD_SCAN_LANES
    const bool any_lanes = kernel == ScanKernel::fastest || kernel == ScanKernel::lanes;
    using Lanes = void (*)(std::span<const GridPoint>, const Tolerance&, uint32_t, int128, uint32_t, uint32_t,
                           Candidates&, std::vector<uint32_t>*);
    const Lanes lanes_kernel = any_lanes && has_avx512()                                   ? avx512::scan_lanes
                               : (any_lanes || kernel == ScanKernel::lanes4) && has_avx2() ? avx2::scan_lanes
                                                                                           : nullptr;
    if (lanes_kernel && exact_in_doubles) {
        lanes_kernel(pts, tol, max_reach, reps2, first, last, out, nullptr);
        return out;
    }
    if (lanes_kernel && l2 && reps2 < int128{1} << 52) {
        // A chain wider than the lanes' 2^26 (a nation's or a state's
        // outline): in windows where it is narrower, each scanning the
        // first half of its starts; a start whose scan reaches the window's
        // end with the wedge still open may go beyond, and takes the scalar
        // scan. The runs go out in start order, the same as the scalar
        // scan's for the whole chain.
        const auto n = static_cast<uint32_t>(pts.size());
        std::vector<uint32_t> ran_out;
        for (uint32_t s0 = first; s0 < last && s0 + 2 < n;) {
            GridBox window;
            window.extend(pts[s0]);
            uint32_t e = s0 + 1; // the window: pts[s0, e)
            for (; e < n; ++e) {
                GridBox wider = window;
                wider.extend(pts[e]);
                if (wider.max_x - wider.min_x >= exact_limit || wider.max_y - wider.min_y >= exact_limit) {
                    break;
                }
                window = wider;
            }
            if (e - s0 < 3) {
                scalar(s0, s0 + 1); // a segment 2^26 long next: nothing for the lanes
                ++s0;
                continue;
            }
            const uint32_t s1 = std::min(last, e == n ? n : s0 + (e - s0) / 2);
            Candidates part;
            ran_out.clear();
            lanes_kernel(pts.subspan(s0, e - s0), tol, max_reach, reps2, 0, s1 - s0, part, e < n ? &ran_out : nullptr);
            const auto runs = part.runs();
            size_t r = 0, q = 0;
            for (uint32_t j = s0; j < s1; ++j) {
                const bool redo = q < ran_out.size() && ran_out[q] + s0 == j;
                q += redo ? 1 : 0;
                for (; r < runs.size() && runs[r].from + s0 == j; ++r) {
                    if (!redo) {
                        out.add_run(j, runs[r].lo + s0, runs[r].hi + s0);
                    }
                }
                if (redo) {
                    scalar(j, j + 1);
                }
            }
            s0 = s1;
        }
        return out;
    }
#endif
    scalar(first, last);
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
            if (p.x < box.min_x || p.x > box.max_x || p.y < box.min_y || p.y > box.max_y || p == pts[j]) {
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
                if (closed.location() != PointLocation::outside && p != pts[k]) {
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
