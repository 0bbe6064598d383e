#include "stages/ingest/regions.hpp"

#include "core/errors.hpp"
#include "core/geometry.hpp"
#include "core/memory.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <map>
#include <mutex>
#include <numbers>
#include <numeric>
#include <set>
#include <span>
#include <unordered_map>
#include <unordered_set>

namespace tigerlod::ingest {

namespace {

/// Boxes here are in micro-degrees: GridBoxes of (lon, lat).
GridPoint as_point(LonLatE6 p) noexcept
{
    return {p.lon, p.lat};
}

GridBox grown(const GridBox& b, int64_t dx, int64_t dy) noexcept
{
    return b.empty() ? b : GridBox{b.min_x - dx, b.min_y - dy, b.max_x + dx, b.max_y + dy};
}

/// The units on the two sides of polyline p (a polygon ring has one, the
/// other side being no_unit).
std::array<uint32_t, 2> sides(const RawMap& part, size_t p) noexcept
{
    return {part.left[p], part.right[p]};
}

std::vector<GridBox> unit_boxes(const RawMap& part)
{
    std::vector<GridBox> boxes(part.units.size());
    for (size_t p = 0; p < part.polyline_count(); ++p) {
        for (const uint32_t u : sides(part, p)) {
            if (u == no_unit) {
                continue;
            }
            for (uint64_t k = part.offsets[p]; k < part.offsets[p + 1]; ++k) {
                boxes[u].extend(as_point(part.coords[k]));
            }
        }
    }
    return boxes;
}

/// A region's map (or the whole map), put together from parts added in file
/// order, numbered as a whole read numbers units, polylines, files and classes.
class Assembly {
  public:
    /// `meta` gives kind, level names, files and classes; `class_of[i]` maps
    /// part i's classes to meta's.
    Assembly(const RawMap& meta, const std::vector<std::vector<uint32_t>>& class_of)
        : m_class_of(class_of), m_edges(meta.kind == RawMap::Kind::edges)
    {
        m_raw.kind = meta.kind;
        m_raw.level_names = meta.level_names;
        m_raw.files = meta.files;
        m_raw.classes = meta.classes;
    }

    /// Add part i: its units where `take`, and its polylines with a taken unit
    /// on a side (all of them for an own part). TIGER parts: a face or an edge
    /// that an earlier part gave is not added again, and an edge's sides are
    /// kept as TFIDs until finish().
    void add(size_t i, RawMap&& part, const std::vector<uint8_t>& take, bool own)
    {
        const size_t nparts = m_class_of.size();
        auto file_of = [&](uint32_t f) { return static_cast<uint32_t>(f * nparts + i); };
        std::vector<uint64_t> face(part.units.size());
        std::vector<uint32_t> new_id(part.units.size(), no_unit);
        for (size_t u = 0; u < part.units.size(); ++u) {
            face[u] = part.units[u].sid;
            if (!take[u]) {
                continue;
            }
            const auto id = static_cast<uint32_t>(m_raw.units.size());
            // TIGER: a face that two counties' files list is the first file's,
            // as a whole read keeps it; edges find their faces by TFID in finish().
            if (m_edges && !m_face_unit.try_emplace(face[u], id).second) {
                continue;
            }
            new_id[u] = id; // polygon rings: the unit's id in the map
            RawUnit unit = std::move(part.units[u]);
            unit.source.file = file_of(unit.source.file);
            m_raw.units.push_back(std::move(unit));
        }
        size_t k = 0; // part.foreign, in polyline order
        for (size_t p = 0; p < part.polyline_count(); ++p) {
            const auto [l, r] = sides(part, p);
            const auto first = static_cast<std::ptrdiff_t>(part.offsets[p]);
            const auto last = static_cast<std::ptrdiff_t>(part.offsets[p + 1]);
            const std::span<const LonLatE6> pts(part.coords.begin() + first, part.coords.begin() + last);
            const uint32_t cls = m_class_of[i][part.feature_class[p]];
            const SourceRef src{file_of(part.source[p].file), part.source[p].feature};
            if (!m_edges) {
                const uint32_t u = l != no_unit ? l : r;
                if (u != no_unit && take[u]) {
                    m_raw.add_polyline(pts, l == no_unit ? no_unit : new_id[l], r == no_unit ? no_unit : new_id[r], cls,
                                       part.source_id[p], src);
                }
                continue;
            }
            std::array<uint64_t, 2> faces{l == no_unit ? 0 : face[l], r == no_unit ? 0 : face[r]};
            for (; k < part.foreign.size() && part.foreign[k].polyline <= p; ++k) {
                if (part.foreign[k].polyline == p) {
                    faces[part.foreign[k].right != 0 ? 1 : 0] = part.foreign[k].face;
                }
            }
            const uint64_t tlid = part.source_id[p];
            if (m_seen.insert(tlid).second && own) {
                m_own_points += pts.size(); // the first file's copy of an edge counts
            }
            if (!own && !(l != no_unit && take[l]) && !(r != no_unit && take[r])) {
                continue;
            }
            if (auto it = m_edge.find(tlid); it != m_edge.end()) {
                // Another county's copy: it may know a side the first left open.
                m_copies.emplace_back(it->second, faces);
                continue;
            }
            m_edge.emplace(tlid, static_cast<uint32_t>(m_raw.polyline_count()));
            m_faces.push_back(faces);
            m_raw.add_polyline(pts, no_unit, no_unit, cls, tlid, src);
        }
        if (own && !m_edges) {
            m_own_points += part.points_read;
        }
        part = RawMap();
    }

