// Unit polygons rebuilt from a node's chains: valid OGC polygons whatever the
// order of the chains, where a unit's boundary passes a vertex twice.
#include "core/geometry.hpp"
#include "reader/reader.hpp"
#include "reader/tree_view.hpp"

#include "../../support/run_tool.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <numeric>
#include <set>

using namespace tigerlod;

namespace {

struct Chain {
    std::vector<GridPoint> points;
    uint32_t left, right;
};

/// The unit `unit`'s polygons from `chains` in the order `order`, each chain
/// reversed (points and sides) where `flip` has its bit.
view::UnitPolygons polygons(const std::vector<Chain>& chains, const std::vector<size_t>& order, unsigned flip,
                            uint32_t unit)
{
    datatree::ChainTable t;
    t.strings = {"", "U", "X", "H"};
    datatree::Geometry g;
    for (size_t k = 0; k < order.size(); ++k) {
        Chain c = chains[order[k]];
        if ((flip >> k) & 1U) {
            std::reverse(c.points.begin(), c.points.end());
            std::swap(c.left, c.right);
        }
        t.chains.push_back({k + 1, c.left, c.right, 0, 0});
        g.add_chain(c.points);
    }
    return view::unit_polygons(t, g, unit);
}

/// A ring is simple at its vertices: closed, no vertex twice.
void expect_simple(const std::vector<GridPoint>& ring)
{
    ASSERT_GE(ring.size(), 4U);
    EXPECT_EQ(ring.front(), ring.back());
    const std::set<GridPoint> distinct(ring.begin(), ring.end() - 1);
    EXPECT_EQ(distinct.size(), ring.size() - 1);
}

/// Every order and direction of `chains`, with the check `f`.
template <class F> void every_order(const std::vector<Chain>& chains, F f)
{
    std::vector<size_t> order(chains.size());
    std::iota(order.begin(), order.end(), 0);
    do {
        for (unsigned flip = 0; flip < (1U << chains.size()); ++flip) {
            SCOPED_TRACE(::testing::Message() << "order " << ::testing::PrintToString(order) << " flip " << flip);
            f(order, flip);
        }
    } while (std::next_permutation(order.begin(), order.end()));
}

constexpr uint32_t U = 1, X = 2, H = 3;

} // namespace

TEST(UnitPolygons, AHoleTouchingTheShellIsAHoleNotASelfTouchingRing)
{
    // U: the square 0..6 with triangle H inside touching its bottom at V (3, 0).
    // The shell's chains meet at (6, 6) and V, so a walk can reach V mid-ring.
    const std::vector<Chain> chains = {{{{3, 0}, {6, 0}, {6, 6}}, U, X},
                                       {{{6, 6}, {0, 6}, {0, 0}, {3, 0}}, U, X},
                                       {{{3, 0}, {4, 1}, {2, 1}, {3, 0}}, H, U}};
    every_order(chains, [&](const std::vector<size_t>& order, unsigned flip) {
        const auto u = polygons(chains, order, flip, U);
        ASSERT_TRUE(u.complete);
        ASSERT_EQ(u.polygons.size(), 1U);
        const auto& p = u.polygons[0];
        expect_simple(p.outer);
        EXPECT_EQ(twice_area(p.outer), 72);
        ASSERT_EQ(p.holes.size(), 1U);
        expect_simple(p.holes[0]);
        EXPECT_EQ(twice_area(p.holes[0]), -2);
        // H itself: one triangle.
        const auto h = polygons(chains, order, flip, H);
        ASSERT_EQ(h.polygons.size(), 1U);
        EXPECT_TRUE(h.polygons[0].holes.empty());
        EXPECT_EQ(twice_area(h.polygons[0].outer), 2);
    });
}

TEST(UnitPolygons, PartsTouchingAtACornerAreTwoPolygons)
{
    // U: squares 0..2 and 2..4 (diagonal), touching at (2, 2), both rings
    // passing through it mid-chain-sequence.
    const std::vector<Chain> chains = {{{{0, 0}, {2, 0}, {2, 2}}, U, X},
                                       {{{2, 2}, {0, 2}, {0, 0}}, U, X},
                                       {{{2, 2}, {4, 2}, {4, 4}}, U, X},
                                       {{{4, 4}, {2, 4}, {2, 2}}, U, X}};
    every_order(chains, [&](const std::vector<size_t>& order, unsigned flip) {
        const auto u = polygons(chains, order, flip, U);
        ASSERT_TRUE(u.complete);
        ASSERT_EQ(u.polygons.size(), 2U);
        for (const auto& p : u.polygons) {
            expect_simple(p.outer);
            EXPECT_EQ(twice_area(p.outer), 8);
            EXPECT_TRUE(p.holes.empty());
        }
    });
}

