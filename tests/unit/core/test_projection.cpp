#include "core/projection.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <numbers>

using namespace tigerlod;

namespace {

/// Projected distance in metres between two lon/lat points, on a 0.1 mm grid
/// of a projection whose origin is near them (so the grid coordinates fit).
double distance_m(ProjectionParams p, double lon1, double lat1, double lon2, double lat2)
{
    p.grid_m = 1e-4;
    if (p.kind != ProjectionParams::Kind::tm) {
        p.lon0_deg = std::round(lon1);
    }
    p.lat0_deg = std::round(lat1);
    const Projection proj(p);
    const auto a = proj.to_grid(lon1, lat1), b = proj.to_grid(lon2, lat2);
    EXPECT_TRUE(a && b);
    return std::hypot(double(a->x) - b->x, double(a->y) - b->y) * p.grid_m;
}

/// The smallest projected distance from (lon, lat) to its eight neighbours on a
/// 1e-6 degree lattice.
double nearest_neighbour_m(const ProjectionParams& p, double lon, double lat)
{
    double best = std::numeric_limits<double>::infinity();
    for (int dx = -1; dx <= 1; ++dx) {
        for (int dy = -1; dy <= 1; ++dy) {
            if (dx != 0 || dy != 0) {
                best = std::min(best, distance_m(p, lon, lat, lon + dx * 1e-6, lat + dy * 1e-6));
            }
        }
    }
    return best;
}

} // namespace

TEST(Projection, LatticeSeparationIsALowerBoundAndNearlyTight)
{
    // Albers (east-west scale k, north-south 1/k), LCC (conformal) and UTM, at
    // latitudes inside and far outside the conics' standard parallels.
    ProjectionParams albers;
    ProjectionParams lcc;
    lcc.kind = ProjectionParams::Kind::lcc;
    lcc.lat0_deg = 33;
    lcc.stdlat1_deg = 33;
    lcc.stdlat2_deg = 45;
    ProjectionParams tm; // as UTM zone 15, with its origin near the points
    tm.kind = ProjectionParams::Kind::tm;
    tm.lon0_deg = -93;
    tm.k0 = 0.9996;
    for (const ProjectionParams& p : {albers, lcc, tm}) {
        const Projection proj(p);
        for (double lat : {-14.0, 0.0, 25.0, 37.9, 40.0, 49.0, 60.0, 71.0}) {
            const double bound = proj.lattice_separation_m(1e-6, lat - 0.25, lat + 0.25);
            double nearest = std::numeric_limits<double>::infinity();
            for (double at : {lat - 0.25, lat, lat + 0.25}) {
                nearest = std::min(nearest, nearest_neighbour_m(p, -93.1, at));
            }
            SCOPED_TRACE(proj.describe() + " lat " + std::to_string(lat));
            EXPECT_LE(bound, nearest);
            // Tight, to the 1% margin, the band's width and the ellipsoid's radii.
            EXPECT_GE(bound, 0.95 * nearest);
        }
    }
    const Projection proj(albers);
    EXPECT_EQ(proj.lattice_separation_m(1e-6, 80.0, 90.0), 0.0); // reaches the pole
    EXPECT_EQ(proj.lattice_separation_m(1e-6, 41.0, 40.0), 0.0); // empty band
    // At 40 degrees east-west steps are the shorter: a cos(40.01) per 1e-6
    // degree, times k at 39.99 (k grows away from the origin at 37.9).
    const double ew = 6378137.0 * std::cos(40.01 * std::numbers::pi / 180) * 1e-6 * std::numbers::pi / 180;
    EXPECT_NEAR(proj.lattice_separation_m(1e-6, 40.0, 40.0), 0.99 * ew * proj.scale(-96, 39.99), 1e-12);
}

