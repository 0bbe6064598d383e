#include "simplification/hull_scan.hpp"

#include "simplification/wedge.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace tigerlod::simplify::detail {

namespace {

/// Squared length of q - p; exact (differences under 2^31).
int64_t dist2(GridPoint p, GridPoint q) noexcept
{
    const int64_t dx = int64_t{q.x} - p.x, dy = int64_t{q.y} - p.y;
    return dx * dx + dy * dy;
}

/// The chain's vertices in aligned blocks: level L holds blocks of 2^L
/// vertices, block m the vertices [m 2^L, (m + 1) 2^L) (the last one
/// shorter), each with its convex hull (counter-clockwise, no three
/// vertices on a line) and its diameter. Levels are built while some block
/// is within eps across: one that is not never serves, nor does any block
/// holding it. Level 0 is the vertices themselves.
class BlockHulls {
  public:
    BlockHulls(std::span<const GridPoint> pts, int64_t reps2) : m_pts(pts)
    {
        m_levels.emplace_back(); // level 0: the vertices
        std::vector<uint32_t> members;
        for (int level = 1; (size_t{1} << (level - 1)) < pts.size() && level < 31; ++level) {
            const size_t count = (pts.size() + (size_t{1} << level) - 1) >> level;
            std::vector<Block> blocks(count);
            bool any = false;
            for (size_t m = 0; m < count; ++m) {
                members.clear();
                for (const size_t child : {2 * m, 2 * m + 1}) {
                    if (level == 1) {
                        if (child < pts.size()) {
                            members.push_back(static_cast<uint32_t>(child));
                        }
                    } else if (child < m_levels[level - 1].size()) {
                        const auto h = hull(level - 1, static_cast<uint32_t>(child));
                        members.insert(members.end(), h.begin(), h.end());
                    }
                }
                Block& b = blocks[m];
                b.begin = static_cast<uint32_t>(m_pool.size());
                make_hull(members);
                b.end = static_cast<uint32_t>(m_pool.size());
                b.diam2 = diameter2(b, reps2);
                any = any || b.diam2 <= reps2;
            }
            m_levels.push_back(std::move(blocks));
            if (!any) {
                break;
            }
        }
    }

    /// The highest level built.
    int top() const noexcept { return static_cast<int>(m_levels.size()) - 1; }
    /// The hull's vertex indices of block m of `level` (>= 1).
    std::span<const uint32_t> hull(int level, uint32_t m) const noexcept
    {
        const Block& b = m_levels[static_cast<size_t>(level)][m];
        return std::span<const uint32_t>(m_pool).subspan(b.begin, b.end - b.begin);
    }
    /// Whether block m of `level` exists (level 0: vertex m).
    bool has(int level, uint32_t m) const noexcept
    {
        return level == 0 ? m < m_pts.size() : m < m_levels[static_cast<size_t>(level)].size();
    }
    /// Whether block m of `level` (>= 1) exists and is within eps across.
    bool usable(int level, uint32_t m, int64_t reps2) const noexcept
    {
        const auto& blocks = m_levels[static_cast<size_t>(level)];
        return m < blocks.size() && blocks[m].diam2 <= reps2;
    }

  private:
    struct Block {
        uint32_t begin = 0, end = 0; ///< the hull in m_pool
        int64_t diam2 = 0;           ///< squared diameter; int64 max when over eps (not computed)
    };

    /// Appends the convex hull of the vertices `members` to m_pool (Andrew's
    /// monotone chain, in exact integers).
    void make_hull(std::vector<uint32_t>& members)
    {
        const auto key = [&](uint32_t i) { return m_pts[i]; };
        std::sort(members.begin(), members.end(),
                  [&](uint32_t u, uint32_t v) { return key(u) < key(v) || (key(u) == key(v) && u < v); });
        members.erase(
            std::unique(members.begin(), members.end(), [&](uint32_t u, uint32_t v) { return key(u) == key(v); }),
            members.end());
        const size_t base = m_pool.size();
        if (members.size() <= 2) {
            m_pool.insert(m_pool.end(), members.begin(), members.end());
            return;
        }
        auto turns_left = [&](uint32_t o, uint32_t p, uint32_t q) {
            const GridPoint a = m_pts[o], b = m_pts[p], c = m_pts[q];
            return (int64_t{b.x} - a.x) * (int64_t{c.y} - a.y) - (int64_t{b.y} - a.y) * (int64_t{c.x} - a.x) > 0;
        };
        auto chain = [&](auto first, auto last, size_t floor) {
            for (auto it = first; it != last; ++it) {
                while (m_pool.size() >= floor + 2 && !turns_left(m_pool[m_pool.size() - 2], m_pool.back(), *it)) {
                    m_pool.pop_back();
                }
                m_pool.push_back(*it);
            }
            m_pool.pop_back(); // the next chain starts with it
        };
        chain(members.begin(), members.end(), base);
        chain(members.rbegin(), members.rend(), m_pool.size());
    }

