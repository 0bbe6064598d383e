#include "stages/ingest/sources.hpp"

#include "core/errors.hpp"
#include "core/geometry.hpp"
#include "core/projection.hpp"

#include <cpl_error.h>
#include <gdal.h>
#include <ogr_api.h>
#include <ogr_srs_api.h>

#include <algorithm>
#include <atomic>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <limits>
#include <exception>
#include <thread>
#include <cstring>
#include <memory>
#include <mutex>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>

namespace fs = std::filesystem;

namespace tigerlod::ingest {

namespace {

/// Collects GDAL's error messages while alive, instead of printing them.
class ErrorCapture {
  public:
    ErrorCapture() { CPLPushErrorHandlerEx(&ErrorCapture::handler, this); }
    ~ErrorCapture() { CPLPopErrorHandler(); }
    ErrorCapture(const ErrorCapture&) = delete;
    ErrorCapture& operator=(const ErrorCapture&) = delete;
    bool failed() const noexcept { return !m_message.empty(); }
    std::string take()
    {
        std::string m = std::move(m_message);
        m_message.clear();
        return m;
    }

  private:
    static void CPL_STDCALL handler(CPLErr level, CPLErrorNum, const char* msg)
    {
        auto* self = static_cast<ErrorCapture*>(CPLGetErrorHandlerUserData());
        if (level >= CE_Failure && self->m_message.empty()) {
            self->m_message = msg;
        }
    }
    std::string m_message;
};

struct DatasetCloser {
    void operator()(void* ds) const noexcept { GDALClose(ds); }
};
struct FeatureDeleter {
    void operator()(OGRFeatureH f) const noexcept { OGR_F_Destroy(f); }
};
using FeaturePtr = std::unique_ptr<std::remove_pointer_t<OGRFeatureH>, FeatureDeleter>;

/// One opened vector source and its chosen layer.
class Source {
  public:
    Source(const fs::path& path, const std::string& layer_name, const char* role)
        : m_path(path), m_name(path.filename().string())
    {
        // Registering drivers is not thread-safe; sources open on several threads.
        static std::once_flag registered;
        std::call_once(registered, [] { GDALAllRegister(); });
        std::string open = path.string();
        if (path.extension() == ".zip") {
            open = "/vsizip/" + open;
        }
        ErrorCapture errors;
        m_ds.reset(GDALOpenEx(open.c_str(), GDAL_OF_VECTOR | GDAL_OF_READONLY, nullptr, nullptr, nullptr));
        if (!m_ds) {
            std::string why = errors.take();
            throw input_error(path.string() + ": cannot open as a vector dataset (" + role + ")" +
                              (why.empty() ? std::string() : ": " + why));
        }
        const int n = GDALDatasetGetLayerCount(m_ds.get());
        if (!layer_name.empty()) {
            m_layer = GDALDatasetGetLayerByName(m_ds.get(), layer_name.c_str());
        } else if (n == 1) {
            m_layer = GDALDatasetGetLayer(m_ds.get(), 0);
        }
        if (m_layer == nullptr) {
            std::string names;
            for (int i = 0; i < n; ++i) {
                names += std::string(i ? ", " : "") + OGR_L_GetName(GDALDatasetGetLayer(m_ds.get(), i));
            }
            throw input_error(path.string() + ": " +
                              (layer_name.empty() ? "holds " + std::to_string(n) + " layers, set dataset.layer"
                                                  : "no layer '" + layer_name + "'") +
                              " (" + role + "; layers: " + (names.empty() ? "none" : names) + ")");
        }
        m_layer_name = OGR_L_GetName(m_layer);
        OGRSpatialReferenceH srs = OGR_L_GetSpatialRef(m_layer);
        if (srs != nullptr && OSRIsProjected(srs)) {
            throw input_error(where() +
                              ": layer has a projected CRS; tigerlod reads lon/lat (NAD83 or WGS84): "
                              "reproject it first, e.g. ogr2ogr -t_srs EPSG:4269 OUT.shp " +
                              m_path.string());
        }
    }
    std::string where() const { return m_name + " layer '" + m_layer_name + "'"; }
    const std::string& name() const noexcept { return m_name; }
    OGRLayerH layer() const noexcept { return m_layer; }

    /// Index of a required field, or input_error naming what it is needed for.
    int field(const std::string& field_name, const char* needed_for) const
    {
        const int i = OGR_FD_GetFieldIndex(OGR_L_GetLayerDefn(m_layer), field_name.c_str());
        if (i < 0) {
            std::string hint;
            if (OGR_FD_GetFieldCount(OGR_L_GetLayerDefn(m_layer)) == 0) {
                // A shapefile whose .dbf is missing opens with no attributes.
                hint = "; the layer has no attributes at all";
                const fs::path& shp = m_path;
                if (shp.extension() == ".shp" && !fs::exists(fs::path(shp).replace_extension(".dbf")) &&
                    !fs::exists(fs::path(shp).replace_extension(".DBF"))) {
                    hint += ": " + fs::path(shp).replace_extension(".dbf").string() +
                            " (its attributes) is missing beside it";
                } else {
                    hint += " (a shapefile without its .dbf?)";
                }
            }
            throw input_error(where() + ": no field '" + field_name + "' (" + needed_for + ")" + hint);
        }
        return i;
    }
    int optional_field(const std::string& field_name) const
    {
        return field_name.empty() ? -1 : OGR_FD_GetFieldIndex(OGR_L_GetLayerDefn(m_layer), field_name.c_str());
    }
    /// Field `i` (if any: i >= 0) must have one of the `allowed` types: a
    /// TLID stored as text or a code stored as an integer would be read as
    /// something else (0, or a code without its leading zeros) and give a
    /// wrong map, not an error.
    int expect_type(int i, const std::string& needed_for, std::initializer_list<OGRFieldType> allowed,
                    const char* wanted) const
    {
        if (i < 0) {
            return i;
        }
        OGRFieldDefnH fd = OGR_FD_GetFieldDefn(OGR_L_GetLayerDefn(m_layer), i);
        const OGRFieldType t = OGR_Fld_GetType(fd);
        for (const auto a : allowed) {
            if (t == a) {
                return i;
            }
        }
        throw input_error(where() + ": field '" + OGR_Fld_GetNameRef(fd) + "' is " + OGR_GetFieldTypeName(t) +
                          ", but " + needed_for + " needs " + wanted);
    }
    /// Check the layer's geometry type against the allowed flat types (wkbUnknown passes).
    void expect_geometry(std::initializer_list<OGRwkbGeometryType> allowed, const char* what) const
    {
        const auto t = wkbFlatten(OGR_L_GetGeomType(m_layer));
        if (t == wkbUnknown) {
            return;
        }
        for (auto a : allowed) {
            if (t == a) {
                return;
            }
        }
        throw input_error(where() + ": geometry type is " + OGRGeometryTypeToName(t) + ", " + what);
    }
    /// Visit every feature; GDAL read errors become input_error naming the
    /// feature, and a layer without features is input_error too: every
    /// input names part of the map, and an empty one (a cut-off download,
    /// the wrong layer) would map nothing there with exit 0.
    /// With a filter (dataset.where), only the features it selects are
    /// visited, still numbered as the file numbers them.
    template <class F> void for_each(F&& f)
    {
        const std::unordered_set<GIntBig> selected = select();
        ErrorCapture errors;
        OGR_L_ResetReading(m_layer);
        int64_t index = 0, visited = 0;
        while (true) {
            FeaturePtr feat(OGR_L_GetNextFeature(m_layer));
            if (errors.failed()) {
                throw input_error(m_name + ":" + std::to_string(index) + ": " + errors.take() +
                                  " (truncated or corrupt file?)");
            }
            if (!feat) {
                break;
            }
            if (m_where.empty() || selected.contains(OGR_F_GetFID(feat.get()))) {
                f(feat.get(), index);
                ++visited;
            }
            ++index;
        }
        if (index == 0) {
            throw input_error(where() + ": no features: an empty layer (a cut-off file, or the wrong layer?) maps "
                                        "nothing; give inputs that hold features");
        }
        if (visited == 0) {
            throw input_error(where() + ": dataset.where '" + m_where + "' selects none of its " +
                              std::to_string(index) +
                              " features: a file that adds nothing to the map is named "
                              "by mistake, or the condition is");
        }
    }
    /// Visit only the features that `condition` (OGR SQL) selects; "" for all.
    void filter(const std::string& condition) { m_where = condition; }

