#pragma once
/// @file adversarial_map.hpp
/// A seeded generator of polygon maps built to break the partition contract
/// (formats/chains/SPEC.md): written as GeoJSON for tigerlod-ingest, with
/// the same geometry under several partitionings (the codes change, the
/// shapes do not).
///
/// The map is a grid of cells, each a tract, whose shared borders are long
/// wiggly polylines (coastline-like, dozens of vertices). On top of that:
/// - teeth: a narrow rectangular bump of one cell's border into its
///   neighbour, deep at coarse tolerances, with the cell's internal point
///   inside it, next to the border (a shortcut across the bump would put the
///   point in the neighbour);
/// - strips: two thin parallel island tracts inside a cell, a gap of 2 to 9 m
///   apart (one or two pixels at 4 m tolerances, under a pixel with a coarse
///   `--pixel-fraction`), each of them a tract of another county than the
///   cell around them;
/// - islands: a wiggly ring tract inside a cell, of another county;
/// - lakes: a wiggly hole that no unit fills, and lakes on borders, whose
///   shores are two chains of two cells between the same two junctions;
/// - bays: a tooth without the cell's point, holding at its far end three
///   tiny triangular tracts of another county around a centre (a K4: six
///   straight chains of two vertices, no middle vertex among them); the
///   tooth's walls are nearer its mouth than the triangles are, so the
///   raster lets a shortcut across the mouth pass, and in a partition that
///   owns the border but none of the triangles' chains no internal point of
///   theirs is in the store: only the chains' ends keep them on their side;
/// - in the partitionings, counties of one tract.
///
/// Every coordinate is on TIGER's 1e-6 degree lattice, and the map is planar
/// by construction: borders keep within a cone of their corners (so borders
/// meeting at a corner do not meet elsewhere) and are monotone along their
/// direction (so a tooth, an extrusion of one segment, meets no other part);
/// islands, strips and lakes keep to the middle of their cell, where no
/// border or tooth reaches.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace tigerlod::testing {

struct MicroDeg {
    int64_t lon = 0, lat = 0;
};

class AdversarialMap {
  public:
    /// Partitionings of the same geometry into states and counties.
    enum class Partitioning {
        whole,     ///< one state, one county: the tract level is one partition
        blocks,    ///< counties of 2 x 2 cells, two states
        scattered, ///< each tract in a random one of five counties, singletons included
    };

    AdversarialMap(uint64_t seed, int cells_x = 5, int cells_y = 4) : m_rng(seed), m_nx(cells_x), m_ny(cells_y)
    {
        build_edges();
        build_cells();
    }

    /// The map as a GeoJSON FeatureCollection with GEOID (state 2 + county 3 +
    /// tract 6) and INTPTLAT / INTPTLON, null where not given.
    std::string geojson(Partitioning p) const
    {
        std::string out = "{\"type\":\"FeatureCollection\",\"features\":[\n";
        for (size_t u = 0; u < m_units.size(); ++u) {
            const Unit& unit = m_units[u];
            out += u ? ",\n" : "";
            out += "{\"type\":\"Feature\",\"properties\":{\"GEOID\":\"" + geoid(p, u) + "\"";
            // null where not given (every unit of a map may lack one): ingest computes it.
            out += ",\"INTPTLAT\":" + (unit.point ? deg(unit.point->lat) : "null") +
                   ",\"INTPTLON\":" + (unit.point ? deg(unit.point->lon) : "null");
            out += "},\"geometry\":{\"type\":\"Polygon\",\"coordinates\":[";
            for (size_t r = 0; r < unit.rings.size(); ++r) {
                out += r ? "," : "";
                out += "[";
                for (size_t k = 0; k < unit.rings[r].size(); ++k) {
                    out += k ? "," : "";
                    // Appended piece by piece: "[" + a temporary trips GCC 12's -Wrestrict (a false positive).
                    out += '[';
                    out += deg(unit.rings[r][k].lon);
                    out += ',';
                    out += deg(unit.rings[r][k].lat);
                    out += ']';
                }
                out += "]";
            }
            out += "]}}";
        }
        return out + "\n]}\n";
    }