    /// The block's squared diameter, or int64 max where its box is already wider than eps.
    int64_t diameter2(const Block& b, int64_t reps2) const noexcept
    {
        GridBox box;
        for (uint32_t i = b.begin; i < b.end; ++i) {
            box.extend(m_pts[m_pool[i]]);
        }
        const int64_t w = box.max_x - box.min_x, h = box.max_y - box.min_y;
        if (w * w > reps2 || h * h > reps2) {
            return std::numeric_limits<int64_t>::max();
        }
        int64_t d2 = 0;
        for (uint32_t i = b.begin; i < b.end; ++i) {
            for (uint32_t k = i + 1; k < b.end; ++k) {
                d2 = std::max(d2, dist2(m_pts[m_pool[i]], m_pts[m_pool[k]]));
            }
        }
        return d2;
    }

    std::span<const GridPoint> m_pts;
    std::vector<std::vector<Block>> m_levels;
    std::vector<uint32_t> m_pool;
};

/// One start's scan. Ends are decided in chain order; before end k is
/// decided, every vertex j + 1 .. k - 1 has narrowed the wedge, as a vertex
/// or as one of the blocks the scan crossed (a unit).
///
/// Why a block of ends can be decided at once (every fact exact, the
/// rounding margins as in scan<> of candidates.cpp):
/// - within eps of the segment a -> p is what "proximate" asks of every
///   vertex between; the points within eps of a segment, of a ray and of
///   a point are convex sets, so a set of vertices satisfies each exactly
///   when its hull's vertices do. Narrowing the wedge by a block's hull
///   vertices gives a wedge containing the one its every vertex gives: its
///   "outside" still proves "not proximate", and deep inside it the ray is
///   within eps of every hull vertex, so of every vertex of the block.
/// - the vertices of the block before an end p of it lie within the
///   block's diameter of p, an end of the segment: within eps when the
///   block is.
/// - a block whose vertices all lie beyond one edge of the wedge (the
///   side of a half-plane, convex) holds no proximate end.
/// - a vertex q before the block, deep in the wedge, is within eps of the
///   segment a -> p unless |q| > |p| (its projection lies past p; L2), and
///   then it is when |q - p| <= eps. So: with every vertex of the block deep
///   in the wedge (its hull's vertices, the deep region being a convex
///   cone), no earlier vertex as far from a as the block's nearest point,
///   or each such one within eps of every hull vertex of the block, every
///   end of the block is proximate.
class HullScan {
  public:
    HullScan(std::span<const GridPoint> pts, const Tolerance& tol, int64_t reps2, const BlockHulls& tree)
        : m_pts(pts), m_tol(tol), m_reps2(reps2), m_tree(tree), m_wc(reps2)
    {
    }

    HullScanCounts counts() const noexcept { return m_counts; }

    /// Shortcuts from j end only at flagged vertices when m_ends is set
    /// (m_before[k]: the flagged vertices before k).
    void restrict_ends(std::span<const uint8_t> ends)
    {
        m_ends = ends;
        m_before.assign(ends.size() + 1, 0);
        for (size_t k = 0; k < ends.size(); ++k) {
            m_before[k + 1] = m_before[k] + (ends[k] ? 1U : 0U);
        }
    }

    void start(uint32_t j, uint32_t last, Candidates& out)
    {
        m_j = j;
        m_a = m_pts[j];
        m_wide = Wedge{};
        m_complete = true;
        m_far2 = 0;
        m_units.clear();
        m_prune_at = 16;
        if (!add(0, j + 1)) {
            return;
        }
        uint32_t pos = j + 2;
        while (pos <= last) {
            int level = 0;
            while (level < m_tree.top() && (pos & ((uint32_t{2} << level) - 1)) == 0 &&
                   uint64_t{pos} + (uint64_t{2} << level) - 1 <= last) {
                ++level;
            }
            bool done = false;
            for (; level >= 1 && !done; --level) {
                const uint32_t m = pos >> level;
                const uint32_t size = uint32_t{1} << level;
                // With ends restricted, a block holding none is only crossed.
                const bool none = !m_ends.empty() && m_before[pos + size] == m_before[pos];
                const bool proven = !none && m_tree.usable(level, m, m_reps2) && certify(level, m);
                if (none || proven || outside(level, m)) {
                    if (proven) {
                        add_ends(j, pos, pos + size - 1, out);
                        m_counts.block_ends += size;
                    } else {
                        m_counts.outside_ends += size;
                    }
                    pos += size;
                    if (!add(level, m)) {
                        return;
                    }
                    done = true;
                }
            }
            if (!done) {
                ++m_counts.single_ends;
                if ((m_ends.empty() || m_ends[pos]) && single(pos)) {
                    out.add(j, pos);
                }
                if (!add(0, pos++)) {
                    return;
                }
            }
        }
    }

