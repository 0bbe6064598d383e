#include "simplification/coloring.hpp"

#include "core/errors.hpp"
#include "core/radix_sort.hpp"
#include "simplification/cell_cover.hpp"

#include <algorithm>
#include <bitset>
#include <cmath>
#include <tuple>
#include <sstream>
#include <unordered_set>

namespace tigerlod::simplify {

double reach_radius(double eps, double pixel, const ColorOptions& opt) noexcept
{
    return eps * l2_reach(opt.metric) + opt.margin_px * pixel;
}

namespace {

struct Seg {
    double ax, ay, bx, by;
    uint32_t chain;
    double r;
};

/// The box of segments grown by their reach.
struct ReachBox {
    double x0 = INFINITY, y0 = INFINITY, x1 = -INFINITY, y1 = -INFINITY;
    void add(const Seg& s) noexcept
    {
        x0 = std::min({x0, s.ax - s.r, s.bx - s.r});
        y0 = std::min({y0, s.ay - s.r, s.by - s.r});
        x1 = std::max({x1, s.ax + s.r, s.bx + s.r});
        y1 = std::max({y1, s.ay + s.r, s.by + s.r});
    }
    bool empty() const noexcept { return !(x0 <= x1); }
    bool meets(const ReachBox& o) const noexcept { return x0 <= o.x1 && o.x0 <= x1 && y0 <= o.y1 && o.y0 <= y1; }
    /// The box less a reach r it was grown by: its segments' own box, but
    /// for the rounding of the growth.
    ReachBox less(double r) const noexcept { return {x0 + r, y0 + r, x1 - r, y1 - r}; }
};

/// Whether two boxes (x0, y0, x1, y1) are at least d >= 0 apart, which
/// every point of one then is from every point of the other: by the
/// Euclidean distance, tighter than the larger axis gap where boxes lie
/// diagonally apart (at 2 km most pairs of a block's small chains that are
/// not close: block stores at 2000 m, 4.1 M such pairs took 867 M segment
/// distances with the axis gap).
template <class P, class Q> bool boxes_apart(const P& p, const Q& q, double d) noexcept
{
    const double gx = std::max({p.x0 - q.x1, q.x0 - p.x1, 0.0});
    const double gy = std::max({p.y0 - q.y1, q.y0 - p.y1, 0.0});
    return gx * gx + gy * gy >= d * d;
}

double point_seg2(double px, double py, const Seg& s) noexcept
{
    const double dx = s.bx - s.ax, dy = s.by - s.ay;
    const double len2 = dx * dx + dy * dy;
    double t = len2 > 0 ? ((px - s.ax) * dx + (py - s.ay) * dy) / len2 : 0.0;
    t = std::clamp(t, 0.0, 1.0);
    const double x = px - s.ax - t * dx, y = py - s.ay - t * dy;
    return x * x + y * y;
}

double seg_seg_distance(const Seg& s, const Seg& t) noexcept
{
    auto orient = [](double ax, double ay, double bx, double by, double cx, double cy) {
        const double v = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
        return (v > 0) - (v < 0);
    };
    const int o1 = orient(s.ax, s.ay, s.bx, s.by, t.ax, t.ay), o2 = orient(s.ax, s.ay, s.bx, s.by, t.bx, t.by);
    const int o3 = orient(t.ax, t.ay, t.bx, t.by, s.ax, s.ay), o4 = orient(t.ax, t.ay, t.bx, t.by, s.bx, s.by);
    if (o1 * o2 < 0 && o3 * o4 < 0) {
        return 0;
    }
    const double d2 = std::min(
        {point_seg2(t.ax, t.ay, s), point_seg2(t.bx, t.by, s), point_seg2(s.ax, s.ay, t), point_seg2(s.bx, s.by, t)});
    return std::sqrt(d2);
}

std::vector<Seg> make_segments(std::span<const ChainGeom> chains, double pixel, const ColorOptions& opt)
{
    std::vector<Seg> segs;
    for (uint32_t c = 0; c < chains.size(); ++c) {
        const auto& pts = chains[c].points;
        const double r = reach_radius(chains[c].eps, pixel, opt);
        for (size_t i = 0; i + 1 < pts.size(); ++i) {
            if (!takes_part(chains[c].keep, i)) {
                continue;
            }
            segs.push_back({double(pts[i].x), double(pts[i].y), double(pts[i + 1].x), double(pts[i + 1].y), c, r});
        }
        if (pts.size() == 1) {
            segs.push_back({double(pts[0].x), double(pts[0].y), double(pts[0].x), double(pts[0].y), c, r});
        }
    }
    return segs;
}

/// The distance test of the conflict graph on chains coarsened first.
///
/// A run of a chain's segments whose inner vertices all lie within delta of
/// the run's first point P becomes one coarse segment from P to the run's
/// last point q. The Hausdorff distance between the run and that segment is
/// at most delta, both ways: every inner vertex is within delta of P, and
/// the run's last segment (v, q) has both ends within delta of P q, so lies
/// within delta of it (the delta-neighbourhood of a segment is convex); and
/// the point (1 - t) P + t q is (1 - t)|P - v| <= delta from (1 - t) v + t q,
/// a point of that last segment. So two coarse segments d apart stand for
/// segments d +- (delta_a + delta_b) apart: a pair of them clearly nearer
/// than r_a + r_b makes the edge at once, one clearly farther holds no close
/// pair, and only pairs near the threshold have their own segments tested,
/// with the exact test the graph always used (the outcome is the same; the
/// slack covers rounding). A chain is coarsened within r / 8: at 2 km a
/// block's chain of a few hundred metres is one or two segments; at a metre
/// nothing is, and the segments are tested as they are.
class ChainDistance {
  public:
    ChainDistance(std::span<const ChainGeom> chains, const std::vector<Seg>& segs) : m_segs(segs)
    {
        m_first.assign(chains.size() + 1, 0);
        m_delta.assign(chains.size(), 0.0);
        m_r.assign(chains.size(), 0.0);
        for (uint32_t i = 0; i < segs.size(); ++i) {
            m_r[segs[i].chain] = segs[i].r;
            m_first[segs[i].chain + 1] = i + 1;
        }
        for (size_t c = 0; c < chains.size(); ++c) {
            m_first[c + 1] = std::max(m_first[c + 1], m_first[c]);
        }
        // Where coarsening keeps most segments (a metre's tolerance on a
        // county), the graph tests the segments themselves: the same result,
        // without the coarse segments' cost (tract ladder at 1-64 m).
        size_t count = 0;
        for (uint32_t c = 0; c < chains.size(); ++c) {
            coarsen(c, [&](uint32_t, uint32_t, double) { ++count; });
        }
        if (10 * count > 7 * segs.size()) {
            return;
        }
        m_coarse_of.reserve(segs.size());
        for (uint32_t c = 0; c < chains.size(); ++c) {
            coarsen(c, [&](uint32_t first, uint32_t last, double far) {
                m_coarse_of.insert(m_coarse_of.end(), last - first, static_cast<uint32_t>(m_coarse.size()));
                Box box = box_of(m_segs[first]);
                for (uint32_t i = first + 1; i < last; ++i) {
                    const Box b = box_of(m_segs[i]);
                    box = {std::min(box.x0, b.x0), std::min(box.y0, b.y0), std::max(box.x1, b.x1),
                           std::max(box.y1, b.y1)};
                }
                m_coarse.push_back({first, last, box});
                m_delta[c] = std::max(m_delta[c], far);
            });
        }
    }

