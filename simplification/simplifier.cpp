#include "simplification/simplifier.hpp"

#include "core/parallel.hpp"
#include "core/projection.hpp"
#include "core/segment_grid.hpp"
#include "simplification/candidates.hpp"
#include "simplification/cell_cover.hpp"
#include "simplification/near_parts.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <future>
#include <iomanip>
#include <optional>
#include <sstream>
#include <stdexcept>

namespace tigerlod::simplify {

using chains::ChainStore;

void ToleranceStats::add(const ToleranceStats& o)
{
    chains += o.chains;
    input_vertices += o.input_vertices;
    output_vertices += o.output_vertices;
    candidates += o.candidates;
    drawn_segments += o.drawn_segments;
    drawn_parts += o.drawn_parts;
    drawn_pixels += o.drawn_pixels;
    tent_segments += o.tent_segments;
    tent_segments_skipped += o.tent_segments_skipped;
    proved_far += o.proved_far;
    banned_raster += o.banned_raster;
    banned_exact += o.banned_exact;
    banned_border += o.banned_border;
    banned_points += o.banned_points;
    self_intersection_repairs += o.self_intersection_repairs;
    orientation_repairs += o.orientation_repairs;
    input_conflicts += o.input_conflicts;
    rounds += o.rounds;
    tiles += o.tiles;
    splits += o.splits;
    max_classes = std::max(max_classes, o.max_classes);
    seconds_color += o.seconds_color;
    seconds_candidates += o.seconds_candidates;
    seconds_voronoi += o.seconds_voronoi;
    seconds_compliance += o.seconds_compliance;
    seconds_constraints += o.seconds_constraints;
    seconds_shortest_path += o.seconds_shortest_path;
    seconds_exact += o.seconds_exact;
    seconds_far += o.seconds_far;
}

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0)
{
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

/// The mean length of the store's segments, in grid units (0 if none).
double mean_segment_length(const ChainStore& store)
{
    double sum = 0;
    size_t n = 0;
    for (const auto& c : store.chains) {
        const auto pts = store.chain_points(c);
        for (size_t i = 0; i + 1 < pts.size(); ++i) {
            const double dx = double(pts[i + 1].x) - pts[i].x, dy = double(pts[i + 1].y) - pts[i].y;
            sum += std::sqrt(dx * dx + dy * dy); // sets a cell size only: no need for hypot's care
            ++n;
        }
    }
    return n ? sum / double(n) : 0.0;
}

/// Lazy rounds per chain before its remaining shortcuts are tested at once,
/// if they are at most `rest_rounds` rounds' worth.
constexpr uint32_t lazy_rounds = 3;
constexpr size_t rest_rounds = 8;

enum State : uint8_t { unknown = 0, good = 1, bad_raster = 2, bad_exact = 3, bad_points = 4 };

/// Per owned chain.
struct Work {
    uint32_t chain = 0; ///< index in store.chains
    Tolerance tol;
    bool ring = false;
    bool fixed = false; ///< problem chain: kept as it is
    Candidates cand;
    std::vector<uint8_t> state;          ///< per shortcut id
    std::vector<uint32_t> path;          ///< vertex indices
    std::vector<uint32_t> path_cand;     ///< candidate index of each path edge, UINT32_MAX for an original edge
    std::vector<uint32_t> checked;       ///< the path the last exact check saw (empty before the first)
    std::vector<uint8_t> border_checked; ///< per shortcut id: the border rule has looked at it (empty before)
    uint32_t rounds = 0;                 ///< lazy rounds that tested this chain
    bool dirty = true;                   ///< path must be recomputed
};

/// A segment of a store in the far rule's grid: its chain and index.
struct GridSeg {
    uint32_t chain, index;
};

/// Twice the signed area of the ring through pts[at(0)], pts[at(1)], ..., pts[at(n-1)].
template <class At> int128 signed_area2(std::span<const GridPoint> pts, size_t n, At at)
{
    int128 a = 0;
    for (size_t i = 0; i + 1 < n; ++i) {
        const GridPoint p = pts[at(i)], q = pts[at(i + 1)];
        a += int128{p.x} * q.y - int128{q.x} * p.y;
    }
    return a;
}

/// Fewest-vertex path 0 -> n-1 over original edges and the candidates not
/// banned, with at least R edges (a ring 3, so it keeps three vertices);
/// among shortest paths, the lexicographically largest vertex sequence (a
/// total order, so lazy and exhaustive testing choose the same path).
void shortest_path(Work& w, size_t n)
{
    // Layer r holds the fewest edges to n-1 using at least r of them. An
    // open chain needs no layer beyond 0: every path from 0 to n-1 > 0 has
    // an edge (a second layer computed the same values again).
    const uint32_t R = w.ring ? 3 : 0;
    constexpr uint32_t inf = UINT32_MAX / 2;
    std::vector<uint32_t> f((R + 1) * n, inf), next((R + 1) * n, 0), via((R + 1) * n, UINT32_MAX);
    auto at = [n](uint32_t r, size_t v) { return r * n + v; };
    f[at(0, n - 1)] = 0;
    for (size_t vv = n - 1; vv-- > 0;) {
        const auto v = static_cast<uint32_t>(vv);
        for (uint32_t r = 0; r <= R; ++r) {
            const uint32_t rr = r > 0 ? r - 1 : 0;
            uint32_t best = inf, bk = 0, bc = UINT32_MAX;
            // Candidates from v, farthest first; ties keep the farthest.
            const auto runs = w.cand.runs_from(v);
            for (size_t q = runs.size(); q-- > 0;) {
                const auto& run = runs[q];
                const uint32_t id0 = w.cand.run_id(w.cand.first_run(v) + q);
                for (uint32_t k = run.hi + 1; k-- > run.lo;) {
                    if (f[at(rr, k)] + 1 < best && w.state[id0 + (k - run.lo)] < bad_raster) {
                        best = f[at(rr, k)] + 1;
                        bk = k;
                        bc = id0 + (k - run.lo);
                    }
                }
            }
            if (f[at(rr, v + 1)] + 1 < best) {
                best = f[at(rr, v + 1)] + 1;
                bk = v + 1;
                bc = UINT32_MAX;
            }
            f[at(r, v)] = best;
            next[at(r, v)] = bk;
            via[at(r, v)] = bc;
        }
    }
    w.path.clear();
    w.path_cand.clear();
    uint32_t v = 0, r = R;
    w.path.push_back(0);
    while (v != n - 1) {
        const uint32_t k = next[at(r, v)];
        w.path_cand.push_back(via[at(r, v)]);
        r = r > 0 ? r - 1 : 0;
        v = k;
        w.path.push_back(v);
    }
}

/// Points that constrain chain `self`: near it, and not its own representative.
struct PointIndex {
    struct Entry {
        GridPoint p;
        uint32_t owner; ///< chain whose representative it is, or UINT32_MAX
    };
    std::vector<Entry> entries; // sorted by x
    void finish()
    {
        std::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) {
            return std::tie(a.p.x, a.p.y, a.owner) < std::tie(b.p.x, b.p.y, b.owner);
        });
        // A junction is the end of every chain that meets there.
        entries.erase(std::unique(entries.begin(), entries.end(),
                                  [](const Entry& a, const Entry& b) { return a.p == b.p && a.owner == b.owner; }),
                      entries.end());
    }
    std::vector<GridPoint> near(const GridBox& box, uint32_t self) const
    {
        std::vector<GridPoint> out;
        auto it = std::lower_bound(entries.begin(), entries.end(), box.min_x,
                                   [](const Entry& e, int64_t x) { return e.p.x < x; });
        for (; it != entries.end() && it->p.x <= box.max_x; ++it) {
            if (it->p.y >= box.min_y && it->p.y <= box.max_y && it->owner != self) {
                out.push_back(it->p);
            }
        }
        return out;
    }
};

} // namespace