    /// The map, TIGER edges' sides resolved to the faces added (no_unit for
    /// a face not taken, as for one no file holds).
    RawMap finish()
    {
        auto unit = [&](uint64_t face) {
            auto it = face == 0 ? m_face_unit.end() : m_face_unit.find(face);
            return it == m_face_unit.end() ? no_unit : it->second;
        };
        for (size_t p = 0; p < m_faces.size(); ++p) {
            m_raw.left[p] = unit(m_faces[p][0]);
            m_raw.right[p] = unit(m_faces[p][1]);
        }
        // A side still open takes the first later copy's face that is known,
        // as the whole read fills it (read_edges_file).
        for (const auto& [p, faces] : m_copies) {
            m_raw.left[p] = m_raw.left[p] == no_unit ? unit(faces[0]) : m_raw.left[p];
            m_raw.right[p] = m_raw.right[p] == no_unit ? unit(faces[1]) : m_raw.right[p];
        }
        return std::move(m_raw);
    }

    /// Input points of the own parts' polylines (TIGER: each edge once).
    uint64_t own_points() const noexcept { return m_own_points; }

  private:
    const std::vector<std::vector<uint32_t>>& m_class_of;
    bool m_edges;
    RawMap m_raw;
    uint64_t m_own_points = 0;
    // TIGER parts (TFIDs and TLIDs are never 0 there; 0 stands for "none").
    std::unordered_map<uint64_t, uint32_t> m_face_unit;                 ///< TFID -> unit
    std::unordered_map<uint64_t, uint32_t> m_edge;                      ///< TLID -> polyline
    std::vector<std::array<uint64_t, 2>> m_faces;                       ///< each polyline's TFIDs, left and right
    std::vector<std::pair<uint32_t, std::array<uint64_t, 2>>> m_copies; ///< later copies' TFIDs, in file order
    std::unordered_set<uint64_t> m_seen;                                ///< TLIDs of every part added
};

/// Coarse cells over lon/lat, for "does this box come near the region's units".
class CellSet {
  public:
    CellSet(int64_t cx, int64_t cy) : m_cx(cx), m_cy(cy) {}
    template <class F> void each(const GridBox& b, F&& f) const
    {
        for (int64_t ix = cell(b.min_x, m_cx); ix <= cell(b.max_x, m_cx); ++ix) {
            for (int64_t iy = cell(b.min_y, m_cy); iy <= cell(b.max_y, m_cy); ++iy) {
                f((static_cast<uint64_t>(ix) << 32) | static_cast<uint64_t>(iy));
            }
        }
    }
    void add(const GridBox& b)
    {
        each(b, [&](uint64_t k) { m_cells.push_back(k); });
    }
    void seal()
    {
        std::sort(m_cells.begin(), m_cells.end());
        m_cells.erase(std::unique(m_cells.begin(), m_cells.end()), m_cells.end());
    }
    bool meets(const GridBox& b) const
    {
        bool hit = false;
        each(b, [&](uint64_t k) { hit = hit || std::binary_search(m_cells.begin(), m_cells.end(), k); });
        return hit;
    }

