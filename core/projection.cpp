#include "core/projection.hpp"

#include "core/errors.hpp"

#include <GeographicLib/AlbersEqualArea.hpp>
#include <GeographicLib/Geodesic.hpp>
#include <GeographicLib/LambertConformalConic.hpp>
#include <GeographicLib/Math.hpp>
#include <GeographicLib/TransverseMercator.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <numbers>
#include <optional>
#include <type_traits>
#include <variant>

namespace tigerlod {

const char* projection_kind_name(ProjectionParams::Kind kind) noexcept
{
    switch (kind) {
    case ProjectionParams::Kind::albers:
        return "albers";
    case ProjectionParams::Kind::lcc:
        return "lcc";
    case ProjectionParams::Kind::tm:
        return "tm";
    case ProjectionParams::Kind::utm:
        return "utm";
    }
    return "?";
}

std::optional<ProjectionParams::Kind> parse_projection_kind(const std::string& name) noexcept
{
    for (auto k : {ProjectionParams::Kind::albers, ProjectionParams::Kind::lcc, ProjectionParams::Kind::tm,
                   ProjectionParams::Kind::utm}) {
        if (name == projection_kind_name(k)) {
            return k;
        }
    }
    return std::nullopt;
}

namespace {

/// Snyder's (1987, pp. 101-102) ellipsoidal Albers, in GeographicLib's frame
/// (y from its latitude of origin), for k0 = 1: a few times faster than
/// GeographicLib's accurate divided differences, and within nanometres of
/// them in double precision. Only rounding uses it, and only away from the
/// half-step ties: to_grid gives what GeographicLib gives (see to_grid).
struct SnyderAlbers {
    double a = 0, e = 0, e2 = 0, n = 0, c = 0, rho0 = 0;

    SnyderAlbers(double a_m, double f, double lat1_deg, double lat2_deg, double origin_deg)
        : a(a_m), e(std::sqrt(f * (2 - f))), e2(f * (2 - f))
    {
        const double m1 = m(lat1_deg), m2 = m(lat2_deg), q1 = q(lat1_deg), q2 = q(lat2_deg);
        n = (m1 * m1 - m2 * m2) / (q2 - q1); // two distinct parallels (fast_albers checks)
        c = m1 * m1 + n * q1;
        rho0 = rho(q(origin_deg));
    }
    static double rad(double deg) { return deg * (std::numbers::pi / 180); }
    double m(double lat_deg) const
    {
        const double s = std::sin(rad(lat_deg));
        return std::cos(rad(lat_deg)) / std::sqrt(1 - e2 * s * s);
    }
    double q_of_sin(double s) const { return (1 - e2) * (s / (1 - e2 * s * s) + std::atanh(e * s) / e); }
    double q(double lat_deg) const { return q_of_sin(std::sin(rad(lat_deg))); }
    double rho(double qv) const { return a * std::sqrt(c - n * qv) / n; }
    /// dlon_deg: longitude from the central meridian, in [-180, 180].
    void forward(double lat_deg, double dlon_deg, double& x, double& y) const
    {
        const double r = rho(q_of_sin(std::sin(rad(lat_deg))));
        const double theta = n * rad(dlon_deg);
        x = r * std::sin(theta);
        y = rho0 - r * std::cos(theta);
    }
};

/// The largest grid coordinate: grid points are 32-bit.
constexpr double grid_limit = 2147483647.0;

} // namespace

struct Projection::Impl {
    ProjectionParams p;
    std::variant<GeographicLib::AlbersEqualArea, GeographicLib::LambertConformalConic,
                 GeographicLib::TransverseMercator>
        proj;
    GeographicLib::Geodesic geodesic;
    double lon0 = 0, x0 = 0, y0 = 0; // subtracted after the forward projection
    bool transverse = false;
    // Snyder's formulas, where they agree with GeographicLib (albers, two
    // standard parallels, a cone opening north, k0 = 1); checked on first use.
    std::optional<SnyderAlbers> fast;
    double tie_guard = 0; // grid steps from a half-step tie where to_grid asks GeographicLib
    std::once_flag fast_checked;
    // The conics' apex in GeographicLib's frame: on the central meridian
    // (x = 0) at y = apex_y, where every meridian's straight image meets;
    // none (a cylinder: n = 0) when the meridians are parallel.
    bool has_apex = false;
    double apex_y = 0;
    double sign = 1; ///< -1 for a mirrored (southern) Albers: GeographicLib's latitude and y are negated

