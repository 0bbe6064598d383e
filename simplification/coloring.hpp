#pragma once
/// @file coloring.hpp
/// Render tiles and stencil classes (tigerlod-color): the tiles a store is
/// drawn in at one tolerance, and per tile a colouring of the chains that
/// touch it into classes 1..max_classes such that an owned chain never
/// shares a class with a chain whose tolerance neighbourhood can overlap its
/// own. Two halo chains may: only owned chains' shortcuts are tested in the
/// stencil, and a test is fooled only by a tent of the tested chain's class.
/// So may two chains neither of which can be tested: an owned chain whose
/// every shortcut is too short for the raster to test a pixel of it
/// (testable_chain) is coloured as the halo is.

#include "core/errors.hpp"
#include "core/geometry.hpp"
#include "core/metric.hpp"

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace tigerlod::simplify {

/// One chain as the colouring sees it.
struct ChainGeom {
    std::span<const GridPoint> points;
    double eps = 0;     ///< tolerance in grid units
    bool owned = false; ///< simplified here (not halo); counts as halo where testable_chain is false
    /// Segment i (points i, i + 1) is seen only if `keep` is empty or
    /// keep[i] != 0: the parts of a halo chain out of every owned chain's reach are left out.
    std::span<const uint8_t> keep = {};
};

/// Whether segment i takes part under a `keep` mask as in ChainGeom (empty: all do).
inline bool takes_part(std::span<const uint8_t> keep, size_t i) noexcept
{
    return keep.empty() || keep[i] != 0;
}

/// A render tile: pixel (i, j) covers [x0 + i p, x0 + (i+1) p) x [y0 + j p, ...).
struct TileSpec {
    double x0 = 0, y0 = 0, pixel = 1;
    uint32_t width = 0, height = 0;
};

/// What color_tiles throws when a tile at min_tile_pixels still needs more
/// classes: the message names the tile in grid units, and `tile` lets a
/// caller that knows the projection place it on the map.
struct tile_overflow_error : input_error {
    tile_overflow_error(const std::string& what, const TileSpec& where) : input_error(what), tile(where) {}
    TileSpec tile;
};

struct ColoredTile {
    TileSpec spec;
    std::vector<uint32_t> chains; ///< indices of the chains drawn in it, ascending
    std::vector<uint8_t> classes; ///< class of each, 1..max_classes
    uint32_t depth = 0;           ///< times split
};

struct ColorOptions {
    Metric metric = Metric::l2;
    double pixel_fraction = 0.25; ///< pixel size as a fraction of the smallest eps
    uint32_t tile_pixels = 4096;  ///< tile width and height before splitting
    uint32_t min_tile_pixels = 16;
    uint32_t max_classes = 255;
    double margin_px = 2.0; ///< added to eps_i + eps_j in the conflict test, and to tents
};

struct ColorResult {
    double pixel = 0; ///< pixel size in grid units
    std::vector<ColoredTile> tiles;
    size_t conflict_edges = 0;
    size_t splits = 0;
    uint32_t max_classes_used = 0;
    double mean_classes = 0;
};

/// Fragments this close to a shortcut's ends, in pixels, are not tested
/// (raster.cpp's test shaders): a junction is on every adjacent chain's
/// region boundary.
inline constexpr double end_margin_px = 1.5;

/// The squared length in grid units^2 (rounded down) at or below which a
/// shortcut leaves the raster no pixel to test at this pixel size, so the
/// raster passes it whatever is drawn. A pixel is tested only when its
/// centre lies within half a pixel of the segment across and between its
/// ends along, so within sqrt((L/2)^2 + 1/4) of the nearer end; below the
/// end margin m for L <= 2 sqrt((m - 0.1)^2 - 1/4), 2.6 pixels. The 0.1
/// pixel covers the shaders' float rounding (under 0.01 pixel on tiles of
/// up to 16384 pixels).
int128 untested_length2(double pixel) noexcept;

/// Whether some shortcut of a chain through `points` can be longer than
/// that: its bounding box's squared diagonal above untested_length2(pixel).
/// Exact (integers), so a chain that is not testable has no shortcut above
/// the length.
bool testable_chain(std::span<const GridPoint> points, double pixel) noexcept;

/// Whether shortcut ab is longer than untested_length2(pixel), exactly.
inline bool testable_shortcut(GridPoint a, GridPoint b, int128 untested2) noexcept
{
    const int128 dx = int64_t{b.x} - a.x, dy = int64_t{b.y} - a.y;
    return dx * dx + dy * dy > untested2;
}

/// Radius in grid units around a chain of tolerance `eps` that its tent and
/// its candidates can touch: eps in the metric, as an L2 distance, plus the margin.
double reach_radius(double eps, double pixel, const ColorOptions& opt) noexcept;

/// The pixel of the tiles color_tiles makes for chains of these tolerances:
/// pixel_fraction x the smallest positive eps (0 when there is none).
double tile_pixel(std::span<const double> eps, const ColorOptions& opt) noexcept;

/// Tile the owned chains and colour each tile; split tiles that need more
/// than max_classes. Deterministic. Throws tile_overflow_error when a tile at
/// min_tile_pixels still needs more classes.
ColorResult color_tiles(std::span<const ChainGeom> chains, const ColorOptions& opt, unsigned threads);

/// L2 distance between segments ab and cd (0 if they meet), in doubles.
double segment_distance(GridPoint a, GridPoint b, GridPoint c, GridPoint d) noexcept;

/// The conflict graph as sorted adjacency lists: chains i != j, at least one
/// of them owned and testable_chain at `pixel`, with segments that take part (ChainGeom::keep) closer than
/// reach_radius(eps_i) + reach_radius(eps_j) (segment_distance, exactly as
/// a test of every pair would find).
std::vector<std::vector<uint32_t>> conflict_graph(std::span<const ChainGeom> chains, double pixel,
                                                  const ColorOptions& opt);

/// DSatur colouring of a graph given as sorted adjacency lists; colours from
/// 1. Returns false if more than max_colors would be needed.
bool dsatur(const std::vector<std::vector<uint32_t>>& adj, uint32_t max_colors, std::vector<uint8_t>& colors);

} // namespace tigerlod::simplify
