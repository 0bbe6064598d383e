#include "simplification/simplifier.hpp"

#include "core/parallel.hpp"
#include "core/projection.hpp"
#include "core/segment_grid.hpp"
#include "core/timing.hpp"
#include "simplification/candidates.hpp"
#include "simplification/cell_cover.hpp"
#include "simplification/fewest_edges.hpp"
#include "simplification/near_parts.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <future>
#include <iomanip>
#include <map>
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
    proved_short += o.proved_short;
    banned_raster += o.banned_raster;
    banned_exact += o.banned_exact;
    banned_region += o.banned_region;
    banned_points += o.banned_points;
    self_intersection_repairs += o.self_intersection_repairs;
    orientation_repairs += o.orientation_repairs;
    input_conflicts += o.input_conflicts;
    reach_capped_chains += o.reach_capped_chains;
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

/// Searches the region rule sends a chain back to before it is asked inside
/// the search (StoreSimplifier::shortest_path).
constexpr uint32_t lazy_region_after = 2;

/// Lazy rounds per chain before its remaining shortcuts are tested at once,
/// if they are at most `rest_rounds` rounds' worth.
constexpr uint32_t lazy_rounds = 3;
constexpr size_t rest_rounds = 8;

enum State : uint8_t { unknown = 0, good = 1, bad_raster = 2, bad_exact = 3, bad_points = 4 };
static_assert(bad_raster == first_banned_state, "fewest_edges_path takes the states from bad_raster on as banned");

/// Per owned chain.
struct Work {
    uint32_t chain = 0; ///< index in store.chains
    Tolerance tol;
    bool ring = false;
    bool fixed = false; ///< problem chain: kept as it is
    Candidates cand;
    std::vector<uint8_t> state;         ///< per shortcut id
    std::vector<uint32_t> path;         ///< vertex indices
    std::vector<uint32_t> path_cand;    ///< candidate index of each path edge, UINT32_MAX for an original edge
    std::vector<uint32_t> checked;      ///< the path the last exact check saw (empty before the first)
    std::vector<uint32_t> region_clear; ///< shortcut ids the region rule has passed, sorted (few: path shortcuts)
    uint32_t rounds = 0;                ///< lazy rounds that tested this chain
    uint32_t region_rounds = 0;         ///< searches the region rule sent back (ban_by_region)
    bool lazy_region = false;           ///< the region rule is asked inside the search (shortest_path)
    bool dirty = true;                  ///< path must be recomputed
};

/// A segment of a store in the far rule's grid: its chain and index.
struct GridSeg {
    uint32_t chain, index;
};

} // namespace

/// The grid of a store's segments in reach of its owned chains, which the
/// region rule and the far rule query: every segment in the cells it passes
/// through (not its bounding box: a 10 km diagonal at 1 m covers 25 M cells
/// of its box, measured at 17 GB), each cell's in (chain, index) order.
/// What a query finds does not depend on the cell size, nor on segments out
/// of reach being there too: simplify_ladder builds one for several
/// tolerances (README.md beside this file, "The ladder").
struct StoreGrid {
    double cell = 0;
    CellGrid cells;
    std::optional<CellBuckets<GridSeg>> buckets;

    StoreGrid(const ChainStore& store, const std::vector<uint8_t>& keep, double cell_size) : cell(cell_size)
    {
        std::vector<std::pair<uint64_t, GridSeg>> grid; // (cell, segment), segments in (chain, index) order
        GridBox extent;
        for (uint32_t c = 0; c < store.chains.size(); ++c) {
            for (const GridPoint p : store.chain_points(store.chains[c])) {
                extent.extend(p);
            }
        }
        if (!extent.empty()) {
            cells =
                CellGrid(double(extent.min_x), double(extent.min_y), double(extent.max_x), double(extent.max_y), cell);
        }
        for (uint32_t c = 0; c < store.chains.size(); ++c) {
            const auto pts = store.chain_points(store.chains[c]);
            const auto use = keep_of(keep, store.chains[c]);
            for (uint32_t i = 0; i + 1 < pts.size(); ++i) {
                if (!takes_part(use, i)) {
                    continue;
                }
                cover_cells(pts[i].x, pts[i].y, pts[i + 1].x, pts[i + 1].y, 0.0, cell, 0.0, 0.0,
                            [&](int64_t x, int64_t y) {
                                grid.emplace_back(cells.key(x, y), GridSeg{c, i});
                            });
            }
        }
        buckets.emplace(grid);
    }
};

namespace {

/// The far rule's reach at tolerances `eps` (grid units, per chain): the
/// largest eps_j in the metric plus the colouring margin, as an L2 distance.
double far_reach(std::span<const double> eps, double pixel, const SimplifyOptions& opt)
{
    const double ball_l2 = l2_reach(opt.metric), margin = pixel * opt.color.margin_px;
    double reach = 0;
    for (const double e : eps) {
        reach = std::max(reach, e * ball_l2 + margin);
    }
    return reach;
}

/// The grid's cell at tolerances `eps` (per chain, grid units; `pixel` the
/// tiles' pixel) for a store whose segments are `mean_segment` long on
/// average. Cells at least three mean segments wide: at 1 m a 2 x reach
/// cell is 3 m, and a county's 100 m segments each filled dozens of them
/// (74 s of the tract ladder's 1 m step); one mean segment still made a
/// query visit nine cells (far rule on the tract level at 16 m 0.65 -> 0.40
/// s with three, contours 0.52 -> 0.39 s; four was slower on the contours).
/// The answer does not depend on the size.
double grid_cell(std::span<const double> eps, double pixel, const SimplifyOptions& opt, double mean_segment,
                 bool far_rule)
{
    if (!far_rule) {
        return std::max(3 * mean_segment, 1.0);
    }
    return std::max({2 * far_reach(eps, pixel, opt), 3 * mean_segment, 1.0});
}

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

/// A (chain, candidate) pair to test: indices into StoreSimplifier's work and that chain's candidates.
using TestPair = std::pair<uint32_t, uint32_t>;

/// simplify_store, step by step (README.md beside this file): the
/// tolerances, colouring, candidates, the point constraints culled up front
/// (Step 3) and the far rule are prepared once; then rounds of Step 4
/// (shortest paths) and Steps 1-2 (the eps-Voronoi diagram and the
/// compliance test on OpenGL) run until every path is clean, and the exact
/// check bans what the raster let through, until nothing meets.
class StoreSimplifier {
  public:
    /// `grid`, if given, holds every segment in reach at this tolerance;
    /// `keep`, if given, the segments in reach at it (segments_in_reach).
    StoreSimplifier(const ChainStore& store, double eps_m, const SimplifyOptions& opt, Raster* raster,
                    const ColorResult* colors, ToleranceStats& st, std::vector<double> eps,
                    const StoreGrid* grid = nullptr, const std::vector<uint8_t>* keep = nullptr)
        : m_store(store), m_eps_m(eps_m), m_opt(opt), m_raster(raster), m_colors(raster ? colors : nullptr), m_st(st),
          m_eps(std::move(eps)), m_keep(keep), m_grid(grid)
    {
        m_st.eps_m = eps_m;
    }