    size_t units() const noexcept { return m_units.size(); }
    size_t vertices() const noexcept
    {
        size_t n = 0;
        for (const auto& u : m_units) {
            for (const auto& r : u.rings) {
                n += r.size();
            }
        }
        return n;
    }
    size_t teeth() const noexcept { return m_teeth; }
    size_t bays() const noexcept { return m_bays; }

  private:
    static constexpr int64_t cell = 3000;           ///< cell side in micro-degrees (255 m east, 333 m north)
    static constexpr int64_t amplitude = cell / 10; ///< largest sideways offset of a border
    static constexpr int64_t lon0 = -100000000, lat0 = 40000000;

    struct Unit {
        std::vector<std::vector<MicroDeg>> rings; ///< outer ring, then holes; closed
        std::optional<MicroDeg> point;
        int cell = -1;      ///< the cell it lies in
        bool inner = false; ///< an island or strip: of another county than its cell
    };

    static std::string deg(int64_t e6)
    {
        char buf[32];
        std::snprintf(buf, sizeof buf, "%s%lld.%06lld", e6 < 0 ? "-" : "",
                      static_cast<long long>(std::llabs(e6) / 1000000),
                      static_cast<long long>(std::llabs(e6) % 1000000));
        return buf;
    }

    double uniform(double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(m_rng); }
    int integer(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(m_rng); }

    MicroDeg corner(int i, int j) const { return {lon0 + i * cell, lat0 + j * cell}; }

    /// A border from corner a to corner b (axis-aligned, `cell` long): its
    /// sideways offset is amplitude x sin(pi t) x u, u a smooth random walk in
    /// [-1, 1], so it stays in the cone of slope pi/10 around each corner and
    /// its steps along the border stay longer than its sideways ones.
    std::vector<MicroDeg> border(MicroDeg a, MicroDeg b)
    {
        const int n = integer(12, 60);
        const bool horizontal = a.lat == b.lat;
        std::vector<MicroDeg> pts;
        double u = uniform(-1, 1);
        for (int k = 0; k <= n; ++k) {
            const double t = double(k) / n;
            u = std::clamp(u + uniform(-0.15, 0.15), -1.0, 1.0);
            const double side = k == 0 || k == n ? 0 : amplitude * std::sin(M_PI * t) * u;
            const auto along = static_cast<int64_t>(std::llround(t * double(cell)));
            const auto off = static_cast<int64_t>(std::llround(side));
            pts.push_back(horizontal ? MicroDeg{a.lon + along, a.lat + off} : MicroDeg{a.lon + off, a.lat + along});
        }
        return pts;
    }

    void build_edges()
    {
        // h[i][j]: corner (i, j) -> (i + 1, j); v[i][j]: corner (i, j) -> (i, j + 1).
        m_h.assign(m_nx, std::vector<std::vector<MicroDeg>>(m_ny + 1));
        m_v.assign(m_nx + 1, std::vector<std::vector<MicroDeg>>(m_ny));
        for (int i = 0; i < m_nx; ++i) {
            for (int j = 0; j <= m_ny; ++j) {
                m_h[i][j] = border(corner(i, j), corner(i + 1, j));
            }
        }
        for (int i = 0; i <= m_nx; ++i) {
            for (int j = 0; j < m_ny; ++j) {
                m_v[i][j] = border(corner(i, j), corner(i, j + 1));
            }
        }
    }

    /// Extrudes a middle segment p q of border `e` by `depth` towards +side;
    /// returns the tooth's parallelogram as a map from (s along p q, t out
    /// of it), both in [0, 1], to the lattice.
    auto tooth(std::vector<MicroDeg>& e, int side, int64_t depth)
    {
        const bool horizontal = e.front().lat == e.back().lat;
        const size_t k = e.size() / 2 - 1 + static_cast<size_t>(integer(0, 1));
        const MicroDeg p = e[k], q = e[k + 1];
        auto out = [&](MicroDeg m) {
            return horizontal ? MicroDeg{m.lon, m.lat + side * depth} : MicroDeg{m.lon + side * depth, m.lat};
        };
        e.insert(e.begin() + static_cast<std::ptrdiff_t>(k) + 1, {out(p), out(q)});
        ++m_teeth;
        return [=](double s, double t) {
            const auto off = static_cast<int64_t>(std::llround(t * double(side * depth)));
            const MicroDeg m{p.lon + std::llround(s * double(q.lon - p.lon)),
                             p.lat + std::llround(s * double(q.lat - p.lat))};
            return horizontal ? MicroDeg{m.lon, m.lat + off} : MicroDeg{m.lon + off, m.lat};
        };
    }

