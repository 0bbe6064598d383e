// The grid search must find exactly what a brute-force all-pairs check finds.
#include "core/segment_grid.hpp"

#include <gtest/gtest.h>

#include <array>
#include <random>
#include <stdexcept>

using namespace tigerlod;

namespace {

std::vector<std::tuple<uint32_t, uint32_t, SegmentRelation>> brute_force(const std::vector<Segment>& segs)
{
    std::vector<std::tuple<uint32_t, uint32_t, SegmentRelation>> out;
    for (uint32_t i = 0; i < segs.size(); ++i) {
        for (uint32_t j = i + 1; j < segs.size(); ++j) {
            const auto r = segment_relation(segs[i].a, segs[i].b, segs[j].a, segs[j].b);
            if (r != SegmentRelation::disjoint && r != SegmentRelation::shared_endpoint) {
                out.emplace_back(i, j, r);
            }
        }
    }
    return out;
}

/// n segments on a small lattice with ends up to coord_max and lengths up to
/// len_max along x, y or a diagonal, so that shared ends, touches and
/// overlaps all occur.
std::vector<Segment> random_segments(std::mt19937& rng, uint32_t n, int coord_max, int len_max)
{
    std::uniform_int_distribution<int> coord(0, coord_max), len(1, len_max);
    std::vector<Segment> segs;
    for (uint32_t i = 0; i < n; ++i) {
        const GridPoint a{coord(rng), coord(rng)};
        GridPoint b{a.x + len(rng) * (coord(rng) % 3 - 1), a.y + len(rng) * (coord(rng) % 3 - 1)};
        if (a == b) {
            b.x += 1;
        }
        segs.push_back({a, b, i});
    }
    return segs;
}

void expect_pairs(const std::vector<Intersection>& got,
                  const std::vector<std::tuple<uint32_t, uint32_t, SegmentRelation>>& want, int round)
{
    ASSERT_EQ(got.size(), want.size()) << "round " << round;
    for (size_t k = 0; k < got.size(); ++k) {
        EXPECT_EQ(got[k].first, std::get<0>(want[k]));
        EXPECT_EQ(got[k].second, std::get<1>(want[k]));
        EXPECT_EQ(got[k].relation, std::get<2>(want[k]));
    }
}

} // namespace

TEST(SegmentGrid, MatchesBruteForceOnRandomSegments)
{
    std::mt19937 rng(12345);
    for (int round = 0; round < 20; ++round) {
        const auto segs = random_segments(rng, 300, 40, round % 2 ? 40 : 4); // long and short in turn
        const auto want = brute_force(segs);
        for (unsigned threads : {1U, 3U}) {
            expect_pairs(find_intersections(segs, threads), want, round);
        }
    }
}

TEST(SegmentGrid, NewSegmentsFindThePairsTheyAreIn)
{
    // With flags, exactly the whole check's pairs that have a flagged member.
    std::mt19937 rng(777);
    for (int round = 0; round < 20; ++round) {
        const auto segs = random_segments(rng, 400, 60, round % 2 ? 50 : 5);
        // None, a few, or many flagged.
        const int per_mille = std::array{0, 5, 50, 500}[round % 4];
        std::vector<uint8_t> is_new(segs.size());
        for (auto& f : is_new) {
            f = static_cast<int>(rng() % 1000) < per_mille ? 1 : 0;
        }
        std::vector<std::tuple<uint32_t, uint32_t, SegmentRelation>> want;
        for (const auto& [i, j, r] : brute_force(segs)) {
            if (is_new[i] || is_new[j]) {
                want.emplace_back(i, j, r);
            }
        }
        if (per_mille >= 50) {
            ASSERT_FALSE(want.empty()) << "round " << round << ": the case should have pairs to find";
        }
        for (unsigned threads : {1U, 3U}) {
            expect_pairs(find_intersections(segs, is_new, threads), want, round);
        }
    }
    EXPECT_THROW(find_intersections(std::vector<Segment>(3), std::vector<uint8_t>(2), 1), std::invalid_argument);
}