namespace {

/// The border rule (formats/chains/SPEC.md, "The partition contract"): a
/// shortcut of an owned chain o may not meet any proximate shortcut of a
/// halo chain h with a smaller id that comes near it. h's own partition can
/// only ever pick h's shortcuts among those (the same scan on the same
/// points at the same eps), and it checks them against o's original edges,
/// as this store checks o's path against h's; so however the two partitions
/// are simplified, apart, their chains cannot meet. Every point of a
/// proximate shortcut lies within eps_h (as an L2 distance: x l2_reach) of a
/// segment of its subchain (near_parts.hpp), so only the shortcuts of h
/// spanning a segment that near are listed; h's are computed once per store,
/// when a path first comes near it.
class BorderRule {
  public:
    BorderRule(const ChainStore& store, std::span<const double> eps, const SimplifyOptions& opt)
        : m_store(store), m_eps(eps), m_opt(opt), m_cand(store.chains.size()), m_done(store.chains.size(), 0),
          m_span(store.chains.size(), 0)
    {
        for (uint32_t i = 0; i < store.chains.size(); ++i) {
            if (store.chains[i].flags & chains::chain_halo) {
                m_eps_max = std::max(m_eps_max, eps[i]);
            }
        }
    }

    /// Bans the path shortcuts of `work` not looked at before that meet a
    /// halo chain's shortcut, finding halo segments near them in the far
    /// rule's grid (`cells` of side `cell`, `grid_cells`); `ball_l2` is the
    /// metric's l2_reach. Returns whether it banned one.
    bool ban(std::vector<Work>& work, const CellGrid& cells, const CellBuckets<GridSeg>& grid_cells, double cell,
             double ball_l2, ToleranceStats& st)
    {
        if (m_eps_max == 0) {
            return false; // no halo: a single partition
        }
        struct Query {
            uint32_t work, cand, halo, kmin, kmax;
        };
        std::vector<std::vector<Query>> per_work(work.size());
        parallel_each(work.size(), m_opt.threads, [&](size_t wi) {
            Work& w = work[wi];
            if (w.cand.empty()) {
                return;
            }
            if (w.border_checked.empty()) {
                w.border_checked.assign(w.cand.size(), 0);
            }
            const auto pts = m_store.chain_points(m_store.chains[w.chain]);
            const uint64_t own_id = m_store.chains[w.chain].id;
            std::vector<Query> found;
            for (size_t e = 0; e < w.path_cand.size(); ++e) {
                const uint32_t ci = w.path_cand[e];
                if (ci == UINT32_MAX || w.border_checked[ci]) {
                    continue;
                }
                w.border_checked[ci] = 1;
                const GridPoint a = pts[w.path[e]], b = pts[w.path[e + 1]];
                found.clear();
                cover_cells(a.x, a.y, b.x, b.y, m_eps_max * ball_l2 + 2, cell, 0.0, 0.0, [&](int64_t x, int64_t y) {
                    if (!cells.contains(x, y)) {
                        return;
                    }
                    for (const GridSeg gs : grid_cells.find(cells.key(x, y))) {
                        const auto& hc = m_store.chains[gs.chain];
                        if (!(hc.flags & chains::chain_halo) || (hc.flags & chains::chain_problem) || hc.id >= own_id) {
                            continue;
                        }
                        const auto hp = m_store.chain_points(hc);
                        // 2 grid units of slack for the rounding of the distance.
                        if (segment_distance(a, b, hp[gs.index], hp[gs.index + 1]) > m_eps[gs.chain] * ball_l2 + 2) {
                            continue;
                        }
                        found.push_back({static_cast<uint32_t>(wi), ci, gs.chain, gs.index, gs.index});
                    }
                });
                // One query per halo chain, over the hull of its near segments.
                std::sort(found.begin(), found.end(), [](const Query& p, const Query& q) { return p.halo < q.halo; });
                for (size_t k = 0; k < found.size();) {
                    Query q = found[k];
                    for (++k; k < found.size() && found[k].halo == q.halo; ++k) {
                        q.kmin = std::min(q.kmin, found[k].kmin);
                        q.kmax = std::max(q.kmax, found[k].kmax);
                    }
                    per_work[wi].push_back(q);
                }
            }
        });
        std::vector<Query> queries;
        for (auto& q : per_work) {
            queries.insert(queries.end(), q.begin(), q.end());
        }
        if (queries.empty()) {
            return false;
        }
        // The halo chains' shortcuts, once per m_store.
        std::vector<uint32_t> need;
        for (const Query& q : queries) {
            if (!m_done[q.halo]) {
                m_done[q.halo] = 1;
                need.push_back(q.halo);
            }
        }
        parallel_each(need.size(), m_opt.threads, [&](size_t k) {
            const uint32_t h = need[k];
            m_cand[h] = proximate_shortcuts(m_store.chain_points(m_store.chains[h]), Tolerance(m_eps[h], m_opt.metric),
                                            m_opt.max_reach);
            for (const auto& run : m_cand[h].runs()) {
                m_span[h] = std::max(m_span[h], run.hi - run.from);
            }
        });
        std::vector<uint8_t> meets(queries.size(), 0);
        parallel_blocks(queries.size(), m_opt.threads, 16, [&](size_t qb, size_t qe) {
            for (size_t qi = qb; qi < qe; ++qi) {
                const Query& q = queries[qi];
                const auto pts = m_store.chain_points(m_store.chains[work[q.work].chain]);
                const Shortcut sc = work[q.work].cand.at(q.cand);
                const GridPoint a = pts[sc.from], b = pts[sc.to];
                const auto hp = m_store.chain_points(m_store.chains[q.halo]);
                const Candidates& hc = m_cand[q.halo];
                const GridBox sbox = [&] {
                    GridBox box;
                    box.extend(a);
                    box.extend(b);
                    return box;
                }();
                // Shortcuts from <= kmax to > kmin span a near segment's hull;
                // none starts more than the longest span before kmin + 1.
                const uint32_t first = q.kmin + 1 > m_span[q.halo] ? q.kmin + 1 - m_span[q.halo] : 0;
                for (const auto& run : hc.empty() ? std::span<const Candidates::Run>{}
                                                  : hc.runs().subspan(hc.first_run(first),
                                                                      hc.first_run(q.kmax + 1) - hc.first_run(first))) {
                    if (run.hi <= q.kmin) {
                        continue;
                    }
                    for (uint32_t to = std::max(run.lo, q.kmin + 1); to <= run.hi && !meets[qi]; ++to) {
                        const GridPoint c = hp[run.from], d = hp[to];
                        GridBox cbox;
                        cbox.extend(c);
                        cbox.extend(d);
                        if (!cbox.intersects(sbox)) {
                            continue;
                        }
                        const auto rel = segment_relation(a, b, c, d);
                        meets[qi] = rel != SegmentRelation::disjoint && rel != SegmentRelation::shared_endpoint;
                    }
                    if (meets[qi]) {
                        break;
                    }
                }
            }
        });
        bool banned = false;
        for (size_t qi = 0; qi < queries.size(); ++qi) {
            Work& w = work[queries[qi].work];
            if (meets[qi] && w.state[queries[qi].cand] != bad_exact) {
                w.state[queries[qi].cand] = bad_exact;
                w.dirty = true;
                ++st.banned_border;
                banned = true;
            }
        }
        return banned;
    }

