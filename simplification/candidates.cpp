#include "simplification/candidates.hpp"

#include "simplification/hull_scan.hpp"
#include "simplification/wedge.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

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
            m_far2 = std::max(m_far2, r2);
            if (r2 >= keep2()) {
                // Mostly the farthest yet (a chain going out): at the end.
                const std::pair<double, uint32_t> e{r2, m_to};
                m_far.insert(std::upper_bound(m_far.begin() + static_cast<std::ptrdiff_t>(m_begin), m_far.end(), e), e);
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

/// Four doubles, and the masks their comparisons give (all bits set or
/// none), as GCC vector extensions; the functions that use them are built
/// for AVX2 (without FMA) and run only where the processor has it.
using V4 = double __attribute__((vector_size(32)));
using M4 = int64_t __attribute__((vector_size(32)));
constexpr int lanes = 4;
/// Steps of the scan worked out ahead, per block (see scan_lanes).
constexpr int block_steps = 8;

bool has_avx2() noexcept
{
    static const bool yes = __builtin_cpu_supports("avx2");
    return yes;
}

#define TIGERLOD_AVX2 __attribute__((target("avx2"), always_inline)) inline

TIGERLOD_AVX2 V4 select(M4 m, V4 a, V4 b) noexcept
{
    return reinterpret_cast<V4>((m & reinterpret_cast<M4>(a)) | (~m & reinterpret_cast<M4>(b)));
}
/// Bit l set when lane l of `m` is.
TIGERLOD_AVX2 int bits(M4 m) noexcept
{
    return _mm256_movemask_pd(reinterpret_cast<__m256d>(m));
}
TIGERLOD_AVX2 V4 load4(const double* p) noexcept
{
    V4 v;
    std::memcpy(&v, p, sizeof v);
    return v;
}
/// x cross y, as Arc computes it: x.x y.y - x.y y.x. Swapping x and y gives
/// exactly its negation (the same two products, subtracted the other way).
TIGERLOD_AVX2 V4 cross(V4 xx, V4 xy, V4 yx, V4 yy) noexcept
{
    return xx * yy - xy * yx;
}

/// Per lane of the group of starts j, j + 1, ...: how many ends it tests (0
/// where no start of [j, starts_hi) is), and the most of them.
TIGERLOD_AVX2 double lane_steps(uint32_t j, uint32_t n, uint32_t starts_hi, uint32_t max_reach, V4& steps) noexcept
{
    steps = V4{};
    double longest = 0;
    for (int l = 0; l < lanes; ++l) {
        const uint32_t start = j + static_cast<uint32_t>(l);
        if (start + 2 < n && start < starts_hi) {
            const auto last = max_reach ? std::min<uint64_t>(n - 1, uint64_t{start} + max_reach) : n - 1;
            steps[l] = double(last - (start + 1));
            longest = std::max(longest, steps[l]);
        }
    }
    return longest;
}

/// scan<> for L2 on four consecutive starts at once, one per lane, every
/// lane doing the scalar scan's arithmetic (no fused multiply-adds), so
/// both find the same shortcuts (tests compare them; so does scan_bench's
/// hash, on the tract set at 1 to 64 m): the wedge's narrowing, the choice
/// of its edges and the tests of each end become selects on masks instead
/// of branches. Lane l starts at j + l and tests end j + l + 2 + t at step
/// t; a group runs until its longest lane ends (5% more lane steps than the
/// scalar scan's on the tract set: consecutive starts reach about as far).
/// Exact in doubles because every coordinate difference is under 2^26 (the
/// caller checks): squared lengths are integers below 2^53.
__attribute__((target("avx2"))) void scan_lanes(std::span<const GridPoint> pts, const Tolerance& tol,
                                                uint32_t max_reach, int128 reps2, uint32_t starts_lo,
                                                uint32_t starts_hi, Candidates& out)
{
    const auto n = static_cast<uint32_t>(pts.size());
    // The points as doubles, padded so that lanes past the end read copies of the last point.
    std::vector<double> xs(n + 2 * lanes), ys(n + 2 * lanes);
    for (uint32_t i = 0; i < n + 2 * lanes; ++i) {
        const GridPoint p = pts[std::min(i, n - 1)];
        xs[i] = p.x;
        ys[i] = p.y;
    }
    const double reps2_d = double(reps2);
    const WedgeConstants wc(reps2);
    const double r_eps = wc.r_eps, cos_s = wc.cos_s, sin_s = wc.sin_s, deep2 = wc.deep2;
    const double eps_cos = r_eps * cos_s, eps_sin = r_eps * sin_s; // scan<>'s products
    // Per lane, the runs it closed in this group, and its unsure ends' test.
    std::vector<Candidates::Run> closed[lanes];
    std::vector<UnsureEnds> unsure(lanes, UnsureEnds(tol, r_eps, r_eps)); // L2: the ball is the disc
    for (uint32_t j = starts_lo; j + 2 < n && j < starts_hi; j += lanes) {
        for (int l = 0; l < lanes; ++l) {
            unsure[l].reset(j + static_cast<uint32_t>(l));
        }
        V4 steps; // per lane, how many ends it tests (0: no start there)
        const double longest = lane_steps(j, n, starts_hi, max_reach, steps);
        const V4 ax = load4(&xs[j]), ay = load4(&ys[j]);
        V4 wax{}, way{}, wbx{}, wby{}; // the wedge's arc, from WA counter-clockwise to WB
        M4 open = ~M4{};               // no arc yet
        M4 alive = steps > 0;          // ends left to test, and the wedge not empty
        // The largest squared distance of an intermediate vertex from the
        // start; infinite once a constraint was left out of the wedge (no
        // end is then sure without the exact test, as in scan<>).
        V4 far2{};
        V4 k = V4{0, 1, 2, 3} + double(j + 2);
        // Per lane, its run: hi the last end found (-2 for none yet), lo[l] its first.
        V4 hi = V4{} - 2;
        uint32_t lo[lanes] = {};
        // Steps go in blocks: first what each step needs that does not
        // depend on the wedge (the constraint's arc, through a square root),
        // for the whole block, then the wedge's narrowing step by step. So
        // the roots' latency overlaps, where one step at a time waits on each.
        struct Step {
            V4 oax, oay, obx, oby; // the constraint's arc OA -> OB (arc_around)
            M4 narrow;             // the constraint narrows the wedge
            V4 far;                // its squared distance, or infinity where it was left out
            V4 bx, by, len2;       // end k, from the start
        };
        Step block[block_steps];
        bool more = true;
        for (double t0 = 0; more && t0 < longest; t0 += block_steps) {
            const int count = static_cast<int>(std::min<double>(block_steps, longest - t0));
            for (int i = 0; i < count; ++i) {
                Step& st = block[i];
                const auto at = static_cast<size_t>(j + 1 + static_cast<uint32_t>(t0) + static_cast<uint32_t>(i));
                const V4 qx = load4(&xs[at]) - ax, qy = load4(&ys[at]) - ay;
                const V4 r2 = qx * qx + qy * qy;
                const V4 d = r2 - reps2_d;
                const V4 c = reinterpret_cast<V4>(_mm256_sqrt_pd(reinterpret_cast<__m256d>(select(d < 0, -d, d))));
                const M4 constrained = r2 > reps2_d;
                const V4 sin_w = eps_cos + c * sin_s, cos_w = c * cos_s - eps_sin;
                const M4 too_wide = cos_w <= 1e-6 * (c + r_eps);
                st.far = select(constrained & too_wide, V4{} + HUGE_VAL, r2);
                st.narrow = constrained & ~too_wide;
                st.oax = qx * cos_w + qy * sin_w;
                st.oay = qy * cos_w - qx * sin_w;
                st.obx = qx * cos_w - qy * sin_w;
                st.oby = qy * cos_w + qx * sin_w;
                st.bx = load4(&xs[at + 1]) - ax;
                st.by = load4(&ys[at + 1]) - ay;
                st.len2 = st.bx * st.bx + st.by * st.by;
            }
            for (int i = 0; i < count; ++i, k += 1) {
                const Step& st = block[i];
                alive &= V4{} + (t0 + i) < steps;
                if (bits(alive) == 0) {
                    more = false;
                    break;
                }
                // Vertex k - 1 becomes an intermediate vertex: narrow the
                // wedge (Arc::intersect): each edge of the wedge stays if the
                // arc holds it, else the arc's if the wedge holds that, else
                // the intersection is empty.
                far2 = select(far2 < st.far, st.far, far2);
                const M4 narrow = st.narrow;
                const V4 oa_wa = cross(st.oax, st.oay, wax, way), wa_ob = cross(wax, way, st.obx, st.oby);
                const V4 oa_wb = cross(st.oax, st.oay, wbx, wby), wb_ob = cross(wbx, wby, st.obx, st.oby);
                const M4 o_holds_wa = (oa_wa >= 0) & (wa_ob >= 0);
                const M4 holds_oa = (oa_wa <= 0) & (oa_wb >= 0); // wa x oa >= 0, oa x wb >= 0
                const M4 o_holds_wb = (oa_wb >= 0) & (wb_ob >= 0);
                const M4 holds_ob = (wa_ob >= 0) & (wb_ob <= 0); // wa x ob >= 0, ob x wb >= 0
                const M4 empty = ~open & ((~o_holds_wa & ~holds_oa) | (~o_holds_wb & ~holds_ob));
                const M4 take_a = narrow & (open | ~o_holds_wa), take_b = narrow & (open | ~o_holds_wb);
                alive &= ~(narrow & empty);
                wax = select(take_a, st.oax, wax);
                way = select(take_a, st.oay, way);
                wbx = select(take_b, st.obx, wbx);
                wby = select(take_b, st.oby, wby);
                open &= ~narrow;
                // End k: in the wedge, and surely or exactly proximate. An
                // end equal to the start (len2 = 0) is never sure, and the
                // exact branch leaves it out, as scan<> does.
                const V4 c1 = cross(wax, way, st.bx, st.by), c2 = cross(st.bx, st.by, wbx, wby);
                const M4 tested = alive & (open | ((c1 >= 0) & (c2 >= 0)));
                const M4 deep = open | ((c1 > 0) & (c2 > 0) & (c1 * c1 >= deep2 * (wax * wax + way * way) * st.len2) &
                                        (c2 * c2 >= deep2 * (wbx * wbx + wby * wby) * st.len2));
                M4 found = tested & (far2 * (1 + 1e-12) < st.len2) & deep;
                if (const int left = bits(tested & ~found)) {
                    // Deep in a complete wedge (far2 is infinite once a
                    // constraint was left out of it).
                    const int deep_complete = bits(deep & (far2 < HUGE_VAL));
                    for (int l = 0; l < lanes; ++l) {
                        const uint32_t start = j + static_cast<uint32_t>(l), end = static_cast<uint32_t>(k[l]);
                        if ((left >> l & 1) != 0 && pts[end] != pts[start] &&
                            unsure[l].proximate(pts, end, (deep_complete >> l & 1) != 0)) {
                            found[l] = ~int64_t{0};
                        }
                    }
                }
                // A found end extends its lane's run, or opens one (after a gap: the old one goes out).
                if (const int opened = bits(found & (hi + 1 != k))) {
                    for (int l = 0; l < lanes; ++l) {
                        if ((opened >> l & 1) != 0) {
                            if (hi[l] >= 0) {
                                closed[l].push_back(
                                    {j + static_cast<uint32_t>(l), lo[l], static_cast<uint32_t>(hi[l])});
                            }
                            lo[l] = static_cast<uint32_t>(k[l]);
                        }
                    }
                }
                hi = select(found, k, hi);
            }
        }
        for (int l = 0; l < lanes; ++l) {
            for (const auto& r : closed[l]) {
                out.add_run(r.from, r.lo, r.hi);
            }
            closed[l].clear();
            if (hi[l] >= 0) {
                out.add_run(j + static_cast<uint32_t>(l), lo[l], static_cast<uint32_t>(hi[l]));
            }
        }
    }
}
#endif

} // namespace

const char* fastest_scan_kernel() noexcept
{
#if TIGERLOD_SCAN_LANES
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
                                    uint32_t first, uint32_t last, ScanKernel kernel)
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
        scan_hulls(pts, tol, max_reach, reps2, first, last, out);
        return out;
    }
#if TIGERLOD_SCAN_LANES
    if ((kernel == ScanKernel::fastest || kernel == ScanKernel::lanes) && has_avx2() && exact_in_doubles) {
        scan_lanes(pts, tol, max_reach, reps2, first, last, out);
        return out;
    }
#endif
    if (!pts.empty() && box.max_x - box.min_x < limit && box.max_y - box.min_y < limit && reps2 < int128{limit}) {
        scan<int64_t>(pts, tol, max_reach, reps2, first, last, out);
    } else {
        scan<int128>(pts, tol, max_reach, reps2, first, last, out);
    }
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
