#pragma once
/// @file verifier.hpp
/// Exact verification of a decoded Data Tree against the original chain
/// stores: what a reader would see, checked with the integer predicates of
/// core/geometry.hpp. The report's schema is in REPORT.md beside this file.

#include "reader/reader.hpp"
#include "simplification/tolerances.hpp"

#include <array>
#include <filesystem>
#include <functional>
#include <map>
#include <set>
#include <string>
#include <vector>

namespace tigerlod::verify {

/// The kinds of violation, in report order.
inline constexpr std::array<const char*, 12> kinds = {
    "crossings",          ///< two chains cross or touch other than at a shared end point
    "lod_crossings",      ///< two chains at two different LODs of a level meet other than at a shared end point
    "overlaps",           ///< two chains share a collinear piece
    "self_intersections", ///< a chain meets itself other than at consecutive segments
    "eps_exceeded",       ///< an original vertex farther than eps from the simplified chain, or the reverse
    "not_subsequence",    ///< the simplified chain is not a subsequence of its original with the same ends
    "ring_collapsed",     ///< a closed ring with fewer than 3 distinct vertices
    "ring_orientation",   ///< a closed ring whose orientation differs from its original's
    "point_constraints",  ///< a unit's internal point or a user point no longer inside its unit
    "invalid_polygons",   ///< a unit's boundary does not close, or its area changed sign
    "border_mismatch",    ///< a chain shown by two nodes with different coordinates
    "skeleton",           ///< skeleton or payload inconsistent: unreadable payload, box, counts, errors
};

struct Violation {
    std::string kind;
    std::string level;
    uint32_t lod = 0;
    std::string node;             ///< unit code of the node ("" for the root)
    std::vector<uint64_t> chains; ///< sorted
    double x = 0, y = 0;          ///< grid units
    double lon = 0, lat = 0;
    std::string detail;
};

/// Counts for one (level, LOD).
struct LevelLod {
    std::string level;
    uint32_t lod = 0;
    double eps_m = 0;
    uint64_t nodes = 0, chains = 0, segments = 0, vertices = 0, points = 0;
    /// On the ellipsoid (Options::ground): the largest ratio of a skipped
    /// vertex's ground distance from its shortcut to its eps (an upper
    /// bound, the geodesic itself wherever the bound came within 1e-6 of
    /// 1), and how many vertices were measured by geodesics.
    double ground_ratio_max = 0;
    uint64_t ground_geodesics = 0;
    std::map<std::string, uint64_t> violations; ///< by kind, every kind present
    uint64_t input_problems = 0;                ///< meetings already in the original map
};

struct Options {
    /// The contract simplify worked to (its manifest, through the tree's):
    /// class_scale, projection_scale, point_constraints (false: points are
    /// not checked). The metric and the ladder are the skeleton's.
    simplify::SimplifyOptions tolerance;
    std::vector<simplify::LonLat> user_points;
    /// Check every skipped vertex on the ellipsoid too, whatever simplify's
    /// model: its geodesic distance from the image of its shortcut within
    /// its eps in ground metres (the class scale's, times sqrt(2) for Linf).
    /// tigerlod-verify sets it where the contract's eps are ground metres
    /// (tolerance.projection_scale).
    bool ground = true;
    unsigned threads = 1;
    size_t max_items = 10000; ///< violations listed one by one at most; all are counted
    /// The meeting checks (crossings within a LOD, and across LODs) look at
    /// the level window by window, each of about this many segments: their
    /// memory follows a window, not the level. The report does not depend on it.
    size_t window_segments = size_t{1} << 22;
    /// Called after each level's LOD is checked, with its segments (a
    /// stage's progress); from the calling thread.
    std::function<void(uint64_t segments)> on_level_lod;
};

struct Report {
    uint64_t nodes = 0, lods = 0, chains = 0, segments = 0, points = 0;
    std::map<std::string, uint64_t> violations; ///< totals by kind
    /// Chains that meet in the tree and already met in the original map (the
    /// crossings ingest reports and flags): listed as items of kind
    /// "input_problem", not counted as violations.
    uint64_t input_problems = 0;
    bool ground = false;         ///< checked on the ellipsoid (Options::ground)
    double ground_ratio_max = 0; ///< the largest of by_level_lod's
    uint64_t ground_geodesics = 0;
    std::vector<LevelLod> by_level_lod;
    std::vector<Violation> items;
    uint64_t items_dropped = 0;
    double seconds = 0;
    /// Time the ground check took, summed over the threads that ran it
    /// (the rest of a verify's work at one thread is seconds minus this).
    double ground_seconds = 0;
    uint64_t total() const
    {
        uint64_t n = 0;
        for (const auto& [k, v] : violations) {
            n += v;
        }
        return n;
    }
};

/// The nodes a workflow job checks: those of some stores, and the nodes
/// decoded beside them to look for meetings near their chains.
struct Selection {
    std::set<std::string> stores; ///< "level/partition"
    /// For each store, the stores of its level that own a chain of its halo
    /// (tigerlod-pack's plan, "near").
    std::map<std::string, std::vector<std::string>> near;
};

/// Verify `tree` against the stores of `original` (a tigerlod-ingest output):
/// every node, or those of `selection`. A meeting of two chains is filed
/// under the home node (the node of the store that owns it) of the one with
/// the smaller (home, id), and is looked for when the other is in that
/// store, own or halo: so the reports of runs on selections that together
/// cover every node, merged (merge_reports), are the whole run's report.
/// Throws input_error when `original` does not match the tree (levels, missing stores).
Report verify_tree(const reader::Tree& tree, const std::filesystem::path& original, const Options& options,
                   const Selection* selection = nullptr);

/// The reports of runs on selections that together cover every node once,
/// as one: counts summed, levels and LODs in the order of `levels`, the
/// first `max_items` items in report order. Seconds are the runs' sum.
Report merge_reports(std::vector<Report>&& shares, const std::vector<std::string>& levels, size_t max_items);

} // namespace tigerlod::verify
