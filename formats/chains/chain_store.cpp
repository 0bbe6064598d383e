#include "formats/chains/chain_store.hpp"

#include "core/bytes.hpp"
#include "core/digest.hpp"
#include "core/errors.hpp"
#include "core/fs.hpp"

#include <algorithm>
#include <bit>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <numeric>
#include <sstream>

namespace tigerlod::chains {

namespace {

constexpr char magic[8] = {'T', 'L', 'D', 'C', 'H', 'A', 'I', 'N'};
constexpr size_t header_size = 24;
constexpr size_t chain_record_size = 8 + 5 * 4;

using Writer = ByteWriter;
using Reader = ByteReader;

} // namespace

uint32_t ChainStore::intern(std::string_view s)
{
    if (m_index.size() != strings.size()) {
        m_index.clear();
        for (uint32_t i = 0; i < strings.size(); ++i) {
            m_index.emplace(strings[i], i);
        }
    }
    auto [it, inserted] = m_index.emplace(std::string(s), static_cast<uint32_t>(strings.size()));
    if (inserted) {
        strings.emplace_back(s);
    }
    return it->second;
}

void ChainStore::add_chain(ChainInfo info, std::span<const GridPoint> pts)
{
    info.first = points.size();
    info.count = static_cast<uint32_t>(pts.size());
    points.insert(points.end(), pts.begin(), pts.end());
    chains.push_back(info);
}

void ChainStore::canonicalize()
{
    std::vector<size_t> order(chains.size());
    std::iota(order.begin(), order.end(), size_t{0});
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
        const auto ha = chains[a].flags & chain_halo, hb = chains[b].flags & chain_halo;
        return ha != hb ? ha < hb : chains[a].id < chains[b].id;
    });
    std::vector<ChainInfo> sorted_chains;
    std::vector<GridPoint> sorted_points;
    sorted_chains.reserve(chains.size());
    sorted_points.reserve(points.size());
    for (size_t i : order) {
        ChainInfo c = chains[i];
        const auto pts = chain_points(c);
        c.first = sorted_points.size();
        sorted_points.insert(sorted_points.end(), pts.begin(), pts.end());
        sorted_chains.push_back(c);
    }
    chains = std::move(sorted_chains);
    points = std::move(sorted_points);
    std::sort(junctions.begin(), junctions.end(), [](const Junction& a, const Junction& b) { return a.id < b.id; });
    std::sort(constraints.begin(), constraints.end(), [&](const ConstraintPoint& a, const ConstraintPoint& b) {
        const auto& ca = strings[a.unit];
        const auto& cb = strings[b.unit];
        if (ca != cb) {
            return ca < cb;
        }
        if (a.kind != b.kind) {
            return a.kind < b.kind;
        }
        return a.p < b.p;
    });
    std::sort(units.begin(), units.end(),
              [&](const UnitRecord& a, const UnitRecord& b) { return strings[a.unit] < strings[b.unit]; });
}

const char* attribute_type_name(AttributeType t) noexcept
{
    switch (t) {
    case AttributeType::integer:
        return "integer";
    case AttributeType::real:
        return "real";
    case AttributeType::text:
        break;
    }
    return "text";
}

PointLocation unit_location(const ChainStore& store, uint32_t unit, GridPoint p)
{
    PointInPolygon pip(p);
    for (const auto& c : store.chains) {
        if ((c.left == unit) != (c.right == unit)) {
            const auto pts = store.chain_points(c);
            for (size_t k = 0; k + 1 < pts.size(); ++k) {
                pip.add_segment(pts[k], pts[k + 1]);
            }
        }
    }
    return pip.location();
}