TEST(UnitPolygons, HolesGoToTheSmallestShellAroundThem)
{
    // U: a square 0..10 with hole H (3..7), and inside H an island of U (4..6)
    // with a hole of its own touching it at (5, 4).
    const std::vector<Chain> chains = {{{{0, 0}, {10, 0}, {10, 10}, {0, 10}, {0, 0}}, U, X},
                                       {{{3, 3}, {7, 3}, {7, 7}, {3, 7}, {3, 3}}, H, U},
                                       {{{4, 4}, {5, 4}, {6, 4}, {6, 6}, {4, 6}, {4, 4}}, U, H},
                                       {{{5, 4}, {5, 5}, {4, 5}, {5, 4}}, X, U}};
    every_order(chains, [&](const std::vector<size_t>& order, unsigned flip) {
        const auto u = polygons(chains, order, flip, U);
        ASSERT_TRUE(u.complete);
        ASSERT_EQ(u.polygons.size(), 2U);
        std::vector<std::pair<int64_t, int64_t>> got; // shell area, hole area
        for (const auto& p : u.polygons) {
            ASSERT_EQ(p.holes.size(), 1U);
            got.emplace_back(static_cast<int64_t>(twice_area(p.outer)), static_cast<int64_t>(twice_area(p.holes[0])));
        }
        std::sort(got.begin(), got.end());
        EXPECT_EQ(got, (std::vector<std::pair<int64_t, int64_t>>{{8, -1}, {200, -32}}));
    });
}

TEST(UnitPolygons, AnOpenBoundaryIsIncomplete)
{
    const std::vector<Chain> chains = {{{{0, 0}, {2, 0}, {2, 2}}, U, X}, {{{2, 2}, {0, 2}}, U, X}};
    EXPECT_FALSE(polygons(chains, {0, 1}, 0, U).complete);
    EXPECT_TRUE(polygons(chains, {0, 1}, 0, U).polygons.empty());
}

// Format goldens: Data Trees checked in at format 2.0 (tests/data/formats/
// data-tree-2.0, packed from the small-map golden) and 2.2 (data-tree-2.2,
// packed from a hand-made map whose counties have names and attributes)
// open, their skeletons re-encode to the same bytes, and every node at every
// LOD decodes to the same text, its units with it (none before 2.2). When the
// format's version changes, the trees stay: the test then says whether the
// new reader still reads them.

static void expect_tree_reads_as_its_text(const char* folder, size_t nodes_expected)
{
    const std::filesystem::path dir = std::filesystem::path(TIGERLOD_SOURCE_DIR) / "tests/data/formats" / folder;
    std::string error;
    const auto tree = reader::Tree::open(dir, error);
    ASSERT_TRUE(tree) << error;
    const std::string bytes = tigerlod::testing::slurp(dir / "skeleton.tls");
    EXPECT_EQ(datatree::encode_skeleton(tree->skeleton()), bytes);
    EXPECT_EQ(view::skeleton_text(*tree), tigerlod::testing::slurp(dir / "skeleton.txt"));
    std::string nodes;
    for (uint32_t n = 0; n < tree->skeleton().nodes.size(); ++n) {
        for (uint32_t lod = 0; lod < tree->skeleton().lod_eps_m.size(); ++lod) {
            nodes += view::node_text(*tree, view::read_node(*tree, n, lod));
        }
    }
    EXPECT_EQ(nodes, tigerlod::testing::slurp(dir / "nodes.txt"));
    EXPECT_EQ(tree->skeleton().nodes.size(), nodes_expected);
}

TEST(FormatGolden, DataTree20ReadsAsItsText)
{
    expect_tree_reads_as_its_text("data-tree-2.0", 3);
}

TEST(FormatGolden, DataTree22ReadsAsItsTextWithItsUnits)
{
    expect_tree_reads_as_its_text("data-tree-2.2", 2);
    std::string error;
    const auto tree =
        reader::Tree::open(std::filesystem::path(TIGERLOD_SOURCE_DIR) / "tests/data/formats/data-tree-2.2", error);
    ASSERT_TRUE(tree) << error;
    datatree::UnitTable units;
    ASSERT_TRUE(tree->read_units(1, units).ok());
    ASSERT_EQ(units.units.size(), 3U);
    EXPECT_EQ(units.units[2].code, "01003");
    EXPECT_EQ(units.units[2].name, "Gamma \xc3\xa9");
    EXPECT_EQ(units.units[2].values, (std::vector<std::string>{"7", "1.25", "z"}));
}
