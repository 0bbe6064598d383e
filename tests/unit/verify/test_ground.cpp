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
#include "../../support/sanitizers.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <numbers>
#include <random>
#include <string>

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
double worst_ground_ratio(const ChainStore& orig, const ChainStore& simp, double eps = eps_m)
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
            worst = std::max(worst, brute_ground_m(proj, o[j], s[i], s[i + 1]) / eps);
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

/// Seeds of the property test: 1-8, 1-3 under the sanitizers (which look
/// for memory faults, the same on any chain), or TIGERLOD_PROPERTY_SEEDS=A-B.
std::pair<uint64_t, uint64_t> ground_seeds()
{
    const char* env = std::getenv("TIGERLOD_PROPERTY_SEEDS");
    if (env == nullptr || *env == '\0') {
        return {1, TIGERLOD_SANITIZED ? 3 : 8};
    }
    const std::string t = env;
    const auto dash = t.find('-');
    return dash == std::string::npos ? std::pair{std::stoull(t), std::stoull(t)}
                                     : std::pair{std::stoull(t.substr(0, dash)), std::stoull(t.substr(dash + 1))};
}

/// A seeded case: a projection of any kind this tool offers, anywhere on
/// the globe its formulas serve (either hemisphere, any central meridian),
/// and one long chain in it: from 2 to 12 degrees long in a random
/// direction, wiggling across it by up to a few eps, a graph over its own
/// axis in longitude/latitude (so simple).
struct GroundCase {
    ChainStore store; ///< its projection is the case's

    double eps_m = 0;
    Metric metric = Metric::l2;
    std::string what;
};

GroundCase ground_case(uint64_t seed)
{
    std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ULL + 7);
    auto uni = [&](double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng); };
    GroundCase c;
    ProjectionParams p;
    const int kind = static_cast<int>(seed % 4);
    const double sign = uni(0, 1) < 0.5 ? 1.0 : -1.0; // the hemisphere
    double lon_lo = 0, lon_hi = 0, lat_lo = 0, lat_hi = 0;
    if (kind <= 1) { // the conics
        p.kind = kind == 0 ? ProjectionParams::Kind::albers : ProjectionParams::Kind::lcc;
        p.lon0_deg = uni(-179, 179);
        const double s1 = uni(20, 50), s2 = s1 + uni(5, 20);
        p.stdlat1_deg = sign * s1;
        p.stdlat2_deg = sign * s2;
        p.lat0_deg = sign * (s1 - 10);
        lon_lo = p.lon0_deg - 40;
        lon_hi = p.lon0_deg + 40;
        lat_lo = 15;
        lat_hi = 75;
    } else if (kind == 2) {
        p.kind = ProjectionParams::Kind::tm;
        p.lon0_deg = uni(-179, 179);
        p.lat0_deg = 0;
        p.k0 = uni(0.9996, 1.0);
        p.false_easting_m = 500000;
        lon_lo = p.lon0_deg - 6;
        lon_hi = p.lon0_deg + 6;
        lat_lo = 0;
        lat_hi = 72;
    } else {
        p.kind = ProjectionParams::Kind::utm;
        p.utm_zone = 1 + static_cast<int>(rng() % 60);
        p.utm_north = sign > 0;
        const double mid = -183 + 6.0 * p.utm_zone;
        lon_lo = mid - 3;
        lon_hi = mid + 3;
        lat_lo = 0;
        lat_hi = 80;
    }
    const double eps_choices[] = {1, 4, 16, 64, 250, 500, 1000, 2000};
    c.eps_m = eps_choices[rng() % 8];
    c.metric = static_cast<Metric>((seed / 4) % 3); // each kind in each metric over 12 seeds
    // The chain: n vertices from a start, along a heading, in degrees.
    const int n = 400 + static_cast<int>(rng() % 800);
    const double length = uni(2, 12), heading = uni(0, 2 * std::numbers::pi);
    const double ux = std::cos(heading), uy = std::sin(heading);
    const double step = length / n;
    // Start so that the whole chain stays in the domain chosen above.
    const double x0 = uni(lon_lo + std::max(0.0, -ux * length), lon_hi - std::max(0.0, ux * length));
    const double y0 = uni(lat_lo + std::max(0.0, -uy * length), lat_hi - std::max(0.0, uy * length));
    // Wiggles of up to 3 eps (in degrees of latitude), their slope at most
    // about half a step a step.
    const double amp = uni(0.3, 3) * c.eps_m / 111000;
    const double period = std::max(12.0, 2 * std::numbers::pi * amp / (0.4 * step));
    const double phase = uni(0, 6.3);
    c.store.level_name = "lines";
    c.store.partition = "all";
    c.store.halo_m = 10000;
    c.store.projection = p;
    const Projection proj(p);
    std::vector<GridPoint> pts;
    for (int i = 0; i < n; ++i) {
        const double w = amp * (std::sin(2 * std::numbers::pi * i / period + phase) +
                                0.3 * std::sin(2 * std::numbers::pi * i / (0.37 * period)));
        // Longitudes wrapped into [-180, 180]: a chain may cross the antimeridian
        // (the conics' cut is 180 degrees from lon0, far from it).
        const double lon = std::remainder(x0 + i * step * ux - w * uy, 360.0),
                     lat = sign * (y0 + i * step * uy + w * ux);
        const auto g = proj.to_grid(lon, lat);
        if (!g) {
            ADD_FAILURE() << "seed " << seed << ": (" << lon << ", " << lat << ") is outside the projection";
            break;
        }
        if (pts.empty() || !(pts.back() == *g)) {
            pts.push_back(*g);
        }
    }
    c.store.add_chain({1, c.store.intern(""), c.store.intern(""), c.store.intern("X0000"), 0, 0, 0}, pts);
    c.store.canonicalize();
    c.what = "seed " + std::to_string(seed) + ": " + projection_kind_name(p.kind) +
             (kind == 3 ? " zone " + std::to_string(p.utm_zone) : " lon0 " + std::to_string(p.lon0_deg)) +
             (sign > 0 ? " north" : " south") + ", " + std::to_string(n) + " vertices over " + std::to_string(length) +
             " degrees, eps " + std::to_string(c.eps_m) + " m " + metric_name(c.metric);
    return c;
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

