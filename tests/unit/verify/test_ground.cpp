// eps on the ground: a chain across 14 degrees of latitude in Alaska, in the
// default CONUS Albers, where the projection's scale varies by a fifth along
// the chain. Simplified, every skipped vertex must lie within eps on the
// ellipsoid of its shortcut, measured here by a brute-force geodesic search
// that uses none of the scale model (only lon/lat and GeographicLib's
// geodesic); the model simplify had before (one scale per chain, at its
// box's centre) must fail that measure, and tigerlod-verify on the ground
// must catch a tree made with it even where its planar check is told to
// trust it.
#include "core/projection.hpp"
#include "formats/chains/chain_store.hpp"
#include "simplification/simplifier.hpp"
#include "stages/pack/packer.hpp"
#include "stages/verify/verifier.hpp"
#include "../../support/ground_distance.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <numbers>

namespace fs = std::filesystem;
using namespace tigerlod;
using chains::ChainStore;

namespace {

constexpr double eps_m = 2000;

/// One line (no units) shaped as an L: north along -150 from latitude 56
/// to 70, then east along 70 to -125, with a wiggle of a few kilometres
/// for simplify to remove, north-south on the second leg, where Albers
/// shrinks that direction most (by 1/k, its scale along the parallel
/// being k > 1 north of its standard parallels). The wiggles fade at the
/// corner, so the line is simple. `north_leg` false: the east leg alone,
/// `east_deg` long.
ChainStore alaska_line(bool north_leg = true, double east_deg = 25)
{
    ChainStore s;
    s.level_name = "lines";
    s.partition = "all";
    s.halo_m = 10000;
    const Projection proj(s.projection);
    std::vector<GridPoint> pts;
    auto add = [&](double lon, double lat) {
        const auto g = proj.to_grid(lon, lat);
        EXPECT_TRUE(g);
        pts.push_back(*g);
    };
    auto wiggle = [](int i, double fade) {
        return std::min(1.0, fade / 30) * (std::sin(2 * std::numbers::pi * i / 23) + 0.4 * std::sin(i / 1.17));
    };
    const int north = north_leg ? 600 : 0, east = int(36 * east_deg);
    for (int i = 0; i < north; ++i) {
        add(-150 + 0.03 * wiggle(i, north - 1 - i), 56 + 14.0 * i / north);
    }
    for (int j = 0; j <= east; ++j) {
        add(-150 + east_deg * j / east, 70 + 0.025 * wiggle(j, north_leg ? j : 30));
    }
    s.add_chain({1, s.intern(""), s.intern(""), s.intern("X0000"), 0, 0, 0}, pts);
    s.canonicalize();
    return s;
}

/// The least geodesic distance from grid point v to the ground image of
/// grid segment ab, by brute force (200 samples, refined).
double brute_ground_m(const Projection& proj, GridPoint v, GridPoint a, GridPoint b)
{
    double vlon = 0, vlat = 0;
    proj.to_lonlat(v.x, v.y, vlon, vlat);
    return tigerlod::testing::ground_to_segment_m(proj, vlon, vlat, a, b, 200);
}

/// The largest ground distance over eps of any vertex `simp` skips.
double worst_ground_ratio(const ChainStore& orig, const ChainStore& simp)
{
    const Projection proj(orig.projection);
    const auto o = orig.chain_points(orig.chains.at(0));
    const auto s = simp.chain_points(simp.chains.at(0));
    double worst = 0;
    size_t m = 0;
    for (size_t i = 0; i + 1 < s.size(); ++i) {
        while (o[m] != s[i]) {
            ++m;
        }
        for (size_t j = m + 1; o[j] != s[i + 1]; ++j) {
            worst = std::max(worst, brute_ground_m(proj, o[j], s[i], s[i + 1]) / eps_m);
        }
    }
    return worst;
}

/// Simplify at eps_m on the ground (the model of this code), or with the
/// model before it: one scale per chain, min(k, 1/k) at its box's centre.
ChainStore simplified(const ChainStore& store, bool centre_scale)
{
    simplify::SimplifyOptions opt;
    double eps = eps_m;
    if (centre_scale) {
        const Projection proj(store.projection);
        GridBox box;
        for (const GridPoint p : store.points) {
            box.extend(p);
        }
        double lon = 0, lat = 0;
        proj.to_lonlat(0.5 * double(box.min_x + box.max_x), 0.5 * double(box.min_y + box.max_y), lon, lat);
        const double k = proj.scale(lon, lat);
        opt.projection_scale = false; // eps in projected metres: eps_m * k_centre, as the old model had
        eps *= std::min(k, 1 / k);
    }
    simplify::ToleranceStats stats;
    ChainStore out = simplify::simplify_store(store, eps, opt, nullptr, nullptr, stats);
    out.eps_m = eps_m;
    return out;
}

class Ground : public ::testing::Test {
  protected:
    fs::path dir;
    void SetUp() override
    {
        dir = fs::temp_directory_path() /
              ("tigerlod-ground-" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "-" +
               std::to_string(::getpid()));
        fs::remove_all(dir);
    }
    void TearDown() override { fs::remove_all(dir); }

