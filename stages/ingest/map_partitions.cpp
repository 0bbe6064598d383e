#include "stages/ingest/map_steps.hpp"

#include "core/errors.hpp"
#include "core/memory.hpp"
#include "core/parallel.hpp"
#include "core/radix_sort.hpp"
#include "core/segment_grid.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <future>
#include <map>
#include <mutex>
#include <numbers>
#include <numeric>
#include <stdexcept>
#include <tuple>
#include <thread>
#include <unordered_map>

namespace tigerlod::ingest::detail {

namespace {

/// The best point strictly inside a unit, from its boundary segments; std::nullopt if none found.
std::optional<GridPoint> point_inside(const std::vector<std::pair<GridPoint, GridPoint>>& segs)
{
    std::vector<int64_t> ys;
    for (const auto& [a, b] : segs) {
        ys.push_back(a.y);
    }
    std::sort(ys.begin(), ys.end());
    ys.erase(std::unique(ys.begin(), ys.end()), ys.end());
    // Candidate scan lines between consecutive vertex heights, widest gaps first,
    // preferring the middle of the unit.
    std::vector<std::pair<int64_t, int64_t>> gaps; // (gap, y)
    for (size_t i = 0; i + 1 < ys.size(); ++i) {
        if (ys[i + 1] - ys[i] >= 2) {
            gaps.push_back({ys[i + 1] - ys[i], ys[i] + (ys[i + 1] - ys[i]) / 2});
        }
    }
    std::sort(gaps.begin(), gaps.end(),
              [](auto a, auto b) { return a.first != b.first ? a.first > b.first : a.second < b.second; });
    if (gaps.size() > 24) {
        gaps.resize(24);
    }
    const size_t mid = ys.size() / 2;
    if (mid + 1 < ys.size() && ys[mid + 1] - ys[mid] >= 2) {
        gaps.insert(gaps.begin(), {0, ys[mid] + (ys[mid + 1] - ys[mid]) / 2});
    }
    std::vector<double> xs;
    for (const auto& gap : gaps) {
        const int64_t y = gap.second;
        xs.clear();
        for (const auto& [a, b] : segs) {
            if ((a.y > y) != (b.y > y)) {
                const double t = static_cast<double>(y - a.y) / static_cast<double>(int64_t{b.y} - a.y);
                xs.push_back(a.x + t * (static_cast<double>(int64_t{b.x} - a.x)));
            }
        }
        std::sort(xs.begin(), xs.end());
        double best = 0;
        std::optional<GridPoint> cand;
        for (size_t i = 0; i + 1 < xs.size(); i += 2) {
            if (xs[i + 1] - xs[i] > best) {
                const double x = std::nearbyint(0.5 * (xs[i] + xs[i + 1]));
                if (x > xs[i] && x < xs[i + 1]) {
                    best = xs[i + 1] - xs[i];
                    cand = GridPoint{static_cast<int32_t>(x), static_cast<int32_t>(y)};
                }
            }
        }
        if (cand) {
            PointInPolygon pip(*cand);
            for (const auto& [a, b] : segs) {
                pip.add_segment(a, b);
            }
            if (pip.location() == PointLocation::inside) {
                return cand;
            }
        }
    }
    return std::nullopt;
}

} // namespace

void log_progress(const BuildOptions& options, const std::string& what)
{
    if (options.log != nullptr) {
        options.log->info(what);
    }
}

namespace {

/// A tile's partition name: `x<column>y<row>`.
std::string tile_name(std::pair<int64_t, int64_t> t)
{
    char buf[48];
    std::snprintf(buf, sizeof buf, "x%lldy%lld", static_cast<long long>(t.first), static_cast<long long>(t.second));
    return buf;
}

/// A unit's internal point: the given one if strictly inside, else one computed.
struct UnitPoint {
    std::optional<GridPoint> pt;
    std::optional<GridPoint> rejected; // a given point not strictly inside
    bool computed = false;
    GridPoint near;
};

/// process_level step by step: the level's chains, each partition's owned
/// chains and halo, the units' internal points (the partition contract:
/// every unit an owned chain bounds), and one store per partition.
class LevelBuild {
  public:
    LevelBuild(const Graph& g, const EdgeEnds& ends, const RawMap& raw, const std::vector<LevelCodes>& lcs, size_t L,
               const std::vector<uint32_t>& bad_edges, const Projection& projection, const BuildOptions& options,
               const Owner& owner, const OwnedCodes& owned, std::vector<FoundProblem>& problems, const StoreSink& sink)
        : m_g(g), m_raw(raw), m_lcs(lcs), m_lc(lcs[L]), m_L(L), m_projection(projection), m_options(options),
          m_owner(owner), m_owned(owned), m_problems(problems), m_sink(sink), m_lev(build_level(g, ends, raw, lcs, L))
    {
        log_progress(options, "level " + raw.level_names[L] + ": built chains");
        for (uint32_t e : bad_edges) {
            if (m_lev.chain_of_edge[e] != none) {
                m_lev.chains[m_lev.chain_of_edge[e]].problem = true;
            }
        }
    }