  private:
    /// The FIDs of the features the filter selects (none without one): a
    /// pass with the filter set and the geometry not read, so that the
    /// visiting pass can number every feature of the file.
    std::unordered_set<GIntBig> select()
    {
        std::unordered_set<GIntBig> fids;
        if (m_where.empty()) {
            return fids;
        }
        ErrorCapture errors;
        if (OGR_L_SetAttributeFilter(m_layer, m_where.c_str()) != OGRERR_NONE) {
            throw input_error(where() + ": dataset.where '" + m_where +
                              "': " + (errors.failed() ? errors.take() : std::string("not a condition OGR SQL reads")));
        }
        const char* ignored[] = {"OGR_GEOMETRY", nullptr};
        OGR_L_SetIgnoredFields(m_layer, ignored);
        OGR_L_ResetReading(m_layer);
        while (FeaturePtr feat{OGR_L_GetNextFeature(m_layer)}) {
            const GIntBig fid = OGR_F_GetFID(feat.get());
            if (fid == OGRNullFID || !fids.insert(fid).second) {
                throw input_error(where() + ": dataset.where needs each feature's own id (FID), which this file "
                                            "does not give");
            }
        }
        const bool failed = errors.failed();
        const std::string why = failed ? errors.take() : std::string();
        OGR_L_SetAttributeFilter(m_layer, nullptr);
        OGR_L_SetIgnoredFields(m_layer, nullptr);
        if (failed) {
            throw input_error(where() + ": dataset.where '" + m_where + "': " + why);
        }
        return fids;
    }

