#pragma once
/// @file candidates.hpp
/// Step 0 and Step 3 of the paper on the CPU, exactly: the proximate
/// shortcuts of a chain, and the point constraints that cull them.

#include "core/geometry.hpp"
#include "stages/simplify/metric.hpp"

#include <cstdint>
#include <span>
#include <vector>

namespace tigerlod::simplify {

/// One shortcut v_from -> v_to (to > from + 1) of a chain.
struct Shortcut {
    uint32_t from = 0, to = 0;
};

/// Every proximate shortcut of `pts`: each original vertex strictly between
/// the ends lies within `tol` of the segment (the segment, not its line, so
/// chains that turn back are handled). Sorted by (from, to). Shortcuts with
/// equal ends (a ring's closure) are left out, and so are those reaching more
/// than `max_reach` vertices ahead (0: no cap).
///
/// O(n * w) for w the reach of a shortcut: for each start, the directions in
/// which a segment can pass within eps of every vertex seen so far form a
/// wedge that only narrows; the scan stops when it is empty, and the exact
/// test runs only for ends near the wedge's edges or beyond the farthest
/// intermediate vertex.
std::vector<Shortcut> proximate_shortcuts(std::span<const GridPoint> pts, const Tolerance& tol, uint32_t max_reach);

/// Point constraints (Algorithm 5.2, exact): removes each shortcut whose
/// region between it and the original subchain holds one of `points`
/// (inside or on the shortcut). The region's even-odd test is accumulated
/// along the subchain, so each (start, point) pair costs O(reach).
/// Returns the number removed.
size_t cull_by_points(std::span<const GridPoint> pts, std::vector<Shortcut>& shortcuts,
                      std::span<const GridPoint> points);

} // namespace tigerlod::simplify