    /// A tooth on border `e` (not an outer border of the map): segment k of
    /// it extruded sideways by `depth` towards +side (+1: north or east). The
    /// point returned lies inside the tooth, near its far end: the internal
    /// point of the cell the tooth belongs to (the one on the -side).
    MicroDeg add_tooth(std::vector<MicroDeg>& e, int side, int64_t depth) { return tooth(e, side, depth)(0.5, 0.85); }

    /// The K4 at the far end of a bay: corners a, b (near the far side), c
    /// (towards the mouth) and the centre d, inside the triangle.
    struct K4 {
        MicroDeg a, b, c, d;
    };

    /// A closed wiggly ring around c, radius r (micro-degrees) +-20%.
    std::vector<MicroDeg> blob(MicroDeg c, double r)
    {
        const int n = integer(16, 60);
        std::vector<MicroDeg> ring;
        double u = uniform(-1, 1);
        for (int k = 0; k < n; ++k) {
            u = std::clamp(u + uniform(-0.3, 0.3), -1.0, 1.0);
            const double a = 2 * M_PI * k / n, rr = r * (1 + 0.2 * u);
            ring.push_back({c.lon + std::llround(rr * std::cos(a)), c.lat + std::llround(rr * std::sin(a))});
        }
        ring.push_back(ring.front());
        return ring;
    }

    /// Two stacked strips in the middle of cell (i, j) with a gap between
    /// them: parallel wiggly sides, `gap` micro-degrees of latitude apart.
    std::pair<std::vector<MicroDeg>, std::vector<MicroDeg>> strips(MicroDeg c, int64_t gap)
    {
        const int n = integer(10, 40);
        const int64_t half = cell * 13 / 100, height = integer(120, 300);
        std::vector<int64_t> wiggle(n + 1);
        double u = uniform(-1, 1);
        for (int k = 0; k <= n; ++k) {
            u = std::clamp(u + uniform(-0.25, 0.25), -1.0, 1.0);
            wiggle[k] = std::llround(cell * 0.04 * u);
        }
        auto ring = [&](int64_t y0, int64_t y1) {
            std::vector<MicroDeg> r;
            for (int k = 0; k <= n; ++k) {
                r.push_back({c.lon - half + 2 * half * k / n, c.lat + y0 + wiggle[k]});
            }
            for (int k = n; k >= 0; --k) {
                r.push_back({c.lon - half + 2 * half * k / n, c.lat + y1 + wiggle[k]});
            }
            r.push_back(r.front());
            return r;
        };
        const int64_t y0 = -height - gap / 2;
        return {ring(y0, y0 + height), ring(y0 + height + gap, y0 + 2 * height + gap)};
    }

    /// Border lakes: on a quarter of the inner borders, segment J K (a
    /// quarter of the way along) opens into a small lake that no unit fills,
    /// whose shore is two chains from J to K, one of each cell's. J K is 4
    /// to 21 m long: under the 1.5 pixels at each end that the raster leaves
    /// untested at coarse tolerances, so the two shores, owned by two
    /// partitions, may both become the segment J K.
    struct Lake {
        size_t k = 0;                      ///< J = border[k], K = border[k + 1]
        std::vector<MicroDeg> plus, minus; ///< the shores between J and K on each side
    };
    std::map<const std::vector<MicroDeg>*, Lake> m_lakes;

