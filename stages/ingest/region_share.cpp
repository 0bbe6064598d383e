#include "stages/ingest/region_share.hpp"

#include "core/bytes.hpp"

namespace tigerlod::ingest {

namespace {

constexpr char share_magic[] = "TLSHARE2"; // 2: units' attributes
constexpr char reads_magic[] = "TLREADS3"; // 2: empty_codes; 3: unit attributes

void put_source(ByteWriter& w, const SourceRef& s)
{
    w.put(s.file);
    w.put(s.feature);
}

SourceRef get_source(ByteReader& r, const char* what)
{
    SourceRef s;
    s.file = r.get<uint32_t>(what);
    s.feature = r.get<int64_t>(what);
    return s;
}

uint64_t get_count(ByteReader& r, size_t record, const char* what)
{
    const uint64_t n = r.get_varint(what);
    r.check_count(n, record, what);
    return n;
}

void put_result(ByteWriter& w, const BuildResult& b)
{
    w.put_varint(b.levels.size());
    for (const auto& l : b.levels) {
        w.put_vstr(l.name);
        for (const uint64_t v : {l.units, l.chains, l.rings, l.vertices, l.junctions, l.partitions, l.halo_chains,
                                 l.constraint_points, l.computed_internal_points, l.neighbour_points, l.tile_cuts}) {
            w.put_varint(v);
        }
    }
    w.put_varint(b.problems.size());
    for (const auto& [k, v] : b.problems) {
        w.put_vstr(k);
        w.put_varint(v);
    }
    w.put_varint(b.samples.size());
    for (const auto& s : b.samples) {
        w.put_vstr(s.kind);
        w.put(s.lon_deg);
        w.put(s.lat_deg);
        w.put_vstr(s.where);
    }
    for (const uint64_t v : {b.input_vertices, b.unique_vertices, b.edges, b.region_map_units}) {
        w.put_varint(v);
    }
    w.put_varint(b.seconds.size());
    for (const auto& [name, s] : b.seconds) {
        w.put_vstr(name);
        w.put(s);
    }
}

BuildResult get_result(ByteReader& r)
{
    BuildResult b;
    b.levels.resize(static_cast<size_t>(get_count(r, 12, "levels")));
    for (auto& l : b.levels) {
        l.name = r.get_vstr("a level");
        for (uint64_t* v : {&l.units, &l.chains, &l.rings, &l.vertices, &l.junctions, &l.partitions, &l.halo_chains,
                            &l.constraint_points, &l.computed_internal_points, &l.neighbour_points, &l.tile_cuts}) {
            *v = r.get_varint("a level's counts");
        }
    }
    const uint64_t nproblems = get_count(r, 2, "problems");
    for (uint64_t i = 0; i < nproblems; ++i) {
        std::string k = r.get_vstr("a problem");
        b.problems[k] = r.get_varint("a problem's count");
    }
    b.samples.resize(static_cast<size_t>(get_count(r, 18, "problem samples")));
    for (auto& s : b.samples) {
        s.kind = r.get_vstr("a problem sample");
        s.lon_deg = r.get<double>("a problem sample");
        s.lat_deg = r.get<double>("a problem sample");
        s.where = r.get_vstr("a problem sample");
    }
    for (uint64_t* v : {&b.input_vertices, &b.unique_vertices, &b.edges, &b.region_map_units}) {
        *v = r.get_varint("the totals");
    }
    const uint64_t nsec = get_count(r, 9, "timings");
    for (uint64_t i = 0; i < nsec; ++i) {
        std::string name = r.get_vstr("a timing");
        b.seconds.emplace_back(std::move(name), r.get<double>("a timing"));
    }
    return b;
}

} // namespace

std::string encode_share(const RegionJobShare& s)
{
    ByteWriter w;
    w.put_bytes(std::string_view(share_magic, 8));
    w.put_vstr(s.job);
    w.put_vstr(s.spec_sha256);
    put_strings(w, s.stores);
    for (size_t i = 0; i < s.stores.size(); ++i) {
        w.put_varint(i < s.store_bytes.size() ? s.store_bytes[i] : 0);
        w.put(i < s.store_mtimes.size() ? s.store_mtimes[i] : int64_t{0});
    }
    w.put_varint(s.share.own_points);
    w.put_varint(s.share.map_units);
    w.put_varint(s.points_read);
    put_result(w, s.share.result);
    const RegionOutput& c = s.share.coarse;
    w.put_varint(c.units.size());
    for (const auto& u : c.units) {
        put_unit(w, u);
    }
    w.put_varint(c.edges.size());
    for (const auto& e : c.edges) {
        w.put_varint(e.keys.size());
        for (const uint64_t k : e.keys) {
            w.put(k);
        }
        w.put_varint(e.points.size());
        w.put_points(e.points);
        w.put_vstr(e.left);
        w.put_vstr(e.right);
        w.put(e.cls);
        w.put(e.sid);
        put_source(w, e.src);
        w.put(static_cast<uint8_t>(e.problem));
    }
    return std::move(w.bytes());
}

namespace {

RegionJobShare decode_head(ByteReader& r)
{
    get_magic(r, share_magic, "a region share of");
    RegionJobShare s;
    s.job = r.get_vstr("the job");
    s.spec_sha256 = r.get_vstr("the spec's digest");
    s.stores = get_strings(r, "stores");
    r.check_count(s.stores.size(), 9, "store stamps");
    for (size_t i = 0; i < s.stores.size(); ++i) {
        s.store_bytes.push_back(r.get_varint("a store's size"));
        s.store_mtimes.push_back(r.get<int64_t>("a store's time"));
    }
    return s;
}

} // namespace

RegionJobShare decode_share_head(std::span<const std::byte> bytes, const std::string& name)
{
    ByteReader r(bytes, name);
    return decode_head(r);
}

RegionJobShare decode_share(std::span<const std::byte> bytes, const std::string& name)
{
    ByteReader r(bytes, name);
    RegionJobShare s = decode_head(r);
    s.share.own_points = r.get_varint("the counts");
    s.share.map_units = r.get_varint("the counts");
    s.points_read = r.get_varint("the counts");
    s.share.result = get_result(r);
    RegionOutput& c = s.share.coarse;
    c.units.resize(static_cast<size_t>(get_count(r, 34, "coarse units")));
    for (auto& u : c.units) {
        u = get_unit(r);
    }
    c.edges.resize(static_cast<size_t>(get_count(r, 28, "coarse edges")));
    for (auto& e : c.edges) {
        e.keys.resize(static_cast<size_t>(get_count(r, 8, "an edge's keys")));
        for (auto& k : e.keys) {
            k = r.get<uint64_t>("an edge's keys");
        }
        const uint64_t np = get_count(r, sizeof(GridPoint), "an edge's points");
        if (np > UINT32_MAX) {
            r.fail("an edge of more than 2^32 points");
        }
        r.get_points(static_cast<uint32_t>(np), e.points);
        e.left = r.get_vstr("an edge");
        e.right = r.get_vstr("an edge");
        e.cls = r.get<uint32_t>("an edge");
        e.sid = r.get<uint64_t>("an edge");
        e.src = get_source(r, "an edge");
        e.problem = r.get<uint8_t>("an edge") != 0;
    }
    if (r.left() != 0) {
        r.fail("bytes after the end");
    }
    return s;
}

std::string encode_reads(const ReadJob& job)
{
    ByteWriter w;
    w.put_bytes(std::string_view(reads_magic, 8));
    w.put_vstr(job.reading);
    w.put_varint(job.parts.size());
    for (const auto& p : job.parts) {
        w.put_varint(p.part);
        w.put_varint(p.files.size());
        for (const auto& f : p.files) {
            w.put_vstr(f.path);
            w.put_varint(f.bytes);
            w.put(f.mtime_ns);
            w.put_vstr(f.sha256);
        }
        w.put_vstr(p.sha256);
        const PartSummary& s = p.summary;
        w.put_varint(s.codes.size());
        for (const auto& level : s.codes) {
            put_strings(w, level);
        }
        w.put_varint(s.many.size());
        for (const uint8_t m : s.many) {
            w.put(m);
        }
        for (const int32_t v : {s.lo.lon, s.lo.lat, s.hi.lon, s.hi.lat}) {
            w.put(v);
        }
        w.put_varint(s.points_read);
        w.put_varint(s.empty_geometries);
        w.put_varint(s.empty_codes);
        w.put(static_cast<uint8_t>(s.kind));
        put_strings(w, s.files);
        put_strings(w, s.classes);
        put_fields(w, s.fields, s.named);
        w.put_varint(s.unpaired_edges);
    }
    return std::move(w.bytes());
}

ReadJob decode_reads(std::span<const std::byte> bytes, const std::string& name)
{
    ByteReader r(bytes, name);
    get_magic(r, reads_magic, "a read job's parts of");
    ReadJob job;
    job.reading = r.get_vstr("how the parts were read");
    job.parts.resize(static_cast<size_t>(get_count(r, 40, "parts")));
    for (auto& p : job.parts) {
        p.part = r.get_varint("a part");
        p.files.resize(static_cast<size_t>(get_count(r, 12, "a part's files")));
        for (auto& f : p.files) {
            f.path = r.get_vstr("a file");
            f.bytes = r.get_varint("a file's size");
            f.mtime_ns = r.get<int64_t>("a file's time");
            f.sha256 = r.get_vstr("a file's digest");
        }
        p.sha256 = r.get_vstr("a part's digest");
        PartSummary& s = p.summary;
        s.codes.resize(static_cast<size_t>(get_count(r, 1, "levels")));
        for (auto& level : s.codes) {
            level = get_strings(r, "a level's codes");
        }
        s.many.resize(static_cast<size_t>(get_count(r, 1, "levels")));
        for (auto& m : s.many) {
            m = r.get<uint8_t>("a level");
        }
        for (int32_t* v : {&s.lo.lon, &s.lo.lat, &s.hi.lon, &s.hi.lat}) {
            *v = r.get<int32_t>("a part's box");
        }
        s.points_read = r.get_varint("a part's counts");
        s.empty_geometries = r.get_varint("a part's counts");
        s.empty_codes = r.get_varint("a part's counts");
        const auto kind = r.get<uint8_t>("a part's kind");
        if (kind > static_cast<uint8_t>(RawMap::Kind::lines)) {
            r.fail("a part of unknown kind");
        }
        s.kind = static_cast<RawMap::Kind>(kind);
        s.files = get_strings(r, "a part's files");
        s.classes = get_strings(r, "a part's classes");
        s.named = get_fields(r, s.fields);
        s.unpaired_edges = r.get_varint("a part's counts");
    }
    if (r.left() != 0) {
        r.fail("bytes after the end");
    }
    return job;
}

} // namespace tigerlod::ingest
