#include "stages/ingest/raw_map.hpp"

#include "core/bytes.hpp"
#include "core/errors.hpp"
#include "core/fs.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <type_traits>

namespace tigerlod::ingest {

namespace {

/// std::llround (half away from zero) for |x| < 2^31, inline: x minus its
/// truncation is exact, so comparing it with one half decides as llround does.
int32_t round_half_away(double x) noexcept
{
    const auto t = static_cast<int64_t>(x);
    const double f = x - static_cast<double>(t);
    return static_cast<int32_t>(t + (f >= 0.5 ? 1 : (f <= -0.5 ? -1 : 0)));
}

} // namespace

namespace {

constexpr char raw_magic[] = "TLRAWPT3"; // 2: empty_codes; 3: unit attributes

template <class T> void put_vec(ByteWriter& w, const std::vector<T>& v)
{
    static_assert(std::is_trivially_copyable_v<T> && std::has_unique_object_representations_v<T>);
    w.put(static_cast<uint64_t>(v.size()));
    w.put_bytes(std::string_view(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T)));
}

template <class T> void get_vec(ByteReader& r, std::vector<T>& v, const char* what)
{
    const auto n = r.get<uint64_t>(what);
    r.check_count(n, sizeof(T), what);
    const auto bytes = r.get_bytes(static_cast<size_t>(n) * sizeof(T), what);
    v.resize(static_cast<size_t>(n));
    std::memcpy(v.data(), bytes.data(), bytes.size());
}

} // namespace

void get_magic(ByteReader& r, const char (&magic)[9], const char* what)
{
    const auto tag = r.get_bytes(8, "the header");
    if (std::memcmp(tag.data(), magic, 8) != 0) {
        r.fail(std::string("not ") + what + " this version of tigerlod-ingest");
    }
}

void put_strings(ByteWriter& w, const std::vector<std::string>& v)
{
    w.put_varint(v.size());
    for (const auto& s : v) {
        w.put_vstr(s);
    }
}

std::vector<std::string> get_strings(ByteReader& r, const char* what)
{
    const uint64_t n = r.get_varint(what);
    r.check_count(n, 1, what);
    std::vector<std::string> v(static_cast<size_t>(n));
    for (auto& s : v) {
        s = r.get_vstr(what);
    }
    return v;
}

void put_unit(ByteWriter& w, const RawUnit& u)
{
    put_strings(w, u.codes);
    w.put(static_cast<uint8_t>(u.intpt.has_value()));
    w.put(u.intpt.value_or(LonLatE6{}).lon);
    w.put(u.intpt.value_or(LonLatE6{}).lat);
    w.put(u.weight);
    w.put(u.source.file);
    w.put(u.source.feature);
    w.put(u.sid);
    put_strings(w, u.attrs);
}

void put_fields(ByteWriter& w, const std::vector<chains::AttributeField>& fields, bool named)
{
    w.put(static_cast<uint8_t>(named));
    w.put(static_cast<uint32_t>(fields.size()));
    for (const auto& f : fields) {
        w.put_vstr(f.name);
        w.put(static_cast<uint8_t>(f.type));
    }
}

bool get_fields(ByteReader& r, std::vector<chains::AttributeField>& fields)
{
    const bool named = r.get<uint8_t>("the unit attributes") != 0;
    const auto n = r.get<uint32_t>("the unit attributes");
    r.check_count(n, 2, "the unit attributes");
    fields.resize(n);
    for (auto& f : fields) {
        f.name = r.get_vstr("a unit attribute");
        const auto t = r.get<uint8_t>("a unit attribute");
        if (t > static_cast<uint8_t>(chains::AttributeType::real)) {
            r.fail("unknown attribute type " + std::to_string(t));
        }
        f.type = static_cast<chains::AttributeType>(t);
    }
    return named;
}

void join_fields(std::vector<chains::AttributeField>& into, const std::vector<chains::AttributeField>& more)
{
    if (into.empty()) {
        into = more;
        return;
    }
    using chains::AttributeType;
    for (size_t k = 0; k < into.size() && k < more.size(); ++k) {
        AttributeType& t = into[k].type;
        if (t != more[k].type) {
            t = t == AttributeType::text || more[k].type == AttributeType::text ? AttributeType::text
                                                                                : AttributeType::real;
        }
    }
}

RawUnit get_unit(ByteReader& r)
{
    RawUnit u;
    u.codes = get_strings(r, "a unit's codes");
    const bool has = r.get<uint8_t>("a unit") != 0;
    LonLatE6 p;
    p.lon = r.get<int32_t>("a unit");
    p.lat = r.get<int32_t>("a unit");
    if (has) {
        u.intpt = p;
    }
    u.weight = r.get<double>("a unit");
    u.source.file = r.get<uint32_t>("a unit");
    u.source.feature = r.get<int64_t>("a unit");
    u.sid = r.get<uint64_t>("a unit");
    u.attrs = get_strings(r, "a unit's attributes");
    return u;
}

