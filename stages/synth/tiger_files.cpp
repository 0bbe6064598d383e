#include "stages/synth/tiger_files.hpp"

#include "core/errors.hpp"
#include "core/timing.hpp"
#include "stages/synth/zip_writer.hpp"

#include <cpl_string.h>
#include <cpl_vsi.h>
#include <gdal.h>
#include <ogr_api.h>
#include <ogr_srs_api.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <initializer_list>
#include <cstdio>

namespace tigerlod::synth {

namespace {

std::atomic<uint64_t> next_folder{0};

using Clock = std::chrono::steady_clock;

/// An attribute of a shapefile: its name, type and width.
struct Field {
    const char* name;
    OGRFieldType type;
    int width;
};

/// A shapefile being written into a /vsimem/ folder of its own.
class MemShapefile {
  public:
    MemShapefile(const std::string& base, OGRwkbGeometryType type, std::initializer_list<Field> fields) : m_base(base)
    {
        m_folder = "/vsimem/tigerlod-synth-" + std::to_string(next_folder++);
        GDALDriverH driver = GDALGetDriverByName("ESRI Shapefile");
        m_ds = driver ? GDALCreate(driver, (m_folder + "/" + base + ".shp").c_str(), 0, 0, 0, GDT_Unknown, nullptr)
                      : nullptr;
        if (!m_ds) {
            throw environment_error("synth: GDAL cannot create a shapefile in memory: " +
                                    std::string(CPLGetLastErrorMsg()));
        }
        OGRSpatialReferenceH srs = OSRNewSpatialReference(nullptr);
        OSRSetWellKnownGeogCS(srs, "NAD83");
        OSRSetAxisMappingStrategy(srs, OAMS_TRADITIONAL_GIS_ORDER);
        const char* options[] = {"DBF_DATE_LAST_UPDATE=2020-12-18", "ENCODING=UTF-8", nullptr};
        m_layer = GDALDatasetCreateLayer(m_ds, base.c_str(), srs, type, const_cast<char**>(options));
        OSRDestroySpatialReference(srs);
        if (!m_layer) {
            throw environment_error("synth: GDAL cannot create layer " + base + ": " +
                                    std::string(CPLGetLastErrorMsg()));
        }
        for (const Field& field : fields) {
            OGRFieldDefnH f = OGR_Fld_Create(field.name, field.type);
            OGR_Fld_SetWidth(f, field.width);
            OGR_L_CreateField(m_layer, f, TRUE);
            OGR_Fld_Destroy(f);
        }
    }
    MemShapefile(const MemShapefile&) = delete;
    MemShapefile& operator=(const MemShapefile&) = delete;
    ~MemShapefile()
    {
        if (m_row) {
            OGR_F_Destroy(m_row);
        }
        if (m_ds) {
            GDALClose(m_ds);
        }
        VSIRmdirRecursive(m_folder.c_str());
    }

    /// The layer's one feature, to fill and write() row after row: one
    /// feature and its geometry for every row, not an allocation of each
    /// per row. A field a row does not set must be unset; `geometry` is
    /// the type of the feature's geometry, created with it.
    OGRFeatureH row(OGRwkbGeometryType geometry)
    {
        if (m_row == nullptr) {
            m_row = OGR_F_Create(OGR_L_GetLayerDefn(m_layer));
            OGR_F_SetGeometryDirectly(m_row, OGR_G_CreateGeometry(geometry));
        }
        OGR_F_SetFID(m_row, OGRNullFID);
        return m_row;
    }
    void write(OGRFeatureH f)
    {
        const OGRErr err = OGR_L_CreateFeature(m_layer, f);
        if (err != OGRERR_NONE) {
            throw environment_error("synth: GDAL cannot write a feature of " + m_base + ": " +
                                    std::string(CPLGetLastErrorMsg()));
        }
    }

    /// Close the shapefile and zip its files, in name order; the seconds
    /// from `start` to the closed files go to `seconds.shapefile`, the zip's
    /// to `seconds.deflate`.
    std::string zip(Clock::time_point start, WriteSeconds& seconds)
    {
        GDALClose(m_ds);
        m_ds = nullptr;
        seconds.shapefile += seconds_since(start);
        const auto closed = Clock::now();
        char** names = VSIReadDir(m_folder.c_str());
        std::vector<std::string> files;
        for (char** n = names; n && *n; ++n) {
            files.emplace_back(*n);
        }
        CSLDestroy(names);
        std::sort(files.begin(), files.end());
        ZipWriter zip(1); // the fastest deflate: 4x level 6 here, 10 % larger
        for (const auto& name : files) {
            vsi_l_offset size = 0;
            const GByte* data = VSIGetMemFileBuffer((m_folder + "/" + name).c_str(), &size, FALSE);
            zip.add(name, std::string_view(reinterpret_cast<const char*>(data), size_t(size)));
        }
        std::string bytes = zip.finish();
        seconds.deflate += seconds_since(closed);
        return bytes;
    }