TEST(Projection, FastAlbersRoundsAsGeographicLibDoes)
{
    const Projection conus{ProjectionParams{}};
    ASSERT_TRUE(conus.fast_albers());
    ProjectionParams scaled;
    scaled.k0 = 0.9996; // GeographicLib's k0 is not Snyder's: no fast path
    EXPECT_FALSE(Projection(scaled).fast_albers());
    ProjectionParams lcc;
    lcc.kind = ProjectionParams::Kind::lcc;
    EXPECT_FALSE(Projection(lcc).fast_albers());
    ProjectionParams one = lcc; // one standard parallel: not taken
    one.kind = ProjectionParams::Kind::albers;
    one.stdlat1_deg = one.stdlat2_deg = 40;
    EXPECT_FALSE(Projection(one).fast_albers());
    ProjectionParams south; // Australian Albers: a cone opening south, not taken
    south.stdlat1_deg = -18;
    south.stdlat2_deg = -36;
    south.lat0_deg = 0;
    south.lon0_deg = 132;
    EXPECT_FALSE(Projection(south).fast_albers());
    ProjectionParams north; // Alaska Albers on a 1 mm grid
    north.stdlat1_deg = 55;
    north.stdlat2_deg = 65;
    north.lat0_deg = 50;
    north.lon0_deg = -154;
    north.grid_m = 0.001;
    const Projection alaska(north);
    ASSERT_TRUE(alaska.fast_albers());

    // Micro-degree points as ingest projects them, over the globe and densely
    // over CONUS, where a 1 cm grid has about 2e-3 of them within the guard.
    std::mt19937_64 rng(11);
    size_t differ = 0, points = 0;
    for (const Projection* p : {&conus, &alaska}) {
        for (int i = 0; i < 400000; ++i) {
            const bool world = i % 4 == 0;
            const double lon = (world ? -180e6 + double(rng() % 360000001) : -125e6 + double(rng() % 58000001)) * 1e-6;
            const double lat = (world ? -89e6 + double(rng() % 178000001) : 24e6 + double(rng() % 26000001)) * 1e-6;
            differ += p->to_grid(lon, lat) != p->to_grid_reference(lon, lat);
            ++points;
        }
    }
    EXPECT_EQ(differ, 0U) << "of " << points;
    // Outside the domain both say so.
    EXPECT_FALSE(conus.to_grid(181, 0));
    EXPECT_FALSE(conus.to_grid(0, std::nan("")));
}

namespace {

/// The least scale of `proj` in any direction at grid point (gx, gy): k
/// along the parallel and, for Albers, 1/k along the meridian.
double least_scale_at(const Projection& proj, double gx, double gy)
{
    double lon = 0, lat = 0;
    proj.to_lonlat(gx, gy, lon, lat);
    const double k = proj.scale(lon, lat);
    return proj.params().kind == ProjectionParams::Kind::albers ? std::min(k, 1 / k) : k;
}

std::vector<ProjectionParams> projections_for_scale_tests()
{
    ProjectionParams conus; // the default Albers (CONUS, GRS 80)
    ProjectionParams south; // a southern cone: its apex lies south
    south.lon0_deg = 135;
    south.lat0_deg = 0;
    south.stdlat1_deg = -18;
    south.stdlat2_deg = -36;
    ProjectionParams lcc;
    lcc.kind = ProjectionParams::Kind::lcc;
    lcc.lat0_deg = 33;
    lcc.stdlat1_deg = 33;
    lcc.stdlat2_deg = 45;
    ProjectionParams tm;
    tm.kind = ProjectionParams::Kind::tm;
    tm.lon0_deg = -93;
    tm.k0 = 0.9996;
    for (auto* p : {&conus, &south, &lcc, &tm}) {
        p->grid_m = 1.0; // boxes of thousands of km fit in 32 bits
    }
    return {conus, south, lcc, tm};
}

} // namespace

TEST(Projection, ConicScaleFallsToOneLeastLatitudeAndRisesBeyondIt)
{
    // smallest_scale's premise: along a meridian the conics' scale k has one
    // minimum and grows monotonically away from it toward both poles.
    for (const ProjectionParams& p : projections_for_scale_tests()) {
        if (p.kind == ProjectionParams::Kind::tm) {
            continue;
        }
        const Projection proj(p);
        SCOPED_TRACE(proj.describe());
        std::vector<double> k;
        for (double lat = -89.5; lat <= 89.5; lat += 0.01) {
            k.push_back(proj.scale(p.lon0_deg, lat));
        }
        const size_t least = size_t(std::min_element(k.begin(), k.end()) - k.begin());
        EXPECT_GT(least, 0U);
        EXPECT_LT(least, k.size() - 1);
        for (size_t i = 1; i < k.size(); ++i) {
            if (i <= least) {
                EXPECT_LE(k[i], k[i - 1]) << "at sample " << i;
            } else {
                EXPECT_GE(k[i], k[i - 1]) << "at sample " << i;
            }
        }
    }
}