    ChainStore run()
    {
        start_colouring();
        collect_work();
        find_candidates();
        cull_by_point_constraints();
        build_far_rule();
        if (m_raster) {
            finish_colouring();
            if (!m_opt.lazy) {
                test_every_candidate();
            }
        }
        do {
            settle_paths();
        } while (exact_check());
        return result();
    }

  private:
    std::span<const GridPoint> points_of(const Work& w) const { return m_store.chain_points(m_store.chains[w.chain]); }

    /// The segments in reach, then the colouring on a thread of its own
    /// beside the candidates, the point constraints and the far rule, which
    /// do not need it: it is one thread's work (contours at 16 m: 0.21 s),
    /// and a single store's other steps would leave the second core idle for it.
    void start_colouring()
    {
        const auto t0 = Clock::now();
        if (!m_keep) {
            m_own_keep = segments_in_reach(m_store, halo_reach(m_eps, m_opt));
            m_keep = &m_own_keep;
        }
        if (m_raster && !m_colors) {
            auto colour = [this] {
                const auto c0 = Clock::now();
                auto result = color_chains(m_store, m_eps, *m_keep, m_opt);
                return std::pair{std::move(result), seconds_since(c0)};
            };
            m_colouring = std::async(m_opt.threads > 1 ? std::launch::async : std::launch::deferred, colour);
        }
        // Without the raster the segments in reach serve the region rule and
        // the exact check alone: their time is counted there.
        (m_raster ? m_st.seconds_color : m_st.seconds_exact) += seconds_since(t0);
        m_pixel = m_colors ? m_colors->pixel : tile_pixel(m_eps, m_opt.color); // m_colors->pixel once known
        m_untested2 = untested_length2(m_pixel);
    }

    /// The owned chains to simplify.
    void collect_work()
    {
        for (uint32_t i = 0; i < m_store.chains.size(); ++i) {
            const auto& c = m_store.chains[i];
            if (c.flags & chains::chain_halo) {
                continue;
            }
            Work w;
            w.chain = i;
            w.tol = Tolerance(m_eps[i], m_opt.metric);
            w.ring = (c.flags & chains::chain_closed) != 0;
            w.fixed = (c.flags & chains::chain_problem) != 0;
            m_work.push_back(std::move(w));
            ++m_st.chains;
            m_st.input_vertices += c.count;
        }
    }

    /// Candidates: every proximate shortcut (exact proximity, candidates.hpp).
    void find_candidates()
    {
        const auto t0 = Clock::now();
        // A long chain's starts in pieces, so that one chain does not hold a
        // single thread (the nation's outline at 2000 m: 52 k vertices, each
        // start reaching thousands ahead); the pieces, appended in order, are
        // the whole chain's scan.
        constexpr uint32_t piece = 4096;
        struct Piece {
            uint32_t work, first, last;
        };
        std::vector<Piece> pieces;
        for (uint32_t wi = 0; wi < m_work.size(); ++wi) {
            if (m_work[wi].fixed) {
                continue;
            }
            const auto n = static_cast<uint32_t>(points_of(m_work[wi]).size());
            const uint32_t step = m_opt.threads > 1 && n > 2 * piece ? piece : std::max(n, 1U);
            uint32_t first = 0;
            do { // at least one piece, [0, 0) for a chain without points
                pieces.push_back({wi, first, std::min(n, first + step)});
                first += step;
            } while (first < n);
        }
        std::vector<Candidates> found(pieces.size());
        parallel_each(pieces.size(), m_opt.threads, [&](size_t i) {
            const Piece& p = pieces[i];
            found[i] = proximate_shortcuts_from(points_of(m_work[p.work]), m_work[p.work].tol, m_opt.max_reach, p.first,
                                                p.last, ScanKernel::fastest, m_opt.end_sample);
        });
        for (size_t i = 0; i < pieces.size(); ++i) {
            Work& w = m_work[pieces[i].work];
            if (pieces[i].first == 0) {
                w.cand = std::move(found[i]);
            } else {
                w.cand.append(found[i]);
            }
            if (pieces[i].last == points_of(w).size()) {
                cap_reach(w);
                w.cand.finish(pieces[i].last);
            }
        }
        m_st.seconds_candidates += seconds_since(t0);
    }

    /// A chain with more proximate shortcuts than max_chain_shortcuts
    /// scanned again with its reach capped at r = max(2, cap / n) vertices:
    /// at most r - 1 shortcuts from each of its n starts, n (r - 1) <= cap
    /// in all (n where r is 2: fewer than a 32-bit id can number). Its
    /// shortcuts are then a subset of the uncapped ones, the original edges
    /// among them, and every rule applies to them as before: the output
    /// keeps every guarantee, with more vertices where longer shortcuts
    /// would have served.
    void cap_reach(Work& w)
    {
        if (w.cand.count() <= m_opt.max_chain_shortcuts) {
            return;
        }
        const auto pts = points_of(w);
        const uint64_t n = pts.size();
        uint64_t reach = std::max<uint64_t>(2, m_opt.max_chain_shortcuts / n);
        if (m_opt.max_reach != 0) {
            reach = std::min<uint64_t>(reach, m_opt.max_reach);
        }
        w.cand = proximate_shortcuts_from(pts, w.tol, static_cast<uint32_t>(std::min<uint64_t>(reach, UINT32_MAX)), 0,
                                          static_cast<uint32_t>(n), ScanKernel::fastest, m_opt.end_sample);
        ++m_st.reach_capped_chains;
    }