std::string encode(const ChainStore& s)
{
    Writer w;
    w.reserve(256 + s.points.size() * sizeof(GridPoint) + s.chains.size() * chain_record_size +
              s.junctions.size() * 20 + s.constraints.size() * 16);
    w.bytes().append(magic, sizeof magic);
    w.put(major_version);
    w.put(minor_version);
    w.put(uint32_t{0});
    w.put(uint64_t{0}); // file size, patched below
    w.put(s.level_index);
    w.put(s.level_count);
    w.put_str(s.level_name);
    w.put_str(s.partition);
    const auto& p = s.projection;
    w.put(static_cast<uint8_t>(p.kind));
    w.put(static_cast<uint8_t>(p.utm_north ? 1 : 0));
    w.put(uint16_t{0});
    w.put(static_cast<int32_t>(p.utm_zone));
    for (double d : {p.lon0_deg, p.lat0_deg, p.stdlat1_deg, p.stdlat2_deg, p.k0, p.false_easting_m, p.false_northing_m,
                     p.grid_m, p.a_m, p.f}) {
        w.put(d);
    }
    w.put(s.halo_m);
    w.put(s.eps_m);
    w.put(s.metric);
    w.put(uint8_t{0});
    w.put(uint16_t{0});
    w.put(static_cast<uint32_t>(s.strings.size()));
    for (const auto& str : s.strings) {
        w.put_str(str);
    }
    w.put(static_cast<uint32_t>(s.chains.size()));
    for (const auto& c : s.chains) {
        w.put(c.id);
        w.put(c.left);
        w.put(c.right);
        w.put(c.feature_class);
        w.put(c.flags);
        w.put(c.count);
        w.put_points(s.chain_points(c));
    }
    w.put(static_cast<uint32_t>(s.junctions.size()));
    for (const auto& j : s.junctions) {
        w.put(j.id);
        w.put(j.p.x);
        w.put(j.p.y);
        w.put(j.degree);
    }
    w.put(static_cast<uint32_t>(s.constraints.size()));
    for (const auto& c : s.constraints) {
        w.put(c.unit);
        w.put(c.kind);
        w.put(c.p.x);
        w.put(c.p.y);
    }
    w.put(static_cast<uint32_t>(s.fields.size()));
    for (const auto& f : s.fields) {
        w.put_str(f.name);
        w.put(static_cast<uint8_t>(f.type));
    }
    w.put(static_cast<uint32_t>(s.units.size()));
    for (const auto& u : s.units) {
        w.put(u.unit);
        w.put_str(u.name);
        for (size_t k = 0; k < s.fields.size(); ++k) {
            w.put_str(k < u.values.size() ? u.values[k] : std::string_view{});
        }
    }
    std::string& out = w.bytes();
    const uint64_t size = out.size() + 4;
    std::memcpy(out.data() + 16, &size, sizeof size);
    w.put(crc32(std::as_bytes(std::span(out.data(), out.size()))));
    return std::move(out);
}

