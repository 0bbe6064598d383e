#pragma once
/// @file tree_view.hpp
/// A Data Tree as people read it: the skeleton and payloads as text, payloads
/// as GeoJSON in lon/lat, and units' polygons rebuilt from their chains.
/// Used by tigerlod-dump, -export and -verify and by the benchmarks.

#include "core/projection.hpp"
#include "reader/reader.hpp"

#include <optional>
#include <string>
#include <vector>

namespace tigerlod::view {

/// The projection a skeleton was made with.
ProjectionParams projection_of(const datatree::Skeleton& s);

/// The node of `spec`: a node index, or a unit code ("" or "root" for the root).
/// Throws usage_error naming `spec` when there is none.
uint32_t find_node(const datatree::Skeleton& s, const std::string& spec);

/// The skeleton as canonical text, one item per line.
std::string skeleton_text(const reader::Tree& tree);

/// A node's chains at one LOD, with their table; throws input_error with the reader's message on bad data.
struct NodeMap {
    uint32_t node = 0, lod = 0;
    datatree::ChainTable table;
    datatree::Geometry geometry;
};
NodeMap read_node(const reader::Tree& tree, uint32_t node, uint32_t lod);

/// A node's map as text: one line per chain with its id, units, class, flags and points.
std::string node_text(const reader::Tree& tree, const NodeMap& m);

/// Write a node's map to `path` (a file, or /vsistdout/) as GeoJSON through
/// GDAL's driver, as tigerlod-export writes: LineStrings in lon/lat (NAD83,
/// 7 decimals) with id, left, right, class and closed. Throws
/// environment_error if GDAL cannot write.
void write_node_geojson(const reader::Tree& tree, const NodeMap& m, const std::string& path);

/// One unit's polygon rings rebuilt from the chains that have it on one side,
/// oriented so the unit is on the left (counter-clockwise outer rings),
/// chained end to start. Rings that do not close are returned as they are,
/// flagged open.
struct Ring {
    std::vector<GridPoint> points;
    bool closed = true;
};
std::vector<Ring> unit_rings(const datatree::ChainTable& table, const datatree::Geometry& g, uint32_t unit);

/// One unit as valid OGC polygons: simple outer rings (counter-clockwise),
/// each with the simple holes (clockwise) that lie in it. A boundary that
/// passes a vertex twice (a hole touching the shell at a point, two parts
/// touching at a corner) is split there, so no ring touches itself; rings of
/// zero area are dropped. Rings are closed (first point == last).
struct UnitPolygon {
    std::vector<GridPoint> outer;
    std::vector<std::vector<GridPoint>> holes;
};
struct UnitPolygons {
    std::vector<UnitPolygon> polygons;
    bool complete = true; ///< false: a ring did not close (the unit is cut by the node); no polygons then
};
UnitPolygons unit_polygons(const datatree::ChainTable& table, const datatree::Geometry& g, uint32_t unit);

} // namespace tigerlod::view
