#pragma once
/// @file raw_map.hpp
/// What the input readers produce and the map builder consumes: polylines in
/// snapped lon/lat with the finest units on their left and right, and those
/// units with their codes per semantic level. No GDAL here, so tests can
/// build maps by hand.

#include "formats/chains/chain_store.hpp"

#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace tigerlod {
class ByteWriter;
class ByteReader;
} // namespace tigerlod

namespace tigerlod::ingest {

/// Marks "no unit": the outside of the map.
constexpr uint32_t no_unit = UINT32_MAX;

/// A lon/lat snapped to TIGER's published precision, in micro-degrees.
struct LonLatE6 {
    int32_t lon = 0;
    int32_t lat = 0;
    friend bool operator==(const LonLatE6&, const LonLatE6&) = default;
};

/// Snap degrees to micro-degrees (round half away from zero).
LonLatE6 snap_e6(double lon_deg, double lat_deg) noexcept;

/// The packed key of a snapped point; also the id of a junction (SPEC.md).
inline uint64_t pack_key(LonLatE6 p) noexcept
{
    return (uint64_t{static_cast<uint32_t>(p.lon + 180000000)} << 32) | static_cast<uint32_t>(p.lat + 90000000);
}
inline LonLatE6 unpack_key(uint64_t k) noexcept
{
    return {static_cast<int32_t>(static_cast<int64_t>(k >> 32) - 180000000),
            static_cast<int32_t>(static_cast<int64_t>(k & 0xFFFFFFFFU) - 90000000)};
}

/// Where a polyline or unit came from, for messages: file index and feature id.
struct SourceRef {
    uint32_t file = 0;
    int64_t feature = -1;
};

/// A unit of the finest level (a TIGER face, a tract polygon, a county).
struct RawUnit {
    std::vector<std::string> codes; ///< code at each level, coarsest first
    std::optional<LonLatE6> intpt;  ///< given internal point, if any
    double weight = 0.0;            ///< area or similar: the largest unit's point represents a coarser unit
    SourceRef source;
    uint64_t sid = 0; ///< a TIGER face's TFID, or 0
    /// What the source says of it (dataset.name_field, dataset.attributes):
    /// its name, then its values of RawMap::fields ("" for none); empty
    /// when the config names neither (RawMap::has_attributes).
    std::vector<std::string> attrs{};
};

/// A side of a polyline whose unit another part holds: a TIGER county's EDGES
/// name the faces across the county's border, which its FACES do not hold.
/// Parts read one county at a time keep these; a region's map finds the faces
/// in the neighbouring parts (stages/ingest/regions.hpp).
struct ForeignFace {
    uint32_t polyline = 0;
    uint32_t right = 0; ///< 0: the left side, 1: the right side
    uint64_t face = 0;  ///< the TFID
};

/// The whole input map.
struct RawMap {
    enum class Kind {
        edges,         ///< noded polylines with faces on each side (TIGER EDGES)
        polygon_rings, ///< closed rings with their polygon on one side; segments that neighbours share get merged
        lines          ///< a one-level map: every polyline is a boundary
    };
    Kind kind = Kind::edges;
    std::vector<std::string> level_names;
    std::vector<std::string> files; ///< input names, for messages
    std::vector<RawUnit> units;
    std::vector<std::string> classes{""}; ///< feature classes; 0 is "unknown"
    /// dataset.attributes, each with what the files read hold (join_fields),
    /// and whether the config names a name_field: what RawUnit::attrs hold.
    std::vector<chains::AttributeField> fields;
    bool named = false;

    std::vector<LonLatE6> coords;
    std::vector<uint64_t> offsets{0}; ///< polyline i is coords[offsets[i], offsets[i+1])
    std::vector<uint32_t> left, right;
    std::vector<uint32_t> feature_class;
    std::vector<uint64_t> source_id; ///< TLID, or 0
    std::vector<SourceRef> source;
    std::vector<ForeignFace> foreign; ///< sides left as no_unit whose face another part holds (parts only)
    uint64_t points_read = 0;         ///< input points, as the files hold them
    uint64_t empty_geometries = 0;    ///< features without geometry, skipped by the reader
    uint64_t empty_codes = 0;         ///< features with an empty code, left out (dataset.empty_code: skip)

    size_t polyline_count() const noexcept { return left.size(); }
    bool has_attributes() const noexcept { return named || !fields.empty(); }
    void add_polyline(std::span<const LonLatE6> pts, uint32_t left_unit, uint32_t right_unit, uint32_t cls,
                      uint64_t sid, SourceRef src);
    uint32_t intern_class(const std::string& name);
    /// Append another map read from other files (same kind and levels): its
    /// files, units, classes and polylines follow this map's. `part` is left empty.
    void append(RawMap&& part);
    /// Room for this many points and polylines in all, so appends do not regrow.
    void reserve(size_t points, size_t polylines);
    /// "file:feature" for messages.
    std::string where(SourceRef src) const;
    /// Rings that meet along the meridian 180 (the parts of a unit that a
    /// source cut at the antimeridian, Fiji's; where 180 is not the
    /// projection's cut, -180 is written 180 first) share their edges along
    /// it only where both sides hold the same vertices there, which sources
    /// clipped at the antimeridian seldom give: the edges would overlap
    /// instead of merging. Into each segment that runs along the meridian
    /// this puts every latitude between its ends at which a point of the map
    /// lies on the meridian, in order from its first end, so that the two
    /// sides' segments are the same segments. The meridian is straight in the
    /// cones, so the points lie on the segment (up to the grid); elsewhere
    /// they lie on the meridian, where the segment means to be. Returns the
    /// number of points put in (none where no two points of a polyline follow
    /// each other on the meridian).
    uint64_t share_seam_vertices();
};

/// Fields read from another file into `into`: the first file's as they
/// are; then a field integer in one and real in another is real, and one
/// text in either is text (its values are text either way).
void join_fields(std::vector<chains::AttributeField>& into, const std::vector<chains::AttributeField>& more);

/// A unit and a list of strings as bytes and back (the parts and the
/// regions' shares): fields one by one, little-endian; the reads throw
/// format_error as ByteReader does.
void put_strings(ByteWriter& w, const std::vector<std::string>& v);
std::vector<std::string> get_strings(ByteReader& r, const char* what);
void put_unit(ByteWriter& w, const RawUnit& u);
/// RawMap::fields and RawMap::named as bytes and back (get_fields returns named).
void put_fields(ByteWriter& w, const std::vector<chains::AttributeField>& fields, bool named);
bool get_fields(ByteReader& r, std::vector<chains::AttributeField>& fields);
RawUnit get_unit(ByteReader& r);
/// The 8-byte tag that opens each of ingest's job files (a part, a share, a
/// read job's parts); a file without it fails as "not `what` this version
/// of tigerlod-ingest" (`what`: "a region share of").
void get_magic(ByteReader& r, const char (&magic)[9], const char* what);

/// A RawMap as bytes and back: a part put aside by one job and read by
/// others (the workflow's region jobs). Equal maps give equal bytes (no
/// padding is written), so a part whose map did not change keeps its file.
/// decode_raw throws format_error naming `name` and the byte where the bytes
/// are not a part of this version (truncated, lengths that disagree).
std::string encode_raw(const RawMap& raw);
RawMap decode_raw(std::span<const std::byte> bytes, const std::string& name);

/// Put a RawMap aside in a file and read it back. Throw environment_error if
/// the file cannot be written or read, format_error as decode_raw.
void write_raw(const RawMap& raw, const std::filesystem::path& path);
RawMap read_raw(const std::filesystem::path& path);

} // namespace tigerlod::ingest