    LevelStats run()
    {
        assign_owners();
        find_halos();
        find_units();
        m_st.name = m_raw.level_names[m_L];
        for (uint32_t code = 0; code < m_lc.codes.size() && m_raw.kind != RawMap::Kind::lines; ++code) {
            m_st.units += owns(m_L, code) ? 1 : 0;
        }
        for (uint32_t part = 0; part < m_npart; ++part) {
            m_st.partitions += owns_part(part) ? 1 : 0;
        }
        find_needed_units();
        compute_internal_points();
        record_points();
        record_attributes();
        collect_own_chains();
        parallel_each(m_npart, m_options.threads, [&](size_t part) { write_store(static_cast<uint32_t>(part)); });
        for (uint32_t v : m_lev.junctions) {
            m_st.junctions += m_owner.vertex(v) ? 1 : 0;
        }
        if (m_options.on_level) {
            m_options.on_level(m_st.chains);
        }
        log_progress(m_options, "level " + m_st.name + ": " + std::to_string(m_st.chains) + " chains in " +
                                    std::to_string(m_st.partitions) + " partitions");
        return m_st;
    }

  private:
    bool owns(size_t level, uint32_t code) const { return m_owned[level].empty() || m_owned[level][code] != 0; }
    uint32_t parent(uint32_t code) const { return m_L == 0 ? 0U : m_lc.parent[code]; }
    bool owns_part(uint32_t part) const { return m_L == 0 || owns(m_L - 1, part); }

    /// Partitions: the parent unit; a chain between two parents belongs to the smaller code.
    /// A line layer cut into tiles: the tile holding the chain's smallest vertex.
    void assign_owners()
    {
        const size_t L = m_L;
        const auto& lcs = m_lcs;
        if (m_raw.kind == RawMap::Kind::lines && m_options.line_tile_m > 0) {
            assign_tiles();
            return;
        }
        if (L > 0) {
            m_part_names = lcs[L - 1].codes;
            m_npart = static_cast<uint32_t>(m_part_names.size());
        }
        for (auto& c : m_lev.chains) {
            uint32_t o = none;
            for (uint32_t side : {c.left, c.right}) {
                if (side != none) {
                    o = std::min(o, parent(side));
                }
            }
            c.owner = o == none ? 0 : o;
        }
    }