    /// Pack `orig` with `simp` as its LOD at eps_m, and verify it.
    verify::Report verify(const ChainStore& orig, const ChainStore& simp, const verify::Options& options)
    {
        fs::create_directories(dir / "orig" / "lines");
        fs::create_directories(dir / "simp" / "eps-2000m" / "lines");
        chains::write(dir / "orig" / "lines" / "all.tlc", orig);
        chains::write(dir / "simp" / "eps-2000m" / "lines" / "all.tlc", simp);
        const pack::PackedTree tree = pack::build_tree(dir / "orig", dir / "simp", {});
        pack::write_tree(dir / "tree", tree, "{}\n");
        std::string error;
        const auto t = reader::Tree::open(dir / "tree", error);
        EXPECT_TRUE(t) << error;
        return verify::verify_tree(*t, dir / "orig", options);
    }
};

} // namespace

TEST_F(Ground, EveryVertexStaysWithinEpsOnTheEllipsoid)
{
    // The L: its box reaches from latitude 56 to beyond 70, and its eps is
    // set by the least scale there.
    const ChainStore store = alaska_line();
    const ChainStore now = simplified(store, false);
    EXPECT_LT(now.points.size(), store.points.size() / 5);
    const double worst = worst_ground_ratio(store, now);
    std::printf("ground: the L keeps %zu of %zu vertices, worst ground distance %.6f eps\n", now.points.size(),
                store.points.size(), worst);
    EXPECT_LE(worst, 1.0);
    // A chain along one parallel, wiggling north-south: its box is narrow in
    // latitude, so the bound is nearly the scale there, and the budget is used.
    const ChainStore east = alaska_line(false, 5);
    const ChainStore east_now = simplified(east, false);
    const double east_worst = worst_ground_ratio(east, east_now);
    std::printf("ground: the east leg alone keeps %zu of %zu vertices, worst ground distance %.6f eps\n",
                east_now.points.size(), east.points.size(), east_worst);
    EXPECT_LE(east_worst, 1.0);
    EXPECT_GT(east_worst, 0.85);
}

TEST_F(Ground, OneScaleAtTheChainsCentreLeavesEpsOnTheGround)
{
    // The model before: the north leg's vertices leave their shortcuts by more than eps.
    const ChainStore store = alaska_line();
    const double worst = worst_ground_ratio(store, simplified(store, true));
    std::printf("ground: the centre's scale alone gives a worst ground distance of %.6f eps\n", worst);
    EXPECT_GT(worst, 1.05);
}

TEST_F(Ground, VerifyOnTheGroundCatchesWhatThePlanarModelPasses)
{
    const ChainStore store = alaska_line();
    verify::Options options;
    // The planar check told to trust eps as projected metres (the scale
    // model is not consulted): the old tree passes it, and only the
    // measure on the ellipsoid can fail it.
    options.tolerance.projection_scale = false;
    options.ground = true;
    const auto old = verify(store, simplified(store, true), options);
    EXPECT_EQ(old.total(), 1U);
    EXPECT_EQ(old.violations.at("eps_exceeded"), 1U);
    ASSERT_EQ(old.items.size(), 1U);
    EXPECT_NE(old.items[0].detail.find("on the ground"), std::string::npos) << old.items[0].detail;
    EXPECT_GT(old.ground_ratio_max, 1.0);
    // The same without the ground check: clean, which is what verify said.
    options.ground = false;
    EXPECT_EQ(verify(store, simplified(store, true), options).total(), 0U);

    // This code's tree: clean with the scale model and on the ground, and the
    // report's largest ratio is the brute force's.
    const ChainStore now = simplified(store, false);
    options.tolerance.projection_scale = true;
    options.ground = true;
    const auto r = verify(store, now, options);
    EXPECT_EQ(r.total(), 0U);
    EXPECT_TRUE(r.ground);
    ASSERT_EQ(r.by_level_lod.size(), 2U);
    EXPECT_EQ(r.by_level_lod[0].ground_ratio_max, 0.0); // LOD 0 skips nothing
    EXPECT_EQ(r.by_level_lod[1].ground_ratio_max, r.ground_ratio_max);
    // An upper bound on the brute force's (the bound takes the least scale
    // in any direction; Albers scales the two axes differently), and at most 1.
    EXPECT_LE(r.ground_ratio_max, 1.0);
    EXPECT_GE(r.ground_ratio_max, worst_ground_ratio(store, now) - 1e-9);
    // Near eps the report is the geodesic itself: the old tree's violation
    // names the brute force's worst distance.
    EXPECT_NEAR(old.ground_ratio_max, worst_ground_ratio(store, simplified(store, true)), 1e-6);
}
