#include "stages/export/lonlat_line.hpp"

#include <algorithm>
#include <cmath>

namespace tigerlod::exporter {

namespace {

/// Distance from (x, y) to segment pq, grid units.
double to_segment(double x, double y, double px, double py, double qx, double qy)
{
    const double dx = qx - px, dy = qy - py, len2 = dx * dx + dy * dy;
    const double t = len2 > 0 ? std::clamp(((x - px) * dx + (y - py) * dy) / len2, 0.0, 1.0) : 0.0;
    return std::hypot(x - (px + t * dx), y - (py + t * dy));
}

/// The largest distance of the lon/lat line's eighths from pq, grid units,
/// and the box around them and pq.
double bow_grid(const Projection& proj, double px, double py, double qx, double qy, GridBox& box)
{
    double plon = 0, plat = 0, qlon = 0, qlat = 0;
    proj.to_lonlat(px, py, plon, plat);
    proj.to_lonlat(qx, qy, qlon, qlat);
    box.extend({int32_t(std::floor(std::min(px, qx))), int32_t(std::floor(std::min(py, qy)))});
    box.extend({int32_t(std::ceil(std::max(px, qx))), int32_t(std::ceil(std::max(py, qy)))});
    double worst = 0;
    for (int i = 1; i < 8; ++i) {
        const double t = i / 8.0;
        double gx = 0, gy = 0;
        if (!proj.forward(plon + t * (qlon - plon), plat + t * (qlat - plat), gx, gy)) {
            return INFINITY;
        }
        box.extend({int32_t(std::floor(gx)), int32_t(std::floor(gy))});
        box.extend({int32_t(std::ceil(gx)), int32_t(std::ceil(gy))});
        worst = std::max(worst, to_segment(gx, gy, px, py, qx, qy));
    }
    return worst;
}

} // namespace

double lonlat_bow_m(const Projection& proj, double px, double py, double qx, double qy)
{
    GridBox box;
    const double d = bow_grid(proj, px, py, qx, qy, box);
    const double s = proj.smallest_scale(box);
    return s > 0 ? d * proj.params().grid_m / s : INFINITY;
}

std::vector<std::pair<double, double>> densify_lonlat(const Projection& proj, std::span<const GridPoint> pts,
                                                      double max_bow_m)
{
    std::vector<std::pair<double, double>> out;
    auto emit = [&](double gx, double gy) {
        double lon = 0, lat = 0;
        proj.to_lonlat(gx, gy, lon, lat);
        out.emplace_back(lon, lat);
    };
    // Bisect [p, q] until each piece bows within half the bound at its eighths.
    auto split = [&](auto&& self, double px, double py, double qx, double qy, int depth) -> void {
        const bool short_piece = std::hypot(qx - px, qy - py) < 1.0;
        if (depth < 40 && !short_piece && lonlat_bow_m(proj, px, py, qx, qy) > 0.5 * max_bow_m) {
            const double mx = 0.5 * (px + qx), my = 0.5 * (py + qy);
            self(self, px, py, mx, my, depth + 1);
            self(self, mx, my, qx, qy, depth + 1);
            return;
        }
        emit(qx, qy);
    };
    for (size_t i = 0; i < pts.size(); ++i) {
        if (i == 0) {
            emit(pts[0].x, pts[0].y);
            continue;
        }
        split(split, pts[i - 1].x, pts[i - 1].y, pts[i].x, pts[i].y, 0);
    }
    return out;
}

} // namespace tigerlod::exporter
