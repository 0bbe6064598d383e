#pragma once
/// @file map_steps.hpp
/// The steps of map_builder.cpp (tigerlod-ingest's build), one file each,
/// and what they share; internal to the ingest stage. In the order a build
/// takes them:
///
/// - map_graph.cpp: intern and project the vertices, clean the polylines,
///   merge the segments neighbouring polygons share into edges (make_graph,
///   merge_segments, join_pieces);
/// - map_levels.cpp: each level's codes and its maximal chains and rings
///   (level_codes, build_level);
/// - map_check.cpp: the exact planarity check of every boundary segment,
///   with the repair of crossings that snapping made (repair_snap_crossings);
/// - map_partitions.cpp: per level, the partitions with their halos, the
///   units' internal points and the stores (process_level);
/// - map_builder.cpp: the build that runs them (build_map, build_region,
///   build_coarse).

#include "stages/ingest/map_builder.hpp"

#include "core/errors.hpp"
#include "core/memory.hpp"
#include "core/parallel.hpp"
#include "core/radix_sort.hpp"
#include "core/segment_grid.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <future>
#include <mutex>
#include <numbers>
#include <numeric>
#include <span>
#include <stdexcept>
#include <tuple>
#include <thread>
#include <unordered_map>

namespace tigerlod::ingest::detail {

inline constexpr uint32_t none = UINT32_MAX;

inline const std::vector<std::string> kinds = {"crossings",
                                               "touches",
                                               "overlaps",
                                               "overlapping_polygons",
                                               "duplicate_points",
                                               "spikes",
                                               "merged_vertices",
                                               "degenerate_polylines",
                                               "non_nesting_units",
                                               "unreferenced_units",
                                               "internal_points_replaced",
                                               "missing_internal_points",
                                               "empty_geometries",
                                               "empty_codes",
                                               "snap_repairs",
                                               "duplicate_segments"};

inline uint64_t splitmix(uint64_t x) noexcept
{
    x += 0x9E3779B97F4A7C15ULL;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
    return x ^ (x >> 31);
}

inline bool same_source(SourceRef a, SourceRef b) noexcept
{
    return a.file == b.file && a.feature == b.feature;
}

/// One run of an edge's segments from one source: from segment `first` on.
struct SourceRun {
    uint32_t first = 0;
    SourceRef src;
};

/// The runs of `m` segments taken the other way round (segment j is m-1-j).
std::vector<SourceRun> reversed_runs(std::span<const SourceRun> runs, uint32_t m);

/// Runs made canonical: starts below `m` segments, the last of equal starts
/// kept, neighbours with one source merged, the first at 0; a single run
/// left is returned as none (the edge's one source).
std::vector<SourceRun> canonical_runs(std::vector<SourceRun> runs, uint32_t m);

/// Everything the levels share: interned vertices and cleaned edges.
struct Graph {
    std::vector<uint64_t> keys;  // vertex id -> packed lon/lat
    std::vector<GridPoint> grid; // vertex id -> grid point
    std::vector<uint32_t> verts; // edge i is verts[off[i], off[i+1])
    std::vector<uint64_t> off{0};
    std::vector<uint32_t> left, right, cls;
    std::vector<uint64_t> sid;
    std::vector<SourceRef> src;
    /// Where the source changes along an edge joined from the features of a
    /// line layer (one river in several features): edge i's runs are
    /// runs[run_off[i], run_off[i+1]), each (its first segment, its source),
    /// the first at segment 0; none where the edge has one source (src[i]).
    /// Empty (no run_off) in maps of polygons, whose problems name the
    /// polygons on each side.
    std::vector<uint64_t> run_off;
    std::vector<SourceRun> runs;
    size_t edge_count() const noexcept { return left.size(); }
    std::span<const uint32_t> edge(size_t i) const noexcept { return {verts.data() + off[i], off[i + 1] - off[i]}; }
    std::span<const SourceRun> runs_of(size_t i) const noexcept
    {
        return run_off.empty() ? std::span<const SourceRun>()
                               : std::span(runs).subspan(run_off[i], run_off[i + 1] - run_off[i]);
    }
    /// The source of edge i's segment `segment` (from its vertex `segment`).
    SourceRef source_at(size_t i, uint32_t segment) const noexcept;
};

/// A problem found on a worker thread, recorded later in a fixed order so
/// that the report does not depend on the threads.
struct FoundProblem {
    const char* kind;
    double x, y; ///< grid units
    std::string where;
};

class Problems {
  public:
    Problems(BuildResult& r, const Projection& proj, size_t max_samples) : m_r(r), m_proj(proj), m_max(max_samples)
    {
        for (const auto& k : kinds) {
            m_r.problems[k] = 0;
        }
    }
    void count(const std::string& kind, uint64_t n = 1) { m_r.problems[kind] += n; }
    void add(const std::string& kind, double gx, double gy, std::string where)
    {
        count(kind);
        if (m_max > 0) {
            ProblemSample s{kind, 0, 0, std::move(where)};
            m_proj.to_lonlat(gx, gy, s.lon_deg, s.lat_deg);
            keep(std::move(s));
        }
    }
    /// Record `found` in its order.
    void add_all(std::vector<FoundProblem>&& found)
    {
        for (auto& f : found) {
            add(f.kind, f.x, f.y, std::move(f.where));
        }
    }
    void add_lonlat(const std::string& kind, LonLatE6 p, std::string where)
    {
        count(kind);
        if (m_max > 0) {
            keep({kind, p.lon * 1e-6, p.lat * 1e-6, std::move(where)});
        }
    }
    /// The samples kept, in their order.
    void finish() { first_samples(m_r.samples, m_max); }

