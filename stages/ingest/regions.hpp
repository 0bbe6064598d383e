#pragma once
/// @file regions.hpp
/// Building a polygon map or a TIGER EDGES + FACES map region by region, so
/// that memory follows the largest region, not the dataset.
///
/// Method. The inputs are read once, one part per file (per county's FACES
/// and EDGES for TIGER), and put aside (the ingest stage writes them to
/// disk). The region level is the first level with more than one code (the
/// states of a nation > state > county > tract map, the counties of one
/// state's TIGER files); the parts that share a code there form one region. Each region is
/// built alone from its own units plus, read-only, the neighbouring units
/// that its results depend on:
/// - the whole finer-level units (counties) of other regions that come within
///   reach of its units: three halo cells, where find_near looks for halos;
/// - every unit that shares a vertex with one of those or with its own units,
///   so that the degree of each vertex it walks through is the whole map's.
/// A region writes the stores of the partitions under its own codes and counts
/// what it owns (map_builder.hpp, RegionScope); the region level and the
/// coarser ones are then built from the edges between region-level codes that
/// the regions hand on. The output is the one a whole build gives, byte for
/// byte: the tests compare them.
///
/// TIGER parts. A county's EDGES name the faces across its border by TFID;
/// the part lists those sides (RawMap::foreign) and the region's map finds
/// them among the units it takes from the neighbouring parts, as a whole read
/// finds them among every county's faces. An edge on a county border is in
/// both counties' files: the region's map keeps the first file's copy, as the
/// whole read does (TLID), and counts its points once. A part must hold the
/// faces of its edges (each edge has one of its faces on a side): where one
/// does not, the FACES and EDGES files do not pair county by county and the
/// map is built as one region.
///
/// Two limits: codes must nest across regions (a partition under two
/// region-level codes is an error here, named), and a repair at a vertex on
/// the outer edge of a region's neighbourhood could see fewer segments than
/// the whole map's check.

#include "core/log.hpp"
#include "core/projection.hpp"
#include "stages/ingest/map_builder.hpp"
#include "stages/ingest/raw_map.hpp"

#include <functional>
#include <string>
#include <vector>

namespace tigerlod::ingest {

/// What the regions plan needs of one part, gathered when it is read.
struct PartSummary {
    /// Distinct codes per level, sorted; a level with more than `max_codes`
    /// codes lists none and sets `many`. Only down to the first level where
    /// the part has more than one code (or many): the region level is never
    /// below it, and the finer levels' codes would be the summaries' memory
    /// (those levels list none).
    std::vector<std::vector<std::string>> codes;
    std::vector<uint8_t> many;
    LonLatE6 lo{INT32_MAX, INT32_MAX}, hi{INT32_MIN, INT32_MIN}; ///< box of the points
    uint64_t points_read = 0, empty_geometries = 0, empty_codes = 0;
    RawMap::Kind kind = RawMap::Kind::polygon_rings;
    std::vector<std::string> files; ///< the part's files, for messages
    std::vector<std::string> classes;
    std::vector<chains::AttributeField> fields; ///< RawMap::fields and RawMap::named of the part
    bool named = false;
    /// TIGER: edges with none of the part's faces on either side (0 where the
    /// part's EDGES and FACES are one county's).
    uint64_t unpaired_edges = 0;
};

/// The summary of a part: read from one polygon file, or from one county's
/// FACES and EDGES files (read_tiger_parts).
PartSummary summarize_part(const RawMap& part, size_t max_codes = 4096);

/// How a map is built region by region, decided from its parts' summaries
/// alone: whether it is built whole (one region, or parts that are not
/// separable), the region level, what every region's map shares (files and
/// classes, numbered as a whole read numbers them), and per region its own
/// parts and codes and the parts near it that its map takes units from.
/// The workflow runs each region as a job of its own from this.
struct RegionPlan {
    bool whole = true;
    size_t level = 0;                            ///< the region level
    RawMap meta;                                 ///< kind, level names, files and classes; no units or polylines
    std::vector<std::vector<uint32_t>> class_of; ///< per part, its classes' numbers in meta
    struct Region {
        std::vector<size_t> parts;    ///< its own parts, in file order
        std::vector<std::string> own; ///< its codes of the region level, sorted
        std::vector<size_t> near;     ///< the other parts within reach, in file order
    };
    std::vector<Region> regions; ///< in the order of their codes; empty when whole
    /// Each part's box of points (micro-degrees lon/lat; empty for a part
    /// without points), its features without geometry and those with an
    /// empty code that were left out.
    std::vector<GridBox> boxes;
    std::vector<uint64_t> empty_geometries;
    std::vector<uint64_t> empty_codes;
};

RegionPlan plan_regions(const std::vector<PartSummary>& parts, const std::vector<std::string>& level_names,
                        const Projection& projection, const BuildOptions& options);

/// What a region's build hands to the finish: its counts (the levels finer
/// than the region level), the edges and units the coarse levels are built
/// from, its input points, and the units of its map.
struct RegionShare {
    BuildResult result;
    RegionOutput coarse;
    uint64_t own_points = 0;
    uint64_t map_units = 0;
};

/// Region r of the plan (not whole): its map assembled from its own parts
/// and the parts near (`load(i)` reads part i; only those are read), its
/// stores to `sink`.
RegionShare build_planned_region(const RegionPlan& plan, size_t r, const std::function<RawMap(size_t)>& load,
                                 const Projection& projection, const BuildOptions& options, const StoreSink& sink);

/// A whole plan's map: every part, every level.
BuildResult build_planned_whole(const RegionPlan& plan, const std::function<RawMap(size_t)>& load,
                                const Projection& projection, const BuildOptions& options, const StoreSink& sink);

/// The region level and the coarser ones from every region's share (in the
/// plan's order), and the totals: what build_by_regions returns.
BuildResult finish_planned(const RegionPlan& plan, std::vector<RegionShare> shares, const Projection& projection,
                           const BuildOptions& options, const StoreSink& sink);

/// The partitions two regions both wrote ("level/partition"), as an
/// input_error naming the first: codes that do not nest across regions.
/// `written` lists each region's stores.
void check_each_store_once(const RegionPlan& plan, const std::vector<std::vector<std::string>>& written,
                           const std::vector<std::string>& level_names);

/// The level builds a plan makes: every level for a whole plan; else each
/// region's levels finer than the region level, then the coarse levels once
/// (build_by_regions's BuildOptions::on_plan).
size_t planned_levels(const RegionPlan& plan);

/// Build a map from its parts, region by region when there are two regions or
/// more, else whole: polygon parts each read from one file (file index 0 in
/// it), or TIGER parts each from one county's FACES (file 0) and EDGES (file 1),
/// numbered in the result as a whole read numbers them (every FACES file, then
/// every EDGES file).
/// `load(i)` reads part i again; it is called from this thread only.
/// Throws as build_map does, and input_error where codes do not nest across
/// regions.
BuildResult build_by_regions(const std::vector<PartSummary>& parts, const std::function<RawMap(size_t)>& load,
                             const std::vector<std::string>& level_names, const Projection& projection,
                             const BuildOptions& options, const StoreSink& sink);

} // namespace tigerlod::ingest
