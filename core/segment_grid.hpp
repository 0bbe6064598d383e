#pragma once
/// @file segment_grid.hpp
/// Spatial searches over segments on a uniform grid of square cells. Each
/// segment is entered in every cell its closed extent touches (a supercover,
/// one grid unit wider to stay conservative), so two segments that meet
/// always share a cell.

#include "core/geometry.hpp"

#include <cstdint>
#include <span>
#include <utility>
#include <vector>

namespace tigerlod {

struct Segment {
    GridPoint a, b;
    uint32_t tag = 0; ///< caller's id (the edge)
};

/// Two segments that meet other than at a shared end point.
struct Intersection {
    uint32_t first = 0, second = 0; ///< indices into the input, first < second
    SegmentRelation relation = SegmentRelation::disjoint;
    double x = 0, y = 0; ///< a point where they meet (grid units)
};

/// All pairs of segments that cross, touch or overlap; shared end points are
/// allowed. Exact (core/geometry.hpp). The result is sorted and does not
/// depend on `threads`.
std::vector<Intersection> find_intersections(const std::vector<Segment>& segs, unsigned threads);

/// The pairs of find_intersections(segs, threads) with at least one segment
/// flagged in `is_new` (one flag per segment): after a change to a few
/// segments of a map already checked, what the change brought. Its cost
/// follows the cells the new segments pass through, not the whole map.
std::vector<Intersection> find_intersections(const std::vector<Segment>& segs, std::span<const uint8_t> is_new,
                                             unsigned threads);

/// The pairs of find_intersections(segs, threads) whose two segments lie in
/// different layers and different groups (`layer` and `group` hold one value
/// per segment): for maps drawn over each other, each map a layer, pairs of
/// the same map or of the same feature (the group) left out. Same cells and
/// predicates as find_intersections, so nothing is missed.
std::vector<Intersection> find_intersections_between(const std::vector<Segment>& segs, std::span<const uint32_t> layer,
                                                     std::span<const uint32_t> group, unsigned threads);

struct SegmentRef {
    GridPoint a, b;
    uint32_t chain = 0;
    uint32_t part = 0;          ///< the part that owns the chain
    uint32_t also = UINT32_MAX; ///< another part the chain bounds (a border between parts), if any
};

/// Pairs (chain, part) such that a segment of `chain` (owned by another part)
/// comes within `distance` grid units of a segment that bounds `part` (owned
/// by it, or a border of it). A conservative superset: pairs up to about two
/// cells apart may be included, the cells being `distance` wide on lines at
/// multiples of it, so that whether a pair is included depends on the two
/// chains alone. Segments of one chain must be consecutive.
/// Sorted by (chain, part). The result does not depend on `threads`.
std::vector<std::pair<uint32_t, uint32_t>> find_near(const std::vector<SegmentRef>& segs, double distance,
                                                     unsigned threads);

} // namespace tigerlod
