#pragma once
/// @file gdal_output.hpp
/// Writing a vector file with GDAL so that a failed write cannot pass:
/// GDAL's C API drops some failures (GDALClose returns nothing before 3.7,
/// and the GeoJSON and GeoPackage writers report a full disk, if at all,
/// only through the error handler), so a writer that trusted return values
/// alone would leave a cut-off file behind an exit 0. A GdalErrorTrap
/// records every error GDAL raises on its thread while it lives, and
/// close_and_check() closes the dataset, then reads the file back and
/// compares each layer's feature count with what was written.

#include "core/projection.hpp"

#include <gdal.h>
#include <ogr_srs_api.h>

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>

namespace tigerlod {

/// While it lives, the errors GDAL raises on this thread (CE_Failure and
/// CE_Fatal) are kept here instead of printed; warnings are dropped.
/// Nested traps each see their own errors only.
class GdalErrorTrap {
  public:
    GdalErrorTrap();
    ~GdalErrorTrap();
    GdalErrorTrap(const GdalErrorTrap&) = delete;
    GdalErrorTrap& operator=(const GdalErrorTrap&) = delete;

    bool failed() const noexcept { return m_count > 0; }
    /// The first error's message ("" if none).
    const std::string& first() const noexcept { return m_first; }
    /// Called by GDAL's handler; not for other use.
    void record(const char* message);

  private:
    int m_count = 0;
    std::string m_first;
}; // class GdalErrorTrap

/// Make the dates GDAL writes into files fixed, so that the same inputs give
/// the same bytes: GeoPackage's gpkg_contents.last_change is otherwise the
/// time of writing. Sets GDAL's OGR_CURRENT_DATE to SOURCE_DATE_EPOCH (the
/// reproducible-builds convention: seconds since 1970) if that is set, else
/// to 1970-01-01T00:00:00.000Z; an OGR_CURRENT_DATE the user set is kept.
/// A SOURCE_DATE_EPOCH that is not a whole number of seconds from 0 to
/// 9999-12-31 throws usage_error (exit 2) naming it. Call before the stage
/// does its work, so that the fault is found before it, not after.
void fix_gdal_dates();

/// Close `ds` (written to `path`) and make sure the file holds what was
/// written: no error GDAL raised while `trap` lived (the writes and the
/// close), the file opens again, and each layer named in `expected` has
/// that many features. Throws environment_error naming `path` and the fault
/// otherwise (exit 3: a full disk, a failed device); `who` prefixes the
/// message ("export", "verify").
void close_and_check(GDALDatasetH ds, const std::filesystem::path& path, const std::map<std::string, int64_t>& expected,
                     const GdalErrorTrap& trap, const std::string& who);

/// The tree's projection as a GDAL spatial reference: EPSG:5070 for the
/// default CONUS Albers on GRS 80, else the projection built from its
/// parameters (on NAD83 where the ellipsoid is GRS 80). Throws usage_error,
/// its message prefixed by `who`, for a conic with k0 != 1, which PROJ's
/// conics cannot state. The caller destroys it (OSRDestroySpatialReference).
OGRSpatialReferenceH tree_srs(const ProjectionParams& p, const std::string& who);

} // namespace tigerlod
