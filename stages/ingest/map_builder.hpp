#pragma once
/// @file map_builder.hpp
/// Turns a RawMap into chain stores: snapped and projected vertices, repaired
/// polylines, the exact planarity check, maximal chains per semantic level,
/// partitions with halos, and the units' internal points.
///
/// Method. Vertices are snapped to 1e-6 degrees and interned, then projected
/// once each onto the integer grid. Two-point polygon segments shared by
/// neighbouring polygons are merged into one edge with a unit on each side,
/// as TopoJSON finds arcs. For each level an edge is a boundary when the
/// level's codes on its two sides differ; boundary edges merge into maximal
/// chains through vertices of degree 2 (where the codes on each side carry
/// through) and into closed rings. Every segment that is a boundary at some
/// level is checked against every other with exact integer predicates
/// (core/geometry.hpp) on a uniform grid of cells: two segments may meet only
/// at a shared end point. Where rounding to the grid pushed a vertex across a
/// segment it lay within the input's precision of, the vertex is dropped (a
/// pass-through vertex only, moving the boundary by at most max_snap_shift_m),
/// as snap rounding (Hobby 1999) would, and the check runs again; each repair
/// is counted as `snap_repairs`, anything left as crossings, touches or overlaps.
/// The levels are then built from the checked graph, the coarser ones one
/// after another on a thread of their own beside the finest.

#include "core/log.hpp"
#include "core/projection.hpp"
#include "formats/chains/chain_store.hpp"
#include "stages/ingest/raw_map.hpp"

#include <functional>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace tigerlod::ingest {

struct BuildOptions {
    double halo_m = 1000.0; ///< halo distance: neighbouring chains within it go into a store's halo
    /// A line layer is cut into square grid tiles of this side (projected
    /// metres), each a partition; 0: one partition, `all`.
    double line_tile_m = 0.0;
    unsigned threads = 1;             ///< worker threads; the output does not depend on it
    size_t max_problem_samples = 200; ///< problems listed with their location in the report
    /// Largest move of a boundary that a snapping repair may make, in metres: one
    /// step of the 1e-6 degree input grid (at most 0.112 m of latitude), plus the
    /// projection's scale error. 0 turns repairs off.
    double max_snap_shift_m = 0.12;
    /// Polygon layers: units of one finest code from two input files are
    /// refused (dataset.duplicate_code: error; one file's are refused as it
    /// is read), or merged into one unit in parts (merge).
    bool merge_duplicate_codes = false;
    std::string code_field;   ///< dataset.code_field, for the message
    const Log* log = nullptr; ///< progress lines, if given
    /// A stage's progress: `on_plan(n)` once a build knows it will build n
    /// levels (over all its regions), then `on_level(chains)` as each is
    /// written; from any thread. Called by build_map and build_by_regions;
    /// a job building one region or the coarse levels calls on_plan itself.
    std::function<void(size_t levels)> on_plan;
    std::function<void(uint64_t chains)> on_level;
};

/// One data problem found (or repaired) by ingest.
struct ProblemSample {
    std::string kind;
    double lon_deg = 0, lat_deg = 0;
    std::string where; ///< input file and feature(s)
};

/// Per-level counts for the report.
struct LevelStats {
    std::string name;
    uint64_t units = 0, chains = 0, rings = 0, vertices = 0, junctions = 0, partitions = 0, halo_chains = 0,
             constraint_points = 0, computed_internal_points = 0;
    /// Internal points of other partitions' units that a store's own chains
    /// bound, summed over the stores (the partition contract).
    uint64_t neighbour_points = 0;
    /// A line layer in tiles: the vertices where a chain was cut at a tile's edge.
    uint64_t tile_cuts = 0;
};

/// Keep the first `max` samples in their order: by kind, longitude, latitude,
/// then place. The order does not depend on how the map was found (whole or
/// region by region) or on the threads.
void first_samples(std::vector<ProblemSample>& samples, size_t max);

struct BuildResult {
    std::vector<LevelStats> levels;
    std::map<std::string, uint64_t> problems; ///< counts by kind, every kind listed
    std::vector<ProblemSample> samples;       ///< the first ones, as first_samples keeps them
    uint64_t input_vertices = 0, unique_vertices = 0;
    /// Edges of the cleaned graph: the TIGER edges, or for polygons and lines
    /// the runs between vertices where the sides change or other than two meet.
    uint64_t edges = 0;
    /// Region by region: the units of every region's map, its own and its
    /// neighbours' (their sum over the finest units is the work repeated).
    /// 0 for a whole build.
    uint64_t region_map_units = 0;
    /// Wall seconds of each phase, in order (for ingest-timings.json; varies by run).
    std::vector<std::pair<std::string, double>> seconds;
};

/// Called once per finished chain store, from several threads at once and in
/// no particular order (the coarser levels are built beside the finest, each
/// on up to BuildOptions::threads threads): it must be thread-safe. Each
/// store's content does not depend on the threads.
using StoreSink = std::function<void(const chains::ChainStore&)>;

/// Build every level's chain stores. Throws input_error (naming file and
/// feature) for a coordinate outside the projection's domain.
BuildResult build_map(RawMap raw, const Projection& projection, const BuildOptions& options, const StoreSink& sink);

// Building a map region by region (stages/ingest/regions.hpp) ---------------

/// One region of a map built region by region: the level whose codes split
/// the map into regions (the first with more than one code), and the
/// region's own codes at that level. Its RawMap holds the units of those codes
/// and, read-only, the neighbouring units that its chains and halos depend on.
struct RegionScope {
    size_t level = 0;
    std::vector<std::string> own; ///< sorted
};

/// An edge that bounds something at the region level or a coarser one, owned
/// by the region: those levels are built afterwards from every region's.
struct CoarseEdge {
    std::vector<uint64_t> keys; ///< the vertices' packed lon/lat
    std::vector<GridPoint> points;
    std::string left, right; ///< region-level codes on each side, "" for the outside
    uint32_t cls = 0;
    uint64_t sid = 0;
    SourceRef src;
    bool problem = false;
};

/// What a region hands on for the coarse levels.
struct RegionOutput {
    /// One unit per own region-level code: the heaviest with a given internal
    /// point (else the first), standing for the code's units at the coarse levels.
    std::vector<RawUnit> units;
    std::vector<CoarseEdge> edges;
};

/// Build a region: the levels finer than `scope.level`, stores of the
/// partitions under its own codes only, counts and problems of what it owns
/// (the smallest region-level code among the units concerned is its own).
BuildResult build_region(RawMap raw, const RegionScope& scope, const Projection& projection,
                         const BuildOptions& options, const StoreSink& sink, RegionOutput& out);

/// Build the levels up to `level` (the region level) from the regions'
/// outputs. `meta` gives kind, level names, classes and files; its units and
/// polylines are ignored. `units` must be in input order (file, feature).
BuildResult build_coarse(const RawMap& meta, std::vector<RawUnit> units, const std::vector<CoarseEdge>& edges,
                         size_t level, const Projection& projection, const BuildOptions& options,
                         const StoreSink& sink);

} // namespace tigerlod::ingest
