#pragma once
/// @file colors.hpp
/// The colours file (formats/colors/SPEC.md): the stencil classes that
/// tigerlod-color gives the chains of one chain store at one tolerance, per
/// render tile, and tigerlod-simplify reads back. Chains are named by their
/// stable ids, so a file stays valid for the store it was made from.

#include "core/metric.hpp"

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace tigerlod::colors {

/// One render tile: its corner and size in pixels of ColorFile::pixel grid
/// units, how many times it was split, and a class 1..255 per chain drawn in it.
struct Tile {
    double x0 = 0, y0 = 0;
    uint32_t width = 0, height = 0;
    uint32_t depth = 0;
    std::vector<uint64_t> chains; ///< chain ids, ascending by the store's order
    std::vector<uint8_t> classes; ///< parallel to chains, each in 1..255
};

struct ColorFile {
    std::string level, partition; ///< the store's level and partition
    double eps_m = 0;             ///< the tolerance the classes are valid for
    Metric metric = Metric::l2;
    double pixel = 0; ///< pixel size in grid units
    uint64_t splits = 0, conflict_edges = 0;
    std::vector<Tile> tiles;
};

/// The file's bytes: one line of JSON (schema "tigerlod.colors/1") and a newline.
std::string encode(const ColorFile& f);

/// Parse a colours file; throws format_error naming `name` and the fault
/// (not JSON, another schema, a field missing or of the wrong type, a class
/// outside 1..255, a tile whose chains and classes differ in number or whose
/// size is 0).
ColorFile decode(std::string_view text, const std::string& name);

} // namespace tigerlod::colors
