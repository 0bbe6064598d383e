#pragma once
/// @file simplifier.hpp
/// One chain store at one tolerance: the paper's Steps 1-4 with lazy
/// compliance and an exact safety net (see README.md beside this file).

#include "formats/chains/chain_store.hpp"
#include "simplification/coloring.hpp"
#include "core/metric.hpp"
#include "simplification/raster.hpp"

#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace tigerlod::simplify {

/// A user point constraint in lon/lat degrees.
struct LonLat {
    double lon = 0, lat = 0;
};

struct SimplifyOptions {
    Metric metric = Metric::l2;
    std::map<std::string, double> class_scale; ///< eps multiplier by feature class
    bool projection_scale = true;              ///< eps in ground metres through the local projection scale
    uint32_t max_reach = 0;                    ///< cap on a shortcut's reach in vertices (0: none)
    bool point_constraints = true;             ///< units' internal points and user points keep their side
    std::vector<LonLat> user_points;
    bool lazy = true;       ///< test only shortcuts on shortest paths
    bool clip_tests = true; ///< draw only the parts of a shortcut that can fail (near_parts.hpp); off for tests
    bool far_rule = true;   ///< accept shortcuts far from every other chain without the raster; off for tests
    ColorOptions color;
    unsigned threads = 1;
    /// Runs GL work on the thread that owns the context, waiting for it:
    /// given, simplify_store hands every use of the Raster to it (several
    /// stores can then be simplified at once); empty, it calls the Raster itself.
    std::function<void(const std::function<void()>&)> gl_thread;
};

/// What happened at one tolerance (summed over stores by the caller).
struct ToleranceStats {
    double eps_m = 0;
    size_t chains = 0;
    size_t input_vertices = 0;
    size_t output_vertices = 0;
    size_t candidates = 0;
    size_t drawn_segments = 0;        ///< shortcuts the raster tested
    size_t drawn_parts = 0;           ///< parts of them drawn (near_parts.hpp), once per tile
    double drawn_pixels = 0;          ///< their length in pixels
    size_t tent_segments = 0;         ///< tents drawn
    size_t tent_segments_skipped = 0; ///< tents of the tiles' chains too far from every drawn part
    size_t proved_far = 0; ///< shortcuts accepted without drawing: farther from every other chain than its reach
    size_t banned_raster = 0;
    size_t banned_exact = 0;
    /// Shortcuts that met a proximate shortcut of a halo chain with a smaller
    /// id (the border rule: partitions simplified apart cannot meet).
    size_t banned_border = 0;
    size_t banned_points = 0;
    size_t self_intersection_repairs = 0;
    size_t orientation_repairs = 0;
    /// Original segments that meet (ingest problems), counted by the check
    /// that finds them; left as they are.
    size_t input_conflicts = 0;
    size_t rounds = 0;
    size_t tiles = 0;
    size_t splits = 0;
    uint32_t max_classes = 0;
    double seconds_color = 0, seconds_candidates = 0, seconds_voronoi = 0, seconds_compliance = 0,
           seconds_constraints = 0, seconds_shortest_path = 0, seconds_exact = 0;
    double seconds_far = 0; ///< the far rule's grid and blocked segments
    void add(const ToleranceStats& o);
};

/// The tolerance of each chain of `store` in grid units for `eps_m` ground metres.
std::vector<double> chain_tolerances(const chains::ChainStore& store, double eps_m, const SimplifyOptions& opt);

/// Per point of `store`, whether the segment starting there takes part:
/// every owned segment, and the halo segments within `reach` grid units of
/// an owned one. The halo holds whole chains with any part near the
/// partition (a kilometre, say), most of whose length is out of reach at
/// any tolerance of the ladder; colouring, gridding and drawing it cost as
/// much as the owned chains did. Decided by cells, so some farther segments
/// stay in and none within reach is left out. Empty when the store has no
/// halo: every segment takes part.
std::vector<uint8_t> segments_in_reach(const chains::ChainStore& store, double reach);

/// Where `store` breaks the point part of the partition contract
/// (formats/chains/SPEC.md, "The partition contract"): the first unit, in
/// chain order, that an owned chain bounds and of which the store holds no
/// internal point (its own, or a neighbour's). Empty when it holds. Without
/// that point a shortcut could cut the unit's point off, and the store alone
/// cannot tell.
std::optional<std::string> partition_contract_fault(const chains::ChainStore& store);

/// Colour `store` at `eps_m` (what tigerlod-color writes).
ColorResult color_store(const chains::ChainStore& store, double eps_m, const SimplifyOptions& opt);

/// Simplify the owned chains of `store` at `eps_m`. `colors`, if given, must
/// come from color_store with the same options. The result holds the owned
/// chains only, simplified, with the store's junctions and constraints.
chains::ChainStore simplify_store(const chains::ChainStore& store, double eps_m, const SimplifyOptions& opt,
                                  Raster& raster, const ColorResult* colors, ToleranceStats& stats);

} // namespace tigerlod::simplify