  private:
    static int64_t cell(int64_t v, int64_t c) noexcept { return (v + 400'000'000) / c; }
    int64_t m_cx, m_cy;
    std::vector<uint64_t> m_cells;
};

size_t find_root(std::vector<size_t>& parent, size_t x)
{
    while (parent[x] != x) {
        parent[x] = parent[parent[x]];
        x = parent[x];
    }
    return x;
}

/// Sum a region's counts into `total`.
void add_result(BuildResult& total, BuildResult&& r, size_t first_level, size_t max_samples)
{
    for (size_t L = first_level; L < r.levels.size(); ++L) {
        auto& t = total.levels[L];
        const auto& l = r.levels[L];
        t.units += l.units;
        t.chains += l.chains;
        t.rings += l.rings;
        t.vertices += l.vertices;
        t.junctions += l.junctions;
        t.partitions += l.partitions;
        t.halo_chains += l.halo_chains;
        t.constraint_points += l.constraint_points;
        t.neighbour_points += l.neighbour_points;
        t.computed_internal_points += l.computed_internal_points;
    }
    for (const auto& [k, v] : r.problems) {
        total.problems[k] += v;
    }
    total.samples.insert(total.samples.end(), std::make_move_iterator(r.samples.begin()),
                         std::make_move_iterator(r.samples.end()));
    first_samples(total.samples, max_samples);
    total.unique_vertices += r.unique_vertices;
    total.edges += r.edges;
    for (auto& [name, s] : r.seconds) {
        auto it =
            std::find_if(total.seconds.begin(), total.seconds.end(), [&](const auto& p) { return p.first == name; });
        if (it == total.seconds.end()) {
            total.seconds.emplace_back(name, s);
        } else {
            it->second += s;
        }
    }
}

} // namespace

PartSummary summarize_part(const RawMap& part, size_t max_codes)
{
    PartSummary s;
    const size_t nlev = part.level_names.size();
    s.codes.resize(nlev);
    s.many.assign(nlev, 0);
    for (size_t L = 0; L < nlev; ++L) {
        auto& codes = s.codes[L];
        for (const auto& u : part.units) {
            codes.push_back(u.codes[L]);
        }
        std::sort(codes.begin(), codes.end());
        codes.erase(std::unique(codes.begin(), codes.end()), codes.end());
        if (codes.size() > max_codes) {
            release(codes);
            s.many[L] = 1;
        }
    }
    for (const auto& p : part.coords) {
        s.lo.lon = std::min(s.lo.lon, p.lon);
        s.lo.lat = std::min(s.lo.lat, p.lat);
        s.hi.lon = std::max(s.hi.lon, p.lon);
        s.hi.lat = std::max(s.hi.lat, p.lat);
    }
    s.points_read = part.points_read;
    s.empty_geometries = part.empty_geometries;
    s.kind = part.kind;
    s.files = part.files;
    s.classes = part.classes;
    if (part.kind == RawMap::Kind::edges) {
        for (size_t p = 0; p < part.polyline_count(); ++p) {
            s.unpaired_edges += part.left[p] == no_unit && part.right[p] == no_unit ? 1 : 0;
        }
    }
    return s;
}

namespace {

/// The region level: the first level with more than one code.
size_t region_level(const std::vector<PartSummary>& parts, size_t nlev)
{
    size_t R = nlev;
    for (size_t L = 0; L < nlev && R == nlev; ++L) {
        const std::string* first = nullptr;
        for (const auto& p : parts) {
            if (p.many[L] != 0) {
                R = L;
                break;
            }
            for (const auto& c : p.codes[L]) {
                if (first == nullptr) {
                    first = &c;
                } else if (c != *first) {
                    R = L;
                    break;
                }
            }
            if (R != nlev) {
                break;
            }
        }
    }
    return R;
}

/// A region: parts that share a code of the region level, and those codes.
struct Region {
    std::vector<size_t> parts;
    std::vector<std::string> own;
};

/// What build_by_regions does, step by step: the region level and the
/// regions (parts sharing a code of it), then for each region its map (its
/// own units, the whole finer units of the parts near that come within
/// reach, and every unit sharing a point with those) built and written, and
/// last the region level and the coarser ones from the regions' borders.
class RegionBuild {
  public:
    RegionBuild(const std::vector<PartSummary>& parts, const std::function<RawMap(size_t)>& load,
                const std::vector<std::string>& level_names, const Projection& projection, const BuildOptions& options,
                const StoreSink& sink)
        : m_parts(parts), m_load(load), m_level_names(level_names), m_projection(projection), m_options(options),
          m_sink(sink), m_R(region_level(parts, level_names.size()))
    {
    }