    /// A line layer's grid tiles (TileGrid): squares of `line_tile_m`
    /// projected metres from the projection's origin, named by column and
    /// row (`x-3y12`). The chains are first cut where they stray out of their
    /// tile by more than an eighth of its side (cut_at_tiles), so that a
    /// tile's own chains lie in it and that margin; each piece belongs to the
    /// tile of its first vertex. Partitions are the tiles that own a chain,
    /// in name order; a layer within one tile is one partition, `all`.
    void assign_tiles()
    {
        const auto side = static_cast<int64_t>(std::llround(m_options.line_tile_m / m_projection.params().grid_m));
        if (side < 8) { // tigerlod-ingest refuses such a config up front
            throw std::invalid_argument("BuildOptions::line_tile_m below 8 grid steps");
        }
        const TileGrid grid{side, side / 8};
        m_st.tile_cuts = cut_at_tiles(m_lev, m_g, grid);
        std::map<std::string, std::vector<uint32_t>> by_name;
        for (uint32_t ci = 0; ci < m_lev.chains.size(); ++ci) {
            const auto t = grid.tile(m_g.grid[m_lev.chain(m_lev.chains[ci]).front()]);
            by_name[tile_name(t)].push_back(ci);
        }
        m_part_names.clear();
        for (const auto& [name, chains] : by_name) {
            for (uint32_t ci : chains) {
                m_lev.chains[ci].owner = static_cast<uint32_t>(m_part_names.size());
            }
            m_part_names.push_back(name);
        }
        if (m_part_names.size() <= 1) {
            m_part_names.assign(1, "all"); // one tile: the layer is one partition, as without tiles
        }
        m_npart = static_cast<uint32_t>(m_part_names.size());
    }

    /// Halo: chains of other partitions that bound one of the partition's
    /// units or come within the halo distance of its chains, found on cells
    /// at least as large as the distance. Cells of at least 100 m: a halo of
    /// 0 then holds the chains that come within about that, and the search
    /// stays fast.
    void find_halos()
    {
        const double halo_grid = std::max(m_options.halo_m, 100.0) / m_projection.params().grid_m;
        m_halo.resize(m_npart);
        if (m_npart > 1) {
            std::vector<SegmentRef> refs;
            size_t nrefs = 0;
            for (const auto& c : m_lev.chains) {
                nrefs += c.count - 1;
            }
            refs.reserve(nrefs);
            for (uint32_t ci = 0; ci < m_lev.chains.size(); ++ci) {
                const auto& c = m_lev.chains[ci];
                // A border between two parts bounds both: the other part's units need it.
                uint32_t also = none;
                for (uint32_t side : {c.left, c.right}) {
                    if (side != none && parent(side) != c.owner) {
                        also = parent(side);
                    }
                }
                const auto cv = m_lev.chain(c);
                for (size_t k = 0; k + 1 < cv.size(); ++k) {
                    refs.push_back({m_g.grid[cv[k]], m_g.grid[cv[k + 1]], ci, c.owner, also});
                }
            }
            for (const auto& [chain, part] : find_near(refs, halo_grid, m_options.threads)) {
                m_halo[part].push_back(chain);
            }
        }
    }

    /// Each code's boundary chains, and its representative finest unit: the
    /// heaviest with a given point.
    void find_units()
    {
        m_unit_chains.resize(m_lc.codes.size());
        for (uint32_t ci = 0; ci < m_lev.chains.size(); ++ci) {
            const auto& c = m_lev.chains[ci];
            if (c.left != none) {
                m_unit_chains[c.left].push_back(ci);
            }
            if (c.right != none && c.right != c.left) {
                m_unit_chains[c.right].push_back(ci);
            }
        }
        m_rep.assign(m_lc.codes.size(), none);
        for (uint32_t u = 0; u < m_raw.units.size(); ++u) {
            if (!m_raw.units[u].intpt) {
                continue;
            }
            uint32_t& r = m_rep[m_lc.of_unit[u]];
            if (r == none || m_raw.units[u].weight > m_raw.units[r].weight) {
                r = u;
            }
        }
    }

