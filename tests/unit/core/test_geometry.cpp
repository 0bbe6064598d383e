#include "core/geometry.hpp"

#include <gtest/gtest.h>

using tigerlod::GridPoint;
using tigerlod::match_subsequence;
using tigerlod::orientation;
using tigerlod::point_segment_distance;
using tigerlod::PointInPolygon;
using tigerlod::PointLocation;
using tigerlod::segment_relation;
using R = tigerlod::SegmentRelation;

namespace {

// Both argument orders and both directions of each segment must agree.
void expect_relation(GridPoint a, GridPoint b, GridPoint c, GridPoint d, R want)
{
    EXPECT_EQ(segment_relation(a, b, c, d), want);
    EXPECT_EQ(segment_relation(b, a, c, d), want);
    EXPECT_EQ(segment_relation(a, b, d, c), want);
    EXPECT_EQ(segment_relation(c, d, a, b), want);
    EXPECT_EQ(segment_relation(d, c, b, a), want);
}

} // namespace

TEST(Orientation, SignsAndExtremes)
{
    EXPECT_EQ(orientation({0, 0}, {10, 0}, {5, 1}), 1);
    EXPECT_EQ(orientation({0, 0}, {10, 0}, {5, -1}), -1);
    EXPECT_EQ(orientation({0, 0}, {10, 0}, {20, 0}), 0);
    // Full 32-bit range: products need more than 64 bits.
    const int32_t M = INT32_MAX, m = INT32_MIN;
    EXPECT_EQ(orientation({m, m}, {M, M}, {M - 1, M}), 1);
    EXPECT_EQ(orientation({m, m}, {M, M}, {M, M - 1}), -1);
    EXPECT_EQ(orientation({m, m}, {M, M}, {0, 0}), 0);
}

TEST(SegmentRelation, Cross)
{
    //   c
    // a-+-b
    //   d
    expect_relation({0, 0}, {4, 0}, {2, 2}, {2, -2}, R::cross);
}

TEST(SegmentRelation, SharedEndpoint)
{
    // a-b/c-d in a V
    expect_relation({0, 0}, {4, 0}, {4, 0}, {6, 3}, R::shared_endpoint);
    // collinear, end to end
    expect_relation({0, 0}, {4, 0}, {4, 0}, {8, 0}, R::shared_endpoint);
}

TEST(SegmentRelation, TouchAtInterior)
{
    //    c
    //    |
    // a--d--b   (d on the interior of ab)
    expect_relation({0, 0}, {4, 0}, {2, 3}, {2, 0}, R::touch);
    // collinear, one end inside the other's span at a single point is impossible;
    // a vertex of one exactly on the other's interior, not collinear:
    expect_relation({0, 0}, {4, 4}, {2, 2}, {0, 5}, R::touch);
}

TEST(SegmentRelation, Overlap)
{
    expect_relation({0, 0}, {4, 0}, {2, 0}, {6, 0}, R::overlap);
    expect_relation({0, 0}, {4, 0}, {0, 0}, {4, 0}, R::overlap); // identical
    expect_relation({0, 0}, {0, 4}, {0, 1}, {0, 2}, R::overlap); // contained, vertical
}

TEST(SegmentRelation, Disjoint)
{
    expect_relation({0, 0}, {4, 0}, {5, 0}, {8, 0}, R::disjoint); // collinear, apart
    expect_relation({0, 0}, {4, 0}, {0, 1}, {4, 1}, R::disjoint); // parallel
    expect_relation({0, 0}, {4, 0}, {2, 1}, {2, 5}, R::disjoint); // would touch if extended
}

TEST(PointInPolygon, InsideOutsideBoundary)
{
    // A square with a square hole:
    // (0,10)------(10,10)
    //   |  (3,7)--(7,7) |
    //   |    | hole |   |
    //   |  (3,3)--(7,3) |
    // (0,0)-------(10,0)
    const std::vector<std::pair<GridPoint, GridPoint>> segs = {
        {{0, 0}, {10, 0}}, {{10, 0}, {10, 10}}, {{10, 10}, {0, 10}}, {{0, 10}, {0, 0}},
        {{3, 3}, {3, 7}},  {{3, 7}, {7, 7}},    {{7, 7}, {7, 3}},    {{7, 3}, {3, 3}}};
    auto where = [&](GridPoint p) {
        PointInPolygon pip(p);
        for (auto [a, b] : segs) {
            pip.add_segment(a, b);
        }
        return pip.location();
    };
    EXPECT_EQ(where({1, 1}), PointLocation::inside);
    EXPECT_EQ(where({5, 5}), PointLocation::outside); // in the hole
    EXPECT_EQ(where({11, 5}), PointLocation::outside);
    EXPECT_EQ(where({10, 5}), PointLocation::boundary);
    EXPECT_EQ(where({3, 5}), PointLocation::boundary);
    EXPECT_EQ(where({1, 3}), PointLocation::inside); // ray passes through hole vertices (3,3), (7,3)
    EXPECT_EQ(where({1, 7}), PointLocation::inside);
}

TEST(Geometry, PointSegmentDistance)
{
    EXPECT_EQ(point_segment_distance({100, 30}, {0, 0}, {200, 0}), 30.0);
    EXPECT_EQ(point_segment_distance({-3, 4}, {0, 0}, {200, 0}), 5.0); // beyond an end: to the end
    EXPECT_EQ(point_segment_distance({3, 4}, {0, 0}, {0, 0}), 5.0);    // a point segment
}

TEST(Geometry, MatchSubsequence)
{
    const std::vector<GridPoint> orig{{0, 0}, {1, 0}, {2, 0}, {3, 0}, {0, 0}};
    std::vector<size_t> at;
    EXPECT_TRUE(match_subsequence(orig, std::vector<GridPoint>{{0, 0}, {2, 0}, {0, 0}}, at));
    EXPECT_EQ(at, (std::vector<size_t>{0, 2, 4})); // a ring: the last point is the original's last
    EXPECT_TRUE(match_subsequence(orig, orig, at));
    EXPECT_EQ(at, (std::vector<size_t>{0, 1, 2, 3, 4}));
    EXPECT_FALSE(match_subsequence(orig, std::vector<GridPoint>{{0, 0}, {3, 0}, {2, 0}, {0, 0}}, at)); // order
    EXPECT_FALSE(match_subsequence(orig, std::vector<GridPoint>{{0, 0}, {5, 0}, {0, 0}}, at));         // foreign
    EXPECT_FALSE(match_subsequence(orig, std::vector<GridPoint>{{1, 0}, {0, 0}}, at));                 // moved end
    const std::vector<GridPoint> one_point(1, GridPoint{0, 0});
    EXPECT_FALSE(match_subsequence(orig, one_point, at));
}