    /// GeographicLib 2.1.2's AlbersEqualArea::Forward is wrong for a cone
    /// opening south (sin(stdlat1) + sin(stdlat2) < 0: its latitude's sign
    /// is reversed twice, so Reverse(Forward(lat)) gives -lat; upstream
    /// issue 55, fixed after 2.1.2). Such a cone is projected as the mirror
    /// image of its northern twin, which is exact: the ellipsoid and the
    /// projection are symmetric in the equator (lat -> -lat, y -> -y).
    static bool mirrored(const ProjectionParams& p)
    {
        return p.kind == ProjectionParams::Kind::albers &&
               std::sin(p.stdlat1_deg * std::numbers::pi / 180) + std::sin(p.stdlat2_deg * std::numbers::pi / 180) < 0;
    }

    static decltype(proj) make(const ProjectionParams& p)
    {
        using K = ProjectionParams::Kind;
        switch (p.kind) {
        case K::albers:
            // A southern cone as the mirror of its northern twin (see `mirror`).
            return mirrored(p) ? GeographicLib::AlbersEqualArea(p.a_m, p.f, -p.stdlat1_deg, -p.stdlat2_deg, p.k0)
                               : GeographicLib::AlbersEqualArea(p.a_m, p.f, p.stdlat1_deg, p.stdlat2_deg, p.k0);
        case K::lcc:
            return GeographicLib::LambertConformalConic(p.a_m, p.f, p.stdlat1_deg, p.stdlat2_deg, p.k0);
        case K::tm:
            return GeographicLib::TransverseMercator(p.a_m, p.f, p.k0);
        case K::utm:
            return GeographicLib::TransverseMercator(p.a_m, p.f, 0.9996);
        }
        throw config_error("unknown projection kind");
    }

    explicit Impl(const ProjectionParams& params)
        : p(params), proj(make(params)), geodesic(params.a_m, params.f), sign(mirrored(params) ? -1.0 : 1.0)
    {
        using K = ProjectionParams::Kind;
        transverse = p.kind == K::tm || p.kind == K::utm;
        lon0 = p.lon0_deg;
        double lat0 = p.lat0_deg;
        if (p.kind == K::utm) {
            lon0 = p.utm_zone * 6.0 - 183.0;
            lat0 = 0.0;
            p.false_easting_m = 500000.0;
            p.false_northing_m = p.utm_north ? 0.0 : 10000000.0;
        }
        double x = 0, y = 0;
        raw_forward(lat0, lon0, x, y);
        x0 = x - p.false_easting_m;
        y0 = y - p.false_northing_m;
        if (!transverse) {
            // Two points of one meridian fix its line; it meets x = 0 at the apex.
            double x1 = 0, y1 = 0, x2 = 0, y2 = 0;
            raw_forward(-10.0, lon0 + 10.0, x1, y1);
            raw_forward(50.0, lon0 + 10.0, x2, y2);
            const double ay = y1 - x1 * (y2 - y1) / (x2 - x1);
            if (std::isfinite(ay) && std::fabs(x2 - x1) > 1e-3 * std::fabs(y2 - y1)) {
                has_apex = true;
                apex_y = ay;
            }
        }
    }

    /// Latitude at (x, y) of GeographicLib's frame.
    double latitude(double x, double y) const
    {
        double lat = 0, lon = 0;
        reverse(x, y, lat, lon);
        return lat;
    }

    /// GeographicLib's Reverse, mirrored back where `sign` says.
    void reverse(double x, double y, double& lat, double& lon) const
    {
        double gamma = 0, k = 0;
        std::visit([&](const auto& pr) { pr.Reverse(lon0, x, sign * y, lat, lon, gamma, k); }, proj);
        lat *= sign;
    }

    /// The point scale k at lon/lat.
    double point_scale(double lat, double lon) const
    {
        double x = 0, y = 0, gamma = 0, k = 0;
        std::visit([&](const auto& pr) { pr.Forward(lon0, sign * lat, lon, x, y, gamma, k); }, proj);
        return k;
    }

