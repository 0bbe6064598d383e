#include "simplification/tolerances.hpp"

#include "core/errors.hpp"
#include "core/projection.hpp"
#include "simplification/cell_cover.hpp"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>

namespace tigerlod::simplify {

using chains::ChainStore;

/// The colouring's options with the metric the simplification uses.
ColorOptions color_options(const SimplifyOptions& opt)
{
    ColorOptions copt = opt.color;
    copt.metric = opt.metric;
    return copt;
}

/// How far from an owned chain a halo segment can matter at these
/// tolerances, in grid units: the conflict graph looks 2 reaches away (eps
/// in the metric plus the colouring margin), the far rule eps + a reach, the
/// tents a reach plus a pixel beyond a tested shortcut, which stays within
/// eps of its chain. The pixel is at most pixel_fraction x the largest eps.
double halo_reach(std::span<const double> eps, const SimplifyOptions& opt)
{
    double eps_max = 0;
    for (const double e : eps) {
        eps_max = std::max(eps_max, e);
    }
    const double pixel = eps_max * opt.color.pixel_fraction;
    const double reach = reach_radius(eps_max, pixel, color_options(opt));
    return 2 * reach + eps_max * l2_reach(opt.metric) + 2 * pixel + 4;
}

/// The part of `keep` (from segments_in_reach) for chain `c`: empty if all of it takes part.
std::span<const uint8_t> keep_of(const std::vector<uint8_t>& keep, const chains::ChainInfo& c)
{
    return keep.empty() ? std::span<const uint8_t>{} : std::span<const uint8_t>(keep).subspan(c.first, c.count);
}

ChainScales::ChainScales(const ChainStore& store, const SimplifyOptions& opt)
    : m_grid_m(store.projection.grid_m), m_class(store.chains.size(), 1.0), m_projection(store.chains.size(), 1.0)
{
    const Projection proj(store.projection);
    for (size_t i = 0; i < store.chains.size(); ++i) {
        const auto& c = store.chains[i];
        if (!opt.class_scale.empty()) {
            const auto it = opt.class_scale.find(store.strings[c.feature_class]);
            if (it != opt.class_scale.end()) {
                m_class[i] = it->second;
            }
        }
        if (opt.projection_scale) {
            GridBox box;
            for (const GridPoint p : store.chain_points(c)) {
                box.extend(p);
            }
            // The least scale over the chain's box in any direction: every
            // skipped vertex, the point of its shortcut nearest to it and the
            // planar segment between them lie in the box, so a planar
            // distance within eps_m * s is within eps_m on the ellipsoid
            // (docs/guarantees.md; Projection::smallest_scale). At most
            // 1: ingest cuts halos in projected metres, and the partition
            // contract needs each planar eps within its ground eps (a
            // conformal conic's scale passes 1 far from its parallels).
            m_projection[i] = std::min(1.0, proj.smallest_scale(box));
        }
    }
}

std::vector<double> ChainScales::tolerances(double eps_m) const
{
    const double base = eps_m / m_grid_m;
    std::vector<double> eps(m_class.size());
    for (size_t i = 0; i < eps.size(); ++i) {
        double e = base;
        e *= m_class[i];
        e *= m_projection[i];
        eps[i] = e;
    }
    return eps;
}

std::vector<double> chain_tolerances(const ChainStore& store, double eps_m, const SimplifyOptions& opt)
{
    return ChainScales(store, opt).tolerances(eps_m);
}

std::vector<uint8_t> segments_in_reach(const ChainStore& store, double reach)
{
    GridBox box;
    size_t owned_segments = 0;
    bool halo = false;
    for (const auto& c : store.chains) {
        if (c.flags & chains::chain_halo) {
            halo = true;
            continue;
        }
        for (const GridPoint p : store.chain_points(c)) {
            box.extend(p);
        }
        owned_segments += c.count > 0 ? c.count - 1 : 0;
    }
    if (!halo) {
        return {};
    }
    std::vector<uint8_t> keep(store.points.size(), 0);
    if (box.empty()) {
        return keep;
    }
    // Cells at least `reach` wide, and few enough that marking them costs
    // about as much as the owned segments (16 cells a segment).
    const double w = double(box.max_x - box.min_x) + 2 * reach, h = double(box.max_y - box.min_y) + 2 * reach;
    const double cell = std::max({reach, std::sqrt(w * h / (16.0 * double(std::max<size_t>(owned_segments, 1)))), 1.0});
    const double ox = double(box.min_x) - reach - cell, oy = double(box.min_y) - reach - cell;
    const auto nx = static_cast<int64_t>(std::ceil(w / cell)) + 3, ny = static_cast<int64_t>(std::ceil(h / cell)) + 3;
    std::vector<uint8_t> near(size_t(nx * ny), 0);
    auto at = [&](int64_t x, int64_t y) -> uint8_t* {
        return x >= 0 && y >= 0 && x < nx && y < ny ? &near[size_t(y * nx + x)] : nullptr;
    };
    for (const auto& c : store.chains) {
        if (c.flags & chains::chain_halo) {
            continue;
        }
        const auto pts = store.chain_points(c);
        for (size_t i = 0; i + 1 < pts.size(); ++i) {
            keep[c.first + i] = 1;
            cover_cells(pts[i].x, pts[i].y, pts[i + 1].x, pts[i + 1].y, reach, cell, ox, oy, [&](int64_t x, int64_t y) {
                if (uint8_t* n = at(x, y)) {
                    *n = 1;
                }
            });
        }
    }
    // Most of the halo is far from every owned segment: whole chains, then
    // segments, that miss the owned box grown by the reach and two cells (so
    // every marked cell is inside) are out at once.
    const double grow = reach + 2 * cell;
    const GridBox near_box{static_cast<int64_t>(std::floor(double(box.min_x) - grow)) - 1,
                           static_cast<int64_t>(std::floor(double(box.min_y) - grow)) - 1,
                           static_cast<int64_t>(std::ceil(double(box.max_x) + grow)) + 1,
                           static_cast<int64_t>(std::ceil(double(box.max_y) + grow)) + 1};
    auto misses = [&](GridPoint a, GridPoint b) {
        return std::max(a.x, b.x) < near_box.min_x || std::min(a.x, b.x) > near_box.max_x ||
               std::max(a.y, b.y) < near_box.min_y || std::min(a.y, b.y) > near_box.max_y;
    };
    for (const auto& c : store.chains) {
        if (!(c.flags & chains::chain_halo)) {
            continue;
        }
        const auto pts = store.chain_points(c);
        GridBox chain_box;
        for (const GridPoint p : pts) {
            chain_box.extend(p);
        }
        if (chain_box.empty() || !chain_box.intersects(near_box)) {
            continue; // keep stays 0
        }
        for (size_t i = 0; i + 1 < pts.size(); ++i) {
            if (misses(pts[i], pts[i + 1])) {
                continue;
            }
            bool hit = false;
            cover_cells(pts[i].x, pts[i].y, pts[i + 1].x, pts[i + 1].y, 0.0, cell, ox, oy, [&](int64_t x, int64_t y) {
                const uint8_t* n = at(x, y);
                hit = hit || (n && *n);
            });
            keep[c.first + i] = hit ? 1 : 0;
        }
    }
    return keep;
}

ColorResult color_chains(const ChainStore& store, std::span<const double> eps, const std::vector<uint8_t>& keep,
                         const SimplifyOptions& opt)
{
    std::vector<ChainGeom> geoms(store.chains.size());
    for (size_t i = 0; i < store.chains.size(); ++i) {
        const auto& c = store.chains[i];
        geoms[i] = {store.chain_points(c), eps[i], !(c.flags & chains::chain_halo), keep_of(keep, c)};
    }
    try {
        return color_tiles(geoms, color_options(opt), opt.threads);
    } catch (const tile_overflow_error& e) {
        // The tile's centre in lon/lat too, to find it in a map viewer.
        const TileSpec& t = e.tile;
        double lon = 0, lat = 0;
        Projection(store.projection)
            .to_lonlat(t.x0 + 0.5 * t.width * t.pixel, t.y0 + 0.5 * t.height * t.pixel, lon, lat);
        std::ostringstream msg;
        msg << e.what() << ", centred at lon/lat (" << std::fixed << std::setprecision(6) << lon << ", " << lat << ")";
        throw input_error(msg.str());
    }
}

ColorResult color_store(const ChainStore& store, double eps_m, const SimplifyOptions& opt)
{
    const auto eps = chain_tolerances(store, eps_m, opt);
    return color_chains(store, eps, segments_in_reach(store, halo_reach(eps, opt)), opt);
}

std::optional<std::string> partition_contract_fault(const ChainStore& store)
{
    std::vector<uint8_t> has_point(store.strings.size(), 0);
    for (const auto& cp : store.constraints) {
        if (cp.kind == chains::constraint_internal || cp.kind == chains::constraint_neighbour) {
            has_point[cp.unit] = 1;
        }
    }
    for (const auto& c : store.chains) {
        if (c.flags & chains::chain_halo) {
            continue;
        }
        for (const uint32_t side : {c.left, c.right}) {
            if (side != 0 && !has_point[side]) {
                std::string why = "chain " + std::to_string(c.id) + " bounds unit " + store.strings[side] +
                                  ", but the store holds no internal point of that unit; without it a shortcut "
                                  "could cut the point off (the partition contract, formats/chains/SPEC.md)";
                if (store.minor < 2) {
                    why += "; the store is chain store 1." + std::to_string(store.minor) +
                           ", written before the contract: re-run tigerlod-ingest";
                } else {
                    why += "; ingest reports such a unit under missing_internal_points";
                }
                return why;
            }
        }
    }
    return std::nullopt;
}

} // namespace tigerlod::simplify