  private:
    const ChainStore& m_store;
    std::span<const double> m_eps;
    const SimplifyOptions& m_opt;
    std::vector<Candidates> m_cand; ///< each halo chain's shortcuts, once needed
    std::vector<uint8_t> m_done;    ///< whether m_cand holds them
    std::vector<uint32_t> m_span;   ///< the longest shortcut of each, in vertices
    double m_eps_max = 0;           ///< the largest halo chain's tolerance; 0 without a halo
};                                  // class BorderRule

} // namespace

ChainStore simplify_store(const ChainStore& store, double eps_m, const SimplifyOptions& opt, Raster& raster,
                          const ColorResult* colors, ToleranceStats& st)
{
    st.eps_m = eps_m;
    const auto eps = chain_tolerances(store, eps_m, opt);
    auto t0 = Clock::now();
    const auto keep = segments_in_reach(store, halo_reach(eps, opt));
    // The colouring runs on a thread of its own beside the candidates, the
    // point constraints and the far rule, which do not need it: it is one
    // thread's work (contours at 16 m: 0.21 s), and a single store's other
    // steps would leave the second core idle for it.
    ColorResult own_colors;
    std::future<std::pair<ColorResult, double>> colouring;
    if (!colors) {
        auto colour = [&] {
            const auto c0 = Clock::now();
            auto result = color_chains(store, eps, keep, opt);
            return std::pair{std::move(result), since(c0)};
        };
        colouring = std::async(opt.threads > 1 ? std::launch::async : std::launch::deferred, colour);
    }
    st.seconds_color += since(t0);
    const double pixel = colors ? colors->pixel : tile_pixel(eps, opt.color); // colors->pixel once known

    // Owned chains to simplify.
    std::vector<Work> work;
    for (uint32_t i = 0; i < store.chains.size(); ++i) {
        const auto& c = store.chains[i];
        if (c.flags & chains::chain_halo) {
            continue;
        }
        Work w;
        w.chain = i;
        w.tol = Tolerance(eps[i], opt.metric);
        w.ring = (c.flags & chains::chain_closed) != 0;
        w.fixed = (c.flags & chains::chain_problem) != 0;
        work.push_back(std::move(w));
        ++st.chains;
        st.input_vertices += c.count;
    }
    auto points_of = [&](const Work& w) { return store.chain_points(store.chains[w.chain]); };

    // Candidates (exact proximity).
    t0 = Clock::now();
    parallel_each(work.size(), opt.threads, [&](size_t i) {
        Work& w = work[i];
        if (!w.fixed) {
            w.cand = proximate_shortcuts(points_of(w), w.tol, opt.max_reach);
        }
    });
    st.seconds_candidates += since(t0);

    // Step 3's point constraints, culled up front: units' internal points,
    // user points, and one vertex of every other chain (an island keeps its side).
    t0 = Clock::now();
    PointIndex index;
    if (opt.point_constraints) {
        for (const auto& cp : store.constraints) {
            index.entries.push_back({cp.p, UINT32_MAX});
        }
        if (!opt.user_points.empty()) {
            const Projection proj(store.projection);
            for (const auto& u : opt.user_points) {
                if (const auto g = proj.to_grid(u.lon, u.lat)) {
                    index.entries.push_back({*g, UINT32_MAX});
                }
            }
        }
    }
    // A chain of two vertices has no middle one: both its ends stand for it
    // (a group of straight chains between junctions, wholly inside the
    // region of a shortcut, would otherwise pass to the other side of it).
    // A junction at a shortcut's own end does not count (cull_by_points).
    for (uint32_t i = 0; i < store.chains.size(); ++i) {
        const auto pts = store.chain_points(store.chains[i]);
        if (pts.size() >= 3) {
            index.entries.push_back({pts[pts.size() / 2], i});
        } else if (pts.size() == 2) {
            index.entries.push_back({pts.front(), UINT32_MAX});
            index.entries.push_back({pts.back(), UINT32_MAX});
        }
    }
    index.finish();
    std::vector<std::vector<uint32_t>> culled(work.size());
    parallel_each(work.size(), opt.threads, [&](size_t i) {
        Work& w = work[i];
        if (w.cand.empty()) {
            return;
        }
        const auto pts = points_of(w);
        GridBox box;
        for (const GridPoint p : pts) {
            box.extend(p);
        }
        const auto r = static_cast<int64_t>(std::ceil(2 * w.tol.eps * l2_reach(opt.metric))) + 1;
        box.min_x -= r;
        box.min_y -= r;
        box.max_x += r;
        box.max_y += r;
        culled[i] = cull_by_points(pts, w.cand, index.near(box, w.chain));
    });
    for (size_t i = 0; i < work.size(); ++i) {
        Work& w = work[i];
        st.banned_points += culled[i].size();
        st.candidates += w.cand.size() - culled[i].size();
        w.state.assign(w.cand.size(), unknown);
        for (const uint32_t id : culled[i]) {
            w.state[id] = bad_points;
        }
    }
    st.seconds_constraints += since(t0);

    // A shortcut farther from every other chain than that chain's reach
    // (eps_j in the metric plus the colouring margin) lies in its own
    // chain's eps-Voronoi region: proximate shortcuts stay within eps_i of
    // their chain in the metric (near_parts.hpp: in any norm), so within
    // eps_i x l2_reach as an L2 distance, and no other region comes near.
    // Those skip the raster.
    t0 = Clock::now();
    const double ball_l2 = l2_reach(opt.metric); // the metric's unit ball lies in the L2 disc of this radius
    const double margin = pixel * opt.color.margin_px;
    double reach_max = 0;
    for (const double e : eps) {
        reach_max = std::max(reach_max, e * ball_l2 + margin);
    }
    // Cells at least three mean segments wide: at 1 m a 2 x reach cell is
    // 3 m, and a county's 100 m segments each filled dozens of them (74 s of
    // the tract ladder's 1 m step); one mean segment still made a query visit
    // nine cells (far rule on the tract level at 16 m 0.65 -> 0.40 s with
    // three, contours 0.52 -> 0.39 s; four was slower on the contours). The
    // answer does not depend on the size.
    const double cell = std::max({2 * reach_max, 3 * mean_segment_length(store), 1.0});
    std::vector<std::pair<uint64_t, GridSeg>> grid; // (cell, segment), segments in (chain, index) order
    // Each segment goes in the cells it passes through (not its bounding box:
    // a 10 km diagonal at 1 m covers 25 M cells of its box, measured at 17 GB).
    GridBox extent;
    for (uint32_t c = 0; c < store.chains.size(); ++c) {
        for (const GridPoint p : store.chain_points(store.chains[c])) {
            extent.extend(p);
        }
    }
    const CellGrid cells = extent.empty() ? CellGrid{}
                                          : CellGrid(double(extent.min_x), double(extent.min_y), double(extent.max_x),
                                                     double(extent.max_y), cell);
    for (uint32_t c = 0; c < store.chains.size(); ++c) {
        const auto pts = store.chain_points(store.chains[c]);
        const auto use = keep_of(keep, store.chains[c]);
        for (uint32_t i = 0; i + 1 < pts.size(); ++i) {
            if (!takes_part(use, i)) {
                continue;
            }
            cover_cells(pts[i].x, pts[i].y, pts[i + 1].x, pts[i + 1].y, 0.0, cell, 0.0, 0.0, [&](int64_t x, int64_t y) {
                grid.emplace_back(cells.key(x, y), GridSeg{c, i});
            });
        }
    }
    const CellBuckets<GridSeg> grid_cells(grid); // each cell's segments in (chain, index) order
    grid = {};
    // The part of segment ab that another chain's segment comes within r of
    // (the hull of those parts, as parameters along ab), or nothing.
    auto near_other = [&](uint32_t chain, GridPoint a, GridPoint b, double r) {
        std::optional<std::pair<double, double>> near;
        const double reach = r * (1 + 1e-9) + 1;
        // The cells within r of ab (a segment within r of ab passes through one).
        cover_cells(a.x, a.y, b.x, b.y, r, cell, 0.0, 0.0, [&](int64_t x, int64_t y) {
            if (near && near->first == 0 && near->second == 1) {
                return; // the whole segment already
            }
            if (!cells.contains(x, y)) {
                return; // beyond every segment of the store
            }
            for (const GridSeg gs : grid_cells.find(cells.key(x, y))) {
                if (gs.chain == chain) {
                    continue;
                }
                const auto p = store.chain_points(store.chains[gs.chain]);
                const GridPoint c = p[gs.index], d = p[gs.index + 1];
                // Boxes farther apart than the reach on an axis first (dense
                // maps put dozens of segments in a query's cells).
                if (double(std::min(c.x, d.x)) - std::max(a.x, b.x) > reach ||
                    double(std::min(a.x, b.x)) - std::max(c.x, d.x) > reach ||
                    double(std::min(c.y, d.y)) - std::max(a.y, b.y) > reach ||
                    double(std::min(a.y, b.y)) - std::max(c.y, d.y) > reach || segment_distance(a, b, c, d) > reach) {
                    continue;
                }
                // Within reach: the part of ab near it; all of ab when ab is a point.
                const auto iv = a == b ? std::optional{std::pair{0.0, 1.0}} : capsule_interval(a, b, c, d, reach);
                const auto part = iv ? *iv : std::pair{0.0, 1.0}; // rounding: take all of it
                near = near ? std::pair{std::min(near->first, part.first), std::max(near->second, part.second)} : part;
            }
        });
        return near;
    };
    // Per owned chain, prefix counts of its segments that have another chain
    // within eps_i x l2_reach + the largest reach (L2): a shortcut spanning
    // only clear segments lies within eps_i x l2_reach of them, so farther
    // than any other chain's reach from that chain. And the blocked segments
    // with the part of each that is near another chain, for the parts of a
    // shortcut that can fail (near_parts.hpp).
    std::vector<std::vector<uint32_t>> blocked(work.size());
    std::vector<std::vector<NearSegment>> blocked_at(work.size());
    parallel_each(work.size(), opt.threads, [&](size_t wi) {
        const Work& w = work[wi];
        if (w.cand.empty() || !opt.far_rule) {
            return;
        }
        const auto pts = points_of(w);
        auto& b = blocked[wi];
        b.assign(pts.size(), 0);
        for (size_t k = 0; k + 1 < pts.size(); ++k) {
            const auto near = near_other(w.chain, pts[k], pts[k + 1], w.tol.eps * ball_l2 + reach_max);
            b[k + 1] = b[k] + (near ? 1 : 0);
            if (near) {
                // Widened by 2 grid units for rounding.
                const double len = std::hypot(double(pts[k + 1].x) - pts[k].x, double(pts[k + 1].y) - pts[k].y);
                const double pad = len > 0 ? 2 / len : 1;
                blocked_at[wi].push_back(
                    {static_cast<uint32_t>(k), std::max(0.0, near->first - pad), std::min(1.0, near->second + pad)});
            }
        }
    });

    st.seconds_far += since(t0);

    if (colouring.valid()) {
        auto [result, seconds] = colouring.get();
        own_colors = std::move(result);
        colors = &own_colors;
        st.seconds_color += seconds;
    }
    if (colors->pixel != pixel) {
        throw std::logic_error("simplify: the tiles' pixel is not the one the far rule took");
    }
    st.tiles += colors->tiles.size();
    st.splits += colors->splits;
    st.max_classes = std::max(st.max_classes, colors->max_classes_used);

    // Tiles each owned chain is drawn in, and its class there.
    std::vector<uint32_t> work_of(store.chains.size(), UINT32_MAX);
    for (uint32_t i = 0; i < work.size(); ++i) {
        work_of[work[i].chain] = i;
    }
    std::vector<std::vector<std::pair<uint32_t, uint8_t>>> tiles_of(work.size());
    for (uint32_t t = 0; t < colors->tiles.size(); ++t) {
        const auto& tile = colors->tiles[t];
        for (size_t m = 0; m < tile.chains.size(); ++m) {
            const uint32_t wi = work_of[tile.chains[m]];
            if (wi != UINT32_MAX) {
                tiles_of[wi].emplace_back(t, tile.classes[m]);
            }
        }
    }

    // The far rule: no blocked segment between the shortcut's ends.
    auto proved_far = [&](uint32_t wi, Shortcut sc) {
        const auto& b = blocked[wi];
        return !b.empty() && b[sc.to] == b[sc.from];
    };

    // Raster test of (work, candidate) pairs, tile by tile.
    auto raster_test = [&](const std::vector<std::pair<uint32_t, uint32_t>>& all_tests) {
        std::vector<std::pair<uint32_t, uint32_t>> tests;
        for (size_t t = 0; t < all_tests.size(); ++t) {
            if (proved_far(all_tests[t].first, work[all_tests[t].first].cand.at(all_tests[t].second))) {
                work[all_tests[t].first].state[all_tests[t].second] = good;
                ++st.proved_far;
            } else {
                tests.push_back(all_tests[t]);
            }
        }
        std::vector<std::vector<TestSegment>> per_tile(colors->tiles.size());
        std::vector<std::pair<double, double>> parts;
        for (uint32_t id = 0; id < tests.size(); ++id) {
            const auto [wi, ci] = tests[id];
            const auto pts = points_of(work[wi]);
            const Shortcut sc = work[wi].cand.at(ci);
            const GridPoint a = pts[sc.from], b = pts[sc.to];
            if (blocked[wi].empty() || !opt.clip_tests) {
                parts.assign(1, {0.0, 1.0});
            } else {
                // Slack of 2 grid units on the radius, and a pixel at each end of a part.
                parts =
                    near_parts(pts, sc.from, sc.to, blocked_at[wi], work[wi].tol.eps * ball_l2 + 2, colors->pixel + 2);
            }
            for (const auto& [p0, p1] : parts) {
                const double ax = a.x + p0 * double(b.x - a.x), ay = a.y + p0 * double(b.y - a.y);
                const double bx = a.x + p1 * double(b.x - a.x), by = a.y + p1 * double(b.y - a.y);
                for (const auto& [t, cls] : tiles_of[wi]) {
                    const TileSpec& s = colors->tiles[t].spec;
                    const double x1 = s.x0 + s.width * s.pixel, y1 = s.y0 + s.height * s.pixel;
                    if (std::max(ax, bx) + s.pixel < s.x0 || std::min(ax, bx) - s.pixel > x1 ||
                        std::max(ay, by) + s.pixel < s.y0 || std::min(ay, by) - s.pixel > y1) {
                        continue;
                    }
                    per_tile[t].push_back({a, b, cls, id, float(p0), float(p1)});
                }
            }
        }
        std::vector<uint8_t> fails(tests.size(), 0);
        size_t parts_in_all = 0;
        for (const auto& p : per_tile) {
            parts_in_all += p.size();
        }
        // What the tiles draw is worked out here, on this store's worker;
        // the GL thread, which every worker shares, only draws it.
        std::vector<uint32_t> drawn_tiles;
        for (uint32_t t = 0; t < per_tile.size(); ++t) {
            if (!per_tile[t].empty()) {
                drawn_tiles.push_back(t);
            }
        }
        std::vector<PreparedTile> prepared(drawn_tiles.size());
        parallel_each(drawn_tiles.size(), opt.threads, [&](size_t i) {
            const auto& tile = colors->tiles[drawn_tiles[i]];
            std::vector<TentChain> tents(tile.chains.size());
            for (size_t m = 0; m < tile.chains.size(); ++m) {
                const auto& c = store.chains[tile.chains[m]];
                tents[m] = {store.chain_points(c), eps[tile.chains[m]], tile.classes[m], keep_of(keep, c)};
            }
            prepared[i] = raster.prepare(tile.spec, tents, per_tile[drawn_tiles[i]]);
        });
        RasterStats before, after;
        auto gl_work = [&] {
            before = raster.stats();
            raster.begin_batch(parts_in_all);
            for (const auto& p : prepared) {
                raster.draw(p, fails);
            }
            raster.end_batch(fails);
            after = raster.stats();
        };
        if (opt.gl_thread) {
            opt.gl_thread(gl_work);
        } else {
            gl_work();
        }
        for (uint32_t id = 0; id < tests.size(); ++id) {
            const auto [wi, ci] = tests[id];
            work[wi].state[ci] = fails[id] ? bad_raster : good;
            st.banned_raster += fails[id];
        }
        st.drawn_segments += tests.size();
        st.drawn_parts += after.drawn_segments - before.drawn_segments;
        st.drawn_pixels += after.drawn_pixels - before.drawn_pixels;
        st.tent_segments += after.tent_segments - before.tent_segments;
        st.tent_segments_skipped += after.tent_segments_skipped - before.tent_segments_skipped;
        st.seconds_voronoi += after.voronoi_seconds - before.voronoi_seconds;
        st.seconds_compliance += after.compliance_seconds - before.compliance_seconds;
    };

    if (!opt.lazy) {
        // Every candidate, but only those the far rule cannot settle are
        // listed: listing all of them cost 8 bytes each (1 GB for one South
        // Dakota county map at 64 m, whose 65 M candidates are 98% far).
        std::vector<std::pair<uint32_t, uint32_t>> near;
        for (uint32_t wi = 0; wi < work.size(); ++wi) {
            auto& w = work[wi];
            const auto runs = w.cand.runs();
            for (size_t r = 0; r < runs.size(); ++r) {
                for (uint32_t k = runs[r].lo; k <= runs[r].hi; ++k) {
                    const uint32_t ci = w.cand.run_id(r) + (k - runs[r].lo);
                    if (w.state[ci] != unknown) {
                        continue; // culled by a point
                    }
                    if (proved_far(wi, {runs[r].from, k})) {
                        w.state[ci] = good;
                        ++st.proved_far;
                    } else {
                        near.emplace_back(wi, ci);
                    }
                }
            }
        }
        raster_test(near);
    }

    BorderRule border(store, eps, opt);

    bool checked_once = false;
    for (;;) {
        // Step 4 for the chains whose candidates changed, then test what the
        // paths use and has not been tested (lazy), until every path is clean.
        for (;;) {
            ++st.rounds;
            t0 = Clock::now();
            parallel_each(work.size(), opt.threads, [&](size_t i) {
                Work& w = work[i];
                if (!w.dirty) {
                    return;
                }
                const auto pts = points_of(w);
                shortest_path(w, pts.size());
                if (w.ring) {
                    // Keep the ring's orientation: ban the longest shortcut until it holds.
                    const int128 orig = signed_area2(pts, pts.size(), [](size_t k) { return k; });
                    for (;;) {
                        const int128 now = signed_area2(pts, w.path.size(), [&](size_t k) { return w.path[k]; });
                        if ((now > 0) == (orig > 0) && now != 0) {
                            break;
                        }
                        uint32_t worst = UINT32_MAX, span = 0;
                        for (size_t e = 0; e < w.path_cand.size(); ++e) {
                            if (w.path_cand[e] != UINT32_MAX && w.path[e + 1] - w.path[e] > span) {
                                span = w.path[e + 1] - w.path[e];
                                worst = w.path_cand[e];
                            }
                        }
                        if (worst == UINT32_MAX) {
                            break;
                        }
                        w.state[worst] = bad_exact;
                        ++st.orientation_repairs;
                        shortest_path(w, pts.size());
                    }
                }
            });
            st.seconds_shortest_path += since(t0);
            // Lazy: test every untested shortcut that starts at a vertex of
            // the current path (the path's own among them). A path of P
            // vertices over shortcuts reaching w ahead costs about P * w = n
            // segments, not the n * w of testing every candidate, and the
            // alternatives a failure needs are mostly tested already, so the
            // rounds (each a redraw of the tiles involved) stay few. The
            // result is the same as testing all: the path is the smallest
            // shortest path over the shortcuts that pass, whatever was tested.
            std::vector<std::pair<uint32_t, uint32_t>> tests;
            for (uint32_t wi = 0; wi < work.size(); ++wi) {
                Work& w = work[wi];
                if (!w.dirty) {
                    continue;
                }
                const size_t before = tests.size();
                for (const uint32_t v : w.path) {
                    for (uint32_t c = w.cand.first_id(v); c < w.cand.first_id(v + 1); ++c) {
                        if (w.state[c] == unknown) {
                            tests.emplace_back(wi, c);
                        }
                    }
                }
                if (++w.rounds > lazy_rounds) {
                    // Still failing after a few rounds: test the rest at once
                    // rather than pay a redraw of its tiles per round, unless
                    // the rest is many rounds' worth (a coarse tolerance: a
                    // chain of n vertices has n x w shortcuts, most of which
                    // no path would take; tract set at 2000 m, 10.9 M tested).
                    const size_t round = tests.size() - before;
                    size_t rest = 0;
                    for (uint32_t c = 0; c < w.cand.size() && rest <= rest_rounds * round; ++c) {
                        rest += w.state[c] == unknown ? 1 : 0;
                    }
                    if (rest <= rest_rounds * round) {
                        tests.resize(before);
                        for (uint32_t c = 0; c < w.cand.size(); ++c) {
                            if (w.state[c] == unknown) {
                                tests.emplace_back(wi, c);
                            }
                        }
                    }
                }
            }
            if (tests.empty()) {
                for (Work& w : work) {
                    w.dirty = false;
                }
                break;
            }
            raster_test(tests);
            // Chains whose tested shortcuts all passed keep their paths.
            std::vector<uint8_t> failed(work.size(), 0);
            for (const auto& [wi, ci] : tests) {
                failed[wi] |= work[wi].state[ci] != good; // the far ones were marked good
            }
            for (uint32_t wi = 0; wi < work.size(); ++wi) {
                work[wi].dirty = failed[wi] != 0;
            }
        }

        // Exact safety net: simplified owned chains against each other and the halo.
        t0 = Clock::now();
        std::vector<Segment> segs;
        struct Tag {
            uint32_t work; ///< UINT32_MAX for a halo chain
            uint32_t cand; ///< candidate index, UINT32_MAX for an original edge
            uint32_t chain;
        };
        std::vector<Tag> tags;
        // After the first check only the edges that are new in a path can
        // meet anything new: a pair of edges both present at the last check
        // was found then. So each meeting pair is found once, in the first
        // check that has both, and a repair costs what it changed.
        const bool first_check = !checked_once;
        std::vector<uint8_t> is_new;
        for (uint32_t wi = 0; wi < work.size(); ++wi) {
            const auto pts = points_of(work[wi]);
            auto& w = work[wi];
            const bool same = w.path == w.checked;
            for (size_t e = 0; e + 1 < w.path.size(); ++e) {
                segs.push_back({pts[w.path[e]], pts[w.path[e + 1]], static_cast<uint32_t>(tags.size())});
                tags.push_back({wi, w.path_cand[e], w.chain});
                if (first_check) {
                    continue;
                }
                bool had = same;
                if (!had) {
                    // Paths rise through the vertices: the old edge from path[e], if any.
                    const auto it = std::lower_bound(w.checked.begin(), w.checked.end(), w.path[e]);
                    had = it != w.checked.end() && *it == w.path[e] && it + 1 != w.checked.end() &&
                          it[1] == w.path[e + 1];
                }
                is_new.push_back(had ? 0 : 1);
            }
            if (!same) {
                w.checked = w.path;
            }
        }
        checked_once = true;
        for (uint32_t i = 0; i < store.chains.size(); ++i) {
            if (!(store.chains[i].flags & chains::chain_halo)) {
                continue;
            }
            const auto pts = store.chain_points(store.chains[i]);
            const auto use = keep_of(keep, store.chains[i]);
            for (size_t e = 0; e + 1 < pts.size(); ++e) {
                if (!takes_part(use, e)) {
                    continue;
                }
                segs.push_back({pts[e], pts[e + 1], static_cast<uint32_t>(tags.size())});
                tags.push_back({UINT32_MAX, UINT32_MAX, i});
                if (!first_check) {
                    is_new.push_back(0);
                }
            }
        }
        bool banned_any = false;
        const auto meets =
            first_check ? find_intersections(segs, opt.threads) : find_intersections(segs, is_new, opt.threads);
        for (const auto& x : meets) {
            const Tag& a = tags[segs[x.first].tag];
            const Tag& b = tags[segs[x.second].tag];
            bool banned = false;
            for (const Tag* t : {&a, &b}) {
                if (t->work != UINT32_MAX && t->cand != UINT32_MAX) {
                    Work& w = work[t->work];
                    if (w.state[t->cand] != bad_exact) {
                        w.state[t->cand] = bad_exact;
                        w.dirty = true;
                        ++st.banned_exact;
                    }
                    banned = true;
                }
            }
            if (!banned) {
                ++st.input_conflicts;
            } else if (a.chain == b.chain) {
                ++st.self_intersection_repairs;
            }
            banned_any |= banned;
        }
        banned_any |= border.ban(work, cells, grid_cells, cell, ball_l2, st);
        st.seconds_exact += since(t0);
        if (!banned_any) {
            break;
        }
    }

    ChainStore out;
    out.level_index = store.level_index;
    out.level_count = store.level_count;
    out.level_name = store.level_name;
    out.partition = store.partition;
    out.projection = store.projection;
    out.halo_m = store.halo_m;
    out.eps_m = eps_m;
    out.metric = static_cast<uint8_t>(opt.metric);
    out.strings = store.strings;
    out.junctions = store.junctions;
    out.constraints = store.constraints;
    std::vector<GridPoint> buf;
    for (const Work& w : work) {
        const auto pts = points_of(w);
        buf.clear();
        for (const uint32_t v : w.path) {
            buf.push_back(pts[v]);
        }
        chains::ChainInfo info = store.chains[w.chain];
        out.add_chain(info, buf);
        st.output_vertices += buf.size();
    }
    out.canonicalize();
    return out;
}

} // namespace tigerlod::simplify
