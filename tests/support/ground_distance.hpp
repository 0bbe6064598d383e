#pragma once
/// @file ground_distance.hpp
/// For tests that measure on the ellipsoid without the scale model: the
/// geodesic distance from a lon/lat point to the image of a grid segment,
/// by brute force (the projection's lon/lat and GeographicLib's geodesic
/// alone). Tests only.
#include "core/projection.hpp"

#include <algorithm>

namespace tigerlod::testing {

/// The least geodesic distance in metres from (lon, lat) to the image of
/// grid segment ab: `samples` points of it, refined around the nearest by
/// ternary search.
inline double ground_to_segment_m(const Projection& proj, double lon, double lat, GridPoint a, GridPoint b, int samples)
{
    auto g = [&](double t) {
        double slon = 0, slat = 0;
        proj.to_lonlat(a.x + t * (double(b.x) - a.x), a.y + t * (double(b.y) - a.y), slon, slat);
        return proj.geodesic_m(lon, lat, slon, slat);
    };
    int best = 0;
    for (int i = 1; i <= samples; ++i) {
        best = g(double(i) / samples) < g(double(best) / samples) ? i : best;
    }
    double lo = std::max(0.0, double(best - 1) / samples), hi = std::min(1.0, double(best + 1) / samples);
    for (int it = 0; it < 60; ++it) {
        const double m1 = lo + (hi - lo) / 3, m2 = hi - (hi - lo) / 3;
        if (g(m1) < g(m2)) {
            hi = m2;
        } else {
            lo = m1;
        }
    }
    return std::min(g(double(best) / samples), g(0.5 * (lo + hi)));
}

} // namespace tigerlod::testing
