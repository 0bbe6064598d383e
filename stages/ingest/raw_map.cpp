#include "stages/ingest/raw_map.hpp"

#include "core/errors.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
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

/// A file of plain values: vectors as a count and their bytes.
class RawFile {
  public:
    RawFile(const std::filesystem::path& path, const char* mode)
        : m_path(path), m_f(std::fopen(path.c_str(), mode), &std::fclose)
    {
        if (!m_f) {
            fail();
        }
    }
    template <class T> void put(const T& v)
    {
        static_assert(std::is_trivially_copyable_v<T>);
        write(&v, sizeof v);
    }
    template <class T> void put_vec(const std::vector<T>& v)
    {
        put(static_cast<uint64_t>(v.size()));
        write(v.data(), v.size() * sizeof(T));
    }
    void put_str(const std::string& s)
    {
        put(static_cast<uint64_t>(s.size()));
        write(s.data(), s.size());
    }
    void put_strs(const std::vector<std::string>& v)
    {
        put(static_cast<uint64_t>(v.size()));
        for (const auto& s : v) {
            put_str(s);
        }
    }
    template <class T> T get()
    {
        T v;
        read(&v, sizeof v);
        return v;
    }
    template <class T> void get_vec(std::vector<T>& v)
    {
        v.resize(get<uint64_t>());
        read(v.data(), v.size() * sizeof(T));
    }
    std::string get_str()
    {
        std::string s(get<uint64_t>(), '\0');
        read(s.data(), s.size());
        return s;
    }
    void get_strs(std::vector<std::string>& v)
    {
        v.resize(get<uint64_t>());
        for (auto& s : v) {
            s = get_str();
        }
    }
    void close()
    {
        if (std::fclose(m_f.release()) != 0) {
            fail();
        }
    }

  private:
    [[noreturn]] void fail() const
    {
        throw environment_error(m_path.string() + ": cannot write or read a part put aside");
    }
    void write(const void* p, size_t n)
    {
        if (n > 0 && std::fwrite(p, 1, n, m_f.get()) != n) {
            fail();
        }
    }
    void read(void* p, size_t n)
    {
        if (n > 0 && std::fread(p, 1, n, m_f.get()) != n) {
            fail();
        }
    }
    std::filesystem::path m_path;
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> m_f;
};

} // namespace

void write_raw(const RawMap& raw, const std::filesystem::path& path)
{
    RawFile f(path, "wb");
    f.put(static_cast<uint32_t>(raw.kind));
    f.put_strs(raw.level_names);
    f.put_strs(raw.files);
    f.put_strs(raw.classes);
    f.put(static_cast<uint64_t>(raw.units.size()));
    for (const auto& u : raw.units) {
        f.put_strs(u.codes);
        f.put(static_cast<uint8_t>(u.intpt.has_value()));
        f.put(u.intpt.value_or(LonLatE6{}));
        f.put(u.weight);
        f.put(u.source);
        f.put(u.sid);
    }
    f.put_vec(raw.coords);
    f.put_vec(raw.offsets);
    f.put_vec(raw.left);
    f.put_vec(raw.right);
    f.put_vec(raw.feature_class);
    f.put_vec(raw.source_id);
    f.put_vec(raw.source);
    f.put_vec(raw.foreign);
    f.put(raw.points_read);
    f.put(raw.empty_geometries);
    f.close();
}

RawMap read_raw(const std::filesystem::path& path)
{
    RawFile f(path, "rb");
    RawMap raw;
    raw.kind = static_cast<RawMap::Kind>(f.get<uint32_t>());
    f.get_strs(raw.level_names);
    f.get_strs(raw.files);
    f.get_strs(raw.classes);
    raw.units.resize(f.get<uint64_t>());
    for (auto& u : raw.units) {
        f.get_strs(u.codes);
        const bool has = f.get<uint8_t>() != 0;
        const auto p = f.get<LonLatE6>();
        if (has) {
            u.intpt = p;
        }
        u.weight = f.get<double>();
        u.source = f.get<SourceRef>();
        u.sid = f.get<uint64_t>();
    }
    f.get_vec(raw.coords);
    f.get_vec(raw.offsets);
    f.get_vec(raw.left);
    f.get_vec(raw.right);
    f.get_vec(raw.feature_class);
    f.get_vec(raw.source_id);
    f.get_vec(raw.source);
    f.get_vec(raw.foreign);
    raw.points_read = f.get<uint64_t>();
    raw.empty_geometries = f.get<uint64_t>();
    return raw;
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