  private:
    /// Shortcuts j -> lo, ..., j -> hi, less those to vertices not flagged.
    void add_ends(uint32_t j, uint32_t lo, uint32_t hi, Candidates& out) const
    {
        if (m_ends.empty()) {
            out.add_run(j, lo, hi);
            return;
        }
        for (uint32_t k = lo; k <= hi; ++k) {
            if (m_ends[k]) {
                uint32_t e = k;
                while (e < hi && m_ends[e + 1]) {
                    ++e;
                }
                out.add_run(j, k, e);
                k = e;
            }
        }
    }

    struct Unit {
        int level = 0;
        uint32_t m = 0;    ///< the block (level >= 1) or the vertex (level 0)
        int64_t maxr2 = 0; ///< the largest squared distance of its vertices from a
    };

    /// The hull of block m of `level`, the vertex itself at level 0 (a view
    /// of `m`, which must outlive it).
    std::span<const uint32_t> hull(int level, const uint32_t& m) const noexcept
    {
        return level == 0 ? std::span<const uint32_t>(&m, 1) : m_tree.hull(level, m);
    }

    int64_t max_r2(int level, uint32_t m) const noexcept
    {
        int64_t r2 = 0;
        for (const uint32_t v : hull(level, m)) {
            r2 = std::max(r2, dist2(m_a, m_pts[v]));
        }
        return r2;
    }

    /// The unit's vertices become vertices between: the wedge narrows by its
    /// hull's (as scan<> narrows by one vertex). False once the wedge is empty.
    bool add(int level, uint32_t m)
    {
        Unit u{level, m, 0};
        const double r_eps = m_wc.r_eps;
        for (const uint32_t v : hull(level, m)) {
            const int64_t qx = int64_t{m_pts[v].x} - m_a.x, qy = int64_t{m_pts[v].y} - m_a.y;
            const int64_t r2 = qx * qx + qy * qy;
            u.maxr2 = std::max(u.maxr2, r2);
            if (r2 > m_reps2) {
                const double c = std::sqrt(double(r2 - m_reps2));
                const double sin_w = r_eps * m_wc.cos_s + c * m_wc.sin_s, cos_w = c * m_wc.cos_s - r_eps * m_wc.sin_s;
                if (cos_w <= 1e-6 * (c + r_eps)) {
                    m_complete = false;
                } else if (!m_wide.narrow(arc_around(double(qx), double(qy), sin_w, cos_w))) {
                    return false;
                }
            }
        }
        m_far2 = std::max(m_far2, u.maxr2);
        // Units no end can need any more: nearer than the farthest vertex by
        // more than eps (an end that near is not proximate).
        if (m_units.size() >= m_prune_at) {
            const double band = std::sqrt(double(m_far2)) - r_eps - 4;
            if (band > 0) {
                const double band2 = band * band;
                std::erase_if(m_units, [&](const Unit& w) { return double(w.maxr2) < band2; });
            }
            m_prune_at = std::max<size_t>(16, 2 * m_units.size());
        }
        m_units.push_back(u);
        return true;
    }

    /// Whether end b (len2 = |b - a|^2) is deep inside the wedge.
    bool deep(double bx, double by, double len2) const noexcept
    {
        return m_complete && (m_wide.state == Wedge::open || m_wide.arc.deep_inside(bx, by, len2, m_wc.deep2));
    }

    /// Every end of block m of `level` proximate, proven as the class says; false: not proven.
    bool certify(int level, uint32_t m)
    {
        const auto h = m_tree.hull(level, m);
        for (const uint32_t v : h) {
            const double bx = double(m_pts[v].x) - m_a.x, by = double(m_pts[v].y) - m_a.y;
            if (!deep(bx, by, bx * bx + by * by)) {
                return false;
            }
        }
        const double near2 = nearest2(h); // a lower bound of the block's squared distances from a
        if (!(near2 > 0)) {
            return false; // a vertex of the block may be the start itself
        }
        if (m_wide.state == Wedge::open || double(m_far2) * (1 + 1e-12) < near2) {
            return true; // every vertex between within eps of a, or none as far as an end
        }
        const double band = std::sqrt(double(m_far2)) - m_wc.r_eps - 4;
        if (band > 0 && near2 < band * band) {
            return false; // an end may lie too near (and units that far were let go)
        }
        for (const Unit& u : m_units) {
            if (double(u.maxr2) >= near2 && !unit_near_all(u.level, u.m, near2, h)) {
                return false;
            }
        }
        return true;
    }

