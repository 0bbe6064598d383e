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
