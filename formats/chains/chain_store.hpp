#pragma once
/// @file chain_store.hpp
/// The chain store: the map of one semantic level within one partition, in
/// memory and on disk. The byte layout is in SPEC.md beside this file; no
/// other code knows it.

#include "core/geometry.hpp"
#include "core/projection.hpp"

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

namespace tigerlod::chains {

constexpr uint16_t major_version = 1;
constexpr uint16_t minor_version = 3;
/// "chain store format 1.3", for --version.
inline std::string format_version_text()
{
    return "chain store format " + std::to_string(major_version) + "." + std::to_string(minor_version);
}

/// Bits of ChainInfo::flags.
enum ChainFlags : uint32_t {
    chain_closed = 1U << 0,  ///< first point equals last
    chain_halo = 1U << 1,    ///< read-only context owned by another partition
    chain_problem = 1U << 2, ///< takes part in a crossing, overlap or touch found by ingest
    chain_known_flags = chain_closed | chain_halo | chain_problem
};

/// One chain; its points are ChainStore::points[first, first + count).
struct ChainInfo {
    uint64_t id = 0;
    uint32_t left = 0;          ///< string index of the unit code on the left
    uint32_t right = 0;         ///< string index of the unit code on the right
    uint32_t feature_class = 0; ///< string index of the feature class
    uint32_t flags = 0;         ///< ChainFlags
    uint64_t first = 0;
    uint32_t count = 0;
};

/// A chain end whose degree in the level's boundary graph is not 2.
struct Junction {
    uint64_t id = 0; ///< packed snapped lon/lat, see SPEC.md
    GridPoint p;
    uint32_t degree = 0;
};

/// Kinds of constraint points.
enum ConstraintKind : uint32_t {
    constraint_internal = 0,  ///< the internal point of one of the partition's own units
    constraint_user = 1,      ///< a user point
    constraint_neighbour = 2, ///< since 1.2: the internal point of another partition's unit that an owned chain bounds
};

/// A point that must stay on its side of the chains: inside its unit.
struct ConstraintPoint {
    uint32_t unit = 0; ///< string index of the unit code
    uint32_t kind = constraint_internal;
    GridPoint p;
};

/// How a unit attribute's values read (since 1.3): all are kept as text,
/// the type says what a GIS should make of them.
enum class AttributeType : uint8_t { text = 0, integer = 1, real = 2 };

/// A source attribute the config names for the level's units (since 1.3).
struct AttributeField {
    std::string name; ///< the source's field name
    AttributeType type = AttributeType::text;
    friend bool operator==(const AttributeField&, const AttributeField&) = default;
};

/// What the source says of one of the partition's own units (since 1.3):
/// its name and the values of ChainStore::fields, in order ("" for none).
struct UnitRecord {
    uint32_t unit = 0; ///< string index of the unit code
    std::string name;
    std::vector<std::string> values;
};

/// "text", "integer" or "real".
const char* attribute_type_name(AttributeType t) noexcept;

/// The map of one level within one partition.
struct ChainStore {
    uint32_t level_index = 0;
    uint32_t level_count = 1;
    std::string level_name;
    std::string partition;
    ProjectionParams projection;
    double halo_m = 0.0;
    uint16_t minor = minor_version;       ///< the minor version it was read from (written: always the current)
    double eps_m = 0.0;                   ///< tolerance this store was simplified at; 0 for original chains
    uint8_t metric = 0;                   ///< metric of eps_m: 0 L2, 1 L1, 2 Linf
    std::vector<std::string> strings{""}; ///< entry 0 is "" (no unit)
    std::vector<ChainInfo> chains;
    std::vector<GridPoint> points;
    std::vector<Junction> junctions;
    std::vector<ConstraintPoint> constraints;
    /// Since 1.3: the attributes the config names for the level's units, and
    /// a record per own unit (one with a kind 0 point) that has a name or a
    /// value; none when the config names none.
    std::vector<AttributeField> fields;
    std::vector<UnitRecord> units;

    std::span<const GridPoint> chain_points(const ChainInfo& c) const noexcept
    {
        return {points.data() + c.first, c.count};
    }
    /// Index of `s` in the string table, adding it if new.
    uint32_t intern(std::string_view s);
    /// Append a chain with the given points; sets first and count.
    void add_chain(ChainInfo info, std::span<const GridPoint> pts);
    /// Sort chains by (halo, id), junctions by id, constraints by (code, kind, x, y),
    /// unit records by code, and compact points into that order. Writers call this; it makes output canonical.
    void canonicalize();

  private:
    std::unordered_map<std::string, uint32_t> m_index;
}; // struct ChainStore

/// Where `p` lies relative to the unit with string index `unit`, by an exact
/// even-odd test over the store's chains (halo included) that have the unit on
/// exactly one side. Exact only if the store holds the unit's whole boundary,
/// as ingest's stores do for the units of their partition.
PointLocation unit_location(const ChainStore& store, uint32_t unit, GridPoint p);

/// Encode as the bytes of a file of the current version (major_version.minor_version).
std::string encode(const ChainStore& store);

/// Decode and validate the bytes of a file; `name` is used in messages.
/// Throws format_error naming `name` and the fault.
ChainStore decode(std::span<const std::byte> bytes, const std::string& name);

/// Write atomically (temporary name, then rename). Throws environment_error.
void write(const std::filesystem::path& path, const ChainStore& store);

/// Read and validate. Throws environment_error if the file cannot be read,
/// format_error if it is not a valid chain store.
ChainStore read(const std::filesystem::path& path);

/// "internal", "user" or "neighbour" (the text dump's and messages' name of a ConstraintKind).
const char* constraint_kind_name(uint32_t kind) noexcept;

/// The folder of a simplify output that holds the stores simplified at
/// `eps_m`: "eps-1m", "eps-0.5m" (simplify writes there, pack reads a
/// folder's tolerance from its name and holds each store to it).
std::string tolerance_dir(double eps_m);

/// Canonical sorted text of a store, one item per line, for diffs and goldens;
/// its first line names the version it was read from (a new store's: the current).
std::string to_text(const ChainStore& store);

} // namespace tigerlod::chains