TEST_F(Ground, SeededLongChainsStayWithinEpsOnTheGroundInEveryProjectionAndMetric)
{
    // What docs/guarantees.md says, for any chain length, latitude and
    // metric: within eps geodesic metres in L2 and L1, sqrt(2) eps in Linf
    // (measured along the grid's axes), by the brute force above.
    const auto [first, last] = ground_seeds();
    double worst_l2 = 0;
    size_t cases = 0, l2_cases = 0;
    for (uint64_t seed = first; seed <= last; ++seed) {
        GroundCase c = ground_case(seed);
        SCOPED_TRACE(c.what);
        simplify::SimplifyOptions opt;
        opt.metric = c.metric;
        simplify::ToleranceStats stats;
        const ChainStore out = simplify::simplify_store(c.store, c.eps_m, opt, nullptr, nullptr, stats);
        ASSERT_EQ(out.chains.size(), 1U);
        const size_t n = c.store.points.size(), kept = out.points.size();
        EXPECT_LT(kept, n * 3 / 4) << "too little simplified to test anything";
        const double worst = worst_ground_ratio(c.store, out, c.eps_m);
        const double bound = c.metric == Metric::linf ? std::numbers::sqrt2 : 1.0;
        EXPECT_LE(worst, bound * (1 + 1e-7)) << "kept " << kept << " of " << n;
        if (c.metric == Metric::l2) {
            worst_l2 = std::max(worst_l2, worst);
            ++l2_cases;
        }
        std::printf("ground: %s: kept %zu of %zu, worst %.6f eps\n", c.what.c_str(), kept, n, worst);
        ++cases;
    }
    EXPECT_GT(cases, 0U);
    if (l2_cases > 0) { // the bound is used, not only kept
        EXPECT_GT(worst_l2, 0.8);
    }
}