std::string encode_raw(const RawMap& raw)
{
    ByteWriter w;
    w.reserve(raw.coords.size() * 8 + raw.polyline_count() * 40 + raw.units.size() * 64 + 1024);
    w.put_bytes(std::string_view(raw_magic, 8));
    w.put(static_cast<uint32_t>(raw.kind));
    put_strings(w, raw.level_names);
    put_strings(w, raw.files);
    put_strings(w, raw.classes);
    put_fields(w, raw.fields, raw.named);
    w.put(static_cast<uint64_t>(raw.units.size()));
    for (const auto& u : raw.units) {
        put_unit(w, u);
    }
    put_vec(w, raw.coords);
    put_vec(w, raw.offsets);
    put_vec(w, raw.left);
    put_vec(w, raw.right);
    put_vec(w, raw.feature_class);
    put_vec(w, raw.source_id);
    // SourceRef has padding: its fields one array each, so equal maps give equal bytes.
    std::vector<uint32_t> files(raw.source.size());
    std::vector<int64_t> features(raw.source.size());
    for (size_t i = 0; i < raw.source.size(); ++i) {
        files[i] = raw.source[i].file;
        features[i] = raw.source[i].feature;
    }
    put_vec(w, files);
    put_vec(w, features);
    w.put(static_cast<uint64_t>(raw.foreign.size()));
    for (const auto& f : raw.foreign) {
        w.put(f.polyline);
        w.put(f.right);
        w.put(f.face);
    }
    w.put(raw.points_read);
    w.put(raw.empty_geometries);
    w.put(raw.empty_codes);
    return std::move(w.bytes());
}

RawMap decode_raw(std::span<const std::byte> bytes, const std::string& name)
{
    ByteReader r(bytes, name);
    get_magic(r, raw_magic, "a part put aside by");
    RawMap raw;
    const auto kind = r.get<uint32_t>("the kind");
    if (kind > static_cast<uint32_t>(RawMap::Kind::lines)) {
        r.fail("unknown kind " + std::to_string(kind));
    }
    raw.kind = static_cast<RawMap::Kind>(kind);
    raw.level_names = get_strings(r, "level names");
    raw.files = get_strings(r, "files");
    raw.classes = get_strings(r, "classes");
    raw.named = get_fields(r, raw.fields);
    const auto nunits = r.get<uint64_t>("units");
    r.check_count(nunits, 33, "units");
    raw.units.resize(static_cast<size_t>(nunits));
    for (auto& u : raw.units) {
        u = get_unit(r);
    }
    get_vec(r, raw.coords, "points");
    get_vec(r, raw.offsets, "offsets");
    get_vec(r, raw.left, "left units");
    get_vec(r, raw.right, "right units");
    get_vec(r, raw.feature_class, "classes of polylines");
    get_vec(r, raw.source_id, "source ids");
    std::vector<uint32_t> files;
    std::vector<int64_t> features;
    get_vec(r, files, "sources");
    get_vec(r, features, "sources");
    const size_t np = raw.left.size();
    if (raw.offsets.size() != np + 1 || raw.right.size() != np || raw.feature_class.size() != np ||
        raw.source_id.size() != np || files.size() != np || features.size() != np || raw.offsets.front() != 0 ||
        raw.offsets.back() != raw.coords.size() || !std::is_sorted(raw.offsets.begin(), raw.offsets.end())) {
        r.fail("polyline arrays of different lengths");
    }
    raw.source.resize(np);
    for (size_t i = 0; i < np; ++i) {
        raw.source[i] = SourceRef{files[i], features[i]};
    }
    const auto nforeign = r.get<uint64_t>("foreign faces");
    r.check_count(nforeign, 16, "foreign faces");
    raw.foreign.resize(static_cast<size_t>(nforeign));
    for (auto& f : raw.foreign) {
        f.polyline = r.get<uint32_t>("a foreign face");
        f.right = r.get<uint32_t>("a foreign face");
        f.face = r.get<uint64_t>("a foreign face");
    }
    raw.points_read = r.get<uint64_t>("the counts");
    raw.empty_geometries = r.get<uint64_t>("the counts");
    raw.empty_codes = r.get<uint64_t>("the counts");
    if (r.left() != 0) {
        r.fail("bytes after the end");
    }
    return raw;
}

void write_raw(const RawMap& raw, const std::filesystem::path& path)
{
    write_file(path, encode_raw(raw));
}

RawMap read_raw(const std::filesystem::path& path)
{
    const std::string bytes = read_file(path);
    return decode_raw(std::as_bytes(std::span(bytes.data(), bytes.size())), path.string());
}