    void add_lakes()
    {
        auto consider = [&](std::vector<MicroDeg>& e) {
            if (integer(0, 3) != 0) {
                return;
            }
            const bool horizontal = e.front().lat == e.back().lat;
            Lake lake;
            lake.k = e.size() / 4;
            const MicroDeg J = e[lake.k], K = e[lake.k + 1];
            auto shore = [&](int side) {
                std::vector<MicroDeg> r{J};
                for (int f = 1; f <= 2; ++f) {
                    const int64_t h = side * integer(50, 300);
                    MicroDeg m{J.lon + (K.lon - J.lon) * f / 3, J.lat + (K.lat - J.lat) * f / 3};
                    (horizontal ? m.lat : m.lon) += h;
                    r.push_back(m);
                }
                r.push_back(K);
                return r;
            };
            lake.plus = shore(+1);
            lake.minus = shore(-1);
            m_lakes[&e] = std::move(lake);
        };
        for (int i = 0; i < m_nx; ++i) {
            for (int j = 1; j < m_ny; ++j) {
                consider(m_h[i][j]);
            }
        }
        for (int i = 1; i < m_nx; ++i) {
            for (int j = 0; j < m_ny; ++j) {
                consider(m_v[i][j]);
            }
        }
    }

    /// Border e as the cell on its `side` sees it: through a lake, that side's shore.
    std::vector<MicroDeg> seen_from(const std::vector<MicroDeg>& e, int side) const
    {
        const auto it = m_lakes.find(&e);
        if (it == m_lakes.end()) {
            return e;
        }
        const Lake& lake = it->second;
        std::vector<MicroDeg> out(e.begin(), e.begin() + static_cast<std::ptrdiff_t>(lake.k));
        const auto& shore = side > 0 ? lake.plus : lake.minus;
        out.insert(out.end(), shore.begin(), shore.end());
        out.insert(out.end(), e.begin() + static_cast<std::ptrdiff_t>(lake.k) + 2, e.end());
        return out;
    }