  private:
    void keep(ProblemSample&& s)
    {
        m_r.samples.push_back(std::move(s));
        if (m_r.samples.size() >= 2 * m_max + 64) {
            first_samples(m_r.samples, m_max);
        }
    }
    BuildResult& m_r;
    const Projection& m_proj;
    size_t m_max;
};

/// What a build counts and reports: everything, for a whole map; for a region
/// (RegionScope), what concerns one of its own codes first: the smallest
/// region-level code among the units around a vertex, on the sides of an edge
/// or a pair of edges, or of a unit. Each such thing then belongs to exactly
/// one region, and that region holds all the units it depends on.
struct Owner {
    std::span<const uint32_t> unit_rank; ///< unit -> region-level code id (LevelCodes::of_unit); empty for a whole map
    std::vector<uint8_t> own_rank;       ///< region-level code id -> own
    std::vector<uint32_t> vertex_rank;

    bool whole() const noexcept { return unit_rank.empty(); }
    uint32_t rank(uint32_t u) const noexcept { return u == no_unit || whole() ? none : unit_rank[u]; }
    bool of_rank(uint32_t r) const noexcept { return whole() || (r != none && own_rank[r] != 0); }
    bool unit(uint32_t u) const noexcept { return whole() || of_rank(rank(u)); }
    bool units(uint32_t a, uint32_t b) const noexcept { return whole() || of_rank(std::min(rank(a), rank(b))); }
    bool vertex(uint32_t v) const noexcept { return whole() || of_rank(vertex_rank[v]); }
};

/// Contiguous ranges of at least 4096 items per thread.
template <class F> void parallel_for(size_t n, unsigned threads, F&& f)
{
    parallel_ranges(n, threads, 4096, std::forward<F>(f));
}

/// One segment after merge_segments: its vertices (a < b), the units on each
/// side (left of a->b), and the input polyline it came from.
struct Piece {
    std::array<uint32_t, 2> ab;
    uint32_t left, right;
    uint32_t edge;
};

/// Codes of every finest unit at one level, as ids into a sorted code list.
struct LevelCodes {
    std::vector<std::string> codes; // sorted
    std::vector<uint32_t> of_unit;  // finest unit -> code id
    std::vector<uint32_t> parent;   // code id -> parent code id at the level above (none at level 0)
    uint32_t side(uint32_t unit) const noexcept { return unit == no_unit ? none : of_unit[unit]; }
};

/// A chain of one level, over graph vertex ids.
struct LevelChain {
    uint64_t first = 0;
    uint32_t count = 0;
    uint32_t left = none, right = none; // code ids
    uint32_t cls = 0;
    uint64_t id = 0;
    bool ring = false; // a cycle without junctions
    bool problem = false;
    uint32_t owner = none; // partition: parent code id (level > 0) or 0
};

/// One level's chains over graph vertex ids, its junctions, and the chain of each boundary edge.
struct Level {
    std::vector<LevelChain> chains;
    std::vector<uint32_t> verts;
    std::vector<uint32_t> junctions; // vertex ids
    std::vector<uint32_t> junction_degree;
    std::vector<uint32_t> chain_of_edge; // edge -> chain, none if not a boundary
    std::span<const uint32_t> chain(const LevelChain& c) const noexcept { return {verts.data() + c.first, c.count}; }
};

/// The vertices where edges end, in increasing order, and the index of each
/// vertex among them (`none` for the others): what the levels' walks need,
/// so that their tables go by edge ends, not by vertices.
struct EdgeEnds {
    std::vector<uint32_t> vertex;
    std::vector<uint32_t> of_vertex;