    /// The units whose internal point the stores need, and each
    /// partition's neighbours: the units of other partitions its chains bound.
    void find_needed_units()
    {
        m_npoints = m_raw.kind == RawMap::Kind::lines ? 0 : m_lc.codes.size();
        m_unit_points.resize(m_npoints);
        // The partition contract (formats/chains/SPEC.md): a store holds the
        // internal point of every unit that one of its own chains bounds, whoever
        // owns the unit, so that a shortcut never cuts a neighbour's point off.
        // The build has those units whole: a region takes the whole neighbouring
        // units within reach (regions.hpp), and a unit touching an owned chain is.
        m_needed.assign(m_npoints, 0);
        for (uint32_t code = 0; code < m_npoints; ++code) {
            m_needed[code] = owns(m_L, code) ? 1 : 0;
        }
        for (const auto& c : m_lev.chains) {
            if (m_npoints == 0 || !owns_part(c.owner)) {
                continue;
            }
            for (uint32_t side : {c.left, c.right}) {
                if (side != none && parent(side) != c.owner) {
                    m_needed[side] = 1;
                    m_neighbours.emplace_back(c.owner, side);
                }
            }
        }
        std::sort(m_neighbours.begin(), m_neighbours.end());
        m_neighbours.erase(std::unique(m_neighbours.begin(), m_neighbours.end()), m_neighbours.end());
    }

    /// The internal points, unit by unit on the worker threads (problems are
    /// recorded afterwards in code order).
    void compute_internal_points()
    {
        // A few thousand units whose cost varies with their boundary: 64 at a time.
        parallel_blocks(m_npoints, m_options.threads, 64, [&](size_t b, size_t e) {
            std::vector<std::pair<GridPoint, GridPoint>> useg;
            for (size_t code = b; code < e; ++code) {
                if (!m_needed[code]) {
                    continue;
                }
                useg.clear();
                for (uint32_t ci : m_unit_chains[code]) {
                    const auto cv = m_lev.chain(m_lev.chains[ci]);
                    for (size_t k = 0; k + 1 < cv.size(); ++k) {
                        useg.push_back({m_g.grid[cv[k]], m_g.grid[cv[k + 1]]});
                    }
                }
                UnitPoint& up = m_unit_points[code];
                up.near = useg.empty() ? GridPoint{} : useg.front().first;
                if (m_rep[code] != none) {
                    const LonLatE6 ll = *m_raw.units[m_rep[code]].intpt;
                    up.pt = m_projection.to_grid(ll.lon * 1e-6, ll.lat * 1e-6);
                    if (up.pt) {
                        PointInPolygon pip(*up.pt);
                        for (const auto& [a, c] : useg) {
                            pip.add_segment(a, c);
                        }
                        if (pip.location() != PointLocation::inside) {
                            up.rejected = up.pt;
                            up.pt.reset();
                        }
                    }
                }
                if (!up.pt) {
                    up.pt = point_inside(useg);
                    up.computed = up.pt.has_value();
                }
            }
        });
    }

    /// Each partition's own points, the problems in code order, and each
    /// partition's neighbour points.
    void record_points()
    {
        m_part_points.resize(m_npart);
        for (uint32_t code = 0; code < m_npoints; ++code) {
            if (!owns(m_L, code)) {
                continue;
            }
            const UnitPoint& up = m_unit_points[code];
            if (up.rejected) {
                m_problems.push_back(
                    {"internal_points_replaced", double(up.rejected->x), double(up.rejected->y),
                     m_raw.where(m_raw.units[m_rep[code]].source) + " (" + m_st.name + " " + m_lc.codes[code] + ")"});
            }
            m_st.computed_internal_points += up.computed;
            if (!up.pt) {
                m_problems.push_back({"missing_internal_points", double(up.near.x), double(up.near.y),
                                      m_st.name + " " + m_lc.codes[code]});
                continue;
            }
            m_part_points[parent(code)].push_back({code, chains::constraint_internal, *up.pt});
        }
        // Each partition's neighbour points: the units of other partitions that its chains bound.
        m_neighbour_points.resize(m_npart);
        for (const auto& [part, unit] : m_neighbours) {
            if (m_unit_points[unit].pt) {
                m_neighbour_points[part].push_back({unit, chains::constraint_neighbour, *m_unit_points[unit].pt});
            }
        }
    }