    BuildResult run()
    {
        const auto groups = group_parts();
        share_files_and_classes();
        if (!m_separable || groups.size() < 2) {
            return build_whole();
        }
        const auto regions = make_regions(groups);
        const size_t nlev = m_level_names.size();
        m_total.levels.resize(nlev);
        for (size_t L = 0; L < nlev; ++L) {
            m_total.levels[L].name = m_level_names[L];
        }
        const StoreSink checked = [this](const chains::ChainStore& s) { check_and_write(s); };
        const auto t_start = std::chrono::steady_clock::now();
        double build_s = 0;
        for (const Region& region : regions) {
            RawMap raw = assemble(region);
            m_total.region_map_units += raw.units.size();
            RegionScope scope;
            scope.level = m_R;
            scope.own = region.own;
            const auto t0 = std::chrono::steady_clock::now();
            add_result(m_total, build_region(std::move(raw), scope, m_projection, m_options, checked, m_coarse_in),
                       m_R + 1, m_options.max_problem_samples);
            build_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        }
        const double regions_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
        return finish_coarse(checked, regions_s, build_s);
    }

  private:
    void log(const std::string& what) const
    {
        if (m_options.log != nullptr) {
            m_options.log->info(what);
        }
    }

    /// Files that share a region-level code make one region (union-find),
    /// when the parts are separable: TIGER parts whose EDGES are not their
    /// FACES' county's are not.
    std::map<size_t, std::vector<size_t>> group_parts()
    {
        const auto& parts = m_parts;
        const size_t R = m_R, nlev = m_level_names.size(), nparts = parts.size();
        std::vector<size_t> parent(nparts);
        std::iota(parent.begin(), parent.end(), size_t{0});
        // TIGER parts whose EDGES are not their FACES' county's are not separable.
        m_separable = R < nlev && nparts > 1 && std::all_of(parts.begin(), parts.end(), [](const PartSummary& p) {
                          return p.unpaired_edges == 0;
                      });
        if (m_separable) {
            std::map<std::string, size_t> first_part;
            for (size_t i = 0; i < nparts && m_separable; ++i) {
                m_separable = parts[i].many[R] == 0;
                for (const auto& c : parts[i].codes[R]) {
                    auto [it, added] = first_part.try_emplace(c, i);
                    if (!added) {
                        parent[find_root(parent, i)] = find_root(parent, it->second);
                    }
                }
            }
        }
        std::map<size_t, std::vector<size_t>> groups;
        for (size_t i = 0; i < nparts; ++i) {
            groups[find_root(parent, i)].push_back(i);
        }
        return groups;
    }

