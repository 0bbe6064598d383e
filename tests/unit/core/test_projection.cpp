#include "core/projection.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
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