    /// Step 3's point constraints, culled up front: units' internal points,
    /// user points, and one vertex of every other chain (an island keeps its side).
    void cull_by_point_constraints()
    {
        const auto t0 = Clock::now();
        PointIndex index;
        if (m_opt.point_constraints) {
            for (const auto& cp : m_store.constraints) {
                index.entries.push_back({cp.p, UINT32_MAX});
            }
            if (!m_opt.user_points.empty()) {
                const Projection proj(m_store.projection);
                for (const auto& u : m_opt.user_points) {
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
        for (uint32_t i = 0; i < m_store.chains.size(); ++i) {
            const auto pts = m_store.chain_points(m_store.chains[i]);
            if (pts.size() >= 3) {
                index.entries.push_back({pts[pts.size() / 2], i});
            } else if (pts.size() == 2) {
                index.entries.push_back({pts.front(), UINT32_MAX});
                index.entries.push_back({pts.back(), UINT32_MAX});
            }
        }
        index.finish();
        std::vector<std::vector<uint32_t>> culled(m_work.size());
        parallel_each(m_work.size(), m_opt.threads, [&](size_t i) {
            Work& w = m_work[i];
            if (w.cand.empty()) {
                return;
            }
            const auto pts = points_of(w);
            GridBox box;
            for (const GridPoint p : pts) {
                box.extend(p);
            }
            const auto r = static_cast<int64_t>(std::ceil(2 * w.tol.eps * l2_reach(m_opt.metric))) + 1;
            box.min_x -= r;
            box.min_y -= r;
            box.max_x += r;
            box.max_y += r;
            culled[i] = cull_by_points(pts, w.cand, index.near(box, w.chain));
        });
        for (size_t i = 0; i < m_work.size(); ++i) {
            Work& w = m_work[i];
            m_st.banned_points += culled[i].size();
            m_st.candidates += w.cand.size() - culled[i].size();
            w.state.assign(w.cand.size(), unknown);
            for (const uint32_t id : culled[i]) {
                w.state[id] = bad_points;
            }
        }
        ban_second_chords();
        m_st.seconds_constraints += seconds_since(t0);
    }

    /// The region rule's one blind spot: two chains between the same two
    /// junctions (a lake's two shores) whose shortcuts are both the chord
    /// lie on each other, each region empty. Of the chains with the same
    /// ends, only the one with the smallest id may become its chord, at any
    /// tolerance and in any partition (the halo holds the others).
    void ban_second_chords()
    {
        auto ends = [](std::span<const GridPoint> pts) {
            GridPoint a = pts.front(), b = pts.back();
            if (std::tie(b.x, b.y) < std::tie(a.x, a.y)) {
                std::swap(a, b);
            }
            return std::tuple{a.x, a.y, b.x, b.y};
        };
        std::map<std::tuple<int32_t, int32_t, int32_t, int32_t>, uint64_t> smallest; // ends -> smallest id
        for (const auto& c : m_store.chains) {
            const auto pts = m_store.chain_points(c);
            if (pts.size() >= 2 && pts.front() != pts.back()) {
                auto [it, fresh] = smallest.try_emplace(ends(pts), c.id);
                it->second = std::min(it->second, c.id);
            }
        }
        for (Work& w : m_work) {
            const auto pts = points_of(w);
            const auto& c = m_store.chains[w.chain];
            if (w.cand.empty() || pts.front() == pts.back() || smallest.at(ends(pts)) == c.id) {
                continue;
            }
            const auto last = static_cast<uint32_t>(pts.size() - 1);
            const auto runs = w.cand.runs_from(0);
            for (size_t r = 0; r < runs.size(); ++r) {
                if (runs[r].lo <= last && last <= runs[r].hi) {
                    const uint32_t id = w.cand.run_id(w.cand.first_run(0) + r) + (last - runs[r].lo);
                    if (w.state[id] == unknown) {
                        w.state[id] = bad_exact;
                        ++m_st.banned_region;
                    }
                }
            }
        }
    }

    /// The far rule's grid and blocked segments. A shortcut farther from
    /// every other chain than that chain's reach (eps_j in the metric plus
    /// the colouring margin) lies in its own chain's eps-Voronoi region:
    /// proximate shortcuts stay within eps_i of their chain in the metric
    /// (near_parts.hpp: in any norm), so within eps_i x l2_reach as an L2
    /// distance, and no other region comes near. Those skip the raster.
    void build_far_rule()
    {
        const auto t0 = Clock::now();
        m_ball_l2 = l2_reach(m_opt.metric); // the metric's unit ball lies in the L2 disc of this radius
        m_reach_max = far_reach(m_eps, m_pixel, m_opt);
        if (!m_grid) {
            m_own_grid.emplace(m_store, *m_keep,
                               grid_cell(m_eps, m_pixel, m_opt, mean_segment_length(m_store), m_raster != nullptr));
            m_grid = &*m_own_grid;
        }
        // Per owned chain, prefix counts of its segments that have another chain
        // within eps_i x l2_reach + the largest reach (L2): a shortcut spanning
        // only clear segments lies within eps_i x l2_reach of them, so farther
        // than any other chain's reach from that chain. And the blocked segments
        // with the part of each that is near another chain, for the parts of a
        // shortcut that can fail (near_parts.hpp).
        m_blocked.resize(m_work.size());
        m_blocked_at.resize(m_work.size());
        parallel_each(m_work.size(), m_opt.threads, [&](size_t wi) {
            const Work& w = m_work[wi];
            if (w.cand.empty() || !m_opt.far_rule || !m_raster) {
                return; // (no raster: nothing to spare it)
            }
            const auto pts = points_of(w);
            if (!testable_chain(pts, m_pixel)) {
                return; // every shortcut too short to be drawn (proved_short)
            }
            auto& b = m_blocked[wi];
            b.assign(pts.size(), 0);
            for (size_t k = 0; k + 1 < pts.size(); ++k) {
                const auto near = near_other(w.chain, pts[k], pts[k + 1], w.tol.eps * m_ball_l2 + m_reach_max);
                b[k + 1] = b[k] + (near ? 1 : 0);
                if (near) {
                    // Widened by 2 grid units for rounding.
                    const double len = std::hypot(double(pts[k + 1].x) - pts[k].x, double(pts[k + 1].y) - pts[k].y);
                    const double pad = len > 0 ? 2 / len : 1;
                    m_blocked_at[wi].push_back({static_cast<uint32_t>(k), std::max(0.0, near->first - pad),
                                                std::min(1.0, near->second + pad)});
                }
            }
        });
        // Without the raster the grid is the region rule's index alone.
        (m_raster ? m_st.seconds_far : m_st.seconds_exact) += seconds_since(t0);
    }

    /// The part of segment ab that another chain's segment comes within r of
    /// (the hull of those parts, as parameters along ab), or nothing.
    std::optional<std::pair<double, double>> near_other(uint32_t chain, GridPoint a, GridPoint b, double r) const
    {
        std::optional<std::pair<double, double>> near;
        const double reach = r * (1 + 1e-9) + 1;
        // The cells within r of ab (a segment within r of ab passes through one).
        cover_cells(a.x, a.y, b.x, b.y, r, m_grid->cell, 0.0, 0.0, [&](int64_t x, int64_t y) {
            if (near && near->first == 0 && near->second == 1) {
                return; // the whole segment already
            }
            if (!m_grid->cells.contains(x, y)) {
                return; // beyond every segment of the store
            }
            for (const GridSeg gs : m_grid->buckets->find(m_grid->cells.key(x, y))) {
                if (gs.chain == chain) {
                    continue;
                }
                const auto p = m_store.chain_points(m_store.chains[gs.chain]);
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
                if (near->first == 0 && near->second == 1) {
                    break; // the whole segment: nothing can add to it (coarse tolerances reach here at once)
                }
            }
        });
        return near;
    }

    /// The colouring's result (given, or from start_colouring), and the
    /// tiles each owned chain is drawn in with its class there.
    void finish_colouring()
    {
        if (m_colouring.valid()) {
            auto [result, seconds] = m_colouring.get();
            m_own_colors = std::move(result);
            m_colors = &m_own_colors;
            m_st.seconds_color += seconds;
        }
        if (m_colors->pixel != m_pixel) {
            throw std::logic_error("simplify: the tiles' pixel is not the one the far rule took");
        }
        m_st.tiles += m_colors->tiles.size();
        m_st.splits += m_colors->splits;
        m_st.max_classes = std::max(m_st.max_classes, m_colors->max_classes_used);
        std::vector<uint32_t> work_of(m_store.chains.size(), UINT32_MAX);
        for (uint32_t i = 0; i < m_work.size(); ++i) {
            work_of[m_work[i].chain] = i;
        }
        m_tiles_of.resize(m_work.size());
        for (uint32_t t = 0; t < m_colors->tiles.size(); ++t) {
            const auto& tile = m_colors->tiles[t];
            for (size_t m = 0; m < tile.chains.size(); ++m) {
                const uint32_t wi = work_of[tile.chains[m]];
                if (wi != UINT32_MAX) {
                    m_tiles_of[wi].emplace_back(t, tile.classes[m]);
                }
            }
        }
    }

    /// The far rule: no blocked segment between the shortcut's ends.
    bool proved_far(uint32_t wi, Shortcut sc) const
    {
        const auto& b = m_blocked[wi];
        return !b.empty() && b[sc.to] == b[sc.from];
    }

    /// Too short for the raster to test a pixel of it (untested_length2):
    /// the raster would pass it, whatever is drawn.
    bool proved_short(uint32_t wi, Shortcut sc) const
    {
        const auto pts = points_of(m_work[wi]);
        return !testable_shortcut(pts[sc.from], pts[sc.to], m_untested2);
    }

    /// Shortcut `sc` (id `ci` of chain `wi`) settled without the raster:
    /// marked good and counted when it is too short to be tested or far
    /// from every other chain; false when it must be drawn.
    bool settled_without_raster(uint32_t wi, Shortcut sc, uint32_t ci)
    {
        if (proved_short(wi, sc)) {
            ++m_st.proved_short;
        } else if (proved_far(wi, sc)) {
            ++m_st.proved_far;
        } else {
            return false;
        }
        m_work[wi].state[ci] = good;
        return true;
    }

    /// Steps 1-2: settle `all_tests` without the raster where it can, draw the
    /// rest tile by tile (the parts of each shortcut that can fail, in every
    /// tile of its chain), and mark each good or bad_raster.
    void raster_test(const std::vector<TestPair>& all_tests)
    {
        std::vector<TestPair> tests;
        for (const auto& [wi, ci] : all_tests) {
            if (!settled_without_raster(wi, m_work[wi].cand.at(ci), ci)) {
                tests.emplace_back(wi, ci);
            }
        }
        const auto per_tile = tile_parts(tests);
        std::vector<uint8_t> fails(tests.size(), 0);
        draw_tiles(per_tile, fails);
        for (uint32_t id = 0; id < tests.size(); ++id) {
            const auto [wi, ci] = tests[id];
            m_work[wi].state[ci] = fails[id] ? bad_raster : good;
            m_st.banned_raster += fails[id];
        }
        m_st.drawn_segments += tests.size();
    }

    /// The parts of each test's shortcut to draw (near_parts.hpp), per tile
    /// of its chain that they come near.
    std::vector<std::vector<TestSegment>> tile_parts(const std::vector<TestPair>& tests) const
    {
        std::vector<std::vector<TestSegment>> per_tile(m_colors->tiles.size());
        std::vector<std::pair<double, double>> parts;
        for (uint32_t id = 0; id < tests.size(); ++id) {
            const auto [wi, ci] = tests[id];
            const auto pts = points_of(m_work[wi]);
            const Shortcut sc = m_work[wi].cand.at(ci);
            const GridPoint a = pts[sc.from], b = pts[sc.to];
            if (m_blocked[wi].empty() || !m_opt.clip_tests) {
                parts.assign(1, {0.0, 1.0});
            } else {
                // Slack of 2 grid units on the radius, and a pixel at each end of a part.
                parts = near_parts(pts, sc.from, sc.to, m_blocked_at[wi], m_work[wi].tol.eps * m_ball_l2 + 2,
                                   m_colors->pixel + 2);
            }
            for (const auto& [p0, p1] : parts) {
                const double ax = a.x + p0 * double(b.x - a.x), ay = a.y + p0 * double(b.y - a.y);
                const double bx = a.x + p1 * double(b.x - a.x), by = a.y + p1 * double(b.y - a.y);
                for (const auto& [t, cls] : m_tiles_of[wi]) {
                    const TileSpec& s = m_colors->tiles[t].spec;
                    const double x1 = s.x0 + s.width * s.pixel, y1 = s.y0 + s.height * s.pixel;
                    if (std::max(ax, bx) + s.pixel < s.x0 || std::min(ax, bx) - s.pixel > x1 ||
                        std::max(ay, by) + s.pixel < s.y0 || std::min(ay, by) - s.pixel > y1) {
                        continue;
                    }
                    per_tile[t].push_back({a, b, cls, id, float(p0), float(p1)});
                }
            }
        }
        return per_tile;
    }

    /// Draw the tiles that have parts to test: the tents of their chains
    /// (Step 1, the eps-Voronoi diagram in the stencil buffer) and the parts
    /// (Step 2, compliance), setting fails[id] for each test that fails.
    void draw_tiles(const std::vector<std::vector<TestSegment>>& per_tile, std::vector<uint8_t>& fails)
    {
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
        parallel_each(drawn_tiles.size(), m_opt.threads, [&](size_t i) {
            const auto& tile = m_colors->tiles[drawn_tiles[i]];
            std::vector<TentChain> tents(tile.chains.size());
            for (size_t m = 0; m < tile.chains.size(); ++m) {
                const auto& c = m_store.chains[tile.chains[m]];
                tents[m] = {m_store.chain_points(c), m_eps[tile.chains[m]], tile.classes[m], keep_of(*m_keep, c)};
            }
            prepared[i] = m_raster->prepare(tile.spec, tents, per_tile[drawn_tiles[i]]);
        });
        RasterStats before, after;
        auto gl_work = [&] {
            before = m_raster->stats();
            m_raster->begin_batch(parts_in_all);
            for (const auto& p : prepared) {
                m_raster->draw(p, fails);
            }
            m_raster->end_batch(fails);
            after = m_raster->stats();
        };
        if (m_opt.gl_thread) {
            m_opt.gl_thread(gl_work);
        } else {
            gl_work();
        }
        m_st.drawn_parts += after.drawn_segments - before.drawn_segments;
        m_st.drawn_pixels += after.drawn_pixels - before.drawn_pixels;
        m_st.tent_segments += after.tent_segments - before.tent_segments;
        m_st.tent_segments_skipped += after.tent_segments_skipped - before.tent_segments_skipped;
        m_st.seconds_voronoi += after.voronoi_seconds - before.voronoi_seconds;
        m_st.seconds_compliance += after.compliance_seconds - before.compliance_seconds;
    }

    /// Not lazy: every candidate at once. Only those the far rule cannot
    /// settle are listed: listing all of them cost 8 bytes each (1 GB for one
    /// South Dakota county map at 64 m, whose 65 M candidates are 98% far).
    void test_every_candidate()
    {
        std::vector<TestPair> near;
        for (uint32_t wi = 0; wi < m_work.size(); ++wi) {
            auto& w = m_work[wi];
            const auto runs = w.cand.runs();
            for (size_t r = 0; r < runs.size(); ++r) {
                for (uint32_t k = runs[r].lo; k <= runs[r].hi; ++k) {
                    const uint32_t ci = w.cand.run_id(r) + (k - runs[r].lo);
                    if (w.state[ci] != unknown) {
                        continue; // culled by a point
                    }
                    if (!settled_without_raster(wi, {runs[r].from, k}, ci)) {
                        near.emplace_back(wi, ci);
                    }
                }
            }
        }
        raster_test(near);
    }

    /// Step 4 for the chains whose candidates changed, then test what the
    /// paths use and has not been tested (lazy), until every path is clean.
    void settle_paths()
    {
        for (;;) {
            ++m_st.rounds;
            shortest_paths();
            // The region rule first, on the CPU: a chain whose path takes a
            // shortcut it refuses finds its path again before anything is
            // drawn (Floyd's blocks at 2000 m: 22,936 raster rounds when it
            // ran after the raster, in the exact check).
            std::vector<uint32_t> changed;
            for (uint32_t wi = 0; wi < m_work.size(); ++wi) {
                if (m_work[wi].dirty) {
                    changed.push_back(wi);
                }
            }
            // (A chain the rule has sent back lazy_region_after times is asked
            // inside the search: shortest_path; its path is clear.)
            for (auto redo = ban_by_region(changed); !redo.empty(); redo = ban_by_region(redo)) {
                shortest_paths(&redo);
            }
            // Without the raster every path is now clear under the exact
            // rules, which is all the guarantee needs.
            const auto tests = m_raster ? lazy_tests() : std::vector<TestPair>{};
            if (tests.empty()) {
                for (Work& w : m_work) {
                    w.dirty = false;
                }
                return;
            }
            raster_test(tests);
            // Chains whose tested shortcuts all passed keep their paths.
            std::vector<uint8_t> failed(m_work.size(), 0);
            for (const auto& [wi, ci] : tests) {
                failed[wi] |= m_work[wi].state[ci] != good; // the far ones were marked good
            }
            for (uint32_t wi = 0; wi < m_work.size(); ++wi) {
                m_work[wi].dirty = failed[wi] != 0;
            }
        }
    }

    /// Step 4: the shortest path of every chain whose candidates changed (of
    /// those in `only`, when given), a ring keeping its orientation.
    void shortest_paths(const std::vector<uint32_t>* only = nullptr)
    {
        const auto t0 = Clock::now();
        parallel_each(only ? only->size() : m_work.size(), m_opt.threads, [&](size_t k) {
            Work& w = m_work[only ? (*only)[k] : k];
            if (!w.dirty) {
                return;
            }
            const auto pts = points_of(w);
            shortest_path(w);
            if (w.ring) {
                keep_orientation(w, pts);
            }
        });
        m_st.seconds_shortest_path += seconds_since(t0);
    }

    /// Step 4 for one chain (fewest_edges.hpp). Without the raster, once
    /// the region rule has sent the chain back lazy_region_after times, the
    /// rule is asked inside the search about each shortcut the search would
    /// take (LazyRule), so that one search finds the path over the shortcuts
    /// it allows: asked after each search about the path's shortcuts alone
    /// (ban_by_region), it sent the chain back for every refusal on its
    /// path (the 10 m contours at 1000 m: 11.0 M refused of 14.0 M
    /// candidates, 117 store-seconds of searches). Asked inside from the
    /// start, it asks about the best shortcut at every vertex, not only the
    /// path's: the tract set at 250-2000 m, whose chains it rarely sends
    /// back, took 0.3 -> 2 store-seconds a tolerance. The same path either
    /// way. With the raster the rule runs after the search, the state
    /// `good` meaning the raster passed the shortcut.
    void shortest_path(Work& w)
    {
        const size_t n = points_of(w).size();
        if (m_raster || !w.lazy_region) {
            fewest_edges_path(w.cand, w.state, n, w.ring, w.path, w.path_cand);
            return;
        }
        const LazyRule rule{[&](uint32_t from, uint32_t to) {
                                if (region_clear(w, from, to)) {
                                    return true;
                                }
                                std::atomic_ref(m_st.banned_region).fetch_add(1, std::memory_order_relaxed);
                                return false;
                            },
                            good, bad_exact};
        fewest_edges_path(w.cand, w.state, n, w.ring, w.path, w.path_cand, RunReading::automatic, &rule);
    }

    /// A ring keeps its orientation: ban the longest shortcut of its path until it holds.
    void keep_orientation(Work& w, std::span<const GridPoint> pts)
    {
        const int128 orig = signed_area2(pts, pts.size(), [](size_t k) { return k; });
        for (;;) {
            const int128 now = signed_area2(pts, w.path.size(), [&](size_t k) { return w.path[k]; });
            if ((now > 0) == (orig > 0) && now != 0) {
                return;
            }
            uint32_t worst = UINT32_MAX, span = 0;
            for (size_t e = 0; e < w.path_cand.size(); ++e) {
                if (w.path_cand[e] != UINT32_MAX && w.path[e + 1] - w.path[e] > span) {
                    span = w.path[e + 1] - w.path[e];
                    worst = w.path_cand[e];
                }
            }
            if (worst == UINT32_MAX) {
                return;
            }
            w.state[worst] = bad_exact;
            std::atomic_ref(m_st.orientation_repairs).fetch_add(1, std::memory_order_relaxed);
            shortest_path(w);
        }
    }

    /// Lazy: every untested shortcut that starts at a vertex of the current
    /// path (the path's own among them). A path of P vertices over shortcuts
    /// reaching w ahead costs about P * w = n segments, not the n * w of
    /// testing every candidate, and the alternatives a failure needs are
    /// mostly tested already, so the rounds (each a redraw of the tiles
    /// involved) stay few. The result is the same as testing all: the path
    /// is the smallest shortest path over the shortcuts that pass, whatever
    /// was tested.
    std::vector<TestPair> lazy_tests()
    {
        std::vector<TestPair> tests;
        for (uint32_t wi = 0; wi < m_work.size(); ++wi) {
            Work& w = m_work[wi];
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
        return tests;
    }

    /// The exact check: settle_paths has left every path's shortcuts clear
    /// under the region rule, so no two chains' paths can meet (README.md
    /// beside this file, step 7); the simplified owned chains go through the
    /// exact check against each other and the halo all the same, which is
    /// left to find a chain meeting itself (and input problems). Bans each
    /// shortcut in a meeting and returns whether it banned any.
    bool exact_check()
    {
        const auto t0 = Clock::now();
        std::vector<Segment> segs;
        std::vector<Tag> tags;
        std::vector<uint8_t> is_new;
        const bool first_check = !m_checked_once;
        collect_check_segments(segs, tags, is_new);
        bool banned_any = false;
        const auto meets =
            first_check ? find_intersections(segs, m_opt.threads) : find_intersections(segs, is_new, m_opt.threads);
        for (const auto& x : meets) {
            const Tag& a = tags[segs[x.first].tag];
            const Tag& b = tags[segs[x.second].tag];
            if (a.work == UINT32_MAX && b.work == UINT32_MAX) {
                // Two halo chains: the partitions that own them count it
                // (and which halo segments are here depends on the cut).
                continue;
            }
            bool banned = false;
            for (const Tag* t : {&a, &b}) {
                if (t->work != UINT32_MAX && t->cand != UINT32_MAX) {
                    Work& w = m_work[t->work];
                    if (w.state[t->cand] != bad_exact) {
                        w.state[t->cand] = bad_exact;
                        w.dirty = true;
                        ++m_st.banned_exact;
                    }
                    banned = true;
                }
            }
            if (!banned) {
                ++m_st.input_conflicts;
            } else if (a.chain == b.chain) {
                ++m_st.self_intersection_repairs;
            }
            banned_any |= banned;
        }
        m_st.seconds_exact += seconds_since(t0);
        return banned_any;
    }

    /// The region rule (README.md beside this file, step 7): every shortcut
    /// of a path whose region, between it and the subchain it replaces, holds
    /// part of another chain's original is banned. Each shortcut is looked at
    /// once, when a path first takes it. Looks at the paths of `chains` (work
    /// indices); returns those it banned a shortcut of.
    std::vector<uint32_t> ban_by_region(const std::vector<uint32_t>& chains)
    {
        const auto t0 = Clock::now();
        std::vector<std::vector<uint32_t>> banned(chains.size());
        parallel_each(chains.size(), m_opt.threads, [&](size_t k) {
            Work& w = m_work[chains[k]];
            auto& ban = banned[k];
            for (size_t e = 0; e < w.path_cand.size(); ++e) {
                const uint32_t ci = w.path_cand[e];
                if (ci == UINT32_MAX) {
                    continue;
                }
                if (!m_raster && w.state[ci] == good) {
                    continue; // without the raster `good` is the region rule's pass
                }
                const auto at = std::lower_bound(w.region_clear.begin(), w.region_clear.end(), ci);
                if (at != w.region_clear.end() && *at == ci) {
                    continue;
                }
                if (!region_clear(w, w.path[e], w.path[e + 1])) {
                    ban.push_back(ci);
                } else if (m_raster) {
                    w.region_clear.insert(at, ci);
                } else {
                    w.state[ci] = good;
                }
            }
        });
        std::vector<uint32_t> redo;
        for (size_t k = 0; k < chains.size(); ++k) {
            Work& w = m_work[chains[k]];
            for (const uint32_t ci : banned[k]) {
                w.state[ci] = bad_exact;
                w.dirty = true;
                ++m_st.banned_region;
            }
            if (!banned[k].empty()) {
                redo.push_back(chains[k]);
                w.lazy_region = !m_raster && ++w.region_rounds >= lazy_region_after;
            }
        }
        m_st.seconds_exact += seconds_since(t0);
        return redo;
    }

    /// Whether no other chain's original meets the region between shortcut
    /// from -> to of `w` and the subchain it replaces. One test sees every
    /// way in: no segment of another chain meets the shortcut other than at
    /// a shared end point. The input is planar for a chain that is
    /// simplified (ingest flags every chain of a meeting as a problem, and
    /// those keep their vertices), so another chain cannot cross the
    /// subchain, and one that enters the region without crossing the
    /// shortcut enters at a corner that is a junction and lies wholly
    /// inside: its middle vertex (or, with two vertices, an end other than
    /// the shortcut's) is then in the region, and the point constraints
    /// refused the shortcut before any path took it (README.md beside this
    /// file, step 7; formats/chains/SPEC.md, "The partition contract"). So
    /// only the cells along the shortcut are looked at, not every cell of
    /// its subchain's box: a segment meeting it passes through one of them
    /// (2 grid units around it, for the rounding of both covers).
    bool region_clear(const Work& w, uint32_t from, uint32_t to) const
    {
        const auto pts = points_of(w);
        const GridPoint a = pts[from], b = pts[to];
        const int32_t min_x = std::min(a.x, b.x), max_x = std::max(a.x, b.x);
        const int32_t min_y = std::min(a.y, b.y), max_y = std::max(a.y, b.y);
        bool clear = true;
        cover_cells(a.x, a.y, b.x, b.y, 2.0, m_grid->cell, 0.0, 0.0, [&](int64_t x, int64_t y) {
            if (!clear || !m_grid->cells.contains(x, y)) {
                return;
            }
            // A segment in several of the cells is seen several times: no harm.
            for (const GridSeg gs : m_grid->buckets->find(m_grid->cells.key(x, y))) {
                if (gs.chain == w.chain) {
                    continue;
                }
                const auto other = m_store.chain_points(m_store.chains[gs.chain]);
                const GridPoint c = other[gs.index], d = other[gs.index + 1];
                if (std::max(c.x, d.x) < min_x || std::min(c.x, d.x) > max_x || std::max(c.y, d.y) < min_y ||
                    std::min(c.y, d.y) > max_y) {
                    continue;
                }
                const SegmentRelation rel = segment_relation(a, b, c, d);
                if (rel != SegmentRelation::disjoint && rel != SegmentRelation::shared_endpoint) {
                    clear = false;
                    return;
                }
            }
        });
        return clear;
    }

    /// What a segment of the exact check is.
    struct Tag {
        uint32_t work; ///< UINT32_MAX for a halo chain
        uint32_t cand; ///< candidate index, UINT32_MAX for an original edge
        uint32_t chain;
    };

    /// The segments of the exact check: every path's edges and the halo's
    /// segments in reach. After the first check only the edges that are new
    /// in a path can meet anything new (is_new): a pair of edges both
    /// present at the last check was found then. So each meeting pair is
    /// found once, in the first check that has both, and a repair costs
    /// what it changed.
    void collect_check_segments(std::vector<Segment>& segs, std::vector<Tag>& tags, std::vector<uint8_t>& is_new)
    {
        const bool first_check = !m_checked_once;
        for (uint32_t wi = 0; wi < m_work.size(); ++wi) {
            const auto pts = points_of(m_work[wi]);
            auto& w = m_work[wi];
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
        m_checked_once = true;
        for (uint32_t i = 0; i < m_store.chains.size(); ++i) {
            if (!(m_store.chains[i].flags & chains::chain_halo)) {
                continue;
            }
            const auto pts = m_store.chain_points(m_store.chains[i]);
            const auto use = keep_of(*m_keep, m_store.chains[i]);
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
    }

    /// The owned chains along their paths, with the store's junctions and constraints.
    ChainStore result() const
    {
        ChainStore out;
        out.level_index = m_store.level_index;
        out.level_count = m_store.level_count;
        out.level_name = m_store.level_name;
        out.partition = m_store.partition;
        out.projection = m_store.projection;
        out.halo_m = m_store.halo_m;
        out.eps_m = m_eps_m;
        out.metric = static_cast<uint8_t>(m_opt.metric);
        out.strings = m_store.strings;
        out.junctions = m_store.junctions;
        out.constraints = m_store.constraints;
        std::vector<GridPoint> buf;
        for (const Work& w : m_work) {
            const auto pts = points_of(w);
            buf.clear();
            for (const uint32_t v : w.path) {
                buf.push_back(pts[v]);
            }
            chains::ChainInfo info = m_store.chains[w.chain];
            out.add_chain(info, buf);
            m_st.output_vertices += buf.size();
        }
        out.canonicalize();
        return out;
    }

    const ChainStore& m_store;
    const double m_eps_m;
    const SimplifyOptions& m_opt;
    Raster* const m_raster;      ///< null: the exact rules alone (no eps-Voronoi test)
    const ColorResult* m_colors; ///< given, or m_own_colors once finish_colouring has it
    ToleranceStats& m_st;
    const std::vector<double> m_eps; ///< per chain, grid units (chain_tolerances)
    /// The segments in reach (segments_in_reach): given, or m_own_keep.
    const std::vector<uint8_t>* m_keep;
    std::vector<uint8_t> m_own_keep;
    ColorResult m_own_colors;
    /// After m_eps and m_own_keep, which it reads: destroyed (waited for) before them.
    std::future<std::pair<ColorResult, double>> m_colouring;
    double m_pixel = 0;      ///< the tiles' pixel, grid units
    int128 m_untested2 = -1; ///< shortcuts at most this long (squared) leave no pixel to test
    std::vector<Work> m_work;
    // The far rule (build_far_rule).
    double m_ball_l2 = 0, m_reach_max = 0;
    const StoreGrid* m_grid; ///< given (simplify_ladder), or m_own_grid
    std::optional<StoreGrid> m_own_grid;
    std::vector<std::vector<uint32_t>> m_blocked;
    std::vector<std::vector<NearSegment>> m_blocked_at;
    std::vector<std::vector<std::pair<uint32_t, uint8_t>>> m_tiles_of; ///< (tile, class) of each owned chain
    bool m_checked_once = false;
}; // class StoreSimplifier

} // namespace

ChainStore simplify_store(const ChainStore& store, double eps_m, const SimplifyOptions& opt, Raster* raster,
                          const ColorResult* colors, ToleranceStats& st)
{
    return StoreSimplifier(store, eps_m, opt, raster, colors, st, chain_tolerances(store, eps_m, opt)).run();
}

void simplify_ladder(const ChainStore& store, std::span<const double> tolerances_m, const SimplifyOptions& opt,
                     Raster* raster, const std::function<const ColorResult*(size_t)>& colors,
                     std::vector<ToleranceStats>& stats,
                     const std::function<void(size_t, const chains::ChainStore&)>& done)
{
    if (!std::is_sorted(tolerances_m.begin(), tolerances_m.end())) {
        throw std::logic_error("simplify_ladder: the tolerances are not in increasing order");
    }
    stats.assign(tolerances_m.size(), ToleranceStats{});
    const auto t0 = Clock::now();
    const double mean = mean_segment_length(store);
    const ChainScales scales(store, opt);
    std::vector<std::vector<double>> eps(tolerances_m.size());
    std::vector<double> cells(tolerances_m.size());
    for (size_t t = 0; t < tolerances_m.size(); ++t) {
        eps[t] = scales.tolerances(tolerances_m[t]);
        cells[t] = grid_cell(eps[t], tile_pixel(eps[t], opt.color), opt, mean, raster != nullptr);
    }
    double planning = seconds_since(t0);
    // Groups of tolerances whose cells are within max_cell_growth of the
    // group's first share one grid, with the largest cell of the group and
    // the segments in reach at its largest tolerance (which that tolerance
    // then takes as its own). A coarser cell makes each query see more
    // segments, but building the grid costs more than that over three
    // doublings (tract set at 250-2000 m, cells 8x apart: one grid took the
    // exact check's store-seconds from 2.48 to 2.25); far apart tolerances
    // (1 m and 2 km in one run) get grids of their own. (A ladder of
    // doublings makes cells exactly 8x apart: the slack keeps rounding from
    // splitting it.)
    constexpr double max_cell_growth = 8;
    for (size_t first = 0; first < tolerances_m.size();) {
        size_t last = first;
        while (last + 1 < tolerances_m.size() && cells[last + 1] <= max_cell_growth * cells[first] * (1 + 1e-9)) {
            ++last;
        }
        const auto g0 = Clock::now();
        const auto keep = segments_in_reach(store, halo_reach(eps[last], opt));
        const StoreGrid grid(store, keep,
                             *std::max_element(cells.begin() + static_cast<std::ptrdiff_t>(first),
                                               cells.begin() + static_cast<std::ptrdiff_t>(last) + 1));
        // Whether the halo the group's cut keeps outnumbers the owned segments.
        size_t owned = 0, halo_kept = 0;
        for (const auto& c : store.chains) {
            if (c.count < 2) {
                continue;
            }
            if (!(c.flags & chains::chain_halo)) {
                owned += c.count - 1;
            } else if (!keep.empty()) {
                for (uint32_t k = 0; k + 1 < c.count; ++k) {
                    halo_kept += keep[c.first + k];
                }
            }
        }
        const bool halo_heavy = halo_kept > owned;
        // Counted where each tolerance alone counts its grid and halo cut.
        (raster ? stats[first].seconds_far : stats[first].seconds_exact) += seconds_since(g0) + planning;
        planning = 0;
        for (size_t t = first; t <= last; ++t) {
            // Without the raster the halo cut serves the exact check alone,
            // where segments out of reach find nothing to meet: the group's
            // cut serves every tolerance of it, unless the halo it keeps
            // outnumbers the owned segments (the colouring and the tents
            // need each tolerance's own cut). Either way the same stores;
            // the time: the 100 M nation's block stores at 250 m with the
            // 2000 m cut spent 0.65 store-seconds a job in the exact check
            // against 0.37 with their own, where the tract set's states
            // (their halo light) gain nothing from their own cuts.
            const bool own_cut = (raster || halo_heavy) && t != last;
            const ChainStore result = StoreSimplifier(store, tolerances_m[t], opt, raster, colors(t), stats[t],
                                                      std::move(eps[t]), &grid, own_cut ? nullptr : &keep)
                                          .run();
            done(t, result);
        }
        first = last + 1;
    }
}

} // namespace tigerlod::simplify