    explicit EdgeEnds(const Graph& g) : of_vertex(g.keys.size(), none)
    {
        for (size_t e = 0; e < g.edge_count(); ++e) {
            const auto ev = g.edge(e);
            of_vertex[ev.front()] = of_vertex[ev.back()] = 0;
        }
        for (uint32_t v = 0; v < of_vertex.size(); ++v) {
            if (of_vertex[v] == 0) {
                of_vertex[v] = static_cast<uint32_t>(vertex.size());
                vertex.push_back(v);
            }
        }
    }
};

/// The segments of the checked edges, and where each lies: (edge, index of its first vertex).
struct SegmentSet {
    std::vector<Segment> segs;
    std::vector<std::pair<uint32_t, uint32_t>> at;
};

/// Codes of each level that a build owns (for a region: those under its own
/// region-level codes); an empty list owns every code of its level.
using OwnedCodes = std::vector<std::vector<uint8_t>>;

/// Intern and project the vertices, then clean every polyline.
Graph make_graph(RawMap& raw, const Projection& proj, unsigned threads, Problems& problems, Owner& owner);

/// Split polygon rings into segments and merge the segments that neighbouring
/// polygons share into one piece with a unit on each side. For a line layer,
/// split the lines and keep one of each set of identical segments (a river
/// stored twice becomes one chain), counted as `duplicate_segments`.
std::vector<Piece> merge_segments(const Graph& g, const RawMap& raw, unsigned threads, Problems& problems,
                                  const Owner& owner);

/// Join the pieces end to end where exactly two piece ends meet at a vertex
/// and the units on each side and the feature class carry through it: the
/// edges become the runs between junctions (the finest level's chains), which
/// the planarity check and every level then walk instead of single segments.
/// The chains a level builds are the same either way. Pieces are taken in
/// order, so the result depends on nothing but the input.
/// With `keep_runs` (a line layer) the joined edges keep where their source
/// changes (Graph::runs), so that a problem names the feature at its place.
void join_pieces(Graph& g, const std::vector<Piece>& pieces, bool keep_runs);

/// The codes of every level; units whose code at a level has another parent
/// than the code's first unit gave it go into `non_nesting` as (unit, level).
std::vector<LevelCodes> level_codes(const RawMap& raw, std::vector<std::pair<uint32_t, uint32_t>>& non_nesting);

/// Level L's chains: the edges whose sides have different codes at L,
/// merged into maximal chains through vertices where the codes on each side
/// carry through, and closed rings; its junctions.
Level build_level(const Graph& g, const EdgeEnds& ends, const RawMap& raw, const std::vector<LevelCodes>& lcs,
                  size_t L);

/// A line layer's grid tiles: squares of `side` grid units from the
/// projection's origin, column and row by floor division.
struct TileGrid {
    int64_t side = 0;   ///< grid units
    int64_t margin = 0; ///< how far a chain may stray out of its tile before it is cut
    std::pair<int64_t, int64_t> tile(GridPoint p) const noexcept
    {
        auto floor_div = [this](int64_t v) { return v >= 0 ? v / side : -((-v + side - 1) / side); };
        return {floor_div(p.x), floor_div(p.y)};
    }
    /// p lies farther than the margin outside tile t.
    bool strays(GridPoint p, std::pair<int64_t, int64_t> t) const noexcept
    {
        return p.x < t.first * side - margin || p.x >= (t.first + 1) * side + margin ||
               p.y < t.second * side - margin || p.y >= (t.second + 1) * side + margin;
    }
};

/// Cut a line layer's chains where they stray out of their tile: walking a
/// chain, the vertex that first lies farther than the margin outside the
/// current tile ends the piece and starts the next, in that vertex's tile.
/// A ring cut at fewer than two vertices stays whole. The first piece keeps
/// the chain's id, the others take a hash of it and their rank, and the ids
/// are then made unique as build_level makes them. The cut vertices become
/// junctions of degree 2. chain_of_edge is cleared (the pieces do not follow
/// edges). Returns the number of cuts.
uint64_t cut_at_tiles(Level& lev, const Graph& g, const TileGrid& grid);

/// Snapping to the grid can push a vertex that lies within a fraction of the
/// input precision of a segment across it. Where a vertex of a crossing,
/// touching or overlapping pair is a plain pass-through vertex (degree 2 in the
/// whole graph, the same units on each side) and dropping it moves the boundary
/// by at most `max_shift` grid units, drop it, as snap rounding would, and
/// check again. Returns the intersections that remain; repairs are counted.
/// A meeting of two edges (Intersection's first and second are edges) and
/// the segment of each where they meet.
struct EdgeMeeting : Intersection {
    uint32_t first_segment = 0, second_segment = 0;
};

std::vector<EdgeMeeting> repair_snap_crossings(Graph& g, const RawMap& raw, const std::vector<LevelCodes>& lcs,
                                               double max_shift, unsigned threads, Problems& problems,
                                               const Owner& owner);

/// One line to the build's log, if it has one.
void log_progress(const BuildOptions& options, const std::string& what);

/// One level: its chains, partitions, halos, internal points and stores
/// (given to `sink`); its problems go to `problems` in a fixed order.
LevelStats process_level(const Graph& g, const EdgeEnds& ends, const RawMap& raw, const std::vector<LevelCodes>& lcs,
                         size_t L, const std::vector<uint32_t>& bad_edges, const Projection& projection,
                         const BuildOptions& options, const Owner& owner, const OwnedCodes& owned,
                         std::vector<FoundProblem>& problems, const StoreSink& sink);

} // namespace tigerlod::ingest::detail
