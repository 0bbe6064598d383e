#pragma once
/// @file projection.hpp
/// Map projections onto the integer grid, on GeographicLib (Karney 2011,
/// "Transverse Mercator with an accuracy of a few nanometers"; Snyder 1987
/// for the conic forms as implemented in GeographicLib's AlbersEqualArea and
/// LambertConformalConic). Errors of the projections themselves are below a
/// micrometre; the grid rounding (half a grid step) dominates. For the
/// default Albers, to_grid evaluates Snyder's closed forms instead (3.5 times
/// as fast) and asks GeographicLib only where they could round differently.

#include "core/geometry.hpp"

#include <memory>
#include <optional>
#include <string>

namespace tigerlod {

/// Parameters of a projection and its grid. Plain data: stored in chain
/// stores, so later stages and readers can map grid points back to lon/lat.
struct ProjectionParams {
    enum class Kind : uint8_t { albers = 0, lcc = 1, tm = 2, utm = 3 };
    Kind kind = Kind::albers;
    double lon0_deg = -96.0;   ///< central meridian
    double lat0_deg = 23.0;    ///< latitude where y = false_northing (albers, lcc, tm)
    double stdlat1_deg = 29.5; ///< first standard parallel (albers, lcc)
    double stdlat2_deg = 45.5; ///< second standard parallel (albers, lcc)
    double k0 = 1.0;           ///< scale on the standard parallels / central meridian
    int utm_zone = 0;          ///< 1..60 (utm)
    bool utm_north = true;     ///< hemisphere (utm)
    double false_easting_m = 0.0;
    double false_northing_m = 0.0;
    double grid_m = 0.01; ///< size of one grid step in metres
    // The ellipsoid: GRS 80, as NAD83.
    double a_m = 6378137.0;
    double f = 1.0 / 298.257222101;

    friend bool operator==(const ProjectionParams&, const ProjectionParams&) = default;
};

/// Name of a projection kind ("albers", "lcc", "tm", "utm").
const char* projection_kind_name(ProjectionParams::Kind kind) noexcept;
/// Parse a kind name; std::nullopt if unknown.
std::optional<ProjectionParams::Kind> parse_projection_kind(const std::string& name) noexcept;

/// A projection ready to use. Thread-safe for concurrent calls.
class Projection {
  public:
    /// Throws config_error for parameters out of range (standard parallels,
    /// UTM zone, grid_m <= 0).
    explicit Projection(const ProjectionParams& params);
    ~Projection();
    Projection(Projection&&) noexcept;
    Projection& operator=(Projection&&) noexcept;

    const ProjectionParams& params() const noexcept;

    /// Project lon/lat in degrees onto the grid. Returns std::nullopt outside
    /// the projection's domain: a non-finite or out-of-range lon/lat, more than
    /// 30 degrees from the central meridian for tm and utm, or a grid
    /// coordinate that does not fit in 32 bits.
    /// For Albers with k0 = 1 the point is projected by Snyder's formulas,
    /// several times faster, and rounded from them unless it lies within 10 um
    /// of a half-step tie; they agree with GeographicLib within 1 um (checked
    /// at construction, else not used), so the result is to_grid_reference's.
    std::optional<GridPoint> to_grid(double lon_deg, double lat_deg) const noexcept;
    /// to_grid through GeographicLib alone.
    std::optional<GridPoint> to_grid_reference(double lon_deg, double lat_deg) const noexcept;
    /// Whether to_grid has Snyder's formulas to go by.
    bool fast_albers() const noexcept;

    /// Project lon/lat onto the grid without rounding (fractional grid
    /// units); false outside the domain to_grid_reference has.
    bool forward(double lon_deg, double lat_deg, double& gx, double& gy) const noexcept;

    /// Map a grid point (possibly fractional) back to lon/lat in degrees.
    void to_lonlat(double gx, double gy, double& lon_deg, double& lat_deg) const noexcept;

    /// Point scale k at lon/lat (ground metres per projected metre is 1/k
    /// along the parallel for the conics).
    double scale(double lon_deg, double lat_deg) const noexcept;

    /// A lower bound s > 0 on the projection's scale over the grid box `box`
    /// in every direction: any curve inside the box is at most its
    /// projected length / s long on the ellipsoid, so a point within planar
    /// distance d of a segment, both in the box, is within d / s ground
    /// metres of the segment's image (the planar segment joining them lies
    /// in the box). Transverse Mercator: k0, its scale on the central
    /// meridian and its least anywhere. The conics: their scale depends on
    /// latitude alone, least on the latitude of origin and growing toward
    /// either pole (checked over every latitude in the tests), and
    /// latitude is monotone in the distance from the cone's apex, so its
    /// range over the box is set by the corners and the box's point nearest
    /// the apex; LCC is conformal (s = k), Albers scales a meridian by 1/k
    /// and a parallel by k, every other direction between them (s =
    /// min(k, 1/k)). With a relative margin of 1e-9 for rounding. 0 when the
    /// box is empty or reaches a pole where the scale has no positive bound.
    double smallest_scale(const GridBox& box) const noexcept;

    /// The geodesic distance in metres between two lon/lat points (degrees)
    /// on the projection's ellipsoid (GeographicLib's Geodesic, Karney 2013:
    /// accurate to nanometres).
    double geodesic_m(double lon1_deg, double lat1_deg, double lon2_deg, double lat2_deg) const noexcept;

    /// A lower bound on the projected distance, in metres, between any two
    /// distinct points of a lon/lat lattice of step `step_deg` that lie in the
    /// band of latitudes [lat_lo_deg, lat_hi_deg]: the smaller of the lattice's
    /// north-south and east-west ground steps there, each times the smallest
    /// scale of the projection in that direction over the band (slightly
    /// widened), with a 1% margin. 0 where the band reaches a pole.
    double lattice_separation_m(double step_deg, double lat_lo_deg, double lat_hi_deg) const noexcept;

    /// A one-line description, e.g. "albers lon0=-96 lat0=23 stdlat=29.5,45.5 grid=0.01m".
    std::string describe() const;

  private:
    struct Impl;
    std::unique_ptr<Impl> m_impl;
}; // class Projection

} // namespace tigerlod
