#include "core/gdal_output.hpp"

#include "core/errors.hpp"

#include <cpl_conv.h>
#include <cpl_error.h>
#include <ogr_api.h>
#include <ogr_srs_api.h>

#include <cstdlib>
#include <ctime>

namespace fs = std::filesystem;

namespace tigerlod {

namespace {

void CPL_STDCALL trap_handler(CPLErr level, CPLErrorNum, const char* message)
{
    if (level == CE_Failure || level == CE_Fatal) {
        static_cast<GdalErrorTrap*>(CPLGetErrorHandlerUserData())->record(message);
    }
}

} // namespace

GdalErrorTrap::GdalErrorTrap()
{
    CPLPushErrorHandlerEx(trap_handler, this);
}

GdalErrorTrap::~GdalErrorTrap()
{
    CPLPopErrorHandler();
}

void GdalErrorTrap::record(const char* message)
{
    if (m_count++ == 0) {
        m_first = message != nullptr ? message : "";
    }
}

void fix_gdal_dates()
{
    if (CPLGetConfigOption("OGR_CURRENT_DATE", nullptr) != nullptr) {
        return;
    }
    std::time_t t = 0;
    if (const char* epoch = std::getenv("SOURCE_DATE_EPOCH"); epoch != nullptr && *epoch != '\0') {
        // Digits only (no sign, no spaces), up to 9999-12-31T23:59:59Z: a
        // date the user set and we cannot write is refused, not replaced.
        constexpr long long last = 253402300799LL;
        long long v = 0;
        bool ok = true;
        for (const char* c = epoch; *c != '\0' && ok; ++c) {
            ok = *c >= '0' && *c <= '9' && v <= last;
            v = ok ? v * 10 + (*c - '0') : v;
        }
        if (!ok || v > last) {
            throw usage_error(std::string("SOURCE_DATE_EPOCH is '") + epoch +
                              "': expected seconds since 1970-01-01 UTC, a whole number from 0 to " +
                              std::to_string(last) + " (9999-12-31)");
        }
        t = static_cast<std::time_t>(v);
    }
    std::tm utc{};
    gmtime_r(&t, &utc);
    char text[32];
    std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%S.000Z", &utc);
    CPLSetConfigOption("OGR_CURRENT_DATE", text);
}

void close_and_check(GDALDatasetH ds, const fs::path& path, const std::map<std::string, int64_t>& expected,
                     const GdalErrorTrap& trap, const std::string& who)
{
    GDALClose(ds);
    if (trap.failed()) {
        throw environment_error(who + ": cannot write " + path.string() + ": " + trap.first());
    }
    // Read back: a writer that lost bytes without a word (a short write
    // its driver did not check) leaves a file that does not open or holds
    // fewer features.
    GdalErrorTrap reading;
    GDALDatasetH back = GDALOpenEx(path.c_str(), GDAL_OF_VECTOR | GDAL_OF_READONLY, nullptr, nullptr, nullptr);
    if (back == nullptr) {
        throw environment_error(who + ": " + path.string() +
                                " was written but does not read back (a full disk or a failed device?): " +
                                (reading.failed() ? reading.first() : std::string("GDAL cannot open it")));
    }
    std::string fault;
    for (const auto& [name, count] : expected) {
        OGRLayerH layer = GDALDatasetGetLayerByName(back, name.c_str());
        const int64_t got = layer == nullptr ? -1 : OGR_L_GetFeatureCount(layer, TRUE);
        if (got != count && fault.empty()) {
            fault = layer == nullptr ? "no layer '" + name + "'"
                                     : "layer '" + name + "' reads back " + std::to_string(got) + " features of " +
                                           std::to_string(count);
        }
    }
    GDALClose(back);
    if (fault.empty() && reading.failed()) {
        fault = reading.first();
    }
    if (!fault.empty()) {
        throw environment_error(
            who + ": " + path.string() +
            " was written but does not read back whole (a full disk or a failed device?): " + fault);
    }
}

OGRSpatialReferenceH tree_srs(const ProjectionParams& p, const std::string& who)
{
    using K = ProjectionParams::Kind;
    OGRSpatialReferenceH srs = OSRNewSpatialReference(nullptr);
    const bool grs80 = p.a_m == 6378137.0 && p.f == 1.0 / 298.257222101;
    if (p == ProjectionParams{.grid_m = p.grid_m}) {
        OSRImportFromEPSG(srs, 5070); // NAD83 / Conus Albers: the default, grid aside
        return srs;
    }
    if ((p.kind == K::albers || p.kind == K::lcc) && p.k0 != 1.0) {
        OSRDestroySpatialReference(srs);
        throw usage_error(who + ": the tree's projection (" + std::string(projection_kind_name(p.kind)) +
                          " with k0 != 1) has no CRS GDAL can state: use --crs lonlat");
    }
    OSRSetProjCS(srs, (std::string("tigerlod ") + projection_kind_name(p.kind)).c_str());
    if (grs80) {
        OSRSetWellKnownGeogCS(srs, "NAD83");
    } else {
        OSRSetGeogCS(srs, "tigerlod", "tigerlod", "tigerlod", p.a_m, 1.0 / p.f, "Greenwich", 0.0, "degree",
                     0.0174532925199433);
    }
    switch (p.kind) {
    case K::albers:
        OSRSetACEA(srs, p.stdlat1_deg, p.stdlat2_deg, p.lat0_deg, p.lon0_deg, p.false_easting_m, p.false_northing_m);
        break;
    case K::lcc:
        OSRSetLCC(srs, p.stdlat1_deg, p.stdlat2_deg, p.lat0_deg, p.lon0_deg, p.false_easting_m, p.false_northing_m);
        break;
    case K::tm:
        OSRSetTM(srs, p.lat0_deg, p.lon0_deg, p.k0, p.false_easting_m, p.false_northing_m);
        break;
    case K::utm:
        OSRSetUTM(srs, p.utm_zone, p.utm_north ? TRUE : FALSE);
        break;
    }
    return srs;
}

} // namespace tigerlod