    /// No end of block m of `level` proximate: every vertex of its hull (so
    /// the whole block: a half-plane is convex) beyond the same edge of the
    /// wedge. The wedge is widened by the slack, far above the rounding of
    /// the sides, so the block lies outside the directions that pass within
    /// eps of every vertex between.
    bool outside(int level, uint32_t m) const noexcept
    {
        if (m_wide.state != Wedge::set) {
            return false;
        }
        const Arc& w = m_wide.arc;
        bool past_a = true, past_b = true;
        for (const uint32_t v : m_tree.hull(level, m)) {
            const double x = double(m_pts[v].x) - m_a.x, y = double(m_pts[v].y) - m_a.y;
            past_a = past_a && w.ax * y - w.ay * x < 0;
            past_b = past_b && x * w.by - y * w.bx < 0;
        }
        return past_a || past_b;
    }

    /// Every vertex of the unit with squared distance from a of at least
    /// `from2` within eps of every vertex `h` (a convex set's hull).
    bool unit_near_all(int level, uint32_t m, double from2, std::span<const uint32_t> h) const
    {
        bool all = true;
        for (const uint32_t q : hull(level, m)) {
            for (const uint32_t v : h) {
                all = all && dist2(m_pts[q], m_pts[v]) <= m_reps2;
            }
        }
        if (all || level == 0) {
            return all;
        }
        for (const uint32_t child : {2 * m, 2 * m + 1}) {
            if (m_tree.has(level - 1, child) && double(max_r2(level - 1, child)) >= from2 &&
                !unit_near_all(level - 1, child, from2, h)) {
                return false;
            }
        }
        return true;
    }

    /// A lower bound of the squared distance from a to the polygon `h`
    /// (0 where a may lie in it).
    double nearest2(std::span<const uint32_t> h) const noexcept
    {
        auto seg2 = [&](GridPoint p, GridPoint q) {
            const double px = double(p.x) - m_a.x, py = double(p.y) - m_a.y;
            const double dx = double(q.x) - p.x, dy = double(q.y) - p.y;
            const double l2 = dx * dx + dy * dy;
            const double t = l2 > 0 ? std::clamp(-(px * dx + py * dy) / l2, 0.0, 1.0) : 0.0;
            const double x = px + t * dx, y = py + t * dy;
            return x * x + y * y;
        };
        double best = std::numeric_limits<double>::infinity();
        bool inside = h.size() >= 3;
        for (size_t i = 0; i < h.size(); ++i) {
            const GridPoint p = m_pts[h[i]], q = m_pts[h[(i + 1) % h.size()]];
            best = std::min(best, h.size() == 1 ? double(dist2(m_a, p)) : seg2(p, q));
            const int64_t cross =
                (int64_t{q.x} - p.x) * (int64_t{m_a.y} - p.y) - (int64_t{q.y} - p.y) * (int64_t{m_a.x} - p.x);
            inside = inside && cross >= 0;
        }
        return inside ? 0.0 : best * (1 - 1e-9) - 1;
    }

    /// Whether end k alone is proximate (every vertex before it has narrowed the wedge).
    bool single(uint32_t k) const
    {
        const GridPoint b = m_pts[k];
        if (b == m_a) {
            return false;
        }
        const double bx = double(b.x) - m_a.x, by = double(b.y) - m_a.y;
        if (m_wide.state == Wedge::set && !m_wide.arc.holds(bx, by)) {
            return false; // the ray through b misses a vertex
        }
        const int64_t len2 = dist2(m_a, b);
        if (!deep(bx, by, double(len2))) {
            return proximate_exact(m_pts, m_j, k, m_tol);
        }
        if (double(m_far2) * (1 + 1e-12) < double(len2)) {
            return true; // no vertex between as far from a as b
        }
        if (std::sqrt(double(m_far2)) > (std::sqrt(double(len2)) + m_wc.r_eps) * (1 + 1e-9) + 1) {
            return false; // a vertex farther than eps from all of ab
        }
        // Only the vertices at least as far from a as b can be farther than eps from ab.
        for (const Unit& u : m_units) {
            if (u.maxr2 >= len2 && !unit_within(u.level, u.m, len2, k)) {
                return false;
            }
        }
        return true;
    }

