#pragma once
/// @file simplifier.hpp
/// One chain store at one tolerance: the paper's Steps 1-4 with lazy
/// compliance and an exact safety net (see README.md beside this file), on
/// OpenGL (raster.hpp). What needs no GL is in tolerances.hpp.

#include "formats/chains/chain_store.hpp"
#include "simplification/raster.hpp"
#include "simplification/tolerances.hpp"

#include <functional>
#include <span>
#include <string>
#include <vector>

namespace tigerlod::simplify {

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
    /// Shortcuts accepted without drawing: too short for the raster to test
    /// a pixel (untested_length2 in coloring.hpp), so it would pass them.
    size_t proved_short = 0;
    size_t banned_raster = 0;
    size_t banned_exact = 0;
    /// Shortcuts whose region (between them and the subchain they replace)
    /// held part of another chain's original: the region rule.
    size_t banned_region = 0;
    size_t banned_points = 0;
    size_t self_intersection_repairs = 0;
    size_t orientation_repairs = 0;
    /// Original segments that meet (ingest problems), one of them of an
    /// owned chain, counted by the check that finds them; left as they are.
    size_t input_conflicts = 0;
    /// Chains with more proximate shortcuts than SimplifyOptions::
    /// max_chain_shortcuts, scanned again with their reach capped.
    size_t reach_capped_chains = 0;
    size_t rounds = 0;
    size_t tiles = 0;
    size_t splits = 0;
    uint32_t max_classes = 0;
    double seconds_color = 0, seconds_candidates = 0, seconds_voronoi = 0, seconds_compliance = 0,
           seconds_constraints = 0, seconds_shortest_path = 0, seconds_exact = 0;
    double seconds_far = 0; ///< the far rule's grid and blocked segments
    void add(const ToleranceStats& o);
};

/// Simplify the owned chains of `store` at `eps_m`. `colors`, if given, must
/// come from color_store with the same options. The result holds the owned
/// chains only, simplified, with the store's junctions and constraints.
/// With `raster` null the eps-Voronoi test is not made (`--shortcut-test
/// exact`): the exact rules alone choose the shortcuts, no OpenGL is used
/// and `colors` is ignored (README.md beside this file, "The exact rules
/// alone").
chains::ChainStore simplify_store(const chains::ChainStore& store, double eps_m, const SimplifyOptions& opt,
                                  Raster* raster, const ColorResult* colors, ToleranceStats& stats);

/// simplify_store at each of `tolerances_m` (increasing) of one store,
/// sharing what one tolerance's work can serve for the next (the grid of the
/// segments in reach, built once for tolerances whose grids are alike).
/// Each result is byte for byte simplify_store's at that tolerance, handed
/// to `done(index, result)` as soon as it is made; `colors(index)` gives
/// what simplify_store's `colors` would be (null for none). `stats` gets
/// one entry per tolerance.
void simplify_ladder(const chains::ChainStore& store, std::span<const double> tolerances_m, const SimplifyOptions& opt,
                     Raster* raster, const std::function<const ColorResult*(size_t)>& colors,
                     std::vector<ToleranceStats>& stats,
                     const std::function<void(size_t, const chains::ChainStore&)>& done);

} // namespace tigerlod::simplify