  private:
    std::string m_base, m_folder;
    GDALDatasetH m_ds = nullptr;
    OGRLayerH m_layer = nullptr;
    OGRFeatureH m_row = nullptr;
};

void set_points(OGRGeometryH g, const std::vector<Pt>& pts)
{
    thread_local std::vector<double> x, y;
    x.resize(pts.size());
    y.resize(pts.size());
    for (size_t k = 0; k < pts.size(); ++k) {
        x[k] = double(pts[k].x) / 1e6;
        y[k] = double(pts[k].y) / 1e6;
    }
    OGR_G_SetPoints(g, int(pts.size()), x.data(), sizeof(double), y.data(), sizeof(double), nullptr, 0);
}

std::string degrees(int64_t e6, int width)
{
    char buf[32];
    std::snprintf(buf, sizeof buf, "%+0*.7f", width, double(e6) / 1e6);
    return buf;
}

/// The area of a face in square metres (rings' signed areas, holes taken off).
int64_t area_m2(const Face& f)
{
    double a = 0;
    double lat = 0;
    for (size_t r = 0; r < f.rings.size(); ++r) {
        const auto& ring = f.rings[r];
        double s = 0;
        for (size_t k = 0; k + 1 < ring.size(); ++k) {
            s += double(ring[k].x - ring[0].x) * double(ring[k + 1].y - ring[0].y) -
                 double(ring[k + 1].x - ring[0].x) * double(ring[k].y - ring[0].y);
        }
        a += r == 0 ? std::abs(s) / 2 : -std::abs(s) / 2;
        if (r == 0 && !ring.empty()) {
            lat = double(ring[0].y) / 1e6;
        }
    }
    const double m_per_e6 = 0.111319 * cos_turns(lat / 360) * 0.110574;
    return std::llround(std::max(0.0, a) * m_per_e6);
}

} // namespace

std::string edges_zip(const std::string& ssccc, const std::string& state, const std::string& county,
                      const std::vector<Edge>& edges, WriteSeconds& seconds)
{
    const auto start = Clock::now();
    MemShapefile shp("tl_2020_" + ssccc + "_edges", wkbLineString,
                     {{"STATEFP", OFTString, 2},
                      {"COUNTYFP", OFTString, 3},
                      {"TLID", OFTInteger64, 10},
                      {"TFIDL", OFTInteger64, 10},
                      {"TFIDR", OFTInteger64, 10},
                      {"MTFCC", OFTString, 5},
                      {"TNIDF", OFTInteger64, 10},
                      {"TNIDT", OFTInteger64, 10}});
    for (const auto& e : edges) {
        OGRFeatureH f = shp.row(wkbLineString);
        OGR_F_SetFieldString(f, 0, state.c_str());
        OGR_F_SetFieldString(f, 1, county.c_str());
        OGR_F_SetFieldInteger64(f, 2, e.tlid);
        for (const auto& [field, face] : {std::pair{3, e.tfidl}, {4, e.tfidr}}) {
            if (face != 0) {
                OGR_F_SetFieldInteger64(f, field, face);
            } else { // outside the nation
                OGR_F_UnsetField(f, field);
            }
        }
        OGR_F_SetFieldString(f, 5, e.mtfcc);
        OGR_F_SetFieldInteger64(f, 6, e.tnidf);
        OGR_F_SetFieldInteger64(f, 7, e.tnidt);
        set_points(OGR_F_GetGeometryRef(f), e.points);
        shp.write(f);
    }
    return shp.zip(start, seconds);
}

std::string faces_zip(const std::string& ssccc, const Nation& nation, const std::vector<Face>& faces,
                      WriteSeconds& seconds)
{
    const auto start = Clock::now();
    MemShapefile shp("tl_2020_" + ssccc + "_faces", wkbPolygon,
                     {{"TFID", OFTInteger64, 10},
                      {"STATEFP20", OFTString, 2},
                      {"COUNTYFP20", OFTString, 3},
                      {"TRACTCE20", OFTString, 6},
                      {"BLKGRPCE20", OFTString, 1},
                      {"BLOCKCE20", OFTString, 4},
                      {"LWFLAG", OFTString, 1},
                      {"ATOTAL", OFTInteger64, 14},
                      {"INTPTLAT", OFTString, 11},
                      {"INTPTLON", OFTString, 12}});
    for (const auto& face : faces) {
        const auto& blk = nation.units(block)[face.block];
        const auto& grp = nation.units(block_group)[blk.parent];
        const auto& trc = nation.units(tract)[grp.parent];
        const auto& cty = nation.units(county)[trc.parent];
        const auto& st = nation.units(state)[cty.parent];
        OGRFeatureH f = shp.row(wkbPolygon);
        OGR_F_SetFieldInteger64(f, 0, face.tfid);
        OGR_F_SetFieldString(f, 1, st.code.c_str());
        OGR_F_SetFieldString(f, 2, cty.code.c_str());
        OGR_F_SetFieldString(f, 3, trc.code.c_str());
        OGR_F_SetFieldString(f, 4, grp.code.c_str());
        OGR_F_SetFieldString(f, 5, blk.code.c_str());
        OGR_F_SetFieldString(f, 6, face.water ? "P" : "L");
        OGR_F_SetFieldInteger64(f, 7, area_m2(face));
        OGR_F_SetFieldString(f, 8, degrees(face.intpt.y, 11).c_str());
        OGR_F_SetFieldString(f, 9, degrees(face.intpt.x, 12).c_str());
        // The rings of the last face are kept and refilled, extra ones removed.
        OGRGeometryH g = OGR_F_GetGeometryRef(f);
        for (size_t r = 0; r < face.rings.size(); ++r) {
            if (int(r) == OGR_G_GetGeometryCount(g)) {
                OGR_G_AddGeometryDirectly(g, OGR_G_CreateGeometry(wkbLinearRing));
            }
            set_points(OGR_G_GetGeometryRef(g, int(r)), face.rings[r]);
        }
        while (OGR_G_GetGeometryCount(g) > int(face.rings.size())) {
            OGR_G_RemoveGeometry(g, OGR_G_GetGeometryCount(g) - 1, TRUE);
        }
        shp.write(f);
    }
    return shp.zip(start, seconds);
}

} // namespace tigerlod::synth
