#include "formats/datatree/datatree.hpp"

#include "core/bytes.hpp"
#include "core/digest.hpp"
#include "core/errors.hpp"

#include <cmath>
#include <cstring>

namespace tigerlod::datatree {

namespace {

constexpr char skeleton_magic[8] = {'T', 'L', 'D', 'S', 'K', 'E', 'L', 'T'};
constexpr char tile_magic[8] = {'T', 'L', 'D', 'T', 'I', 'L', 'E', 'S'};
constexpr size_t header_size = 24;
constexpr size_t ref_size = 4 + 8 + 4 + 4;
constexpr size_t node_fixed_size = 7 * 4 + 4 * 4 + ref_size;
constexpr size_t lod_size = 8 + 8 + ref_size;
constexpr uint8_t kind_table = 1;
constexpr uint8_t kind_units = 3; // 2 is the geometry payload (geometry.cpp)

void put_header(ByteWriter& w, const char (&magic)[8], uint64_t file_size, uint16_t minor = minor_version)
{
    w.put_bytes(std::string_view(magic, 8));
    w.put(major_version);
    w.put(minor);
    w.put(uint32_t{0});
    w.put(file_size);
}

/// Checks magic, version, flags and size; `what` names the kind of file in
/// messages. Returns the minor version.
uint16_t check_header(ByteReader& r, const char (&magic)[8], uint64_t file_size, const char* what)
{
    r.need(header_size, "header");
    const auto m = r.get_bytes(8, "magic");
    if (std::memcmp(m.data(), magic, 8) != 0) {
        r.fail(std::string("not a ") + what + " (wrong magic)");
    }
    const auto major = r.get<uint16_t>("version");
    const auto minor = r.get<uint16_t>("version");
    if (major != major_version) {
        r.fail("unsupported major version " + std::to_string(major) + " (reads " + std::to_string(major_version) + ")");
    }
    if (r.get<uint32_t>("flags") != 0) {
        r.fail("unknown flags");
    }
    const auto size = r.get<uint64_t>("file size");
    if (size != file_size) {
        r.fail(size > file_size
                   ? "truncated: header says " + std::to_string(size) + " bytes, file has " + std::to_string(file_size)
                   : "trailing bytes: header says " + std::to_string(size) + " bytes, file has " +
                         std::to_string(file_size));
    }
    return minor;
}

void put_ref(ByteWriter& w, const PayloadRef& p)
{
    w.put(p.tile);
    w.put(p.offset);
    w.put(p.size);
    w.put(p.crc);
}

PayloadRef get_ref(ByteReader& r)
{
    PayloadRef p;
    p.tile = r.get<uint32_t>("payload tile");
    p.offset = r.get<uint64_t>("payload offset");
    p.size = r.get<uint32_t>("payload size");
    p.crc = r.get<uint32_t>("payload crc");
    return p;
}

} // namespace

std::string encode_skeleton(const Skeleton& s)
{
    ByteWriter w;
    put_header(w, skeleton_magic, 0, s.minor);
    w.put(s.projection_kind);
    w.put(s.utm_north);
    w.put(s.metric);
    w.put(uint8_t{0});
    w.put(s.utm_zone);
    for (double v : s.projection) {
        w.put(v);
    }
    w.put(static_cast<uint32_t>(s.level_names.size()));
    for (const auto& n : s.level_names) {
        w.put_str(n);
    }
    w.put(static_cast<uint32_t>(s.lod_eps_m.size()));
    for (double e : s.lod_eps_m) {
        w.put(e);
    }
    w.put(static_cast<uint32_t>(s.strings.size()));
    for (const auto& str : s.strings) {
        w.put_str(str);
    }
    w.put(static_cast<uint32_t>(s.tiles.size()));
    for (const auto& t : s.tiles) {
        w.put_str(t.file);
        w.put(t.size);
    }
    w.put(static_cast<uint32_t>(s.nodes.size()));
    w.reserve(w.size() + s.nodes.size() * (node_fixed_size + s.lod_eps_m.size() * lod_size) + 4);
    for (const auto& n : s.nodes) {
        for (uint32_t v : {n.parent, n.first_child, n.child_count, n.level, n.code, n.name, n.chains}) {
            w.put(v);
        }
        for (int32_t v : {n.box.min_x, n.box.min_y, n.box.max_x, n.box.max_y}) {
            w.put(v);
        }
        put_ref(w, n.table);
        for (const auto& l : n.lods) {
            w.put(l.error_m);
            w.put(l.vertices);
            put_ref(w, l.payload);
        }
    }
    std::string& out = w.bytes();
    const uint64_t size = out.size() + 4;
    std::memcpy(out.data() + 16, &size, sizeof size);
    const uint32_t crc = crc32(std::as_bytes(std::span(out.data(), out.size())));
    w.put(crc);
    return std::move(out);
}

Skeleton decode_skeleton(std::span<const std::byte> bytes, const std::string& name)
{
    ByteReader r(bytes, name);
    const uint16_t minor = check_header(r, skeleton_magic, bytes.size(), "Data Tree skeleton");
    uint32_t stored_crc = 0;
    std::memcpy(&stored_crc, bytes.data() + bytes.size() - 4, 4);
    if (bytes.size() < header_size + 4 || crc32(bytes.first(bytes.size() - 4)) != stored_crc) {
        throw format_error(name + ": checksum mismatch");
    }
    ByteReader b(bytes.first(bytes.size() - 4), name);
    b.get_bytes(header_size, "header");
    Skeleton s;
    s.minor = minor;
    s.projection_kind = b.get<uint8_t>("projection kind");
    s.utm_north = b.get<uint8_t>("utm_north");
    s.metric = b.get<uint8_t>("metric");
    if (b.get<uint8_t>("reserved") != 0) {
        b.fail("reserved byte not 0");
    }
    s.utm_zone = b.get<int32_t>("utm_zone");
    if (s.projection_kind > 3 || s.metric > 2) {
        b.fail("unknown projection kind or metric");
    }
    for (double& v : s.projection) {
        v = b.get<double>("projection");
        if (!std::isfinite(v)) {
            b.fail("projection parameter not finite");
        }
    }
    if (!(s.grid_m() > 0)) {
        b.fail("grid size must be positive");
    }
    const uint32_t nlevels = b.get_count(4, "levels");
    for (uint32_t i = 0; i < nlevels; ++i) {
        s.level_names.push_back(b.get_str("level name"));
    }
    const uint32_t nlods = b.get_count(8, "LODs");
    if (nlods == 0) {
        b.fail("no LODs");
    }
    for (uint32_t i = 0; i < nlods; ++i) {
        const double e = b.get<double>("LOD eps");
        if (!std::isfinite(e) || e < 0 || (i > 0 && !(e > s.lod_eps_m.back()))) {
            b.fail("LOD tolerances must be finite and increasing from 0");
        }
        s.lod_eps_m.push_back(e);
    }
    const uint32_t nstrings = b.get_count(4, "strings");
    s.strings.clear();
    for (uint32_t i = 0; i < nstrings; ++i) {
        s.strings.push_back(b.get_str("string"));
    }
    if (s.strings.empty() || !s.strings[0].empty()) {
        b.fail("string 0 must be empty");
    }
    const uint32_t ntiles = b.get_count(12, "tiles");
    for (uint32_t i = 0; i < ntiles; ++i) {
        Tile t;
        t.file = b.get_str("tile file");
        t.size = b.get<uint64_t>("tile size");
        if (t.file.empty() || t.file.find("..") != std::string::npos || t.file.front() == '/') {
            b.fail("tile file name '" + t.file + "' must be relative and stay inside the tree");
        }
        s.tiles.push_back(std::move(t));
    }
    const uint32_t nnodes = b.get_count(node_fixed_size + nlods * lod_size, "nodes");
    if (nnodes == 0) {
        b.fail("no nodes");
    }
    s.nodes.resize(nnodes);
    auto check_ref = [&](const PayloadRef& p, uint32_t node) {
        if (p.tile >= ntiles || p.offset < header_size || p.size > s.tiles[p.tile].size ||
            p.offset > s.tiles[p.tile].size - p.size) {
            b.fail("node " + std::to_string(node) + ": payload outside its tile");
        }
    };
    for (uint32_t i = 0; i < nnodes; ++i) {
        Node& n = s.nodes[i];
        n.parent = b.get<uint32_t>("node");
        n.first_child = b.get<uint32_t>("node");
        n.child_count = b.get<uint32_t>("node");
        n.level = b.get<uint32_t>("node");
        n.code = b.get<uint32_t>("node");
        n.name = b.get<uint32_t>("node");
        n.chains = b.get<uint32_t>("node");
        n.box.min_x = b.get<int32_t>("node box");
        n.box.min_y = b.get<int32_t>("node box");
        n.box.max_x = b.get<int32_t>("node box");
        n.box.max_y = b.get<int32_t>("node box");
        n.table = get_ref(b);
        n.lods.resize(nlods);
        for (auto& l : n.lods) {
            l.error_m = b.get<double>("LOD error");
            l.vertices = b.get<uint64_t>("LOD vertices");
            l.payload = get_ref(b);
        }
        const std::string at = "node " + std::to_string(i) + ": ";
        if (n.level >= nlevels || n.code >= nstrings || n.name >= nstrings) {
            b.fail(at + "level or string index out of range");
        }
        if (n.box.min_x > n.box.max_x || n.box.min_y > n.box.max_y) {
            b.fail(at + "empty bounding box");
        }
        if ((i == 0) != (n.parent == no_node) || (i > 0 && n.parent >= i)) {
            b.fail(at + "parent " + std::to_string(n.parent) + " is not an earlier node");
        }
        if (n.child_count > 0 &&
            (n.first_child <= i || n.first_child > nnodes || n.child_count > nnodes - n.first_child)) {
            b.fail(at + "children out of range");
        }
        check_ref(n.table, i);
        double prev = 0.0;
        for (const auto& l : n.lods) {
            check_ref(l.payload, i);
            if (!std::isfinite(l.error_m) || l.error_m < prev) {
                b.fail(at + "LOD errors must be finite and grow with the LOD index");
            }
            prev = l.error_m;
            if (l.vertices < 2ULL * n.chains || l.vertices > UINT32_MAX) {
                b.fail(at + "LOD vertex count out of range");
            }
        }
    }
    // Breadth-first: every node but the root is the child of its parent, children in order.
    uint32_t next = 1;
    for (uint32_t i = 0; i < nnodes; ++i) {
        const Node& n = s.nodes[i];
        if (n.child_count == 0) {
            continue;
        }
        if (n.first_child != next) {
            b.fail("node " + std::to_string(i) + ": children not in breadth-first order");
        }
        for (uint32_t c = n.first_child; c < n.first_child + n.child_count; ++c) {
            if (s.nodes[c].parent != i) {
                b.fail("node " + std::to_string(c) + ": parent does not list it as a child");
            }
        }
        next += n.child_count;
    }
    if (next != nnodes) {
        b.fail("nodes not reachable from the root");
    }
    if (b.left() != 0) {
        b.fail("trailing bytes after the nodes");
    }
    return s;
}

std::string tile_header(uint64_t file_size)
{
    ByteWriter w;
    put_header(w, tile_magic, file_size);
    return std::move(w.bytes());
}

void check_tile_header(std::span<const std::byte> bytes, uint64_t file_size, const std::string& name)
{
    ByteReader r(bytes.first(std::min(bytes.size(), header_size)), name);
    check_header(r, tile_magic, file_size, "Data Tree tile");
}

std::string encode_table(const ChainTable& t)
{
    ByteWriter w;
    w.put(kind_table);
    w.put_varint(t.strings.size());
    for (const auto& s : t.strings) {
        w.put_vstr(s);
    }
    w.put_varint(t.chains.size());
    uint64_t prev = 0;
    for (const auto& c : t.chains) {
        w.put_svarint(static_cast<int64_t>(c.id - prev));
        prev = c.id;
        w.put_varint(c.left);
        w.put_varint(c.right);
        w.put_varint(c.feature_class);
        w.put_varint(c.flags);
    }
    return std::move(w.bytes());
}

ChainTable decode_table(std::span<const std::byte> bytes, const std::string& name)
{
    ByteReader r(bytes, name);
    if (r.get<uint8_t>("payload kind") != kind_table) {
        r.fail("not a chain table payload");
    }
    ChainTable t;
    const uint64_t nstrings = r.get_varint("string count");
    r.check_count(nstrings, 1, "strings");
    t.strings.clear();
    for (uint64_t i = 0; i < nstrings; ++i) {
        t.strings.push_back(r.get_vstr("string"));
    }
    if (t.strings.empty() || !t.strings[0].empty()) {
        r.fail("string 0 must be empty");
    }
    const uint64_t nchains = r.get_varint("chain count");
    r.check_count(nchains, 5, "chains");
    t.chains.resize(static_cast<size_t>(nchains));
    uint64_t prev = 0;
    const uint64_t max_string = nstrings - 1;
    for (auto& c : t.chains) {
        c.id = prev + static_cast<uint64_t>(r.get_svarint("chain id"));
        prev = c.id;
        c.left = static_cast<uint32_t>(r.get_varint("left unit", max_string));
        c.right = static_cast<uint32_t>(r.get_varint("right unit", max_string));
        c.feature_class = static_cast<uint32_t>(r.get_varint("feature class", max_string));
        c.flags = static_cast<uint32_t>(r.get_varint("chain flags", 0xFFFFFFFFU));
    }
    if (r.left() != 0) {
        r.fail("trailing bytes after the chain table");
    }
    return t;
}

std::string encode_units(const UnitTable& t, GridPoint origin)
{
    ByteWriter w;
    w.put_varint(t.fields.size());
    for (const auto& f : t.fields) {
        w.put_vstr(f.name);
        w.put(f.type);
    }
    w.put_varint(t.units.size());
    GridPoint prev = origin;
    for (const auto& u : t.units) {
        w.put_vstr(u.code);
        w.put_vstr(u.name);
        w.put_svarint(int64_t{u.point.x} - prev.x);
        w.put_svarint(int64_t{u.point.y} - prev.y);
        prev = u.point;
        for (size_t k = 0; k < t.fields.size(); ++k) {
            w.put_vstr(k < u.values.size() ? u.values[k] : std::string_view{});
        }
    }
    const std::string& body = w.bytes();
    ByteWriter out;
    out.put(kind_units);
    out.put(uint8_t{0});
    out.put(uint16_t{0});
    out.put(static_cast<uint32_t>(body.size()));
    out.put(crc32(std::as_bytes(std::span(body.data(), body.size()))));
    out.put_bytes(body);
    return std::move(out.bytes());
}

std::pair<uint32_t, uint32_t> units_body(std::span<const std::byte> head, const std::string& name)
{
    ByteReader r(head.first(std::min(head.size(), units_head_size)), name);
    if (r.get<uint8_t>("units payload") != kind_units || r.get<uint8_t>("units payload") != 0 ||
        r.get<uint16_t>("units payload") != 0) {
        r.fail("not a units payload");
    }
    const auto size = r.get<uint32_t>("units payload");
    return {size, r.get<uint32_t>("units payload")};
}

UnitTable decode_units(std::span<const std::byte> body, GridPoint origin, const std::string& name)
{
    ByteReader r(body, name);
    UnitTable t;
    const uint64_t nfields = r.get_varint("field count");
    r.check_count(nfields, 2, "fields");
    t.fields.resize(static_cast<size_t>(nfields));
    for (auto& f : t.fields) {
        f.name = r.get_vstr("field");
        f.type = r.get<uint8_t>("field");
        if (f.type > 2) {
            r.fail("unknown field type " + std::to_string(f.type));
        }
    }
    const uint64_t nunits = r.get_varint("unit count");
    r.check_count(nunits, 4 + static_cast<size_t>(nfields), "units");
    t.units.resize(static_cast<size_t>(nunits));
    GridPoint prev = origin;
    for (auto& u : t.units) {
        u.code = r.get_vstr("unit code");
        u.name = r.get_vstr("unit name");
        // Modular, as geometry payloads: damaged bytes give wrong points, never undefined behaviour.
        u.point.x =
            static_cast<int32_t>(static_cast<uint32_t>(prev.x) + static_cast<uint32_t>(r.get_svarint("unit point")));
        u.point.y =
            static_cast<int32_t>(static_cast<uint32_t>(prev.y) + static_cast<uint32_t>(r.get_svarint("unit point")));
        prev = u.point;
        u.values.resize(static_cast<size_t>(nfields));
        for (auto& v : u.values) {
            v = r.get_vstr("unit value");
        }
    }
    if (r.left() != 0) {
        r.fail("trailing bytes after the units");
    }
    return t;
}

} // namespace tigerlod::datatree