    /// The conics' latitude of least scale.
    template <class T> double origin_latitude(const T& pr) const { return sign * pr.OriginLatitude(); }

    /// Use Snyder's formulas if they agree with GeographicLib within 1 um
    /// over the globe; to_grid then asks GeographicLib within 10 um of a tie.
    const SnyderAlbers* fast_albers()
    {
        std::call_once(fast_checked, [this] {
            if (p.kind == ProjectionParams::Kind::albers && p.k0 == 1.0 && p.stdlat1_deg != p.stdlat2_deg) {
                check_fast(std::get<GeographicLib::AlbersEqualArea>(proj));
            }
        });
        return fast ? &*fast : nullptr;
    }

    void check_fast(const GeographicLib::AlbersEqualArea& albers)
    {
        const SnyderAlbers s(p.a_m, p.f, p.stdlat1_deg, p.stdlat2_deg, origin_latitude(albers));
        if (!(std::isfinite(s.n) && std::isfinite(s.rho0) && s.n > 0)) { // northern cones only
            return;
        }
        double worst = 0;
        for (double lat = -84.5; lat <= 84.5; lat += 6.5) {
            for (double dlon = -179.5; dlon <= 179.5; dlon += 11.9) {
                double xg = 0, yg = 0, xs = 0, ys = 0;
                raw_forward(lat, lon0 + dlon, xg, yg);
                s.forward(lat, dlon, xs, ys);
                worst = std::max({worst, std::fabs(xg - xs), std::fabs(yg - ys)});
            }
        }
        if (worst < 1e-6) {
            fast = s;
            tie_guard = 1e-5 / p.grid_m;
        }
    }