    fs::path m_path;
    std::string m_name, m_layer_name, m_where;
    std::unique_ptr<void, DatasetCloser> m_ds;
    OGRLayerH m_layer = nullptr;
};

/// A longitude difference in micro-degrees, wrapped to (-180, 180] degrees.
int64_t wrap_micro(int64_t d)
{
    constexpr int64_t half = 180000000, turn = 2 * half;
    d %= turn;
    return d + (d <= -half ? turn : d > half ? -turn : 0);
}

/// Snap a whole simple geometry's points; checks lon/lat ranges.
void snap_points(OGRGeometryH g, std::vector<LonLatE6>& out, const std::string& where)
{
    out.clear();
    const int n = OGR_G_GetPointCount(g);
    out.reserve(static_cast<size_t>(n));
    // All points in one call, not two calls a point. The buffer is reused, so
    // it starts as NaN: a point the call did not fill fails the check below
    // instead of taking the last geometry's value.
    thread_local std::vector<double> xy;
    xy.assign(2 * static_cast<size_t>(n), std::numeric_limits<double>::quiet_NaN());
    if (n > 0) {
        constexpr int stride = 2 * sizeof(double);
        OGR_G_GetPoints(g, xy.data(), stride, xy.data() + 1, stride, nullptr, 0);
    }
    for (int i = 0; i < n; ++i) {
        const double lon = xy[2 * static_cast<size_t>(i)], lat = xy[2 * static_cast<size_t>(i) + 1];
        if (!std::isfinite(lon) || !std::isfinite(lat) || std::fabs(lon) > 180 || std::fabs(lat) > 90) {
            char buf[128];
            std::snprintf(buf, sizeof buf, ": point %d (%.9g, %.9g) is not a lon/lat in degrees", i, lon, lat);
            throw input_error(where + buf);
        }
        out.push_back(snap_e6(lon, lat));
    }
}

/// A ring or line of lon/lat points made fit for the plane of a conic
/// (Albers, LCC), which tears the globe along its cut, the meridian
/// opposite its central one (lon0 + 180): a point exactly on the cut maps to
/// one edge of the map only, whichever side its neighbours are on.
///  1. A run of points on the cut between points on one side of it (data
///     cut at the antimeridian, as Natural Earth's, for a map centred on
///     Greenwich) moves a micro-degree into that side, the snapping step:
///     its segments then stay on their side instead of crossing the map.
///  2. A run between the two sides crosses the cut: refused, naming the
///     place and the fix, unless it is at a pole (within 0.1 degree), where
///     a ring around the pole is closed (Antarctica's closure from -180 to
///     180), its segments kept as they are.
///  3. A segment crossing the cut the short way round is refused too.
/// Other projections are left as they are (Transverse Mercator's domain
/// ends 30 degrees from its central meridian). Everywhere but on a conic
/// cut there, longitude -180 is written 180 first (one meridian, one key).
void fit_to_globe(std::vector<LonLatE6>& pts, const ProjectionParams& proj, const std::string& where)
{
    constexpr int64_t half = 180000000, turn = 2 * half, pole = 89900000;
    const int64_t lon0 = std::llround(proj.lon0_deg * 1e6);
    const bool conic = proj.kind == ProjectionParams::Kind::albers || proj.kind == ProjectionParams::Kind::lcc;
    // -180 and 180 are one meridian: where it is not the cut, one key, so
    // that the parts of a unit cut there (Fiji, the Aleutians, Antarctica's
    // seam) share their edges along it, which then are inner edges, gone.
    if (!conic || std::llabs((180000000 - lon0) % turn) != half) {
        for (auto& p : pts) {
            p.lon = p.lon == -half ? static_cast<int32_t>(half) : p.lon;
        }
    }
    if (!conic) {
        return;
    }
    // Longitude east of the central meridian, in (-180, 180] degrees (micro).
    auto east = [&](int64_t lon) { return wrap_micro(lon - lon0); };
    auto on_cut = [&](const LonLatE6& p) { return east(p.lon) == half; };
    int64_t cut = lon0 + half; // for messages, in (-180, 180]
    cut += cut > half ? -turn : 0;
    auto polar = [&](const LonLatE6& p) { return std::abs(int64_t{p.lat}) >= pole; };
    auto refuse = [&](const LonLatE6& p, const LonLatE6& q) {
        char buf[400];
        std::snprintf(buf, sizeof buf,
                      ": from (%.6f, %.6f) to (%.6f, %.6f) it crosses longitude %.6f, where the projection (lon0 %g) "
                      "cuts the globe, and would be drawn across the whole map: choose a projection.lon0 whose "
                      "opposite meridian misses the map, or split the feature there",
                      p.lon * 1e-6, p.lat * 1e-6, q.lon * 1e-6, q.lat * 1e-6, double(cut) * 1e-6, proj.lon0_deg);
        throw input_error(where + buf);
    };
    const bool closed = pts.size() > 2 && pts.front() == pts.back();
    const size_t n = closed ? pts.size() - 1 : pts.size(); // a ring's points once
    for (size_t i = 0; i < n;) {
        if (!on_cut(pts[i])) {
            ++i;
            continue;
        }
        size_t e = i;
        while (e < n && on_cut(pts[e])) {
            ++e;
        }
        // The side of the nearest point off the cut before and after the run
        // (around a ring), 0 where there is none.
        auto side_at = [&](size_t k) { return east(pts[k].lon) > 0 ? 1 : -1; };
        int before = 0, after = 0;
        if (i > 0 || closed) {
            for (size_t k = 1; k <= n && before == 0; ++k) {
                const size_t j = (i + n - k) % n;
                if (!closed && j >= i) {
                    break;
                }
                before = on_cut(pts[j]) ? 0 : side_at(j);
            }
        }
        for (size_t k = e; (k < n || closed) && after == 0 && k < e + n; ++k) {
            const size_t j = k % n;
            after = on_cut(pts[j]) ? 0 : side_at(j);
        }
        bool at_pole = false;
        for (size_t k = i; k < e; ++k) {
            at_pole = at_pole || polar(pts[k]);
        }
        if (before != 0 && after != 0 && before != after) {
            if (!at_pole) {
                refuse(pts[i > 0 ? i - 1 : n - 1], pts[e < n ? e : 0]);
            }
        } else if (const int side = before != 0 ? before : after; side != 0) {
            for (size_t k = i; k < e; ++k) { // a micro-degree into its side
                int64_t lon = pts[k].lon - side;
                lon += lon < -half ? turn : lon > half ? -turn : 0;
                pts[k].lon = static_cast<int32_t>(lon);
            }
        }
        i = e;
    }
    if (closed) {
        pts.back() = pts.front();
    }
    for (size_t i = 1; i < pts.size(); ++i) {
        const LonLatE6 p = pts[i - 1], q = pts[i];
        if (polar(p) && polar(q)) {
            continue;
        }
        // The short way from p, by s in (-180, 180]: across the cut when the
        // eastings of p and p + s lie on two sides of it.
        int64_t s = (int64_t{q.lon} - p.lon) % turn;
        s += s <= -half ? turn : s > half ? -turn : 0;
        const int64_t a = east(p.lon);
        if (a + s > half || a + s < -half) {
            refuse(p, q);
        }
    }
}

using XY = std::pair<double, double>;

/// The part of a closed ring (first point = last) on one side of the
/// vertical line at `x` (points on it count as on the kept side), as closed
/// rings. Each run of the ring on the kept side goes from where it enters
/// to where it leaves, both on the line. Along the line, the inside of a
/// simple ring is the intervals between its crossings sorted by y, the
/// first and second, the third and fourth, and so on; each such interval
/// joins the run that leaves at one end to the run that enters at the
/// other, and following them gives the pieces, as many as the ring has on
/// that side (a C cut across its opening gives two, not one joined by a
/// bridge along the line). Runs that lie on the line alone (the ring
/// touches it from the far side) enclose nothing and are left out. Where
/// the crossings do not pair up so (a ring that crosses itself), the ring
/// is clipped in one piece (Sutherland-Hodgman), its parts joined along
/// the line, and ingest reports the overlap there.
std::vector<std::vector<XY>> clip_ring(const std::vector<XY>& in, double x, bool keep_above)
{
    auto inside = [&](const XY& p) { return keep_above ? p.first >= x : p.first <= x; };
    auto cross = [&](const XY& p, const XY& q) -> XY {
        const double t = (x - p.first) / (q.first - p.first);
        return {x, p.second + t * (q.second - p.second)};
    };
    const size_t n = in.size() - 1; // the ring's points once
    // Start at a point outside, so that the walk begins with an entry.
    size_t start = n;
    for (size_t i = 0; i < n && start == n; ++i) {
        start = inside(in[i]) ? start : i;
    }
    if (start == n) {
        return {in}; // all on the kept side
    }
    std::vector<std::vector<XY>> runs;
    for (size_t s = 0; s < n; ++s) {
        const XY& p = in[(start + s) % n];
        const XY& q = in[(start + s + 1) % n];
        if (!inside(p) && inside(q)) {
            runs.push_back({cross(p, q)});
            if (!(runs.back().back() == q)) {
                runs.back().push_back(q);
            }
        } else if (inside(p) && inside(q)) {
            runs.back().push_back(q);
        } else if (inside(p) && !inside(q)) {
            if (const XY c = cross(p, q); !(runs.back().back() == c)) {
                runs.back().push_back(c);
            }
        }
    }
    std::erase_if(runs, [&](const std::vector<XY>& r) {
        return std::all_of(r.begin(), r.end(), [&](const XY& p) { return p.first == x; });
    });
    if (runs.empty()) {
        return {};
    }
    // The runs' ends by y (entry: 2 r, exit: 2 r + 1), paired in order.
    std::vector<size_t> ends(2 * runs.size());
    std::iota(ends.begin(), ends.end(), size_t{0});
    auto y_of = [&](size_t e) { return e % 2 == 0 ? runs[e / 2].front().second : runs[e / 2].back().second; };
    std::sort(ends.begin(), ends.end(),
              [&](size_t a, size_t b) { return std::pair(y_of(a), a) < std::pair(y_of(b), b); });
    std::vector<size_t> next(runs.size(), SIZE_MAX);
    bool paired = true;
    for (size_t i = 0; i + 1 < ends.size(); i += 2) {
        const size_t e = ends[i], f = ends[i + 1];
        if (e % 2 == f % 2) {
            paired = false; // two entries (or exits) bound one interval
            break;
        }
        const size_t exit = e % 2 == 1 ? e : f, entry = e % 2 == 1 ? f : e;
        next[exit / 2] = entry / 2;
    }
    if (!paired) {
        std::vector<XY> res; // Sutherland-Hodgman: one ring, bridged along the line
        for (size_t i = 0; i + 1 < in.size(); ++i) {
            if (inside(in[i])) {
                res.push_back(in[i]);
            }
            if (inside(in[i]) != inside(in[i + 1])) {
                res.push_back(cross(in[i], in[i + 1]));
            }
        }
        if (!res.empty()) {
            res.push_back(res.front());
        }
        return {res};
    }
    std::vector<std::vector<XY>> out;
    std::vector<uint8_t> used(runs.size(), 0);
    for (size_t r0 = 0; r0 < runs.size(); ++r0) {
        if (used[r0]) {
            continue;
        }
        std::vector<XY> ring;
        for (size_t r = r0; !used[r]; r = next[r]) {
            used[r] = 1;
            ring.insert(ring.end(), runs[r].begin(), runs[r].end());
        }
        ring.push_back(ring.front());
        out.push_back(std::move(ring));
    }
    return out;
}

/// A polygon ring cut along a conic's cut (the meridian opposite its
/// central one), where the plane tears: the ring unwrapped the short way
/// round from its first point, clipped to each strip of 360 degrees of
/// longitude it reaches (Sutherland-Hodgman against the strip's two
/// meridians, the clip points on the line straight in lon/lat), each piece
/// a ring of its own moved back into [-180, 180], its points on the cut a
/// micro-degree inside their side so that each maps to its own edge of the
/// map. A ring that crosses nothing comes back alone (points that lie on
/// the cut from its west side moved a micro-degree west of it too). A ring
/// round a pole (it winds once round the globe) is first closed along the
/// pole, a degree a step (the cones draw a pole as an arc). A ring that
/// leaves and enters a strip more than once gives a piece for each part
/// of it there (clip_ring).
std::vector<std::vector<LonLatE6>> split_at_cut(const std::vector<LonLatE6>& ring, const ProjectionParams& proj)
{
    if ((proj.kind != ProjectionParams::Kind::albers && proj.kind != ProjectionParams::Kind::lcc) || ring.size() < 4 ||
        !(ring.front() == ring.back())) {
        return {ring};
    }
    constexpr int64_t half = 180000000, turn = 2 * half;
    const int64_t lon0 = std::llround(proj.lon0_deg * 1e6);
    // Unwrapped eastings (micro-degrees east of lon0) and latitudes.
    std::vector<std::pair<double, double>> u;
    u.reserve(ring.size());
    int64_t e = wrap_micro(ring[0].lon - lon0);
    u.emplace_back(double(e), double(ring[0].lat));
    for (size_t i = 1; i < ring.size(); ++i) {
        e += wrap_micro(int64_t{ring[i].lon} - ring[i - 1].lon);
        u.emplace_back(double(e), double(ring[i].lat));
    }
    if (const int64_t winding = std::llround(u.back().first - u.front().first); winding != 0) {
        // Round a pole: closed along it (a degree a step, an arc on the
        // cones) back to where it started, it winds no more, and is cut as
        // any other ring.
        constexpr int64_t step = 1000000;
        const double pole = (ring[0].lat < 0 ? -90.0 : 90.0) * 1e6, x0 = u.front().first, x1 = u.back().first;
        const double dir = x1 > x0 ? -1.0 : 1.0; // from x1 back to x0
        for (double x = x1; dir * (x0 - x) > 0; x += dir * double(step)) {
            u.emplace_back(x, pole);
        }
        u.emplace_back(x0, pole);
        u.push_back(u.front());
    }
    double lo = INFINITY, hi = -INFINITY;
    for (const auto& [x, y] : u) {
        lo = std::min(lo, x);
        hi = std::max(hi, x);
    }
    const auto k_lo = int64_t(std::floor((lo + double(half)) / double(turn)));
    // A strip the ring only touches gives a piece of under 4 points, left out below.
    const auto k_hi = int64_t(std::floor((hi + double(half)) / double(turn)));
    std::vector<std::vector<LonLatE6>> out;
    for (int64_t k = k_lo; k <= k_hi; ++k) {
        const double a = double(-half + k * turn), b = double(half + k * turn);
        for (const auto& half_piece : clip_ring(u, a, true)) {
            for (const auto& piece : clip_ring(half_piece, b, false)) {
                if (piece.size() < 4) {
                    continue;
                }
                std::vector<LonLatE6> r;
                for (const auto& [x, y] : piece) {
                    // On a strip's meridian: a micro-degree inside it.
                    const double xi = x <= a ? a + 1 : x >= b ? b - 1 : x;
                    int64_t lon = lon0 + std::llround(xi) - k * turn;
                    lon += lon > half ? -turn : lon < -half ? turn : 0;
                    const LonLatE6 pt{static_cast<int32_t>(lon), static_cast<int32_t>(std::llround(y))};
                    if (r.empty() || !(r.back() == pt)) {
                        r.push_back(pt);
                    }
                }
                if (r.size() >= 4 && r.front() == r.back()) {
                    out.push_back(std::move(r));
                }
            }
        }
    }
    return out.empty() ? std::vector<std::vector<LonLatE6>>{ring} : out;
}

std::optional<LonLatE6> intpt(OGRFeatureH f, int lat_i, int lon_i)
{
    if (lat_i < 0 || lon_i < 0 || !OGR_F_IsFieldSetAndNotNull(f, lat_i) || !OGR_F_IsFieldSetAndNotNull(f, lon_i)) {
        return std::nullopt;
    }
    const double lat = OGR_F_GetFieldAsDouble(f, lat_i), lon = OGR_F_GetFieldAsDouble(f, lon_i);
    if (!std::isfinite(lat) || !std::isfinite(lon) || std::fabs(lat) > 90 || std::fabs(lon) > 180 ||
        (lat == 0 && lon == 0)) {
        return std::nullopt;
    }
    return snap_e6(lon, lat);
}

/// The first `n` characters of UTF-8 `text` (whole characters, never a
/// byte inside one), or nullopt if it has fewer or is not UTF-8.
std::optional<std::string> utf8_prefix(const std::string& text, size_t n)
{
    size_t i = 0;
    for (size_t chars = 0; chars < n; ++chars) {
        if (i >= text.size()) {
            return std::nullopt;
        }
        const auto lead = static_cast<unsigned char>(text[i]);
        const size_t len = lead < 0x80           ? 1
                           : (lead >> 5) == 0x6  ? 2
                           : (lead >> 4) == 0xE  ? 3
                           : (lead >> 3) == 0x1E ? 4
                                                 : 0;
        if (len == 0 || i + len > text.size()) {
            return std::nullopt;
        }
        for (size_t k = 1; k < len; ++k) {
            if ((static_cast<unsigned char>(text[i + k]) & 0xC0) != 0x80) {
                return std::nullopt;
            }
        }
        i += len;
    }
    return text.substr(0, i);
}

/// A unit's code at `level`: the constant, the first `prefix` characters of
/// the code field's `code_value` (input_error naming `where` if it is
/// shorter: a prefix of it would be a made-up unit), or the fields joined.
std::string level_code(const LevelSpec& level, OGRFeatureH f, const std::vector<int>& field_index,
                       const std::string& code_value, const std::string& where = "")
{
    if (!level.code.empty()) {
        return level.code;
    }
    if (level.prefix > 0) {
        const auto prefix = utf8_prefix(code_value, static_cast<size_t>(level.prefix));
        if (!prefix) {
            throw input_error(where + ": code '" + code_value + "' is shorter than level '" + level.name +
                              "' needs (its first " + std::to_string(level.prefix) +
                              " characters), or not UTF-8: a shorter prefix would be a made-up unit; fix the code or "
                              "the level's prefix");
        }
        return *prefix;
    }
    std::string s;
    for (int i : field_index) {
        s += OGR_F_GetFieldAsString(f, i);
    }
    return s;
}

/// The config's unit attributes on a layer (dataset.name_field, then
/// dataset.attributes): their field indices (-1 for no name_field), none
/// when the config names neither. What each field holds is joined into
/// `raw.fields`; a missing field is an input_error naming the layer and the key.
std::vector<int> attribute_fields(const IngestConfig& cfg, const Source& src, RawMap& raw)
{
    const DatasetSpec& d = cfg.dataset;
    std::vector<int> idx;
    if (d.name_field.empty() && d.attributes.empty()) {
        return idx;
    }
    raw.named = !d.name_field.empty();
    idx.push_back(d.name_field.empty() ? -1 : src.field(d.name_field, "dataset.name_field"));
    std::vector<chains::AttributeField> fields;
    for (const auto& a : d.attributes) {
        const int i = src.field(a, "dataset.attributes");
        idx.push_back(i);
        const OGRFieldType t = OGR_Fld_GetType(OGR_FD_GetFieldDefn(OGR_L_GetLayerDefn(src.layer()), i));
        fields.push_back({a, t == OFTInteger || t == OFTInteger64 ? chains::AttributeType::integer
                             : t == OFTReal                       ? chains::AttributeType::real
                                                                  : chains::AttributeType::text});
    }
    join_fields(raw.fields, fields);
    return idx;
}

/// A feature's values of attribute_fields as text: integers in decimal,
/// reals in the shortest form that reads back as the same double, "" where
/// a field is null or unset.
std::vector<std::string> attribute_values(OGRFeatureH f, const std::vector<int>& idx)
{
    std::vector<std::string> out;
    out.reserve(idx.size());
    for (const int i : idx) {
        if (i < 0 || !OGR_F_IsFieldSetAndNotNull(f, i)) {
            out.emplace_back();
            continue;
        }
        switch (OGR_Fld_GetType(OGR_F_GetFieldDefnRef(f, i))) {
        case OFTInteger:
        case OFTInteger64:
            out.push_back(std::to_string(OGR_F_GetFieldAsInteger64(f, i)));
            break;
        case OFTReal: {
            char buf[40];
            const auto r = std::to_chars(buf, buf + sizeof buf, OGR_F_GetFieldAsDouble(f, i));
            out.emplace_back(buf, r.ptr);
            break;
        }
        default:
            out.emplace_back(OGR_F_GetFieldAsString(f, i));
            break;
        }
    }
    return out;
}

/// What a code field needs: text, or an integer (whose codes have no leading zeros).
constexpr const char* code_type = "text or an integer";
constexpr const char* id_type = "an integer (Integer or Integer64)";
constexpr const char* number_type = "a number, or text holding one";

/// The internal point fields, the class field and ATOTAL, whichever are given: of usable types.
void expect_optional_types(const Source& src, int lat, int lon, int cls, int area)
{
    src.expect_type(lat, "dataset.intpt_lat_field", {OFTReal, OFTInteger, OFTInteger64, OFTString}, number_type);
    src.expect_type(lon, "dataset.intpt_lon_field", {OFTReal, OFTInteger, OFTInteger64, OFTString}, number_type);
    src.expect_type(cls, "dataset.class_field", {OFTString, OFTInteger, OFTInteger64}, code_type);
    src.expect_type(area, "the face weight ATOTAL", {OFTReal, OFTInteger, OFTInteger64, OFTString}, number_type);
}

std::vector<std::vector<int>> level_fields(const Source& src, const std::vector<LevelSpec>& levels)
{
    std::vector<std::vector<int>> out;
    for (const auto& l : levels) {
        std::vector<int> idx;
        for (const auto& name : l.fields) {
            const std::string needed_for = "level '" + l.name + "'";
            idx.push_back(src.expect_type(src.field(name, needed_for.c_str()), needed_for,
                                          {OFTString, OFTInteger, OFTInteger64}, code_type));
        }
        out.push_back(idx);
    }
    return out;
}

/// A FACES layer, checked, with its field indices.
struct FacesLayer {
    Source src;
    int tfid, lat, lon, area;
    std::vector<std::vector<int>> levels;
};
FacesLayer open_faces(const IngestConfig& cfg, const fs::path& path)
{
    Source src(path, cfg.dataset.layer, "TIGER FACES");
    src.expect_geometry({wkbPolygon, wkbMultiPolygon}, "TIGER FACES need polygons");
    const int tfid = src.expect_type(src.field("TFID", "TIGER FACES face id"), "TFID, the face id",
                                     {OFTInteger, OFTInteger64}, id_type);
    auto levels = level_fields(src, cfg.levels);
    const int lat = src.optional_field(cfg.dataset.intpt_lat_field);
    const int lon = src.optional_field(cfg.dataset.intpt_lon_field);
    const int area = src.optional_field("ATOTAL");
    expect_optional_types(src, lat, lon, -1, area);
    return {std::move(src), tfid, lat, lon, area, std::move(levels)};
}

/// An EDGES layer, checked, with its field indices.
struct EdgesLayer {
    Source src;
    int tlid, tfidl, tfidr, cls;
};
EdgesLayer open_edges(const IngestConfig& cfg, const fs::path& path)
{
    Source src(path, cfg.dataset.layer, "TIGER EDGES");
    src.expect_geometry({wkbLineString}, "TIGER EDGES need line strings");
    const std::initializer_list<OGRFieldType> ids{OFTInteger, OFTInteger64};
    const int tlid = src.expect_type(src.field("TLID", "TIGER EDGES edge id"), "TLID, the edge id", ids, id_type);
    const int tfidl = src.expect_type(src.field("TFIDL", "TIGER EDGES face on the left"), "TFIDL, the face on the left",
                                      ids, id_type);
    const int tfidr = src.expect_type(src.field("TFIDR", "TIGER EDGES face on the right"),
                                      "TFIDR, the face on the right", ids, id_type);
    const int cls = src.optional_field(cfg.dataset.class_field);
    expect_optional_types(src, -1, -1, cls, -1);
    return {std::move(src), tlid, tfidl, tfidr, cls};
}

/// A polygon layer, checked, with its field indices.
struct PolygonLayer {
    Source src;
    int code, lat, lon, cls;
    std::vector<std::vector<int>> levels;
};
PolygonLayer open_polygons(const IngestConfig& cfg, const fs::path& path)
{
    Source src(path, cfg.dataset.layer, "polygons");
    src.filter(cfg.dataset.where);
    src.expect_geometry({wkbPolygon, wkbMultiPolygon}, "a polygons dataset needs polygons");
    const int code = src.expect_type(src.field(cfg.dataset.code_field, "dataset.code_field"), "dataset.code_field",
                                     {OFTString, OFTInteger, OFTInteger64}, code_type);
    auto levels = level_fields(src, cfg.levels);
    const int lat = src.optional_field(cfg.dataset.intpt_lat_field);
    const int lon = src.optional_field(cfg.dataset.intpt_lon_field);
    if (!cfg.dataset.intpt_lat_field.empty() && (lat < 0 || lon < 0)) {
        throw input_error(src.where() + ": no field '" + cfg.dataset.intpt_lat_field + "' or '" +
                          cfg.dataset.intpt_lon_field + "' (dataset.intpt_lat_field/intpt_lon_field)");
    }
    const int cls = src.optional_field(cfg.dataset.class_field);
    expect_optional_types(src, lat, lon, cls, -1);
    return {std::move(src), code, lat, lon, cls, std::move(levels)};
}

/// A line layer, checked, with its field indices.
struct LineLayer {
    Source src;
    int cls;
};
LineLayer open_lines(const IngestConfig& cfg, const fs::path& path)
{
    Source src(path, cfg.dataset.layer, "lines");
    src.filter(cfg.dataset.where);
    src.expect_geometry({wkbLineString, wkbMultiLineString}, "a lines dataset needs line strings");
    const int cls = src.optional_field(cfg.dataset.class_field);
    if (!cfg.dataset.class_field.empty() && cls < 0) {
        throw input_error(src.where() + ": no field '" + cfg.dataset.class_field + "' (dataset.class_field)");
    }
    expect_optional_types(src, -1, -1, cls, -1);
    return {std::move(src), cls};
}

/// One FACES file's faces into `raw` as units (file index: the next in
/// raw.files), each face once: a TFID already in `face_unit` is skipped.
void read_faces_file(const IngestConfig& cfg, const fs::path& path, RawMap& raw,
                     std::unordered_map<int64_t, uint32_t>& face_unit)
{
    // Named, not a structured binding: lambdas below use them, and Clang 14
    // (the sanitizer build's compiler) cannot capture a binding.
    FacesLayer layer = open_faces(cfg, path);
    Source& src = layer.src;
    const int tfid = layer.tfid, lat_i = layer.lat, lon_i = layer.lon, area_i = layer.area;
    const auto& fields = layer.levels;
    const std::vector<int> attrs = attribute_fields(cfg, src, raw);
    OGR_L_SetIgnoredFields(src.layer(), std::array<const char*, 2>{"OGR_GEOMETRY", nullptr}.data());
    const auto file = static_cast<uint32_t>(raw.files.size());
    raw.files.push_back(src.name());
    src.for_each([&](OGRFeatureH f, int64_t index) {
        const int64_t id = OGR_F_GetFieldAsInteger64(f, tfid);
        if (face_unit.contains(id)) {
            return; // a face listed by two counties' files
        }
        RawUnit u;
        for (size_t L = 0; L < cfg.levels.size(); ++L) {
            u.codes.push_back(level_code(cfg.levels[L], f, fields[L], ""));
        }
        u.intpt = intpt(f, lat_i, lon_i);
        u.weight = area_i >= 0 ? OGR_F_GetFieldAsDouble(f, area_i) : 0.0;
        u.source = {file, index};
        u.sid = static_cast<uint64_t>(id);
        u.attrs = attribute_values(f, attrs);
        face_unit.emplace(id, static_cast<uint32_t>(raw.units.size()));
        raw.units.push_back(std::move(u));
    });
}

/// One EDGES file's edges into `raw` (file index: the next in raw.files),
/// their sides the faces of `face_unit`. An edge whose TLID is in `seen_tlid`
/// (a neighbouring county's file had it) only fills the sides that copy left
/// without a face. With `keep_foreign`, a side whose TFID is not in
/// `face_unit` is listed in raw.foreign for another part to resolve.
/// An edge of a county's EDGES bounds a face of that county: one that names
/// no face of `face_unit` on either side means EDGES and FACES that do not
/// belong together (another county's, or FACES with faces missing), and
/// input_error says how many, with examples and where they are. `faces_from`
/// names the FACES files for that message; empty, nothing is checked (a
/// part of a region build, whose edges another part may resolve: a build
/// whose parts cannot is done whole, and checked then).
void read_edges_file(const IngestConfig& cfg, const fs::path& path, RawMap& raw,
                     const std::unordered_map<int64_t, uint32_t>& face_unit,
                     std::unordered_map<int64_t, uint32_t>& seen_tlid, bool keep_foreign, const std::string& faces_from)
{
    size_t edges = 0, orphans = 0;
    std::string examples;
    EdgesLayer layer = open_edges(cfg, path); // named: see read_faces_file
    Source& src = layer.src;
    const int tlid = layer.tlid, tfidl = layer.tfidl, tfidr = layer.tfidr, cls = layer.cls;
    const auto file = static_cast<uint32_t>(raw.files.size());
    raw.files.push_back(src.name());
    std::vector<LonLatE6> pts;
    // The unit of a side, and its TFID where the face is not one of ours (else 0).
    auto side = [&](OGRFeatureH f, int i) -> std::pair<uint32_t, uint64_t> {
        if (!OGR_F_IsFieldSetAndNotNull(f, i)) {
            return {no_unit, 0};
        }
        const int64_t id = OGR_F_GetFieldAsInteger64(f, i);
        auto it = face_unit.find(id);
        return it == face_unit.end() ? std::pair{no_unit, static_cast<uint64_t>(id)}
                                     : std::pair{it->second, uint64_t{0}};
    };
    src.for_each([&](OGRFeatureH f, int64_t index) {
        const int64_t id = OGR_F_GetFieldAsInteger64(f, tlid);
        const auto [l, l_foreign] = side(f, tfidl);
        const auto [r, r_foreign] = side(f, tfidr);
        ++edges;
        if (l == no_unit && r == no_unit && ++orphans <= 3) {
            // One call at a time: GDAL returns the string in a buffer it reuses.
            const std::string left = OGR_F_GetFieldAsString(f, tfidl);
            const std::string right = OGR_F_GetFieldAsString(f, tfidr);
            examples += std::string(examples.empty() ? "" : "; ") + "TLID " + std::to_string(id) + " (TFIDL " + left +
                        ", TFIDR " + right + ")";
            if (OGRGeometryH g = OGR_F_GetGeometryRef(f); g != nullptr && OGR_G_GetPointCount(g) > 0) {
                char at[64];
                std::snprintf(at, sizeof at, " at %.6f, %.6f", OGR_G_GetX(g, 0), OGR_G_GetY(g, 0));
                examples += at;
            }
        }
        if (auto it = seen_tlid.find(id); it != seen_tlid.end()) {
            // The same edge from a neighbouring county: it may know the other side's face.
            auto& pl = raw.left[it->second];
            auto& pr = raw.right[it->second];
            pl = pl == no_unit ? l : pl;
            pr = pr == no_unit ? r : pr;
            return;
        }
        OGRGeometryH g = OGR_F_GetGeometryRef(f);
        const std::string where = src.name() + ":" + std::to_string(index);
        if (g == nullptr || wkbFlatten(OGR_G_GetGeometryType(g)) != wkbLineString) {
            throw input_error(where + ": TLID " + std::to_string(id) + " has no line string geometry");
        }
        snap_points(g, pts, where);
        raw.points_read += pts.size();
        const uint32_t c = cls >= 0 ? raw.intern_class(OGR_F_GetFieldAsString(f, cls)) : 0;
        const auto p = static_cast<uint32_t>(raw.polyline_count());
        seen_tlid.emplace(id, p);
        raw.add_polyline(pts, l, r, c, static_cast<uint64_t>(id), {file, index});
        if (keep_foreign && l_foreign != 0) {
            raw.foreign.push_back({p, 0, l_foreign});
        }
        if (keep_foreign && r_foreign != 0) {
            raw.foreign.push_back({p, 1, r_foreign});
        }
    });
    if (faces_from.empty()) {
        return;
    }
    if (orphans == edges && edges > 0) {
        throw input_error(src.where() + " and " + faces_from + " share no face: every edge names faces that " +
                          faces_from + " does not hold (e.g. " + examples +
                          "); give each county's EDGES with its own FACES");
    }
    if (orphans > 0) {
        throw input_error(src.where() + ": " + std::to_string(orphans) + " of " + std::to_string(edges) +
                          " edges name no face of " + faces_from + " on either side (e.g. " + examples +
                          "): FACES is incomplete or of another county");
    }
}

/// Every face's boundary closes: at each end point of the edges that have
/// the face on one side only, an even number of them meet. An edge missing
/// from EDGES (a cut-off file, another vintage than FACES) leaves the
/// faces on its sides open, which ingest would map as a wrong boundary and
/// a later stage fail on; input_error names the face, the place and the
/// EDGES files.
void check_faces_close(const RawMap& raw, const std::string& edges_from)
{
    // (face, end point) once for each boundary edge of the face ending
    // there; sorted, a point of the face is open where its run is odd.
    std::vector<std::pair<uint32_t, uint64_t>> ends;
    for (size_t p = 0; p < raw.polyline_count(); ++p) {
        const uint32_t l = raw.left[p], r = raw.right[p];
        if (l == r) {
            continue; // inside one face (or outside every face given)
        }
        for (const uint32_t face : {l, r}) {
            if (face != no_unit) {
                ends.emplace_back(face, pack_key(raw.coords[raw.offsets[p]]));
                ends.emplace_back(face, pack_key(raw.coords[raw.offsets[p + 1] - 1]));
            }
        }
    }
    std::sort(ends.begin(), ends.end());
    // The first open face in unit order, at its smallest open point.
    for (size_t i = 0; i < ends.size();) {
        size_t j = i;
        while (j < ends.size() && ends[j] == ends[i]) {
            ++j;
        }
        if ((j - i) % 2 == 1) {
            const uint32_t face = ends[i].first;
            size_t count = 0;
            for (size_t k = i; k < ends.size() && ends[k].first == face;) {
                size_t m = k;
                while (m < ends.size() && ends[m] == ends[k]) {
                    ++m;
                }
                count += (m - k) % 2;
                k = m;
            }
            const LonLatE6 at = unpack_key(ends[i].second);
            const RawUnit& u = raw.units[face];
            char where[96];
            std::snprintf(where, sizeof where, "(%.6f, %.6f)", at.lon * 1e-6, at.lat * 1e-6);
            throw input_error(edges_from + ": the boundary of face TFID " + std::to_string(u.sid) + " (" +
                              raw.files[u.source.file] + ":" + std::to_string(u.source.feature) +
                              ") does not close: " + std::to_string(count) + " loose ends, the first at " + where +
                              ": an edge is missing (EDGES cut off, or of another vintage than FACES?)");
        }
        i = j;
    }
}

void read_tiger(const IngestConfig& cfg, RawMap& raw, const Log& log, const std::function<void(uint64_t)>& on_file)
{
    std::unordered_map<int64_t, uint32_t> face_unit;
    for (const auto& path : cfg.dataset.faces) {
        read_faces_file(cfg, path, raw, face_unit);
        log.info("read " + path.string() + ": " + std::to_string(raw.units.size()) + " faces so far");
        if (on_file) {
            on_file(0);
        }
    }
    std::unordered_map<int64_t, uint32_t> seen_tlid;
    const std::string faces_from =
        cfg.dataset.faces.size() == 1 ? cfg.dataset.faces.front().filename().string() : "the FACES files given";
    for (const auto& path : cfg.dataset.edges) {
        const uint64_t before = raw.points_read;
        read_edges_file(cfg, path, raw, face_unit, seen_tlid, false, faces_from);
        log.info("read " + path.string() + ": " + std::to_string(raw.polyline_count()) + " edges so far");
        if (on_file) {
            on_file(raw.points_read - before);
        }
    }
    check_faces_close(raw, cfg.dataset.edges.size() == 1 ? cfg.dataset.edges.front().filename().string()
                                                         : "the EDGES files given");
}

/// A ring's longitudes as the plane lays them out: micro-degrees east of
/// the central meridian (a UTM zone's own), in (-180, 180] degrees. Read straight, 180 and -180
/// are a turn apart, and a ring that touches the meridian 180 from the east
/// (written 180 there, see fit_to_globe) would wind the wrong way round.
std::vector<int64_t> eastings(const std::vector<LonLatE6>& r, const ProjectionParams& proj)
{
    // UTM's central meridian is its zone's.
    const double central = proj.kind == ProjectionParams::Kind::utm ? proj.utm_zone * 6.0 - 183.0 : proj.lon0_deg;
    const int64_t lon0 = std::llround(central * 1e6);
    std::vector<int64_t> x(r.size());
    for (size_t i = 0; i < r.size(); ++i) {
        x[i] = wrap_micro(r[i].lon - lon0);
    }
    return x;
}

/// Signed area sign of a ring in micro-degrees east of lon0 (exact).
int ring_orientation(const std::vector<LonLatE6>& r, const std::vector<int64_t>& x)
{
    int128 a = 0;
    for (size_t i = 0; i + 1 < r.size(); ++i) {
        a += static_cast<int128>(x[i]) * r[i + 1].lat - static_cast<int128>(x[i + 1]) * r[i].lat;
    }
    return (a > 0) - (a < 0);
}

double ring_area_deg2(const std::vector<LonLatE6>& r, const std::vector<int64_t>& x)
{
    double a = 0;
    for (size_t i = 0; i + 1 < r.size(); ++i) {
        a += 1e-12 * (static_cast<double>(x[i]) * r[i + 1].lat - static_cast<double>(x[i + 1]) * r[i].lat);
    }
    return 0.5 * a;
}

/// A feature for a message: its index, and its name where it has a
/// `name` or `NAME` attribute (Natural Earth's, GeoJSON's habit).
std::string feature_name(OGRFeatureH f, int64_t index)
{
    std::string out = "feature " + std::to_string(index);
    for (const char* field : {"name", "NAME"}) {
        const int i = OGR_F_GetFieldIndex(f, field);
        if (i >= 0 && OGR_F_IsFieldSetAndNotNull(f, i)) {
            out += std::string(" '") + OGR_F_GetFieldAsString(f, i) + "'";
            break;
        }
    }
    return out;
}

/// One polygon file into `raw` (a part of its own: file index 0).
void read_polygon_file(const IngestConfig& cfg, const fs::path& path, RawMap& raw)
{
    std::vector<LonLatE6> ring;
    {
        PolygonLayer layer = open_polygons(cfg, path); // named: see read_faces_file
        Source& src = layer.src;
        const int code_i = layer.code, lat_i = layer.lat, lon_i = layer.lon, cls = layer.cls;
        const auto& fields = layer.levels;
        const std::vector<int> attrs = attribute_fields(cfg, src, raw);
        const auto file = static_cast<uint32_t>(raw.files.size());
        raw.files.push_back(src.name());
        uint64_t empty_codes = 0; // features with an empty code, and the first three
        std::string examples;
        // Codes on more than one feature: the first feature of each code,
        // how many features repeat one, and the first three.
        std::unordered_map<std::string, std::string> first_of_code;
        uint64_t repeated = 0;
        std::string repeats;
        src.for_each([&](OGRFeatureH f, int64_t index) {
            const std::string where = src.name() + ":" + std::to_string(index);
            OGRGeometryH g = OGR_F_GetGeometryRef(f);
            if (g == nullptr || OGR_G_IsEmpty(g)) {
                ++raw.empty_geometries;
                return;
            }
            const auto type = wkbFlatten(OGR_G_GetGeometryType(g));
            if (type != wkbPolygon && type != wkbMultiPolygon) {
                throw input_error(where + ": geometry type is " + OGRGeometryTypeToName(type) +
                                  ", a polygons dataset needs polygons");
            }
            const std::string code = OGR_F_GetFieldAsString(f, code_i);
            if (code.empty()) {
                if (++empty_codes <= 3) {
                    examples += (examples.empty() ? "" : ", ") + feature_name(f, index);
                }
                return;
            }
            if (const auto [it, fresh] = first_of_code.emplace(code, feature_name(f, index)); !fresh) {
                if (++repeated <= 3) {
                    repeats += (repeats.empty() ? "'" : ", '") + code + "' on " + it->second + " and " +
                               feature_name(f, index);
                }
            }
            RawUnit u;
            for (size_t L = 0; L < cfg.levels.size(); ++L) {
                u.codes.push_back(level_code(cfg.levels[L], f, fields[L], code, where));
            }
            u.intpt = intpt(f, lat_i, lon_i);
            u.source = {file, index};
            u.attrs = attribute_values(f, attrs);
            const auto unit = static_cast<uint32_t>(raw.units.size());
            const uint32_t c = cls >= 0 ? raw.intern_class(OGR_F_GetFieldAsString(f, cls)) : 0;
            const int nparts = type == wkbPolygon ? 1 : OGR_G_GetGeometryCount(g);
            for (int part = 0; part < nparts; ++part) {
                OGRGeometryH poly = type == wkbPolygon ? g : OGR_G_GetGeometryRef(g, part);
                const int nrings = OGR_G_GetGeometryCount(poly);
                for (int ri = 0; ri < nrings; ++ri) {
                    snap_points(OGR_G_GetGeometryRef(poly, ri), ring, where);
                    raw.points_read += ring.size();
                    if (ring.size() < 2) {
                        continue;
                    }
                    if (!(ring.front() == ring.back())) {
                        ring.push_back(ring.front());
                    }
                    // Cut where the projection tears the globe, then checked.
                    for (auto& piece : split_at_cut(ring, cfg.projection)) {
                        fit_to_globe(piece, cfg.projection, where);
                        // Exterior rings counter-clockwise, holes clockwise: the unit is on the left.
                        const std::vector<int64_t> x = eastings(piece, cfg.projection);
                        const int o = ring_orientation(piece, x);
                        const bool unit_left = ri == 0 ? o >= 0 : o <= 0;
                        u.weight += (ri == 0 ? 1 : -1) * std::fabs(ring_area_deg2(piece, x));
                        raw.add_polyline(piece, unit_left ? unit : no_unit, unit_left ? no_unit : unit, c, 0,
                                         {file, index});
                    }
                }
            }
            raw.units.push_back(std::move(u));
        });
        if (repeated > 0) {
            const std::string what = src.name() + ": " + std::to_string(repeated) + " feature" +
                                     (repeated == 1 ? " repeats" : "s repeat") + " the '" + cfg.dataset.code_field +
                                     "' of another (" + repeats + (repeated > 3 ? ", ..." : "") + ")";
            if (!cfg.dataset.merge_duplicate_codes) {
                throw input_error(what + ": give each unit its own code, or set dataset.duplicate_code: merge to "
                                         "make each code one unit in parts");
            }
            std::fprintf(stderr, "tigerlod-ingest: %s merged, one unit a code (dataset.duplicate_code: merge)\n",
                         what.c_str());
        }
        if (empty_codes > 0) {
            const std::string what = src.name() + ": " + std::to_string(empty_codes) + " feature" +
                                     (empty_codes == 1 ? "" : "s") + " with an empty '" + cfg.dataset.code_field +
                                     "' (" + examples + (empty_codes > 3 ? ", ..." : "") + ")";
            if (!cfg.dataset.skip_empty_codes) {
                throw input_error(what + ": give each a code, or set dataset.empty_code: skip to leave them out");
            }
            raw.empty_codes += empty_codes; // the report's empty_codes
            std::fprintf(stderr, "tigerlod-ingest: %s left out (dataset.empty_code: skip)\n", what.c_str());
        }
    }
}

/// One line file into `raw` (a part of its own: file index 0).
void read_line_file(const IngestConfig& cfg, const fs::path& path, RawMap& raw)
{
    std::vector<LonLatE6> pts;
    {
        LineLayer layer = open_lines(cfg, path); // named: see read_faces_file
        Source& src = layer.src;
        const int cls = layer.cls;
        const auto file = static_cast<uint32_t>(raw.files.size());
        raw.files.push_back(src.name());
        src.for_each([&](OGRFeatureH f, int64_t index) {
            const std::string where = src.name() + ":" + std::to_string(index);
            OGRGeometryH g = OGR_F_GetGeometryRef(f);
            if (g == nullptr || OGR_G_IsEmpty(g)) {
                ++raw.empty_geometries;
                return;
            }
            const auto type = wkbFlatten(OGR_G_GetGeometryType(g));
            if (type != wkbLineString && type != wkbMultiLineString) {
                throw input_error(where + ": geometry type is " + OGRGeometryTypeToName(type) +
                                  ", a lines dataset needs line strings");
            }
            const uint32_t c = cls >= 0 ? raw.intern_class(OGR_F_GetFieldAsString(f, cls)) : 0;
            const int nparts = type == wkbLineString ? 1 : OGR_G_GetGeometryCount(g);
            for (int part = 0; part < nparts; ++part) {
                snap_points(type == wkbLineString ? g : OGR_G_GetGeometryRef(g, part), pts, where);
                raw.points_read += pts.size();
                fit_to_globe(pts, cfg.projection, where);
                raw.add_polyline(pts, no_unit, no_unit, c, 0, {file, index});
            }
        });
    }
}

/// A map of `kind` with the config's levels and nothing in it yet.
RawMap empty_map(const IngestConfig& cfg, RawMap::Kind kind)
{
    RawMap raw;
    raw.kind = kind;
    for (const auto& l : cfg.levels) {
        raw.level_names.push_back(l.name);
    }
    return raw;
}

/// Read every file with `read_one(i, part)` on up to `threads` threads, each
/// into a part of its own, handed to `take` on the thread that read it. The
/// first error in file order is the one thrown, whatever the thread count.
template <class F>
void read_each(const std::vector<fs::path>& files, unsigned threads, const Log& log, F&& read_one,
               const std::function<void(size_t, RawMap&&)>& take, std::span<const size_t> only = {})
{
    std::vector<size_t> all;
    if (only.empty()) {
        all.resize(files.size());
        std::iota(all.begin(), all.end(), size_t{0});
        only = all;
    }
    std::vector<std::exception_ptr> errors(files.size());
    std::atomic<size_t> next{0};
    auto work = [&] {
        for (size_t k = next++; k < only.size(); k = next++) {
            const size_t i = only[k];
            try {
                if (i >= files.size()) {
                    throw std::out_of_range("read_each: part " + std::to_string(i) + " of " +
                                            std::to_string(files.size()));
                }
                RawMap part;
                read_one(i, part);
                log.info("read " + files[i].string() + ": " + std::to_string(part.units.size()) + " units, " +
                         std::to_string(part.points_read) + " points");
                take(i, std::move(part));
            } catch (...) {
                errors[i] = std::current_exception();
            }
        }
    };
    std::vector<std::thread> pool;
    for (unsigned t = 1; t < std::min<size_t>(threads, only.size()); ++t) {
        pool.emplace_back(work);
    }
    work();
    for (auto& t : pool) {
        t.join();
    }
    for (const auto& e : errors) {
        if (e) {
            std::rethrow_exception(e);
        }
    }
}

/// Read every file into `raw`, in file order.
template <class F>
void read_files(const std::vector<fs::path>& files, unsigned threads, RawMap& raw, const Log& log, F&& read_one,
                const std::function<void(uint64_t)>& on_file)
{
    std::vector<RawMap> parts(files.size());
    read_each(
        files, threads, log, [&](size_t i, RawMap& part) { read_one(files[i], part); },
        [&](size_t i, RawMap&& part) {
            if (on_file) {
                on_file(part.points_read);
            }
            parts[i] = std::move(part);
        });
    size_t points = raw.coords.size(), lines = raw.polyline_count();
    for (const auto& part : parts) {
        points += part.coords.size();
        lines += part.polyline_count();
    }
    raw.reserve(points, lines);
    for (auto& part : parts) {
        raw.append(std::move(part));
    }
}

} // namespace

RawMap read_dataset(const IngestConfig& cfg, unsigned threads, const Log& log,
                    const std::function<void(uint64_t)>& on_file)
{
    RawMap raw;
    switch (cfg.dataset.kind) {
    case DatasetSpec::Kind::tiger:
        raw = empty_map(cfg, RawMap::Kind::edges);
        read_tiger(cfg, raw, log, on_file);
        break;
    case DatasetSpec::Kind::polygons:
        raw = empty_map(cfg, RawMap::Kind::polygon_rings);
        read_files(
            cfg.dataset.inputs, threads, raw, log,
            [&](const fs::path& p, RawMap& part) { read_polygon_file(cfg, p, part); }, on_file);
        break;
    case DatasetSpec::Kind::lines:
        raw = empty_map(cfg, RawMap::Kind::lines);
        read_files(
            cfg.dataset.inputs, threads, raw, log,
            [&](const fs::path& p, RawMap& part) { read_line_file(cfg, p, part); }, on_file);
        break;
    }
    return raw;
}

size_t dataset_files(const IngestConfig& cfg)
{
    return cfg.dataset.kind == DatasetSpec::Kind::tiger ? cfg.dataset.faces.size() + cfg.dataset.edges.size()
                                                        : cfg.dataset.inputs.size();
}

void read_polygon_parts(const IngestConfig& cfg, unsigned threads, const Log& log,
                        const std::function<void(size_t, RawMap&&)>& take, std::span<const size_t> only)
{
    read_each(
        cfg.dataset.inputs, threads, log,
        [&](size_t i, RawMap& part) {
            part = empty_map(cfg, RawMap::Kind::polygon_rings);
            read_polygon_file(cfg, cfg.dataset.inputs[i], part);
        },
        take, only);
}

void read_tiger_parts(const IngestConfig& cfg, unsigned threads, const Log& log,
                      const std::function<void(size_t, RawMap&&)>& take, std::span<const size_t> only)
{
    if (cfg.dataset.faces.size() != cfg.dataset.edges.size()) {
        throw std::logic_error("read_tiger_parts: FACES and EDGES files do not pair");
    }
    read_each(
        cfg.dataset.faces, threads, log,
        [&](size_t i, RawMap& part) {
            part = empty_map(cfg, RawMap::Kind::edges);
            std::unordered_map<int64_t, uint32_t> face_unit, seen_tlid;
            read_faces_file(cfg, cfg.dataset.faces[i], part, face_unit);
            read_edges_file(cfg, cfg.dataset.edges[i], part, face_unit, seen_tlid, true, "");
        },
        take, only);
}

void check_grid_span(const std::string& where, double grid_m, double span_x, double span_y, const std::string& what)
{
    constexpr double most = 2147483647.0; // a node's payload holds steps of 32 bits
    const double span = std::max(span_x, span_y);
    if (span <= most) {
        return;
    }
    const double grid = grid_m;
    // The next step up that fits, as a round figure (1, 2 or 5 times a power of ten).
    const double need = grid * span / most;
    double fit = std::pow(10.0, std::floor(std::log10(need)));
    for (const double m : {1.0, 2.0, 5.0, 10.0}) {
        if (fit * m >= need) {
            fit *= m;
            break;
        }
    }
    char buf[512];
    std::snprintf(buf, sizeof buf,
                  "%s: %s spans %.0f km %s in the projection, %.0f steps of projection.grid_m = %g m, more than "
                  "a Data Tree node holds across (2^31 - 1 steps, %.0f km at this grid): set projection.grid_m to "
                  "%g or more",
                  where.c_str(), what.c_str(), span * grid / 1000, span_x >= span_y ? "east-west" : "north-south", span,
                  grid, most * grid / 1000, fit);
    throw config_error(buf);
}

void validate_dataset(const IngestConfig& cfg)
{
    for (const auto& p : cfg.dataset.faces) {
        open_faces(cfg, p);
    }
    for (const auto& p : cfg.dataset.edges) {
        open_edges(cfg, p);
    }
    // A polygons or lines dataset's span on the grid, from every vertex
    // projected (a lon/lat box would not do: a map across the antimeridian
    // spans every longitude), so that a map wider than a node can hold is a
    // config error now rather than pack's. TIGER's many files are left to
    // ingest, which checks the projected map exactly.
    const Projection proj(cfg.projection);
    double lo_x = INFINITY, lo_y = INFINITY, hi_x = -INFINITY, hi_y = -INFINITY;
    auto take = [&](auto&& self, OGRGeometryH g) -> void {
        if (g == nullptr) {
            return;
        }
        for (int i = 0; i < OGR_G_GetGeometryCount(g); ++i) {
            self(self, OGR_G_GetGeometryRef(g, i));
        }
        for (int i = 0; i < OGR_G_GetPointCount(g); ++i) {
            double x = 0, y = 0;
            if (proj.forward(OGR_G_GetX(g, i), OGR_G_GetY(g, i), x, y)) {
                lo_x = std::min(lo_x, x);
                hi_x = std::max(hi_x, x);
                lo_y = std::min(lo_y, y);
                hi_y = std::max(hi_y, y);
            }
        }
    };
    for (const auto& p : cfg.dataset.inputs) {
        Source src = cfg.dataset.kind == DatasetSpec::Kind::polygons ? std::move(open_polygons(cfg, p).src)
                                                                     : std::move(open_lines(cfg, p).src);
        src.for_each([&](OGRFeatureH f, int64_t) { take(take, OGR_F_GetGeometryRef(f)); });
    }
    if (lo_x <= hi_x) {
        check_grid_span(cfg.file.string(), cfg.projection.grid_m, hi_x - lo_x, hi_y - lo_y, "the inputs' map");
    }
}

std::string gdal_version()
{
    return std::string("GDAL ") + GDALVersionInfo("RELEASE_NAME");
}

} // namespace tigerlod::ingest