TEST(Projection, SmallestScaleIsALowerBoundOverTheBoxAndNearlyTight)
{
    std::mt19937 rng(49);
    for (const ProjectionParams& p : projections_for_scale_tests()) {
        const Projection proj(p);
        SCOPED_TRACE(proj.describe());
        std::uniform_real_distribution<double> lon(p.lon0_deg - 25, p.lon0_deg + 25);
        std::uniform_real_distribution<double> lat(p.stdlat1_deg < 0 ? -70.0 : 0.0, p.stdlat1_deg < 0 ? 0.0 : 75.0);
        std::uniform_real_distribution<double> half(0.5e3, 1.5e6); // box half-sides, metres
        for (int trial = 0; trial < 200; ++trial) {
            const auto c = proj.to_grid(lon(rng), lat(rng));
            ASSERT_TRUE(c);
            const auto hx = int64_t(half(rng)), hy = int64_t(half(rng));
            const GridBox box{c->x - hx, c->y - hy, c->x + hx, c->y + hy};
            const double bound = proj.smallest_scale(box);
            double least = INFINITY;
            constexpr int n = 60;
            for (int i = 0; i <= n; ++i) {
                for (int j = 0; j <= n; ++j) {
                    least = std::min(least, least_scale_at(proj, double(box.min_x) + double(2 * hx) * i / n,
                                                           double(box.min_y) + double(2 * hy) * j / n));
                }
            }
            // The box's point nearest the apex lies on the central meridian (x = the
            // grid's x of lon0), which the lattice may miss: sample it too.
            const auto m = proj.to_grid(p.lon0_deg, p.stdlat1_deg);
            if (m && m->x > box.min_x && m->x < box.max_x) {
                for (const int64_t y : {box.min_y, box.max_y}) {
                    least = std::min(least, least_scale_at(proj, double(m->x), double(y)));
                }
            }
            ASSERT_GT(bound, 0.0);
            EXPECT_LE(bound, least) << "box " << box.min_x << "," << box.min_y << " - " << box.max_x << ","
                                    << box.max_y;
            // Tight: the lattice misses the extreme by at most a step's change.
            if (p.kind != ProjectionParams::Kind::tm) {
                EXPECT_GE(bound, least * (1 - 2e-3));
            }
        }
    }
    const Projection conus(projections_for_scale_tests()[0]);
    EXPECT_EQ(conus.smallest_scale(GridBox{}), 0.0); // empty
}

TEST(Projection, TransverseMercatorScaleIsLeastOnItsCentralMeridian)
{
    // smallest_scale gives Transverse Mercator's k0: k >= k0 over its domain.
    const Projection proj(projections_for_scale_tests()[3]);
    for (double lat = -80; lat <= 80; lat += 2.5) {
        for (double dlon = -30; dlon <= 30; dlon += 1.5) {
            EXPECT_GE(proj.scale(-93 + dlon, lat), 0.9996 * (1 - 1e-12)) << lat << " " << dlon;
        }
    }
    EXPECT_NEAR(proj.smallest_scale(GridBox{0, 0, 1000, 1000}), 0.9996, 1e-8);
}

TEST(Projection, GeodesicDistanceOnTheEllipsoid)
{
    const Projection proj(ProjectionParams{});
    // One degree of latitude at the equator on GRS 80: 110,574.4 m.
    EXPECT_NEAR(proj.geodesic_m(0, 0, 0, 1), 110574.3, 0.5);
    EXPECT_NEAR(proj.geodesic_m(-96, 40, -96, 40), 0.0, 1e-9);
}

TEST(Projection, SouthernAlbersRoundTripsAndHasUnitScaleOnItsParallels)
{
    // A cone opening south (Australia's Albers: parallels -18 and -36), which
    // GeographicLib 2.1.2's Forward alone gets wrong (upstream issue 55).
    ProjectionParams p;
    p.lon0_deg = 132;
    p.lat0_deg = 0;
    p.stdlat1_deg = -18;
    p.stdlat2_deg = -36;
    p.grid_m = 0.01;
    const Projection proj(p);
    for (const double lat : {-10.0, -18.0, -27.0, -36.0, -43.0}) {
        for (const double lon : {115.0, 132.0, 153.0}) {
            const auto g = proj.to_grid(lon, lat);
            ASSERT_TRUE(g);
            double lon2 = 0, lat2 = 0;
            proj.to_lonlat(g->x, g->y, lon2, lat2); // within the 5 mm grid rounding
            EXPECT_NEAR(lat2, lat, 1e-7) << lon << " " << lat;
            EXPECT_NEAR(lon2, lon, 1e-7) << lon << " " << lat;
        }
    }
    EXPECT_NEAR(proj.scale(132, -18), 1.0, 1e-12);
    EXPECT_NEAR(proj.scale(140, -36), 1.0, 1e-12);
    EXPECT_LT(proj.scale(132, -27), 1.0);
    // North is up: Sydney (-33.9) lies south of Darwin (-12.5).
    EXPECT_LT(proj.to_grid(151.2, -33.9)->y, proj.to_grid(130.8, -12.5)->y);
}