    /// Whether chains a and b have segments closer than r_a + r_b, looking
    /// from their segments in one cell of the grid: `ea` and `eb` index
    /// segs, ascending; `reach_b` is the box of eb grown by r_b. False says
    /// only that no segment of ea is that close to one of eb.
    template <class Entries, class Grown>
    bool close(uint32_t a, uint32_t b, const Entries& ea, const Entries& eb, const Grown& reach_b)
    {
        const double limit = m_r[a] + m_r[b];
        const double spread = m_delta[a] + m_delta[b];
        const double slack = 1e-9 * limit + 1e-6;
        const double near = limit + spread + slack; // coarse pairs farther apart hold no close pair
        // A coarse segment of a this far from eb's box (grown by r_b) is
        // r_b + delta_a + ... away from every segment of eb.
        const double off = m_r[a] + m_delta[a] + slack;
        m_unsure.clear();
        uint32_t last_s = UINT32_MAX;
        for (const auto& [cell_a, i] : ea) {
            const uint32_t ks = coarse_of(i);
            if (ks == last_s) {
                continue;
            }
            last_s = ks;
            const Seg s = seg_of(ks);
            const Box sbox = box_of(s);
            if (gap(sbox, reach_b) >= off) {
                continue;
            }
            uint32_t last_t = UINT32_MAX;
            for (const auto& [cell_b, j] : eb) {
                const uint32_t kt = coarse_of(j);
                if (kt == last_t) {
                    continue;
                }
                last_t = kt;
                const Seg t = seg_of(kt);
                if (gap(sbox, box_of(t)) >= near) {
                    continue;
                }
                const double d = seg_seg_distance(s, t);
                if (m_coarse.empty() ? d < limit : d + spread + slack < limit) {
                    return true; // where nothing is coarsened, the test itself
                }
                if (d < near && !m_coarse.empty()) {
                    m_unsure.emplace_back(ks, kt);
                }
            }
        }
        // Each unsure coarse pair on their own segments; a segment whose box
        // is clearly farther than the limit from all of the other run's
        // segments' box skips the run.
        for (const auto& [ks, kt] : m_unsure) {
            for (uint32_t u = m_coarse[ks].first; u < m_coarse[ks].last; ++u) {
                const Box bu = box_of(m_segs[u]);
                if (boxes_apart(bu, m_coarse[kt].box, limit + slack)) {
                    continue;
                }
                for (uint32_t v = m_coarse[kt].first; v < m_coarse[kt].last; ++v) {
                    if (!boxes_apart(bu, box_of(m_segs[v]), limit + slack) &&
                        seg_seg_distance(m_segs[u], m_segs[v]) < limit) {
                        return true;
                    }
                }
            }
        }
        return false;
    }