    /// What every region's map shares: files and classes, numbered as a
    /// whole read numbers them (TIGER: every FACES file, then every EDGES file).
    void share_files_and_classes()
    {
        const auto& parts = m_parts;
        const size_t nparts = parts.size();
        auto& meta = m_meta;
        auto& class_of = m_class_of;
        meta.kind = nparts > 0 ? parts[0].kind : RawMap::Kind::polygon_rings;
        meta.level_names = m_level_names;
        class_of.resize(nparts);
        const size_t files_per_part = nparts > 0 ? parts[0].files.size() : 0;
        for (size_t f = 0; f < files_per_part; ++f) {
            for (size_t i = 0; i < nparts; ++i) {
                meta.files.push_back(f < parts[i].files.size() ? parts[i].files[f] : std::string());
            }
        }
        for (size_t i = 0; i < nparts; ++i) {
            for (const auto& c : parts[i].classes) {
                class_of[i].push_back(meta.intern_class(c));
            }
        }
    }

    /// One region: the whole map at once.
    BuildResult build_whole()
    {
        const size_t nparts = m_parts.size();
        Assembly whole(m_meta, m_class_of);
        uint64_t empty = 0;
        for (size_t i = 0; i < nparts; ++i) {
            RawMap part = m_load(i);
            empty += part.empty_geometries;
            const std::vector<uint8_t> all(part.units.size(), 1);
            whole.add(i, std::move(part), all, true);
        }
        RawMap raw = whole.finish();
        raw.points_read = whole.own_points();
        raw.empty_geometries = empty;
        log("building the map whole (one region)");
        return build_map(std::move(raw), m_projection, m_options, m_sink);
    }

    /// The regions, in the order of their codes; a group without a code of the region level is none.
    std::vector<Region> make_regions(const std::map<size_t, std::vector<size_t>>& groups) const
    {
        const size_t R = m_R;
        std::vector<Region> regions;
        for (auto& [root, members] : groups) {
            Region r;
            r.parts = members;
            for (size_t i : members) {
                r.own.insert(r.own.end(), m_parts[i].codes[R].begin(), m_parts[i].codes[R].end());
            }
            std::sort(r.own.begin(), r.own.end());
            r.own.erase(std::unique(r.own.begin(), r.own.end()), r.own.end());
            if (!r.own.empty()) {
                regions.push_back(std::move(r));
            }
        }
        std::sort(regions.begin(), regions.end(), [](const Region& a, const Region& b) { return a.own < b.own; });

        return regions;
    }

    /// Every store once: a partition written twice has units under two codes
    /// of the region level in different files.
    void check_and_write(const chains::ChainStore& s)
    {
        {
            const std::lock_guard lock(m_written_mutex);
            if (!m_written.insert(s.level_name + "/" + s.partition).second) {
                throw input_error("level '" + s.level_name + "': partition '" + s.partition +
                                  "' has units under two codes of level '" + m_level_names[m_R] +
                                  "' in different files: the codes do not nest");
            }
        }
        m_sink(s);
    }