TEST(SegmentGrid, BetweenLayersFindsThePairsOfDifferentLayersAndGroups)
{
    // Exactly the whole check's pairs whose members differ in layer and in group.
    std::mt19937 rng(4242);
    for (int round = 0; round < 20; ++round) {
        const auto segs = random_segments(rng, 400, 60, round % 2 ? 50 : 5);
        const uint32_t layers = 1 + round % 4, groups = std::array{1U, 2U, 7U, 400U}[round % 4];
        std::vector<uint32_t> layer(segs.size()), group(segs.size());
        for (size_t i = 0; i < segs.size(); ++i) {
            layer[i] = static_cast<uint32_t>(rng() % layers);
            group[i] = static_cast<uint32_t>(rng() % groups);
        }
        std::vector<std::tuple<uint32_t, uint32_t, SegmentRelation>> want;
        for (const auto& [i, j, r] : brute_force(segs)) {
            if (layer[i] != layer[j] && group[i] != group[j]) {
                want.emplace_back(i, j, r);
            }
        }
        if (layers > 1 && groups > 2) {
            ASSERT_FALSE(want.empty()) << "round " << round << ": the case should have pairs to find";
        }
        for (unsigned threads : {1U, 3U}) {
            expect_pairs(find_intersections_between(segs, layer, group, threads), want, round);
        }
    }
    EXPECT_THROW(
        find_intersections_between(std::vector<Segment>(3), std::vector<uint32_t>(3), std::vector<uint32_t>(2), 1),
        std::invalid_argument);
}

TEST(SegmentGrid, LongDiagonalsAmongShortSegments)
{
    // A 2^30-long diagonal among short segments: the supercover must still find the hit.
    std::vector<Segment> segs;
    const int32_t big = 1 << 30;
    segs.push_back({{0, 0}, {big, big}, 0});
    for (uint32_t i = 1; i < 200; ++i) {
        const int32_t x = static_cast<int32_t>(i) * (big / 200);
        segs.push_back({{x + 10, x - 10}, {x + 30, x - 30}, i}); // near the diagonal, not on it
    }
    segs.push_back({{big / 2 - 5, big / 2 + 5}, {big / 2 + 5, big / 2 - 5}, 200}); // crosses it
    const auto got = find_intersections(segs, 2);
    ASSERT_EQ(got.size(), 1U);
    EXPECT_EQ(got[0].first, 0U);
    EXPECT_EQ(got[0].second, 200U);
    EXPECT_EQ(got[0].relation, SegmentRelation::cross);
    EXPECT_NEAR(got[0].x, big / 2, 1.0);
}

TEST(SegmentGrid, NearFindsChainsWithinTheDistanceOnly)
{
    // Part 0 owns a chain along y=0; part 1 owns one 50 units above and one 5000 above.
    std::vector<SegmentRef> segs = {
        {{0, 0}, {1000, 0}, 0, 0}, {{0, 50}, {1000, 50}, 1, 1}, {{0, 5000}, {1000, 5000}, 2, 1}};
    const auto near = find_near(segs, 100.0, 1);
    EXPECT_EQ(near, (std::vector<std::pair<uint32_t, uint32_t>>{{0, 1}, {1, 0}}));
}

TEST(SegmentGrid, NearFollowsALongChainOfShortSegmentsThroughEveryCell)
{
    // Part 0 owns a chain of 100 segments, 30 units each, along y=0 to x=3000
    // (cells are 100 wide); part 1 owns a segment 60 above its far end and one
    // 5000 above its start.
    std::vector<SegmentRef> segs;
    for (int32_t k = 0; k < 100; ++k) {
        segs.push_back({{30 * k, 0}, {30 * (k + 1), 0}, 0, 0});
    }
    segs.push_back({{2950, 60}, {3050, 60}, 1, 1});
    segs.push_back({{0, 5000}, {100, 5000}, 2, 1});
    const auto near = find_near(segs, 100.0, 1);
    EXPECT_EQ(near, (std::vector<std::pair<uint32_t, uint32_t>>{{0, 1}, {1, 0}}));
}

TEST(SegmentGrid, BordersReachBothParts)
{
    // Part 2 owns nothing near chain 0, but chain 0 (owned by part 0) bounds part 2: it is in part 2's halo.
    std::vector<SegmentRef> segs = {{{0, 0}, {1000, 0}, 0, 0, 2}, {{0, 90000}, {1000, 90000}, 1, 2}};
    const auto near = find_near(segs, 100.0, 1);
    EXPECT_EQ(near, (std::vector<std::pair<uint32_t, uint32_t>>{{0, 2}}));
}
