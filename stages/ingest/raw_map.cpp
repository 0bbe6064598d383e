#include "stages/ingest/raw_map.hpp"

#include <algorithm>
#include <cmath>

namespace tigerlod::ingest {

LonLatE6 snap_e6(double lon_deg, double lat_deg) noexcept
{
    return {static_cast<int32_t>(std::llround(lon_deg * 1e6)), static_cast<int32_t>(std::llround(lat_deg * 1e6))};
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

std::string RawMap::where(SourceRef src) const
{
    std::string s = src.file < files.size() ? files[src.file] : std::string("?");
    if (src.feature >= 0) {
        s += ":" + std::to_string(src.feature);
    }
    return s;
}

} // namespace tigerlod::ingest