    /// How far a region's results can depend on other units, in the input's
    /// 1e-6 degrees (x, y): three halo cells (find_near reaches up to about
    /// two) and a margin, for the smallest scale of the projection over `own_box`.
    std::pair<int64_t, int64_t> reach_of(const GridBox& own_box) const
    {
        const double reach_m = 3.0 * std::max(m_options.halo_m, 100.0) + 100.0;
        const Projection& projection = m_projection;
        double kmin = 1.0;
        double max_lat = 0.0;
        if (!own_box.empty()) {
            for (int64_t x : {own_box.min_x, (own_box.min_x + own_box.max_x) / 2, own_box.max_x}) {
                for (int64_t y : {own_box.min_y, (own_box.min_y + own_box.max_y) / 2, own_box.max_y}) {
                    const double k = projection.scale(static_cast<double>(x) * 1e-6, static_cast<double>(y) * 1e-6);
                    if (k > 0 && std::isfinite(k)) {
                        kmin = std::min({kmin, k, 1.0 / k});
                    }
                }
            }
            max_lat = static_cast<double>(std::max(std::abs(own_box.min_y), std::abs(own_box.max_y))) * 1e-6;
        }
        const double e_lat = 1.25 * reach_m / (110000.0 * kmin);
        const double e_lon =
            e_lat / std::max(0.01, std::cos(std::min(89.0, max_lat + e_lat) * std::numbers::pi / 180.0));
        const auto ex = static_cast<int64_t>(std::ceil(e_lon * 1e6)) + 1;
        const auto ey = static_cast<int64_t>(std::ceil(e_lat * 1e6)) + 1;

        return {ex, ey};
    }

    /// What a region's map is assembled from: which parts are its own, the
    /// parts near, the own parts already loaded, the points a unit of a
    /// part near could share with one taken (keys) and where those units
    /// lie (key_cells), and per part near its whole finer-level units within
    /// reach (core).
    struct Neighbourhood {
        std::vector<uint8_t> is_own;
        std::vector<size_t> near;
        std::vector<GridBox> near_boxes;
        std::map<size_t, RawMap> loaded;
        CellSet key_cells{50'000, 50'000};
        std::vector<uint64_t> keys;
        std::map<size_t, std::vector<uint8_t>> core;
    };

    /// The region's map, parts in file order: its own units, the whole
    /// finer-level units of the parts near that come within reach, and every
    /// unit that shares a point with one of those.
    RawMap assemble(const Region& region)
    {
        const auto& parts = m_parts;
        Neighbourhood nb;
        nb.is_own.assign(parts.size(), 0);
        GridBox own_box;
        for (size_t i : region.parts) {
            nb.is_own[i] = 1;
            if (parts[i].lo.lon <= parts[i].hi.lon) {
                own_box.extend(as_point(parts[i].lo));
                own_box.extend(as_point(parts[i].hi));
            }
        }
        const auto [ex, ey] = reach_of(own_box);
        find_parts_near(nb, grown(own_box, ex, ey));
        CellSet cells(std::max<int64_t>(ex, 50'000), std::max<int64_t>(ey, 50'000));
        load_own_parts(region, nb, cells, ex, ey);
        if (m_R + 1 < m_level_names.size()) { // finer levels: halos
            take_whole_units_near(nb, cells);
        }
        nb.key_cells.seal();
        std::sort(nb.keys.begin(), nb.keys.end());
        nb.keys.erase(std::unique(nb.keys.begin(), nb.keys.end()), nb.keys.end());

        Assembly assembly(m_meta, m_class_of);
        std::vector<size_t> order = region.parts;
        order.insert(order.end(), nb.near.begin(), nb.near.end());
        std::sort(order.begin(), order.end());
        size_t own_units = 0;
        for (size_t i : order) {
            RawMap part;
            if (auto it = nb.loaded.find(i); it != nb.loaded.end()) {
                part = std::move(it->second);
                nb.loaded.erase(it);
            } else {
                part = m_load(i);
            }
            const std::vector<uint8_t> take = units_to_take(i, part, nb);
            if (nb.is_own[i]) {
                own_units += part.units.size();
            }
            assembly.add(i, std::move(part), take, nb.is_own[i] != 0);
        }
        m_own_points += assembly.own_points();
        RawMap raw = assembly.finish();
        release(nb.keys);
        log("region " + region.own.front() + (region.own.size() > 1 ? "..." : "") + ": " + std::to_string(own_units) +
            " own units, " + std::to_string(raw.units.size() - own_units) + " neighbouring, " +
            std::to_string(raw.coords.size()) + " points");
        return raw;
    }

