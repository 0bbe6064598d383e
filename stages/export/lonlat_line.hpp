#pragma once
/// @file lonlat_line.hpp
/// A tree's segment written in lon/lat: a GIS reading lon/lat coordinates
/// draws and measures straight lines between them, which in the tree's
/// projection bow away from the straight segment the tree holds (by
/// kilometres for a long segment). densify_lonlat adds points of the
/// segment until each lon/lat piece stays within a bound of it on the
/// ground.

#include "core/geometry.hpp"
#include "core/projection.hpp"

#include <span>
#include <utility>
#include <vector>

namespace tigerlod::exporter {

/// How far, in ground metres, the straight lon/lat line between two points
/// of grid segment pq strays from pq: the largest of its distances, taken
/// at 1/8, 2/8, ..., 7/8 of the lon/lat line, each the planar distance to pq
/// over the least scale of the projection around them.
double lonlat_bow_m(const Projection& proj, double px, double py, double qx, double qy);

/// The lon/lat points of chain `pts`: every vertex, and between two of them
/// points of their grid segment, bisected until lonlat_bow_m of each piece
/// is within `max_bow_m` (half of it at the eighths, so the bound holds
/// between them with a factor 2 to spare; tested by dense sampling) or a
/// piece is shorter than a grid step.
std::vector<std::pair<double, double>> densify_lonlat(const Projection& proj, std::span<const GridPoint> pts,
                                                      double max_bow_m);

} // namespace tigerlod::exporter