  private:
    /// A box of a segment, not grown.
    struct Box {
        double x0, y0, x1, y1;
    };
    struct Coarse {
        uint32_t first, last; ///< the chain's segments it stands for, [first, last)
        Box box;              ///< theirs
    };

    static Box box_of(const Seg& s) noexcept
    {
        return {std::min(s.ax, s.bx), std::min(s.ay, s.by), std::max(s.ax, s.bx), std::max(s.ay, s.by)};
    }
    /// A lower bound of the distance between two boxes (the larger axis gap).
    template <class P, class Q> static double gap(const P& p, const Q& q) noexcept
    {
        return std::max({p.x0 - q.x1, q.x0 - p.x1, p.y0 - q.y1, q.y0 - p.y1, 0.0});
    }
    /// The coarse segment that segment i is part of (itself where nothing is coarsened).
    uint32_t coarse_of(uint32_t i) const noexcept { return m_coarse.empty() ? i : m_coarse_of[i]; }
    Seg seg_of(uint32_t k) const noexcept
    {
        if (m_coarse.empty()) {
            return m_segs[k];
        }
        const Seg &f = m_segs[m_coarse[k].first], &l = m_segs[m_coarse[k].last - 1];
        return {f.ax, f.ay, l.bx, l.by, f.chain, f.r};
    }