namespace {

/// A string index of a record, checked against the string table.
void check_index(Reader& body, const ChainStore& s, uint32_t idx, const char* what)
{
    if (idx >= s.strings.size()) {
        body.fail(std::string(what) + " string index " + std::to_string(idx) + " out of range");
    }
}

/// The header: magic, version, flags, size and the trailer's CRC. Returns the minor version.
uint16_t check_header(std::span<const std::byte> bytes, const std::string& name)
{
    Reader r(bytes, name);
    if (bytes.size() < sizeof magic || std::memcmp(bytes.data(), magic, sizeof magic) != 0) {
        throw format_error(name + ": not a chain store (bad magic)");
    }
    if (bytes.size() < header_size + 4) {
        throw format_error(name + ": truncated: " + std::to_string(bytes.size()) + " bytes");
    }
    for (size_t i = 0; i < sizeof magic; ++i) {
        r.get<char>("magic");
    }
    const auto major = r.get<uint16_t>("header");
    const auto minor = r.get<uint16_t>("header");
    if (major != major_version) {
        throw format_error(name + ": unsupported major version " + std::to_string(major) + " (reads " +
                           std::to_string(major_version) + ")");
    }
    const auto flags = r.get<uint32_t>("header");
    if (flags != 0) {
        throw format_error(name + ": unknown header flags " + std::to_string(flags));
    }
    const auto file_size = r.get<uint64_t>("header");
    if (file_size > bytes.size()) {
        throw format_error(name + ": truncated: " + std::to_string(bytes.size()) + " bytes, header says " +
                           std::to_string(file_size));
    }
    if (file_size < bytes.size()) {
        throw format_error(name + ": " + std::to_string(bytes.size() - file_size) +
                           " trailing bytes after the end the header gives");
    }
    uint32_t stored_crc;
    std::memcpy(&stored_crc, bytes.data() + bytes.size() - 4, 4);
    if (crc32(bytes.first(bytes.size() - 4)) != stored_crc) {
        throw format_error(name + ": checksum mismatch (corrupt file)");
    }
    return minor;
}

/// The level, partition, projection, halo and (1.1) tolerance and metric; then the string table.
void read_meta(Reader& body, ChainStore& s)
{
    s.level_index = body.get<uint32_t>("meta");
    s.level_count = body.get<uint32_t>("meta");
    if (s.level_index >= s.level_count) {
        body.fail("level index " + std::to_string(s.level_index) + " not below level count " +
                  std::to_string(s.level_count));
    }
    s.level_name = body.get_str("meta");
    s.partition = body.get_str("meta");
    auto& p = s.projection;
    const auto kind = body.get<uint8_t>("meta");
    if (kind > 3) {
        body.fail("unknown projection kind " + std::to_string(kind));
    }
    p.kind = static_cast<ProjectionParams::Kind>(kind);
    p.utm_north = body.get<uint8_t>("meta") != 0;
    body.get<uint16_t>("meta");
    p.utm_zone = body.get<int32_t>("meta");
    for (double* d : {&p.lon0_deg, &p.lat0_deg, &p.stdlat1_deg, &p.stdlat2_deg, &p.k0, &p.false_easting_m,
                      &p.false_northing_m, &p.grid_m, &p.a_m, &p.f}) {
        *d = body.get<double>("meta");
    }
    s.halo_m = body.get<double>("meta");
    if (s.minor >= 1) {
        s.eps_m = body.get<double>("meta");
        s.metric = body.get<uint8_t>("meta");
        if (!(s.eps_m >= 0) || s.metric > 2) {
            body.fail("invalid tolerance " + std::to_string(s.eps_m) + " m or metric " + std::to_string(s.metric));
        }
        body.get<uint8_t>("meta");
        body.get<uint16_t>("meta");
    }
    const uint32_t nstrings = body.get_count(4, "strings");
    if (nstrings == 0) {
        body.fail("empty string table (entry 0 must be \"\")");
    }
    s.strings.clear();
    for (uint32_t i = 0; i < nstrings; ++i) {
        s.strings.push_back(body.get_str("strings"));
    }
    if (!s.strings[0].empty()) {
        body.fail("string 0 must be empty");
    }
}

/// The chain records and their points.
void read_chains(Reader& body, ChainStore& s)
{
    const uint32_t nchains = body.get_count(chain_record_size, "chains");
    s.chains.reserve(nchains);
    for (uint32_t i = 0; i < nchains; ++i) {
        ChainInfo c;
        c.id = body.get<uint64_t>("chain");
        c.left = body.get<uint32_t>("chain");
        c.right = body.get<uint32_t>("chain");
        c.feature_class = body.get<uint32_t>("chain");
        c.flags = body.get<uint32_t>("chain");
        c.count = body.get<uint32_t>("chain");
        check_index(body, s, c.left, "left");
        check_index(body, s, c.right, "right");
        check_index(body, s, c.feature_class, "feature class");
        if ((c.flags & ~chain_known_flags) != 0) {
            body.fail("chain " + std::to_string(c.id) + ": unknown flags " + std::to_string(c.flags));
        }
        if (c.count < 2) {
            body.fail("chain " + std::to_string(c.id) + " has " + std::to_string(c.count) + " points, need at least 2");
        }
        c.first = s.points.size();
        body.get_points(c.count, s.points);
        const bool closed = s.points[c.first] == s.points.back();
        if (closed != ((c.flags & chain_closed) != 0)) {
            body.fail("chain " + std::to_string(c.id) + ": closed flag disagrees with its end points");
        }
        if (closed && c.count < 4) {
            body.fail("closed chain " + std::to_string(c.id) + " has fewer than 4 points");
        }
        s.chains.push_back(c);
    }
}

/// The junctions and the constraint points.
void read_points(Reader& body, ChainStore& s)
{
    const uint32_t njunctions = body.get_count(20, "junctions");
    s.junctions.reserve(njunctions);
    for (uint32_t i = 0; i < njunctions; ++i) {
        Junction j;
        j.id = body.get<uint64_t>("junction");
        j.p.x = body.get<int32_t>("junction");
        j.p.y = body.get<int32_t>("junction");
        j.degree = body.get<uint32_t>("junction");
        s.junctions.push_back(j);
    }
    const uint32_t nconstraints = body.get_count(16, "constraint points");
    s.constraints.reserve(nconstraints);
    for (uint32_t i = 0; i < nconstraints; ++i) {
        ConstraintPoint c;
        c.unit = body.get<uint32_t>("constraint point");
        c.kind = body.get<uint32_t>("constraint point");
        c.p.x = body.get<int32_t>("constraint point");
        c.p.y = body.get<int32_t>("constraint point");
        check_index(body, s, c.unit, "constraint unit");
        if (c.kind > constraint_neighbour || (c.kind == constraint_neighbour && s.minor < 2)) {
            body.fail("unknown constraint kind " + std::to_string(c.kind));
        }
        s.constraints.push_back(c);
    }
}

/// 1.3: the unit attributes section (the fields, then a record per own unit).
void read_unit_attributes(Reader& body, ChainStore& s)
{
    const uint32_t nfields = body.get_count(5, "unit attributes");
    for (uint32_t i = 0; i < nfields; ++i) {
        AttributeField f;
        f.name = body.get_str("unit attributes");
        const auto type = body.get<uint8_t>("unit attributes");
        if (type > static_cast<uint8_t>(AttributeType::real)) {
            body.fail("unknown attribute type " + std::to_string(type));
        }
        f.type = static_cast<AttributeType>(type);
        s.fields.push_back(std::move(f));
    }
    const uint32_t nunits = body.get_count(8 + 4 * size_t{nfields}, "unit records");
    s.units.reserve(nunits);
    for (uint32_t i = 0; i < nunits; ++i) {
        UnitRecord u;
        u.unit = body.get<uint32_t>("unit record");
        check_index(body, s, u.unit, "unit record's unit");
        u.name = body.get_str("unit record");
        u.values.reserve(nfields);
        for (uint32_t k = 0; k < nfields; ++k) {
            u.values.push_back(body.get_str("unit record"));
        }
        s.units.push_back(std::move(u));
    }
}

} // namespace