    void raw_forward(double lat, double lon, double& x, double& y) const
    {
        double gamma = 0, k = 0;
        std::visit([&](const auto& pr) { pr.Forward(lon0, sign * lat, lon, x, y, gamma, k); }, proj);
        y *= sign;
    }
};

Projection::Projection(const ProjectionParams& params)
{
    using K = ProjectionParams::Kind;
    if (!(params.grid_m > 0) || !std::isfinite(params.grid_m)) {
        throw config_error("projection: 'grid_m' must be > 0");
    }
    if (params.kind == K::albers || params.kind == K::lcc) {
        for (double lat : {params.stdlat1_deg, params.stdlat2_deg}) {
            if (!(std::fabs(lat) < 90)) {
                throw config_error("projection: standard parallels must lie in (-90, 90)");
            }
        }
    }
    if (params.kind == K::utm && (params.utm_zone < 1 || params.utm_zone > 60)) {
        throw config_error("projection: 'utm_zone' must be in 1..60");
    }
    if (!(std::fabs(params.lat0_deg) < 90) || !(std::fabs(params.lon0_deg) <= 180)) {
        throw config_error("projection: 'lat0' must lie in (-90, 90) and 'lon0' in [-180, 180]");
    }
    try {
        m_impl = std::make_unique<Impl>(params);
    } catch (const GeographicLib::GeographicErr& e) {
        throw config_error(std::string("projection: ") + e.what());
    }
}

Projection::~Projection() = default;
Projection::Projection(Projection&&) noexcept = default;
Projection& Projection::operator=(Projection&&) noexcept = default;

const ProjectionParams& Projection::params() const noexcept
{
    return m_impl->p;
}

std::optional<GridPoint> Projection::to_grid(double lon_deg, double lat_deg) const noexcept
{
    if (const SnyderAlbers* fast = m_impl->fast_albers()) {
        // Rounded from Snyder's formulas unless a coordinate lies within the
        // guard of a half-step tie, where their nanometres could decide it.
        const double dlon = lon_deg - m_impl->lon0;
        if (std::fabs(dlon) <= 180 && std::fabs(lat_deg) <= 84.5) { // where check_fast compared them
            double x = 0, y = 0;
            fast->forward(lat_deg, dlon, x, y);
            const double fx = (x - m_impl->x0) / m_impl->p.grid_m, fy = (y - m_impl->y0) / m_impl->p.grid_m;
            const double tx = std::fabs(fx - std::floor(fx) - 0.5), ty = std::fabs(fy - std::floor(fy) - 0.5);
            if (tx > m_impl->tie_guard && ty > m_impl->tie_guard && std::fabs(fx) < grid_limit &&
                std::fabs(fy) < grid_limit) {
                return GridPoint{static_cast<int32_t>(std::nearbyint(fx)), static_cast<int32_t>(std::nearbyint(fy))};
            }
        }
    }
    return to_grid_reference(lon_deg, lat_deg);
}

std::optional<GridPoint> Projection::to_grid_reference(double lon_deg, double lat_deg) const noexcept
{
    if (!std::isfinite(lon_deg) || !std::isfinite(lat_deg) || std::fabs(lon_deg) > 180 || std::fabs(lat_deg) > 90) {
        return std::nullopt;
    }
    if (m_impl->transverse && std::fabs(GeographicLib::Math::AngDiff(m_impl->lon0, lon_deg)) > 30) {
        return std::nullopt;
    }
    double x = 0, y = 0;
    m_impl->raw_forward(lat_deg, lon_deg, x, y);
    const double gx = std::nearbyint((x - m_impl->x0) / m_impl->p.grid_m);
    const double gy = std::nearbyint((y - m_impl->y0) / m_impl->p.grid_m);
    if (!std::isfinite(gx) || !std::isfinite(gy) || std::fabs(gx) > grid_limit || std::fabs(gy) > grid_limit) {
        return std::nullopt;
    }
    return GridPoint{static_cast<int32_t>(gx), static_cast<int32_t>(gy)};
}

bool Projection::forward(double lon_deg, double lat_deg, double& gx, double& gy) const noexcept
{
    if (!std::isfinite(lon_deg) || !std::isfinite(lat_deg) || std::fabs(lon_deg) > 180 || std::fabs(lat_deg) > 90) {
        return false;
    }
    if (m_impl->transverse && std::fabs(GeographicLib::Math::AngDiff(m_impl->lon0, lon_deg)) > 30) {
        return false;
    }
    double x = 0, y = 0;
    m_impl->raw_forward(lat_deg, lon_deg, x, y);
    gx = (x - m_impl->x0) / m_impl->p.grid_m;
    gy = (y - m_impl->y0) / m_impl->p.grid_m;
    return std::isfinite(gx) && std::isfinite(gy);
}

bool Projection::fast_albers() const noexcept
{
    return m_impl->fast_albers() != nullptr;
}

void Projection::to_lonlat(double gx, double gy, double& lon_deg, double& lat_deg) const noexcept
{
    const double x = gx * m_impl->p.grid_m + m_impl->x0;
    const double y = gy * m_impl->p.grid_m + m_impl->y0;
    m_impl->reverse(x, y, lat_deg, lon_deg);
}

double Projection::scale(double lon_deg, double lat_deg) const noexcept
{
    return m_impl->point_scale(lat_deg, lon_deg);
}

double Projection::smallest_scale(const GridBox& box) const noexcept
{
    if (box.empty()) {
        return 0.0;
    }
    const Impl& m = *m_impl;
    double s = 0.0;
    std::visit(
        [&](const auto& pr) {
            using T = std::decay_t<decltype(pr)>;
            if constexpr (std::is_same_v<T, GeographicLib::TransverseMercator>) {
                s = pr.CentralScale();
            } else {
                const double g = m.p.grid_m;
                const double xa = double(box.min_x) * g + m.x0, xb = double(box.max_x) * g + m.x0;
                const double ya = double(box.min_y) * g + m.y0, yb = double(box.max_y) * g + m.y0;
                double lo = 90, hi = -90;
                auto take = [&](double lat) {
                    lo = std::min(lo, lat);
                    hi = std::max(hi, lat);
                };
                for (const double x : {xa, xb}) {
                    for (const double y : {ya, yb}) {
                        take(m.latitude(x, y)); // the farthest point from the apex is a corner
                    }
                }
                if (m.has_apex) {
                    const double px = std::clamp(0.0, xa, xb), py = std::clamp(m.apex_y, ya, yb);
                    if (px == 0.0 && py == m.apex_y) {
                        take(m.apex_y > 0 ? 90.0 : -90.0); // the box holds the apex: the pole is in reach
                    } else {
                        take(m.latitude(px, py));
                    }
                }
                const double k_lo = scale(m.lon0, lo), k_hi = scale(m.lon0, hi);
                const double origin = m.origin_latitude(pr);
                const double k_min = origin >= lo && origin <= hi ? pr.CentralScale() : std::min(k_lo, k_hi);
                const double k_max = std::max(k_lo, k_hi);
                s = std::is_same_v<T, GeographicLib::AlbersEqualArea> ? std::min(k_min, 1.0 / k_max) : k_min;
            }
        },
        m.proj);
    s *= 1 - 1e-9;
    return std::isfinite(s) && s > 0 ? s : 0.0;
}

double Projection::geodesic_m(double lon1_deg, double lat1_deg, double lon2_deg, double lat2_deg) const noexcept
{
    double s12 = 0;
    m_impl->geodesic.Inverse(lat1_deg, lon1_deg, lat2_deg, lon2_deg, s12);
    return s12;
}

double Projection::lattice_separation_m(double step_deg, double lat_lo_deg, double lat_hi_deg) const noexcept
{
    const auto& p = m_impl->p;
    // Widened a little, so the bound also holds on the short projected segment
    // between two points near the band's edge.
    const double lo = std::max(-90.0, lat_lo_deg - 0.01), hi = std::min(90.0, lat_hi_deg + 0.01);
    const double cos_min = std::cos(std::max(std::fabs(lo), std::fabs(hi)) * std::numbers::pi / 180);
    if (!(lo <= hi) || !(cos_min > 1e-6)) {
        return 0.0;
    }
    // Two distinct lattice points differ by whole steps north-south or
    // east-west; a step is at least a(1 - e^2) times its angle north-south (the
    // meridian's radius of curvature) and a cos(lat) east-west.
    const double e2 = p.f * (2 - p.f);
    const double step = step_deg * std::numbers::pi / 180 * p.a_m;
    // The smallest scales over the band east-west (k) and north-south (h).
    // Transverse Mercator is conformal with k >= k0 everywhere. The conics' k
    // depends on latitude alone, with its minimum on the latitude of origin;
    // LCC is conformal, Albers scales north-south by 1/k.
    double k_min = 0.0, h_min = 0.0;
    std::visit(
        [&](const auto& pr) {
            using T = std::decay_t<decltype(pr)>;
            if constexpr (std::is_same_v<T, GeographicLib::TransverseMercator>) {
                k_min = h_min = pr.CentralScale();
            } else {
                const double k_lo = scale(m_impl->lon0, lo), k_hi = scale(m_impl->lon0, hi);
                const double origin = m_impl->origin_latitude(pr);
                k_min = origin > lo && origin < hi ? pr.CentralScale() : std::min(k_lo, k_hi);
                h_min = std::is_same_v<T, GeographicLib::AlbersEqualArea> ? 1 / std::max(k_lo, k_hi) : k_min;
            }
        },
        m_impl->proj);
    const double d = 0.99 * std::min(step * (1 - e2) * h_min, step * cos_min * k_min);
    return std::isfinite(d) && d > 0 ? d : 0.0;
}

std::string Projection::describe() const
{
    const auto& p = m_impl->p;
    char buf[256];
    using K = ProjectionParams::Kind;
    if (p.kind == K::utm) {
        std::snprintf(buf, sizeof buf, "utm zone=%d%s grid=%gm", p.utm_zone, p.utm_north ? "N" : "S", p.grid_m);
    } else if (p.kind == K::tm) {
        std::snprintf(buf, sizeof buf, "tm lon0=%g lat0=%g k0=%g grid=%gm", p.lon0_deg, p.lat0_deg, p.k0, p.grid_m);
    } else {
        std::snprintf(buf, sizeof buf, "%s lon0=%g lat0=%g stdlat=%g,%g grid=%gm", projection_kind_name(p.kind),
                      p.lon0_deg, p.lat0_deg, p.stdlat1_deg, p.stdlat2_deg, p.grid_m);
    }
    return buf;
}

} // namespace tigerlod
