#include "stages/ingest/raw_map.hpp"

#include <algorithm>
#include <cmath>

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