    /// The other parts whose box meets `near_box`.
    void find_parts_near(Neighbourhood& nb, const GridBox& near_box) const
    {
        for (size_t j = 0; j < m_parts.size(); ++j) {
            const auto& p = m_parts[j];
            const GridBox b{p.lo.lon, p.lo.lat, p.hi.lon, p.hi.lat};
            if (!nb.is_own[j] && b.intersects(near_box)) {
                nb.near.push_back(j);
                nb.near_boxes.push_back(b);
            }
        }
    }

    /// The own parts, their units' neighbourhood as cells (grown by the
    /// reach), and their points that a unit of a part near could share.
    void load_own_parts(const Region& region, Neighbourhood& nb, CellSet& cells, int64_t ex, int64_t ey) const
    {
        for (size_t i : region.parts) {
            RawMap part = m_load(i);
            for (const GridBox& b : unit_boxes(part)) {
                if (!b.empty()) {
                    cells.add(grown(b, ex, ey));
                    // Where the keys' units are: a unit of a part near whose
                    // box misses these cells shares no point with them, and
                    // is not searched.
                    nb.key_cells.add(b);
                }
            }
            for (const auto& p : part.coords) {
                const GridBox at{p.lon, p.lat, p.lon, p.lat};
                if (std::any_of(nb.near_boxes.begin(), nb.near_boxes.end(),
                                [&](const GridBox& b) { return b.intersects(at); })) {
                    nb.keys.push_back(pack_key(p));
                }
            }
            nb.loaded.emplace(i, std::move(part));
        }
        cells.seal();
    }

    /// The whole finer-level units (counties) of the parts near that come
    /// within reach (`cells`): taken, their points added to the keys.
    void take_whole_units_near(Neighbourhood& nb, const CellSet& cells) const
    {
        const size_t R = m_R;
        for (size_t j : nb.near) {
            const RawMap part = m_load(j);
            const auto boxes = unit_boxes(part);
            std::set<std::string> band;
            for (size_t u = 0; u < part.units.size(); ++u) {
                if (!boxes[u].empty() && cells.meets(boxes[u])) {
                    band.insert(part.units[u].codes[R + 1]);
                }
            }
            if (band.empty()) {
                continue;
            }
            auto& flags = nb.core[j];
            flags.assign(part.units.size(), 0);
            for (size_t u = 0; u < part.units.size(); ++u) {
                flags[u] = band.count(part.units[u].codes[R + 1]) != 0 ? 1 : 0;
            }
            for (size_t p = 0; p < part.polyline_count(); ++p) {
                const auto [l, r] = sides(part, p);
                if ((l != no_unit && flags[l]) || (r != no_unit && flags[r])) {
                    for (uint64_t k = part.offsets[p]; k < part.offsets[p + 1]; ++k) {
                        nb.keys.push_back(pack_key(part.coords[k]));
                    }
                }
            }
            for (size_t u = 0; u < part.units.size(); ++u) {
                if (flags[u] && !boxes[u].empty()) {
                    nb.key_cells.add(boxes[u]);
                }
            }
        }
    }

