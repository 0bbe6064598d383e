#pragma once
/// @file hull_scan.hpp
/// The candidate scan for coarse tolerances (L2), crossing blocks of
/// vertices by their convex hulls: a start decides a whole block of ends in
/// O(hull) when it can prove them, and falls back to one end at a time where
/// it cannot. Private to the simplification library (candidates.cpp
/// chooses it); same answers as every other scan, exactly
/// (simplification/README.md, "Long chains and coarse tolerances").

#include "simplification/candidates.hpp"

#include <cstdint>
#include <span>
#include <vector>

namespace tigerlod::simplify::detail {

/// Whether the hull scan is worth its blocks for `pts` at squared L2
/// tolerance `reps2`: at least 40 % of its blocks of 16 consecutive vertices
/// fit in a box whose diagonal is within eps (a coarse tolerance for this
/// chain's spacing; measured on the tract and synthetic levels at 64 m to
/// 2 km, BENCHMARKS.md). A choice of speed only: every scan gives the same
/// shortcuts.
bool hull_scan_pays(std::span<const GridPoint> pts, int128 reps2) noexcept;

/// What the hull scan decided how: ends proven proximate by blocks, ends
/// shown not proximate by blocks (beyond an edge of the wedge), and ends
/// decided one at a time.
struct HullScanCounts {
    uint64_t block_ends = 0, outside_ends = 0, single_ends = 0;
};

/// The proximate shortcuts (L2, squared tolerance `reps2` = tol.threshold)
/// from the starts in [starts_lo, starts_hi), appended to `out`, each start's
/// ends at most `max_reach` ahead (0: no cap). Every coordinate difference
/// of the chain must be under 2^31 and `reps2` under 2^62 (squared lengths
/// in int64); what is computed in doubles is decided with margins far above
/// its rounding, as in the scalar scan.
/// With `ends` non-empty (one flag per vertex), only the shortcuts between
/// two flagged vertices: a start or an end not flagged is crossed (the
/// wedge narrows by it) without being decided, so a block of ends none of
/// which is flagged costs one narrowing by its hull. The result is then
/// exactly the unrestricted one less the shortcuts with an end not flagged.
HullScanCounts scan_hulls(std::span<const GridPoint> pts, const Tolerance& tol, uint32_t max_reach, int128 reps2,
                          uint32_t starts_lo, uint32_t starts_hi, Candidates& out, std::span<const uint8_t> ends = {});

/// The vertices a greedy fit of the chain within `d` grid units keeps
/// (flags, one per vertex), the chain's two ends always: from each kept
/// vertex a, the fit goes on while some ray from a passes within d of
/// every vertex since (the wedge of such directions is not empty), and
/// keeps the last vertex before it empties. O(n). A heuristic set of the
/// chain alone (a neighbouring partition could compute it too); where
/// shortcuts end only at its vertices, each shortcut still takes every rule.
std::vector<uint8_t> greedy_fit_vertices(std::span<const GridPoint> pts, double d);

} // namespace tigerlod::simplify::detail
