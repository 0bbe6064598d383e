#pragma once
/// @file geometry.hpp
/// Integer points and exact predicates on them.
///
/// Coordinates are integers on the projected grid (1 cm by default). Every
/// predicate here is exact for coordinates of magnitude below 2^31: differences
/// fit in 33 bits and their products in 66, so they are computed in __int128.
/// Topology never uses a tolerance.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace tigerlod {

/// A 128-bit integer for exact products of 64-bit differences (a GCC/Clang extension).
__extension__ typedef __int128 int128;

/// A point of the projected integer grid.
struct GridPoint {
    int32_t x = 0;
    int32_t y = 0;
    friend bool operator==(const GridPoint&, const GridPoint&) = default;
    friend auto operator<=>(const GridPoint&, const GridPoint&) = default;
};

/// Axis-aligned box of grid points, inclusive; empty when min > max.
struct GridBox {
    int64_t min_x = INT64_MAX, min_y = INT64_MAX, max_x = INT64_MIN, max_y = INT64_MIN;
    void extend(GridPoint p) noexcept
    {
        min_x = std::min<int64_t>(min_x, p.x);
        min_y = std::min<int64_t>(min_y, p.y);
        max_x = std::max<int64_t>(max_x, p.x);
        max_y = std::max<int64_t>(max_y, p.y);
    }
    bool empty() const noexcept { return min_x > max_x; }
    bool intersects(const GridBox& o) const noexcept
    {
        return min_x <= o.max_x && o.min_x <= max_x && min_y <= o.max_y && o.min_y <= max_y;
    }
};

/// Sign of the orientation of (a, b, c): +1 counter-clockwise (c left of a->b),
/// -1 clockwise, 0 collinear. Exact.
inline int orientation(GridPoint a, GridPoint b, GridPoint c) noexcept
{
    const int128 abx = int64_t{b.x} - a.x, aby = int64_t{b.y} - a.y;
    const int128 acx = int64_t{c.x} - a.x, acy = int64_t{c.y} - a.y;
    const int128 det = abx * acy - aby * acx;
    return (det > 0) - (det < 0);
}

/// True if c, known to be collinear with a and b, lies in the closed box of a, b.
inline bool in_span(GridPoint a, GridPoint b, GridPoint c) noexcept
{
    return std::min(a.x, b.x) <= c.x && c.x <= std::max(a.x, b.x) && std::min(a.y, b.y) <= c.y &&
           c.y <= std::max(a.y, b.y);
}

/// How two closed segments meet. Segments must have distinct endpoints.
enum class SegmentRelation {
    disjoint,        ///< no common point
    shared_endpoint, ///< exactly one common point, an endpoint of both: allowed in a planar map
    touch,           ///< one common point, interior to at least one segment (a T or an X at a vertex)
    cross,           ///< one common point, interior to both (a proper crossing)
    overlap          ///< collinear with a common part longer than a point, or identical
};

/// Classify how segments ab and cd meet. Exact; symmetric in its two segments
/// and in the direction of each.
inline SegmentRelation segment_relation(GridPoint a, GridPoint b, GridPoint c, GridPoint d) noexcept
{
    const int o1 = orientation(a, b, c), o2 = orientation(a, b, d);
    const int o3 = orientation(c, d, a), o4 = orientation(c, d, b);
    if (o1 == 0 && o2 == 0) { // collinear: project on the dominant axis
        const bool use_x = a.x != b.x;
        auto key = [use_x](GridPoint p) { return use_x ? int64_t{p.x} : int64_t{p.y}; };
        const int64_t lo1 = std::min(key(a), key(b)), hi1 = std::max(key(a), key(b));
        const int64_t lo2 = std::min(key(c), key(d)), hi2 = std::max(key(c), key(d));
        const int64_t lo = std::max(lo1, lo2), hi = std::min(hi1, hi2);
        if (lo > hi) {
            return SegmentRelation::disjoint;
        }
        if (lo < hi) {
            return SegmentRelation::overlap;
        }
        const bool endpoint_of_first = key(a) == lo || key(b) == lo;
        const bool endpoint_of_second = key(c) == lo || key(d) == lo;
        return endpoint_of_first && endpoint_of_second ? SegmentRelation::shared_endpoint : SegmentRelation::touch;
    }
    if (o1 * o2 > 0 || o3 * o4 > 0) {
        return SegmentRelation::disjoint;
    }
    if (o1 != 0 && o2 != 0 && o3 != 0 && o4 != 0) {
        return SegmentRelation::cross;
    }
    // Exactly one point in common, and it is an endpoint of at least one segment.
    const bool shared = a == c || a == d || b == c || b == d;
    return shared ? SegmentRelation::shared_endpoint : SegmentRelation::touch;
}