ChainStore decode(std::span<const std::byte> bytes, const std::string& name)
{
    ChainStore s;
    s.minor = check_header(bytes, name);
    Reader body(bytes.first(bytes.size() - 4), name);
    for (size_t i = 0; i < header_size; ++i) {
        body.get<char>("header");
    }
    read_meta(body, s);
    read_chains(body, s);
    read_points(body, s);
    if (s.minor >= 3) {
        read_unit_attributes(body, s);
    }
    if (body.left() != 0) {
        body.fail(std::to_string(body.left()) + " unread bytes before the trailer");
    }
    return s;
}

void write(const std::filesystem::path& path, const ChainStore& store)
{
    write_file_atomic(path, encode(store));
}

ChainStore read(const std::filesystem::path& path)
{
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        throw environment_error(path.string() + ": cannot open for reading");
    }
    std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (in.bad()) {
        throw environment_error(path.string() + ": read failed");
    }
    return decode(std::as_bytes(std::span(data.data(), data.size())), path.string());
}

const char* constraint_kind_name(uint32_t kind) noexcept
{
    switch (kind) {
    case constraint_internal:
        return "internal";
    case constraint_user:
        return "user";
    case constraint_neighbour:
        return "neighbour";
    default:
        return "unknown";
    }
}

std::string to_text(const ChainStore& s)
{
    ChainStore c = s;
    c.canonicalize();
    std::ostringstream out;
    out.precision(17);
    out << "chain-store " << major_version << "." << c.minor << "\n"; // the version it was read from
    out << "level " << c.level_index << "/" << c.level_count << " " << c.level_name << "\n";
    out << "partition " << c.partition << "\n";
    out << "projection " << Projection(c.projection).describe() << "\n";
    out << "halo_m " << c.halo_m << "\n";
    if (c.eps_m > 0) {
        out << "simplified eps_m=" << c.eps_m << " metric=" << static_cast<int>(c.metric) << "\n";
    }
    out << "chains " << c.chains.size() << " points " << c.points.size() << " junctions " << c.junctions.size()
        << " constraints " << c.constraints.size() << "\n";
    for (const auto& ch : c.chains) {
        out << "chain " << ch.id << " left=" << c.strings[ch.left] << " right=" << c.strings[ch.right]
            << " class=" << c.strings[ch.feature_class] << " flags=";
        out << ((ch.flags & chain_closed) ? "c" : "-") << ((ch.flags & chain_halo) ? "h" : "-")
            << ((ch.flags & chain_problem) ? "p" : "-");
        out << " n=" << ch.count << " :";
        for (GridPoint p : c.chain_points(ch)) {
            out << ' ' << p.x << ',' << p.y;
        }
        out << "\n";
    }
    for (const auto& j : c.junctions) {
        out << "junction " << j.id << ' ' << j.p.x << ',' << j.p.y << " degree=" << j.degree << "\n";
    }
    for (const auto& cp : c.constraints) {
        out << "point " << c.strings[cp.unit] << ' ' << constraint_kind_name(cp.kind) << ' ' << cp.p.x << ',' << cp.p.y
            << "\n";
    }
    for (const auto& f : c.fields) {
        out << "field " << f.name << ' ' << attribute_type_name(f.type) << "\n";
    }
    for (const auto& u : c.units) {
        out << "unit " << c.strings[u.unit] << " name=" << u.name;
        for (size_t k = 0; k < u.values.size(); ++k) {
            out << ' ' << (k < c.fields.size() ? c.fields[k].name : "?") << '=' << u.values[k];
        }
        out << "\n";
    }
    return out.str();
}

std::string tolerance_dir(double eps_m)
{
    char buf[64];
    std::snprintf(buf, sizeof buf, "eps-%gm", eps_m);
    return buf;
}

} // namespace tigerlod::chains