LonLatE6 snap_e6(double lon_deg, double lat_deg) noexcept
{
    return {round_half_away(lon_deg * 1e6), round_half_away(lat_deg * 1e6)};
}

void RawMap::add_polyline(std::span<const LonLatE6> pts, uint32_t left_unit, uint32_t right_unit, uint32_t cls,
                          uint64_t sid, SourceRef src)
{
    coords.insert(coords.end(), pts.begin(), pts.end());
    offsets.push_back(coords.size());
    left.push_back(left_unit);
    right.push_back(right_unit);
    feature_class.push_back(cls);
    source_id.push_back(sid);
    source.push_back(src);
}

uint32_t RawMap::intern_class(const std::string& name)
{
    auto it = std::find(classes.begin(), classes.end(), name);
    if (it != classes.end()) {
        return static_cast<uint32_t>(it - classes.begin());
    }
    classes.push_back(name);
    return static_cast<uint32_t>(classes.size() - 1);
}

void RawMap::append(RawMap&& part)
{
    const auto file0 = static_cast<uint32_t>(files.size());
    const auto unit0 = static_cast<uint32_t>(units.size());
    files.insert(files.end(), part.files.begin(), part.files.end());
    join_fields(fields, part.fields);
    named = named || part.named;
    for (auto& u : part.units) {
        u.source.file += file0;
        units.push_back(std::move(u));
    }
    std::vector<uint32_t> cls(part.classes.size());
    for (size_t c = 0; c < part.classes.size(); ++c) {
        cls[c] = intern_class(part.classes[c]);
    }
    for (auto ff : part.foreign) {
        ff.polyline += static_cast<uint32_t>(polyline_count());
        foreign.push_back(ff);
    }
    const uint64_t coord0 = coords.size();
    coords.insert(coords.end(), part.coords.begin(), part.coords.end());
    for (size_t p = 0; p < part.polyline_count(); ++p) {
        offsets.push_back(coord0 + part.offsets[p + 1]);
        left.push_back(part.left[p] == no_unit ? no_unit : part.left[p] + unit0);
        right.push_back(part.right[p] == no_unit ? no_unit : part.right[p] + unit0);
        feature_class.push_back(cls[part.feature_class[p]]);
        source_id.push_back(part.source_id[p]);
        source.push_back({part.source[p].file + file0, part.source[p].feature});
    }
    points_read += part.points_read;
    empty_geometries += part.empty_geometries;
    empty_codes += part.empty_codes;
    part = RawMap();
}

void RawMap::reserve(size_t points, size_t polylines)
{
    coords.reserve(points);
    offsets.reserve(polylines + 1);
    left.reserve(polylines);
    right.reserve(polylines);
    feature_class.reserve(polylines);
    source_id.reserve(polylines);
    source.reserve(polylines);
}

uint64_t RawMap::share_seam_vertices()
{
    constexpr int32_t seam = 180000000;
    std::vector<int32_t> lats;
    bool along = false; // some segment runs along the meridian
    for (size_t i = 0; i < polyline_count(); ++i) {
        for (uint64_t k = offsets[i]; k < offsets[i + 1]; ++k) {
            if (coords[k].lon == seam) {
                lats.push_back(coords[k].lat);
                along = along || (k > offsets[i] && coords[k - 1].lon == seam);
            }
        }
    }
    if (!along) {
        return 0;
    }
    std::sort(lats.begin(), lats.end());
    lats.erase(std::unique(lats.begin(), lats.end()), lats.end());
    std::vector<LonLatE6> out;
    out.reserve(coords.size());
    std::vector<uint64_t> offs{0};
    offs.reserve(offsets.size());
    for (size_t i = 0; i < polyline_count(); ++i) {
        for (uint64_t k = offsets[i]; k < offsets[i + 1]; ++k) {
            const LonLatE6 q = coords[k];
            if (k > offsets[i] && q.lon == seam && coords[k - 1].lon == seam) {
                const int32_t a = coords[k - 1].lat, b = q.lat;
                auto lo = std::upper_bound(lats.begin(), lats.end(), std::min(a, b));
                auto hi = std::lower_bound(lats.begin(), lats.end(), std::max(a, b));
                if (a < b) {
                    for (auto it = lo; it < hi; ++it) {
                        out.push_back({seam, *it});
                    }
                } else {
                    for (auto it = hi; it > lo; --it) {
                        out.push_back({seam, *(it - 1)});
                    }
                }
            }
            out.push_back(q);
        }
        offs.push_back(out.size());
    }
    const uint64_t added = out.size() - coords.size();
    coords = std::move(out);
    offsets = std::move(offs);
    return added;
}

std::string RawMap::where(SourceRef src) const
{
    std::string s = src.file < files.size() ? files[src.file] : std::string("?");
    if (src.feature >= 0) {
        s += ':';
        s += std::to_string(src.feature);
    }
    return s;
}

} // namespace tigerlod::ingest