/// Where point p lies relative to a closed polygon given as boundary segments.
enum class PointLocation { outside, inside, boundary };

/// The shoelace terms of a point sequence: twice the signed area when it is
/// closed (first == last), positive counter-clockwise; summed over the pieces
/// of a closed boundary, too. Exact.
inline int128 twice_area(std::span<const GridPoint> pts) noexcept
{
    int128 a = 0;
    for (size_t i = 0; i + 1 < pts.size(); ++i) {
        a += int128{pts[i].x} * pts[i + 1].y - int128{pts[i + 1].x} * pts[i].y;
    }
    return a;
}

/// Whether segment ab crosses the horizontal ray from p to +x (half-open in
/// y, so a vertex on the ray counts once): the even-odd rule's step, for p
/// not on ab.
inline bool crosses_ray_right(GridPoint a, GridPoint b, GridPoint p) noexcept
{
    if ((a.y > p.y) == (b.y > p.y)) {
        return false;
    }
    const int o = orientation(a, b, p);
    return (b.y > a.y) ? o > 0 : o < 0;
}

/// Accumulates an exact even-odd point-in-polygon test for point p, one
/// boundary segment at a time (the segments may come in any order and from any
/// number of rings). Half-open rule on y, so vertices are counted once.
class PointInPolygon {
  public:
    explicit PointInPolygon(GridPoint p) noexcept : m_p(p) {}
    void add_segment(GridPoint a, GridPoint b) noexcept
    {
        if (m_on_boundary) {
            return;
        }
        if (orientation(a, b, m_p) == 0 && in_span(a, b, m_p)) {
            m_on_boundary = true;
            return;
        }
        if (crosses_ray_right(a, b, m_p)) {
            m_inside = !m_inside;
        }
    }
    PointLocation location() const noexcept
    {
        return m_on_boundary ? PointLocation::boundary : (m_inside ? PointLocation::inside : PointLocation::outside);
    }

  private:
    GridPoint m_p;
    bool m_inside = false;
    bool m_on_boundary = false;
}; // class PointInPolygon

/// Euclidean distance from p to the closed segment ab, in grid units. In
/// double precision: for reports and error bounds, never for a decision that
/// must be exact. tigerlod-pack writes each LOD's error with it and
/// tigerlod-verify checks that error with it.
inline double point_segment_distance(GridPoint p, GridPoint a, GridPoint b) noexcept
{
    const double dx = double(b.x) - a.x, dy = double(b.y) - a.y;
    const double ux = double(p.x) - a.x, uy = double(p.y) - a.y;
    const double len2 = dx * dx + dy * dy;
    const double t = len2 > 0 ? std::clamp((ux * dx + uy * dy) / len2, 0.0, 1.0) : 0.0;
    const double ex = ux - t * dx, ey = uy - t * dy;
    return std::sqrt(ex * ex + ey * ey);
}

/// Whether `simp` is a subsequence of `orig` with the same first and last
/// point; if so, `at` gets the position in `orig` of each point of `simp`:
/// each at its first match after the previous one, the last at orig's last.
inline bool match_subsequence(std::span<const GridPoint> orig, std::span<const GridPoint> simp, std::vector<size_t>& at)
{
    at.clear();
    if (simp.size() < 2 || orig.empty() || simp.front() != orig.front() || simp.back() != orig.back()) {
        return false;
    }
    at.push_back(0);
    size_t j = 0;
    for (size_t i = 1; i < simp.size(); ++i) {
        if (i + 1 == simp.size()) {
            j = orig.size() - 1;
            if (j <= at.back()) {
                return false;
            }
        } else {
            ++j;
            while (j < orig.size() && orig[j] != simp[i]) {
                ++j;
            }
            if (j + 1 >= orig.size()) {
                return false;
            }
        }
        at.push_back(j);
    }
    return true;
}

} // namespace tigerlod