    /// Calls emit(first, last, far) for each coarse segment of chain c: its
    /// segments [first, last), which follow one another except where a halo
    /// chain's parts out of reach were left out (a new run starts there), and
    /// how far its inner vertices are from its first point.
    template <class Emit> void coarsen(uint32_t c, Emit&& emit) const
    {
        const double target = m_r[c] / 8, target2 = target * target;
        const uint32_t end = m_first[c + 1];
        uint32_t i = m_first[c];
        while (i < end) {
            const Seg& s0 = m_segs[i];
            double far2 = 0; // of the inner vertices from P
            uint32_t j = i;
            for (; j + 1 < end && m_segs[j + 1].ax == m_segs[j].bx && m_segs[j + 1].ay == m_segs[j].by; ++j) {
                const double dx = m_segs[j].bx - s0.ax, dy = m_segs[j].by - s0.ay;
                const double d2 = dx * dx + dy * dy;
                if (d2 > target2) {
                    break;
                }
                far2 = std::max(far2, d2);
            }
            // Rounded up a little: the bound must hold, not be tight.
            emit(i, j + 1, std::sqrt(far2) * (1 + 1e-12));
            i = j + 1;
        }
    }

    const std::vector<Seg>& m_segs;
    std::vector<uint32_t> m_first;     ///< first segment of each chain, and the end
    std::vector<Coarse> m_coarse;      ///< empty where nothing is coarsened
    std::vector<uint32_t> m_coarse_of; ///< per segment
    std::vector<double> m_delta;       ///< how far each chain's coarse segments may be from it
    std::vector<double> m_r;
    std::vector<std::pair<uint32_t, uint32_t>> m_unsure;
}; // class ChainDistance

/// Conflict graph: chains i != j, one of them owned, with segments closer
/// than r_i + r_j. Two halo chains are never joined: only owned chains'
/// shortcuts are tested in the stencil, and a test can be fooled only by a
/// chain of its own class whose tent reaches it (coloring.hpp). The pairs
/// to test come from a cell grid: two chains closer than r_i + r_j have
/// segments in one cell, whose boxes grown by their reach meet there.
std::vector<std::vector<uint32_t>> graph_of(std::span<const ChainGeom> chains, const std::vector<Seg>& segs)
{
    double rmax = 0, length = 0;
    for (const auto& s : segs) {
        rmax = std::max(rmax, s.r);
        const double dx = s.bx - s.ax, dy = s.by - s.ay;
        length += std::sqrt(dx * dx + dy * dy); // sets a cell size only: no need for hypot's care
    }
    // At least four mean segments: small tolerances made 2 x reach cells a
    // fraction of a segment, each segment filling dozens, and sorting the
    // entries took half the graph's time; the chains' boxes below keep large
    // cells cheap where many chains share one (tract level at 16 m: graph
    // 0.63 -> 0.31 s; contours 0.27 -> 0.16 s). The graph does not depend on
    // the size (a pair within r_s + r_t shares a cell).
    const double mean = segs.empty() ? 0.0 : length / double(segs.size());
    const double cell = std::max({2 * rmax, 4 * mean, 1.0});
    ReachBox all;
    for (const auto& s : segs) {
        all.add(s);
    }
    const CellGrid cells = segs.empty() ? CellGrid{} : CellGrid(all.x0, all.y0, all.x1, all.y1, cell);
    // Only a cell with an owned chain's segment can give an edge. Where
    // those are few (coarse tolerances, whose short owned chains count as
    // halo), the other chains' segments are entered only in those cells:
    // the same pairs, fewer entries to sort (block stores at 2000 m: the
    // sort was half of the colouring's time).
    size_t owned_segs = 0;
    for (const auto& s : segs) {
        owned_segs += chains[s.chain].owned ? 1 : 0;
    }
    const bool filter = 4 * owned_segs < segs.size();
    std::vector<uint64_t> owned_cells;
    if (filter) {
        for (const auto& s : segs) {
            if (chains[s.chain].owned) {
                cover_cells(s.ax, s.ay, s.bx, s.by, s.r, cell, 0.0, 0.0,
                            [&](int64_t x, int64_t y) { owned_cells.push_back(cells.key(x, y)); });
            }
        }
        std::sort(owned_cells.begin(), owned_cells.end());
        owned_cells.erase(std::unique(owned_cells.begin(), owned_cells.end()), owned_cells.end());
    }
    std::vector<std::pair<uint64_t, uint32_t>> entries;
    for (uint32_t i = 0; i < segs.size(); ++i) {
        const Seg& s = segs[i];
        const bool owned = chains[s.chain].owned;
        cover_cells(s.ax, s.ay, s.bx, s.by, s.r, cell, 0.0, 0.0, [&](int64_t x, int64_t y) {
            const uint64_t key = cells.key(x, y);
            if (!filter || owned || std::binary_search(owned_cells.begin(), owned_cells.end(), key)) {
                entries.emplace_back(key, i);
            }
        });
    }
    // Each cell's segments in index order, so by chain; the entries came in
    // index order, so a counting sort by cell gives it where the grid is
    // not much larger than the entries.
    if (cells.size() <= 4 * entries.size()) {
        counting_sort_pairs(entries, cells.size());
    } else {
        radix_sort_pairs(entries);
    }
    ChainDistance distance(chains, segs);
    std::unordered_set<uint64_t> known; // pairs found close
    std::vector<std::pair<uint32_t, uint32_t>> edges;
    std::vector<size_t> run;        // where each chain's entries start in the cell, and its end
    std::vector<size_t> owned_runs; // the runs of the owned chains
    std::vector<ReachBox> boxes;
    for (size_t b = 0; b < entries.size();) {
        size_t e = b;
        run.clear();
        owned_runs.clear();
        while (e < entries.size() && entries[e].first == entries[b].first) {
            const uint32_t c = segs[entries[e].second].chain;
            if (e == b || c != segs[entries[e - 1].second].chain) {
                if (chains[c].owned) {
                    owned_runs.push_back(run.size());
                }
                run.push_back(e);
            }
            ++e;
        }
        run.push_back(e);
        if (owned_runs.empty()) {
            b = e;
            continue;
        }
        auto chain_at = [&](size_t p) { return segs[entries[run[p]].second].chain; };
        // Each chain's segments in the cell as a box grown by their reach: two
        // chains whose boxes miss each other have no close pair there (dense
        // maps, contours, put dozens of chains in a cell).
        boxes.clear();
        for (size_t p = 0; p + 1 < run.size(); ++p) {
            ReachBox bx;
            for (size_t i = run[p]; i < run[p + 1]; ++i) {
                bx.add(segs[entries[i].second]);
            }
            boxes.push_back(bx);
        }
        auto in_cell = [&](size_t p) {
            return std::span<const std::pair<uint64_t, uint32_t>>(entries).subspan(run[p], run[p + 1] - run[p]);
        };
        // The chains p < q in the cell (their runs), one of them owned.
        auto consider = [&](size_t p, size_t q) {
            const uint32_t lo = chain_at(p), hi = chain_at(q);
            if (!boxes[p].meets(boxes[q])) {
                return;
            }
            // Their segments' own boxes (the reach boxes less r_lo and
            // r_hi) at least r_lo + r_hi apart, by the Euclidean gap: no
            // close pair in this cell (block stores at 2000 m: most pairs
            // that are not close). The slack of ChainDistance::close
            // covers the rounding of the growth.
            const double r_lo = segs[entries[run[p]].second].r, r_hi = segs[entries[run[q]].second].r;
            const double limit = r_lo + r_hi;
            if (boxes_apart(boxes[p].less(r_lo), boxes[q].less(r_hi), limit + 1e-9 * limit + 1e-6)) {
                return;
            }
            const uint64_t key = (uint64_t{lo} << 32) | hi;
            if (!known.contains(key) && distance.close(lo, hi, in_cell(p), in_cell(q), boxes[q])) {
                known.insert(key);
                edges.emplace_back(lo, hi);
            }
        };
        // Pairs from the owned chains only: where few are owned (coarse
        // tolerances) a cell's other chains are not paired among themselves.
        for (const size_t p : owned_runs) {
            for (size_t q = 0; q + 1 < run.size(); ++q) {
                if (q == p || (chains[chain_at(q)].owned && q < p)) {
                    continue; // itself, or a pair of owned chains taken from q
                }
                q < p ? consider(q, p) : consider(p, q);
            }
        }
        b = e;
    }
    std::vector<std::vector<uint32_t>> adj(chains.size());
    for (auto [a, b] : edges) {
        adj[a].push_back(b);
        adj[b].push_back(a);
    }
    for (auto& l : adj) {
        std::sort(l.begin(), l.end());
    }
    return adj;
}

struct Tiler {
    std::span<const ChainGeom> chains;
    const std::vector<Seg>& segs;
    std::vector<size_t> seg_begin; // first segment of each chain
    const std::vector<std::vector<uint32_t>>& adj;
    const ColorOptions& opt;
    ColorResult& out;