    /// Every vertex of the unit at squared distance at least `from2` from a
    /// within eps of the segment a -> pts[k].
    bool unit_within(int level, uint32_t m, int64_t from2, uint32_t k) const
    {
        const GridPoint b = m_pts[k];
        bool near_b = true;
        for (const uint32_t q : hull(level, m)) {
            near_b = near_b && dist2(m_pts[q], b) <= m_reps2;
        }
        if (near_b) {
            return true;
        }
        if (level == 0) {
            return within(m_pts[m], m_a, b, m_tol);
        }
        for (const uint32_t child : {2 * m, 2 * m + 1}) {
            if (m_tree.has(level - 1, child) && max_r2(level - 1, child) >= from2 &&
                !unit_within(level - 1, child, from2, k)) {
                return false;
            }
        }
        return true;
    }

    std::span<const GridPoint> m_pts;
    const Tolerance& m_tol;
    int64_t m_reps2;
    const BlockHulls& m_tree;
    WedgeConstants m_wc;
    uint32_t m_j = 0;
    GridPoint m_a;
    Wedge m_wide;
    bool m_complete = true;
    int64_t m_far2 = 0; ///< the largest squared distance from a of a vertex between
    std::vector<Unit> m_units;
    size_t m_prune_at = 16; ///< units let go (those too near) when this many
    HullScanCounts m_counts;
    std::span<const uint8_t> m_ends;
    std::vector<uint32_t> m_before;
};

} // namespace

bool hull_scan_pays(std::span<const GridPoint> pts, int128 reps2) noexcept
{
    constexpr size_t block = 16;
    size_t blocks = 0, small = 0;
    for (size_t b = 0; b + block <= pts.size(); b += block) {
        GridBox box;
        for (size_t i = b; i < b + block; ++i) {
            box.extend(pts[i]);
        }
        const int128 w = box.max_x - box.min_x, h = box.max_y - box.min_y;
        ++blocks;
        small += w * w + h * h <= reps2;
    }
    return blocks > 0 && 5 * small >= 2 * blocks;
}

HullScanCounts scan_hulls(std::span<const GridPoint> pts, const Tolerance& tol, uint32_t max_reach, int128 reps2,
                          uint32_t starts_lo, uint32_t starts_hi, Candidates& out, std::span<const uint8_t> ends)
{
    const auto n = static_cast<uint32_t>(pts.size());
    const auto r2 = static_cast<int64_t>(reps2); // under 2^62: checked by the caller
    const BlockHulls tree(pts, r2);
    HullScan scan(pts, tol, r2, tree);
    if (!ends.empty()) {
        scan.restrict_ends(ends);
    }
    for (uint32_t j = starts_lo; j + 2 < n && j < starts_hi; ++j) {
        if (!ends.empty() && !ends[j]) {
            continue;
        }
        const auto last = static_cast<uint32_t>(max_reach ? std::min<uint64_t>(n - 1, uint64_t{j} + max_reach) : n - 1);
        scan.start(j, last, out);
    }
    return scan.counts();
}

std::vector<uint8_t> greedy_fit_vertices(std::span<const GridPoint> pts, double d)
{
    // Only IEEE operations that are correctly rounded (+, -, x, sqrt; no
    // libm trigonometry, no fused multiply-adds): the same set on every
    // machine, as the stores must be.
    const size_t n = pts.size();
    std::vector<uint8_t> keep(n, 0);
    if (n == 0) {
        return keep;
    }
    keep[0] = keep[n - 1] = 1;
    const double d2 = d * d;
    size_t a = 0;
    while (a + 1 < n) {
        // The directions from a that pass within d of every vertex since.
        Wedge wedge;
        size_t k = a + 1;
        for (; k < n; ++k) {
            const double qx = double(pts[k].x) - double(pts[a].x), qy = double(pts[k].y) - double(pts[a].y);
            const double r2 = qx * qx + qy * qy;
            if (r2 <= d2) {
                continue;
            }
            if (!wedge.narrow(arc_around(qx, qy, d, std::sqrt(r2 - d2)))) {
                break;
            }
        }
        if (k >= n) {
            break;
        }
        // pts[k] emptied the wedge: the fit from a ends at k - 1 (at least
        // one vertex on, so the fit advances).
        a = std::max(a + 1, k - 1);
        keep[a] = 1;
    }
    return keep;
}

} // namespace tigerlod::simplify::detail