    void build_cells()
    {
        // Teeth first: they change the borders every cell then reads.
        std::vector<std::optional<MicroDeg>> tooth_point(static_cast<size_t>(m_nx * m_ny));
        std::vector<std::optional<K4>> bay(static_cast<size_t>(m_nx * m_ny));
        for (int i = 0; i < m_nx; ++i) {
            for (int j = 0; j < m_ny; ++j) {
                if (integer(0, 2) != 0) {
                    continue; // a third of the cells
                }
                // One of the cell's inner borders, bulging into the neighbour.
                // A bay bulges south or west: into a cell with a smaller code
                // in the blocks partitioning, whose partition then owns the
                // border but none of the triangles' chains.
                const bool is_bay = integer(0, 2) == 0;
                std::vector<std::pair<std::vector<MicroDeg>*, int>> options;
                if (j + 1 < m_ny && !is_bay) {
                    options.push_back({&m_h[i][j + 1], +1});
                }
                if (j > 0) {
                    options.push_back({&m_h[i][j], -1});
                }
                if (i + 1 < m_nx && !is_bay) {
                    options.push_back({&m_v[i + 1][j], +1});
                }
                if (i > 0) {
                    options.push_back({&m_v[i][j], -1});
                }
                if (options.empty()) {
                    continue; // a bay in the south-west cell
                }
                auto [e, side] = options[static_cast<size_t>(integer(0, static_cast<int>(options.size()) - 1))];
                if (m_toothed.count(e)) {
                    continue; // one tooth per border
                }
                m_toothed.insert(e);
                // 17 to 67 m deep: cut at coarse tolerances unless its point holds it.
                const int64_t depth = integer(200, cell / 5);
                if (is_bay) {
                    // The segment is 4 to 21 m wide, the triangles 75-90% of the
                    // way out, farther from the mouth than its walls.
                    const auto at = tooth(*e, side, depth);
                    ++m_bays;
                    bay[static_cast<size_t>(i * m_ny + j)] =
                        K4{at(0.3, 0.9), at(0.7, 0.9), at(0.5, 0.75), at(0.5, 0.85)};
                } else {
                    tooth_point[static_cast<size_t>(i * m_ny + j)] = add_tooth(*e, side, depth);
                }
            }
        }
        add_lakes();
        for (int i = 0; i < m_nx; ++i) {
            for (int j = 0; j < m_ny; ++j) {
                Unit u;
                u.cell = i * m_ny + j;
                // The cell lies on the + side (north, east) of its south and
                // west borders, on the - side of its east and north borders.
                std::vector<MicroDeg> ring = seen_from(m_h[i][j], +1); // south, west to east
                const auto east = seen_from(m_v[i + 1][j], -1), north = seen_from(m_h[i][j + 1], -1),
                           west = seen_from(m_v[i][j], +1);
                ring.insert(ring.end(), east.begin() + 1, east.end());     // east, going north
                ring.insert(ring.end(), north.rbegin() + 1, north.rend()); // north, going west
                ring.insert(ring.end(), west.rbegin() + 1, west.rend());   // west, going south
                u.rings.push_back(std::move(ring));
                u.point = tooth_point[static_cast<size_t>(u.cell)];
                const MicroDeg c{lon0 + i * cell + cell / 2, lat0 + j * cell + cell / 2};
                const size_t self = m_units.size();
                m_units.push_back(std::move(u));
                if (const auto& k4 = bay[static_cast<size_t>(m_units[self].cell)]) {
                    m_units[self].rings.push_back({k4->a, k4->b, k4->c, k4->a});
                    for (const auto& [p, q] : {std::pair{k4->a, k4->b}, {k4->b, k4->c}, {k4->c, k4->a}}) {
                        Unit tri;
                        tri.rings.push_back({p, q, k4->d, p});
                        tri.cell = m_units[self].cell;
                        tri.inner = true;
                        m_units.push_back(std::move(tri));
                    }
                }
                switch (integer(0, 3)) {
                case 0: { // strips, 20 to 80 micro-degrees of latitude (2.2 to 8.9 m) apart
                    const int64_t gaps[] = {20, 40, 80};
                    auto [a, b] = strips(c, gaps[integer(0, 2)]);
                    for (auto* s : {&a, &b}) {
                        m_units[self].rings.push_back(*s);
                        Unit strip;
                        strip.rings.push_back(std::move(*s));
                        strip.cell = m_units[self].cell;
                        strip.inner = true;
                        m_units.push_back(std::move(strip));
                    }
                    break;
                }
                case 1: { // an island of another county
                    auto shore = blob(c, cell * 0.09);
                    m_units[self].rings.push_back(shore);
                    Unit island;
                    island.rings.push_back(std::move(shore));
                    island.cell = m_units[self].cell;
                    island.inner = true;
                    m_units.push_back(std::move(island));
                    break;
                }
                case 2: // a lake
                    m_units[self].rings.push_back(blob(c, cell * 0.08));
                    break;
                default:
                    break;
                }
            }
        }
    }

    /// GEOID of unit u: state (2) + county (3) + tract (6).
    std::string geoid(Partitioning p, size_t u) const
    {
        const Unit& unit = m_units[u];
        const int i = unit.cell / m_ny, j = unit.cell % m_ny;
        int state = 1, county = 1;
        switch (p) {
        case Partitioning::whole:
            break;
        case Partitioning::blocks:
            county = 1 + (i / 2) * ((m_ny + 1) / 2) + j / 2 + (unit.inner ? 50 : 0);
            state = i < m_nx / 2 ? 1 : 2;
            break;
        case Partitioning::scattered: {
            // A fixed hash of the unit, not of the seed's draw order.
            const uint64_t h = (uint64_t(u) + 1) * 0x9E3779B97F4A7C15ULL;
            county = 1 + int((h >> 33) % 5);
            if (u % 7 == 3) {
                county = 100 + int(u); // a county of one tract
            }
            break;
        }
        }
        char buf[64];
        std::snprintf(buf, sizeof buf, "%02d%03d%06zu", state, county, u + 1);
        return buf;
    }

    std::mt19937_64 m_rng;
    int m_nx, m_ny;
    std::vector<std::vector<std::vector<MicroDeg>>> m_h, m_v;
    std::set<const std::vector<MicroDeg>*> m_toothed;
    std::vector<Unit> m_units;
    size_t m_teeth = 0, m_bays = 0;
}; // class AdversarialMap

} // namespace tigerlod::testing