    /// The units of part i the region's map takes: all of an own part's;
    /// of a part near, its whole units near and every unit sharing a point
    /// (a key) with one taken.
    std::vector<uint8_t> units_to_take(size_t i, const RawMap& part, const Neighbourhood& nb) const
    {
        std::vector<uint8_t> take(part.units.size(), nb.is_own[i]);
        if (auto it = nb.core.find(i); it != nb.core.end()) {
            for (size_t u = 0; u < take.size(); ++u) {
                take[u] = take[u] | it->second[u];
            }
        }
        if (nb.is_own[i]) {
            return take;
        }
        // Only units whose box meets an own or whole neighbouring unit's
        // cells can share a point with one: the others are not searched
        // (every point of a neighbouring state was: 0.10 s of the tract set's
        // 0.27 s of region work).
        const auto boxes = unit_boxes(part);
        std::vector<uint8_t> maybe(part.units.size(), 0);
        for (size_t u = 0; u < maybe.size(); ++u) {
            maybe[u] = !boxes[u].empty() && nb.key_cells.meets(boxes[u]) ? 1 : 0;
        }
        for (size_t p = 0; p < part.polyline_count(); ++p) {
            // The sides not yet taken that may share a point.
            auto open = sides(part, p);
            for (uint32_t& u : open) {
                u = u == no_unit || take[u] || !maybe[u] ? no_unit : u;
            }
            if (open[0] == no_unit && open[1] == no_unit) {
                continue;
            }
            for (uint64_t k = part.offsets[p]; k < part.offsets[p + 1]; ++k) {
                if (std::binary_search(nb.keys.begin(), nb.keys.end(), pack_key(part.coords[k]))) {
                    for (const uint32_t u : open) {
                        if (u != no_unit) {
                            take[u] = 1;
                        }
                    }
                    break;
                }
            }
        }
        return take;
    }

    /// The region level and the coarser ones, from the regions' edges
    /// between codes; the totals.
    BuildResult finish_coarse(const StoreSink& checked, double regions_s, double build_s)
    {
        const size_t R = m_R, nlev = m_level_names.size();
        auto& total = m_total;
        auto& coarse_in = m_coarse_in;
        const auto& parts = m_parts;
        std::sort(coarse_in.units.begin(), coarse_in.units.end(), [](const RawUnit& a, const RawUnit& b) {
            return std::pair{a.source.file, a.source.feature} < std::pair{b.source.file, b.source.feature};
        });
        const auto t_coarse = std::chrono::steady_clock::now();
        BuildResult coarse =
            build_coarse(m_meta, std::move(coarse_in.units), coarse_in.edges, R, m_projection, m_options, checked);
        for (size_t L = 0; L <= R; ++L) {
            total.levels[L] = coarse.levels[L];
        }
        add_result(total, std::move(coarse), nlev, m_options.max_problem_samples);
        total.seconds.emplace_back("coarse_levels",
                                   std::chrono::duration<double>(std::chrono::steady_clock::now() - t_coarse).count());
        total.seconds.emplace_back("regions_load", regions_s - build_s);
        total.input_vertices = m_own_points;
        for (const auto& p : parts) {
            total.problems["empty_geometries"] += p.empty_geometries;
        }
        return std::move(total);
    }

    const std::vector<PartSummary>& m_parts;
    const std::function<RawMap(size_t)>& m_load;
    const std::vector<std::string>& m_level_names;
    const Projection& m_projection;
    const BuildOptions& m_options;
    const StoreSink& m_sink;
    const size_t m_R; ///< the region level
    bool m_separable = false;
    RawMap m_meta;                                 ///< files and classes every region's map shares
    std::vector<std::vector<uint32_t>> m_class_of; ///< per part, its classes' numbers in m_meta
    BuildResult m_total;
    std::mutex m_written_mutex;
    std::set<std::string> m_written; ///< level/partition of every store written
    RegionOutput m_coarse_in;        ///< the regions' units and edges for the coarse levels
    uint64_t m_own_points = 0;
}; // class RegionBuild

} // namespace

BuildResult build_by_regions(const std::vector<PartSummary>& parts, const std::function<RawMap(size_t)>& load,
                             const std::vector<std::string>& level_names, const Projection& projection,
                             const BuildOptions& options, const StoreSink& sink)
{
    return RegionBuild(parts, load, level_names, projection, options, sink).run();
}

} // namespace tigerlod::ingest