    bool touches(uint32_t c, const TileSpec& t) const
    {
        const double tx1 = t.x0 + t.width * t.pixel, ty1 = t.y0 + t.height * t.pixel;
        for (size_t i = seg_begin[c]; i < seg_begin[c + 1]; ++i) {
            const Seg& s = segs[i];
            if (std::max(s.ax, s.bx) + s.r >= t.x0 && std::min(s.ax, s.bx) - s.r <= tx1 &&
                std::max(s.ay, s.by) + s.r >= t.y0 && std::min(s.ay, s.by) - s.r <= ty1) {
                return true;
            }
        }
        return false;
    }

    void color(const TileSpec& spec, std::vector<uint32_t> members, uint32_t depth)
    {
        if (std::none_of(members.begin(), members.end(), [&](uint32_t c) { return chains[c].owned; })) {
            return;
        }
        std::vector<uint32_t> local(chains.size(), UINT32_MAX);
        for (uint32_t i = 0; i < members.size(); ++i) {
            local[members[i]] = i;
        }
        std::vector<std::vector<uint32_t>> sub(members.size());
        for (uint32_t i = 0; i < members.size(); ++i) {
            for (uint32_t n : adj[members[i]]) {
                if (local[n] != UINT32_MAX) {
                    sub[i].push_back(local[n]);
                }
            }
        }
        std::vector<uint8_t> classes;
        if (dsatur(sub, opt.max_classes, classes)) {
            ColoredTile t;
            t.spec = spec;
            t.chains = std::move(members);
            t.classes = std::move(classes);
            t.depth = depth;
            out.tiles.push_back(std::move(t));
            return;
        }
        if (spec.width <= opt.min_tile_pixels && spec.height <= opt.min_tile_pixels) {
            std::ostringstream msg;
            msg << "a render tile of " << spec.width << "x" << spec.height << " pixels at grid ("
                << std::llround(spec.x0) << ", " << std::llround(spec.y0) << ") needs more than " << opt.max_classes
                << " stencil classes even after splitting (" << members.size() << " chains within reach)";
            throw tile_overflow_error(msg.str(), spec);
        }
        ++out.splits;
        const uint32_t w0 = (spec.width + 1) / 2, h0 = (spec.height + 1) / 2;
        for (int q = 0; q < 4; ++q) {
            TileSpec c = spec;
            c.width = (q & 1) ? spec.width - w0 : w0;
            c.height = (q & 2) ? spec.height - h0 : h0;
            c.x0 = spec.x0 + ((q & 1) ? w0 * spec.pixel : 0.0);
            c.y0 = spec.y0 + ((q & 2) ? h0 * spec.pixel : 0.0);
            if (c.width == 0 || c.height == 0) {
                continue;
            }
            std::vector<uint32_t> sub_members;
            for (uint32_t m : members) {
                if (touches(m, c)) {
                    sub_members.push_back(m);
                }
            }
            color(c, std::move(sub_members), depth + 1);
        }
    }
}; // struct Tiler

} // namespace

double segment_distance(GridPoint a, GridPoint b, GridPoint c, GridPoint d) noexcept
{
    const Seg s{double(a.x), double(a.y), double(b.x), double(b.y), 0, 0};
    const Seg t{double(c.x), double(c.y), double(d.x), double(d.y), 0, 0};
    return seg_seg_distance(s, t);
}

bool dsatur(const std::vector<std::vector<uint32_t>>& adj, uint32_t max_colors, std::vector<uint8_t>& colors)
{
    const auto n = static_cast<uint32_t>(adj.size());
    colors.assign(n, 0);
    std::vector<std::bitset<256>> used(n);
    std::vector<uint32_t> sat(n, 0);
    // Order: highest saturation, then highest degree, then lowest index: a
    // heap of (saturation, degree, -index) with an entry pushed each time a
    // vertex's saturation grows; an entry whose vertex is coloured, or whose
    // saturation is not the vertex's now, is stale and skipped. The valid
    // entry of a vertex outranks its stale ones (saturation only grows), so
    // the vertices come in the same order as from an ordered set of the keys,
    // at a heap's cost (a std::set was 13 % of colouring block stores at 2 km).
    using Key = std::tuple<uint32_t, size_t, int64_t>;
    auto key = [&](uint32_t v) { return Key{sat[v], adj[v].size(), -int64_t(v)}; };
    std::vector<Key> heap;
    heap.reserve(n);
    for (uint32_t v = 0; v < n; ++v) {
        heap.push_back(key(v));
    }
    std::make_heap(heap.begin(), heap.end());
    while (!heap.empty()) {
        std::pop_heap(heap.begin(), heap.end());
        const Key top = heap.back();
        heap.pop_back();
        const auto v = static_cast<uint32_t>(-std::get<2>(top));
        if (colors[v] != 0 || std::get<0>(top) != sat[v]) {
            continue; // stale
        }
        uint32_t c = 1;
        while (c < 256 && used[v][c]) {
            ++c;
        }
        if (c > max_colors || c > 255) {
            return false;
        }
        colors[v] = static_cast<uint8_t>(c);
        for (uint32_t u : adj[v]) {
            if (colors[u] != 0 || used[u][c]) {
                continue;
            }
            used[u][c] = true;
            ++sat[u];
            heap.push_back(key(u));
            std::push_heap(heap.begin(), heap.end());
        }
    }
    return true;
}

int128 untested_length2(double pixel) noexcept
{
    const double m = end_margin_px - 0.1;
    const double length = 2 * std::sqrt(m * m - 0.25) * pixel;
    return length > 0 ? static_cast<int128>(std::floor(length * length)) : -1;
}

bool testable_chain(std::span<const GridPoint> points, double pixel) noexcept
{
    if (points.empty()) {
        return false;
    }
    GridBox box;
    for (const GridPoint p : points) {
        box.extend(p);
    }
    // Every two points of the chain are at most the box's diagonal apart.
    const int128 dx = box.max_x - box.min_x, dy = box.max_y - box.min_y;
    return dx * dx + dy * dy > untested_length2(pixel);
}

namespace {

/// `chains` with `owned` cleared where no shortcut can be tested at `pixel`.
std::vector<ChainGeom> as_tested(std::span<const ChainGeom> chains, double pixel)
{
    std::vector<ChainGeom> out(chains.begin(), chains.end());
    for (auto& c : out) {
        c.owned = c.owned && testable_chain(c.points, pixel);
    }
    return out;
}

} // namespace

std::vector<std::vector<uint32_t>> conflict_graph(std::span<const ChainGeom> given, double pixel,
                                                  const ColorOptions& opt)
{
    const auto chains = as_tested(given, pixel);
    return graph_of(chains, make_segments(chains, pixel, opt));
}

double tile_pixel(std::span<const double> eps, const ColorOptions& opt) noexcept
{
    double eps_min = 0;
    for (const double e : eps) {
        if (e > 0 && (eps_min == 0 || e < eps_min)) {
            eps_min = e;
        }
    }
    return eps_min * opt.pixel_fraction;
}

ColorResult color_tiles(std::span<const ChainGeom> given, const ColorOptions& opt, unsigned /*threads*/)
{
    ColorResult out;
    std::vector<double> eps(given.size());
    for (size_t i = 0; i < given.size(); ++i) {
        eps[i] = given[i].eps;
    }
    out.pixel = tile_pixel(eps, opt);
    if (out.pixel <= 0) {
        return out;
    }
    // From here `owned` is "owned and testable": the tiles cover those
    // chains' reach, and only their pairs are joined.
    const auto tested = as_tested(given, out.pixel);
    const std::span<const ChainGeom> chains = tested;
    const auto segs = make_segments(chains, out.pixel, opt);
    const auto adj = graph_of(chains, segs);
    for (const auto& l : adj) {
        out.conflict_edges += l.size();
    }
    out.conflict_edges /= 2;

    Tiler tiler{chains, segs, {}, adj, opt, out};
    tiler.seg_begin.assign(chains.size() + 1, 0);
    for (const auto& s : segs) {
        ++tiler.seg_begin[s.chain + 1];
    }
    for (size_t c = 0; c < chains.size(); ++c) {
        tiler.seg_begin[c + 1] += tiler.seg_begin[c];
    }
    // The tile grid covers the owned chains' reach.
    ReachBox reach;
    for (const auto& s : segs) {
        if (chains[s.chain].owned) {
            reach.add(s);
        }
    }
    if (reach.empty()) {
        return out;
    }
    const double x0 = reach.x0, y0 = reach.y0, x1 = reach.x1, y1 = reach.y1;
    const double size = opt.tile_pixels * out.pixel;
    const auto nx = static_cast<uint64_t>(std::ceil((x1 - x0) / size)) + (x1 == x0 ? 1 : 0);
    const auto ny = static_cast<uint64_t>(std::ceil((y1 - y0) / size)) + (y1 == y0 ? 1 : 0);
    // Members of each top-level tile: the tiles each segment's reach touches.
    // A chain's segments mostly fall in the tile of the one before: that
    // pair is entered once (tiles of 2048 km at 2000 m hold whole stores).
    std::vector<std::pair<uint64_t, uint32_t>> member_of;
    for (const auto& s : segs) {
        cover_cells(s.ax, s.ay, s.bx, s.by, s.r, size, x0, y0, [&](int64_t tx, int64_t ty) {
            if (tx >= 0 && ty >= 0 && uint64_t(tx) < nx && uint64_t(ty) < ny) {
                const std::pair<uint64_t, uint32_t> e{uint64_t(ty) * nx + uint64_t(tx), s.chain};
                if (member_of.empty() || member_of.back() != e) {
                    member_of.push_back(e);
                }
            }
        });
    }
    radix_sort_pairs(member_of); // each tile's chains in increasing order
    member_of.erase(std::unique(member_of.begin(), member_of.end()), member_of.end());
    for (size_t b = 0; b < member_of.size();) {
        size_t e = b;
        std::vector<uint32_t> members;
        while (e < member_of.size() && member_of[e].first == member_of[b].first) {
            members.push_back(member_of[e].second);
            ++e;
        }
        const uint64_t t = member_of[b].first;
        TileSpec spec;
        spec.pixel = out.pixel;
        spec.width = spec.height = opt.tile_pixels;
        spec.x0 = x0 + double(t % nx) * size;
        spec.y0 = y0 + double(t / nx) * size;
        tiler.color(spec, std::move(members), 0);
        b = e;
    }
    size_t sum = 0;
    for (const auto& t : out.tiles) {
        const uint32_t m = t.classes.empty() ? 0 : *std::max_element(t.classes.begin(), t.classes.end());
        out.max_classes_used = std::max(out.max_classes_used, m);
        sum += m;
    }
    out.mean_classes = out.tiles.empty() ? 0 : double(sum) / double(out.tiles.size());
    return out;
}

} // namespace tigerlod::simplify
