#pragma once
/// @file datatree.hpp
/// The Data Tree on disk: the skeleton (the only part a reader keeps in
/// memory), tile files that hold the payloads of subtrees, and the two kinds
/// of payload: a node's chain table and its geometry at one LOD (Draco). The
/// byte layout is in SPEC.md beside this file; no other code knows it.
///
/// Everything here is free of GL and GDAL: the reader runtime links it.

#include "core/geometry.hpp"

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace tigerlod::datatree {

constexpr uint16_t major_version = 2;
constexpr uint16_t minor_version = 2;
/// "Data Tree format 2.2", for --version.
inline std::string format_version_text()
{
    return "Data Tree format " + std::to_string(major_version) + "." + std::to_string(minor_version);
}
constexpr uint32_t no_node = 0xFFFFFFFFU;

/// Where a payload lies: a byte range of a tile file, and its CRC-32.
struct PayloadRef {
    uint32_t tile = 0;
    uint64_t offset = 0;
    uint32_t size = 0;
    uint32_t crc = 0;
    friend bool operator==(const PayloadRef&, const PayloadRef&) = default;
};

/// One geometric LOD of a node.
struct LodInfo {
    double error_m = 0.0;  ///< largest distance from an original vertex to its simplified chain, projected metres
    uint64_t vertices = 0; ///< points of all chains, as drawn
    PayloadRef payload;
    friend bool operator==(const LodInfo&, const LodInfo&) = default;
};

/// Integer box in grid units, inclusive.
struct Box {
    int32_t min_x = 0, min_y = 0, max_x = 0, max_y = 0;
    friend bool operator==(const Box&, const Box&) = default;
};

/// A node: a unit whose map (the boundaries between its child units) it holds.
struct Node {
    uint32_t parent = no_node;
    uint32_t first_child = 0; ///< children are nodes [first_child, first_child + child_count)
    uint32_t child_count = 0;
    uint32_t level = 0;  ///< semantic level of the map the node shows (its child units' level)
    uint32_t code = 0;   ///< string index: the unit's code ("" for the root)
    uint32_t name = 0;   ///< string index: the unit's name, "" when the input has none
    uint32_t chains = 0; ///< chains of its map, the same at every LOD
    Box box;             ///< of every point of its map
    PayloadRef table;    ///< the chain table: ids, unit codes, feature classes, flags
    std::vector<LodInfo> lods;
    friend bool operator==(const Node&, const Node&) = default;
};

struct Tile {
    std::string file; ///< relative to the tree folder, e.g. tiles/51063-0123456789abcdef.tlt
    uint64_t size = 0;
    friend bool operator==(const Tile&, const Tile&) = default;
};

/// The in-memory skeleton.
struct Skeleton {
    /// The format's minor version: the file's when decoded, this library's when new.
    uint16_t minor = minor_version;
    /// Projection and grid, as in the chain store (kind, utm_north, utm_zone, 10 doubles).
    uint8_t projection_kind = 0;
    uint8_t utm_north = 1;
    int32_t utm_zone = 0;
    double projection[10] = {}; ///< lon0, lat0, stdlat1, stdlat2, k0, fe, fn, grid_m, a, f
    uint8_t metric = 0;         ///< metric of the tolerances: 0 L2, 1 L1, 2 Linf
    std::vector<std::string> level_names;
    std::vector<double> lod_eps_m; ///< nominal tolerance of each LOD; LOD 0 is the original (0)
    std::vector<std::string> strings{""};
    std::vector<Tile> tiles;
    std::vector<Node> nodes; ///< node 0 is the root; breadth-first, so children are contiguous

    double grid_m() const noexcept { return projection[7]; }
    const std::string& code(const Node& n) const { return strings[n.code]; }
    friend bool operator==(const Skeleton&, const Skeleton&) = default;
};

std::string encode_skeleton(const Skeleton& s);
/// Decode and validate (structure, indices, tree shape, CRC). Throws format_error naming `name`.
Skeleton decode_skeleton(std::span<const std::byte> bytes, const std::string& name);

/// Tile file header and trailer.
constexpr size_t tile_header_size = 24;
std::string tile_header(uint64_t file_size);
/// Throws format_error naming `name` unless `bytes` (at least the first 24 of a
/// tile) is a tile header of this major version for a file of `file_size` bytes.
void check_tile_header(std::span<const std::byte> bytes, uint64_t file_size, const std::string& name);

/// Where a chain table entry's flags keep its border level (format 2.1).
constexpr uint32_t border_level_shift = 8;
constexpr uint32_t border_level_mask = 0xFFU << border_level_shift;

/// A node's chain table.
struct ChainTable {
    struct Entry {
        uint64_t id = 0;
        uint32_t left = 0;  ///< index into strings: unit code on the left
        uint32_t right = 0; ///< unit code on the right
        uint32_t feature_class = 0;
        /// Chain store flags (bit 0 closed, bit 2 problem), and in bits 8-15
        /// the border level (format 2.1): the coarsest level whose map has a
        /// border along the chain (border_level()).
        uint32_t flags = 0;
        uint32_t border_level() const noexcept { return (flags & border_level_mask) >> border_level_shift; }
        friend bool operator==(const Entry&, const Entry&) = default;
    };
    std::vector<std::string> strings{""};
    std::vector<Entry> chains;
    friend bool operator==(const ChainTable&, const ChainTable&) = default;
};

std::string encode_table(const ChainTable& t);
ChainTable decode_table(std::span<const std::byte> bytes, const std::string& name);

/// A node's units (format 2.2): the units of its map as its own (a county
/// node's tracts), each with its internal point and what the source says
/// of it (the config's dataset.name_field and dataset.attributes). The
/// payload has no reference in the skeleton: it follows the node's last LOD
/// payload in the same tile (units_at), behind a head that gives its size
/// and CRC, so that readers of 2.0 and 2.1 never see it.
struct UnitTable {
    /// How a field's values read (they are text either way): 0 text, 1 integer, 2 real.
    struct Field {
        std::string name;
        uint8_t type = 0;
        friend bool operator==(const Field&, const Field&) = default;
    };
    struct Unit {
        std::string code;
        std::string name;                ///< "" when the source names none
        GridPoint point;                 ///< its internal point, strictly inside it
        std::vector<std::string> values; ///< one per field, "" for none
        friend bool operator==(const Unit&, const Unit&) = default;
    };
    std::vector<Field> fields;
    std::vector<Unit> units; ///< sorted by code
    friend bool operator==(const UnitTable&, const UnitTable&) = default;
};

/// The units payload's head: kind (1 byte), 3 bytes 0, the body's size
/// (u32) and CRC-32 (u32).
constexpr size_t units_head_size = 12;
/// Where a 2.2 node's units payload begins in its tile: right after its last LOD payload.
inline uint64_t units_at(const Node& n) noexcept
{
    const PayloadRef& last = n.lods.empty() ? n.table : n.lods.back().payload;
    return last.offset + last.size;
}
/// Encode head and body; points relative to `origin` (the node box's minimum corner).
std::string encode_units(const UnitTable& t, GridPoint origin);
/// The body's size and CRC from a head (format_error naming `name` if it is not one).
std::pair<uint32_t, uint32_t> units_body(std::span<const std::byte> head, const std::string& name);
/// Decode a body (after its head, its CRC checked by the caller).
UnitTable decode_units(std::span<const std::byte> body, GridPoint origin, const std::string& name);

/// A node's map at one LOD: chain i is points[offsets[i], offsets[i + 1]), absolute grid coordinates.
struct Geometry {
    std::vector<uint32_t> offsets{0};
    std::vector<GridPoint> points;

    size_t chain_count() const noexcept { return offsets.size() - 1; }
    std::span<const GridPoint> chain(size_t i) const noexcept
    {
        return {points.data() + offsets[i], offsets[i + 1] - offsets[i]};
    }
    void add_chain(std::span<const GridPoint> pts)
    {
        points.insert(points.end(), pts.begin(), pts.end());
        offsets.push_back(static_cast<uint32_t>(points.size()));
    }
    /// Heap bytes held (capacities): what a cache charges for it.
    size_t memory_bytes() const noexcept
    {
        return offsets.capacity() * sizeof(uint32_t) + points.capacity() * sizeof(GridPoint);
    }
    friend bool operator==(const Geometry&, const Geometry&) = default;
};

/// Bytes a decoded Geometry of `chains` chains and `vertices` points holds (decode reserves exactly).
constexpr size_t geometry_bytes(uint64_t chains, uint64_t vertices) noexcept
{
    return static_cast<size_t>((chains + 1) * sizeof(uint32_t) + vertices * sizeof(GridPoint));
}

/// Draco encoder speed (0 best compression .. 10 fastest); see SPEC.md.
struct GeometryOptions {
    int draco_speed = 0;
};

/// Encode relative to `origin` (the node box's minimum corner). Every point
/// must lie in the node box given by origin and the 31-bit range.
std::string encode_geometry(const Geometry& g, GridPoint origin, const GeometryOptions& options = {});
/// Decode; `expect_chains` and `expect_vertices` come from the skeleton and are checked.
Geometry decode_geometry(std::span<const std::byte> bytes, GridPoint origin, uint64_t expect_chains,
                         uint64_t expect_vertices, const std::string& name);

} // namespace tigerlod::datatree