    /// The finest level's units' attributes (dataset.name_field and
    /// attributes), each partition's own: a unit takes the values of its
    /// largest feature (by weight, the least values among equal ones, so
    /// that the choice does not depend on the order features are read in).
    void record_attributes()
    {
        m_part_units.resize(m_npart);
        if (!m_raw.has_attributes() || m_L + 1 != m_lcs.size() || m_raw.kind == RawMap::Kind::lines) {
            return;
        }
        std::vector<uint32_t> rep(m_lc.codes.size(), none);
        for (uint32_t u = 0; u < m_raw.units.size(); ++u) {
            uint32_t& r = rep[m_lc.of_unit[u]];
            const RawUnit& c = m_raw.units[u];
            if (r == none || c.weight > m_raw.units[r].weight ||
                (c.weight == m_raw.units[r].weight && c.attrs < m_raw.units[r].attrs)) {
                r = u;
            }
        }
        for (uint32_t code = 0; code < m_lc.codes.size(); ++code) {
            if (owns(m_L, code) && rep[code] != none) {
                m_part_units[parent(code)].emplace_back(code, rep[code]);
            }
        }
    }

    /// Each partition's own chains in order of id (unique within the
    /// level), so that a store's strings come in an order that depends on
    /// its content alone; the level's counts.
    void collect_own_chains()
    {
        m_own.resize(m_npart);
        for (uint32_t ci = 0; ci < m_lev.chains.size(); ++ci) {
            const auto& c = m_lev.chains[ci];
            if (!owns_part(c.owner)) {
                continue;
            }
            m_own[c.owner].push_back(ci);
            m_st.chains += 1;
            m_st.rings += c.ring ? 1 : 0;
            m_st.vertices += c.count;
        }
        auto by_id = [&](uint32_t a, uint32_t b) { return m_lev.chains[a].id < m_lev.chains[b].id; };
        for (uint32_t part = 0; part < m_npart; ++part) {
            if (!owns_part(part)) {
                continue;
            }
            std::sort(m_own[part].begin(), m_own[part].end(), by_id);
            std::sort(m_halo[part].begin(), m_halo[part].end(), by_id);
            m_st.halo_chains += m_halo[part].size();
            m_st.constraint_points += m_part_points[part].size();
            m_st.neighbour_points += m_neighbour_points[part].size();
        }
    }

    /// One partition's store, built, encoded and handed to the sink (on a
    /// worker thread, each taking the next partition as it finishes one).
    void write_store(uint32_t part) const
    {
        std::vector<GridPoint> pts;
        if (!owns_part(part) || (m_own[part].empty() && m_part_points[part].empty())) {
            return;
        }
        chains::ChainStore s;
        s.level_index = static_cast<uint32_t>(m_L);
        s.level_count = static_cast<uint32_t>(m_lcs.size());
        s.level_name = m_st.name;
        s.partition = m_part_names[part];
        s.projection = m_projection.params();
        s.halo_m = m_options.halo_m;
        std::unordered_map<uint32_t, uint32_t> sidx;
        auto str = [&](uint32_t code) {
            if (code == none) {
                return 0U;
            }
            auto [it, added] = sidx.try_emplace(code, 0U);
            if (added) {
                it->second = s.intern(m_lc.codes[code]);
            }
            return it->second;
        };
        std::vector<uint32_t> cls_idx(m_raw.classes.size(), none);
        auto add = [&](uint32_t ci, bool is_halo) {
            const auto& c = m_lev.chains[ci];
            const auto cv = m_lev.chain(c);
            pts.clear();
            for (uint32_t v : cv) {
                pts.push_back(m_g.grid[v]);
            }
            if (cls_idx[c.cls] == none) {
                cls_idx[c.cls] = s.intern(m_raw.classes[c.cls]);
            }
            chains::ChainInfo info;
            info.id = c.id;
            info.left = str(c.left);
            info.right = str(c.right);
            info.feature_class = cls_idx[c.cls];
            info.flags = (cv.front() == cv.back() ? chains::chain_closed : 0U) | (is_halo ? chains::chain_halo : 0U) |
                         (c.problem ? chains::chain_problem : 0U);
            s.add_chain(info, pts);
        };
        for (uint32_t ci : m_own[part]) {
            add(ci, false);
        }
        for (uint32_t ci : m_halo[part]) {
            add(ci, true);
        }
        // Junctions at the ends of the partition's own chains.
        std::vector<uint32_t> chain_ends;
        for (uint32_t ci : m_own[part]) {
            const auto cv = m_lev.chain(m_lev.chains[ci]);
            chain_ends.push_back(cv.front());
            chain_ends.push_back(cv.back());
        }
        std::sort(chain_ends.begin(), chain_ends.end());
        chain_ends.erase(std::unique(chain_ends.begin(), chain_ends.end()), chain_ends.end());
        for (uint32_t v : chain_ends) {
            auto it = std::lower_bound(m_lev.junctions.begin(), m_lev.junctions.end(), v);
            if (it != m_lev.junctions.end() && *it == v) {
                const auto k = static_cast<size_t>(it - m_lev.junctions.begin());
                s.junctions.push_back({m_g.keys[v], m_g.grid[v], m_lev.junction_degree[k]});
            }
        }
        for (const auto* points : {&m_part_points[part], &m_neighbour_points[part]}) {
            for (const auto& cp : *points) {
                s.constraints.push_back({str(cp.unit), cp.kind, cp.p});
            }
        }
        if (m_raw.has_attributes() && m_L + 1 == m_lcs.size()) {
            s.fields = m_raw.fields;
            for (const auto& [code, u] : m_part_units[part]) {
                const auto& attrs = m_raw.units[u].attrs;
                chains::UnitRecord rec;
                rec.unit = str(code);
                rec.name = attrs.empty() ? std::string() : attrs.front();
                rec.values.assign(attrs.begin() + (attrs.empty() ? 0 : 1), attrs.end());
                rec.values.resize(s.fields.size());
                s.units.push_back(std::move(rec));
            }
        }
        s.canonicalize();
        m_sink(s);
    }

    const Graph& m_g;
    const RawMap& m_raw;
    const std::vector<LevelCodes>& m_lcs;
    const LevelCodes& m_lc;
    const size_t m_L;
    const Projection& m_projection;
    const BuildOptions& m_options;
    const Owner& m_owner;
    const OwnedCodes& m_owned;
    std::vector<FoundProblem>& m_problems;
    const StoreSink& m_sink;
    Level m_lev;
    uint32_t m_npart = 1;
    std::vector<std::string> m_part_names{"all"};
    std::vector<std::vector<uint32_t>> m_halo;        ///< per partition
    std::vector<std::vector<uint32_t>> m_unit_chains; ///< per code
    std::vector<uint32_t> m_rep;                      ///< per code: its representative finest unit
    LevelStats m_st;
    size_t m_npoints = 0; ///< codes with an internal point (none for a line layer)
    std::vector<UnitPoint> m_unit_points;
    std::vector<uint8_t> m_needed;
    std::vector<std::pair<uint32_t, uint32_t>>
        m_neighbours; ///< (partition, unit of another partition its chain bounds)
    std::vector<std::vector<chains::ConstraintPoint>> m_part_points, m_neighbour_points;
    std::vector<std::vector<uint32_t>> m_own; ///< per partition, its chains
    /// Per partition, its own units of the finest level as (code, the raw
    /// unit whose attributes it takes); empty without attributes.
    std::vector<std::vector<std::pair<uint32_t, uint32_t>>> m_part_units;
}; // class LevelBuild

} // namespace

LevelStats process_level(const Graph& g, const EdgeEnds& ends, const RawMap& raw, const std::vector<LevelCodes>& lcs,
                         size_t L, const std::vector<uint32_t>& bad_edges, const Projection& projection,
                         const BuildOptions& options, const Owner& owner, const OwnedCodes& owned,
                         std::vector<FoundProblem>& problems, const StoreSink& sink)
{
    return LevelBuild(g, ends, raw, lcs, L, bad_edges, projection, options, owner, owned, problems, sink).run();
}

} // namespace tigerlod::ingest::detail
