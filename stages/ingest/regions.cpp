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
        m_raw.fields = meta.fields;
        m_raw.named = meta.named;
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
    for (const auto& [name, s] : r.seconds) {
        auto it = std::find_if(total.seconds.begin(), total.seconds.end(),
                               [&n = name](const auto& p) { return p.first == n; });
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
        if (s.many[L] != 0 || codes.size() > 1) {
            // The region level is at most this one (this part has two codes
            // here): the finer levels' codes are never asked for. (The 100 M
            // synthetic nation's blocks: the plan job's peak 820 -> 628 MiB.)
            break;
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
    s.empty_codes = part.empty_codes;
    s.kind = part.kind;
    s.files = part.files;
    s.classes = part.classes;
    s.fields = part.fields;
    s.named = part.named;
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

/// Parts that share a code of the region level and those codes (the regions
/// before their parts near are found).
struct Group {
    std::vector<size_t> parts;
    std::vector<std::string> own;
};

/// Files that share a region-level code make one region (union-find), when
/// the parts are separable: TIGER parts whose EDGES are not their FACES'
/// county's are not. Sets `separable`.
std::map<size_t, std::vector<size_t>> group_parts(const std::vector<PartSummary>& parts, size_t R, size_t nlev,
                                                  bool& separable)
{
    const size_t nparts = parts.size();
    std::vector<size_t> parent(nparts);
    std::iota(parent.begin(), parent.end(), size_t{0});
    separable = R < nlev && nparts > 1 &&
                std::all_of(parts.begin(), parts.end(), [](const PartSummary& p) { return p.unpaired_edges == 0; });
    if (separable) {
        std::map<std::string, size_t> first_part;
        for (size_t i = 0; i < nparts && separable; ++i) {
            separable = parts[i].many[R] == 0;
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

/// The groups in the order of their codes; a group without a code of the region level is none.
std::vector<Group> make_groups(const std::vector<PartSummary>& parts,
                               const std::map<size_t, std::vector<size_t>>& groups, size_t R)
{
    std::vector<Group> out;
    for (const auto& [root, members] : groups) {
        Group g;
        g.parts = members;
        for (size_t i : members) {
            g.own.insert(g.own.end(), parts[i].codes[R].begin(), parts[i].codes[R].end());
        }
        std::sort(g.own.begin(), g.own.end());
        g.own.erase(std::unique(g.own.begin(), g.own.end()), g.own.end());
        if (!g.own.empty()) {
            out.push_back(std::move(g));
        }
    }
    std::sort(out.begin(), out.end(), [](const Group& a, const Group& b) { return a.own < b.own; });
    return out;
}

/// How far a region's results can depend on other units, in the input's
/// 1e-6 degrees (x, y): three halo cells (find_near reaches up to about
/// two) and a margin, for the smallest scale of the projection over `own_box`.
std::pair<int64_t, int64_t> reach_of(const GridBox& own_box, const Projection& projection, double halo_m)
{
    const double reach_m = 3.0 * std::max(halo_m, 100.0) + 100.0;
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
    const double e_lon = e_lat / std::max(0.01, std::cos(std::min(89.0, max_lat + e_lat) * std::numbers::pi / 180.0));
    const auto ex = static_cast<int64_t>(std::ceil(e_lon * 1e6)) + 1;
    const auto ey = static_cast<int64_t>(std::ceil(e_lat * 1e6)) + 1;
    return {ex, ey};
}

/// The box of a region's own parts' points.
GridBox own_box_of(const RegionPlan& plan, const RegionPlan::Region& region)
{
    GridBox own_box;
    for (size_t i : region.parts) {
        const GridBox& b = plan.boxes[i];
        if (!b.empty()) {
            own_box.min_x = std::min(own_box.min_x, b.min_x);
            own_box.min_y = std::min(own_box.min_y, b.min_y);
            own_box.max_x = std::max(own_box.max_x, b.max_x);
            own_box.max_y = std::max(own_box.max_y, b.max_y);
        }
    }
    return own_box;
}

/// What a region's map is assembled from: which parts are its own, the
/// parts near, the own parts already loaded, the points a unit of a part
/// near could share with one taken (keys) and where those units lie
/// (key_cells), and per part near its whole finer-level units within reach
/// (core).
struct Neighbourhood {
    std::vector<uint8_t> is_own;
    std::vector<size_t> near;
    std::vector<GridBox> near_boxes;
    std::map<size_t, RawMap> loaded;
    CellSet key_cells{50'000, 50'000};
    std::vector<uint64_t> keys;
    std::map<size_t, std::vector<uint8_t>> core;
};

/// A region's map: its own units, the whole finer-level units of the parts
/// near that come within reach, and every unit that shares a point with one
/// of those, parts in file order.
class RegionAssembler {
  public:
    RegionAssembler(const RegionPlan& plan, const std::function<RawMap(size_t)>& load, const Projection& projection,
                    const BuildOptions& options)
        : m_plan(plan), m_load(load), m_projection(projection), m_options(options)
    {
    }

    /// Region r's map; `own_points` gets its own parts' input points.
    RawMap assemble(size_t r, uint64_t& own_points)
    {
        const RegionPlan::Region& region = m_plan.regions[r];
        const size_t nparts = m_plan.boxes.size();
        Neighbourhood nb;
        nb.is_own.assign(nparts, 0);
        for (size_t i : region.parts) {
            nb.is_own[i] = 1;
        }
        const auto [ex, ey] = reach_of(own_box_of(m_plan, region), m_projection, m_options.halo_m);
        nb.near = region.near;
        for (size_t j : nb.near) {
            nb.near_boxes.push_back(m_plan.boxes[j]);
        }
        CellSet cells(std::max<int64_t>(ex, 50'000), std::max<int64_t>(ey, 50'000));
        load_own_parts(region, nb, cells, ex, ey);
        if (m_plan.level + 1 < m_plan.meta.level_names.size()) { // finer levels: halos
            take_whole_units_near(nb, cells);
        }
        nb.key_cells.seal();
        std::sort(nb.keys.begin(), nb.keys.end());
        nb.keys.erase(std::unique(nb.keys.begin(), nb.keys.end()), nb.keys.end());

        Assembly assembly(m_plan.meta, m_plan.class_of);
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
        own_points = assembly.own_points();
        RawMap raw = assembly.finish();
        release(nb.keys);
        if (m_options.log != nullptr) {
            m_options.log->info("region " + region.own.front() + (region.own.size() > 1 ? "..." : "") + ": " +
                                std::to_string(own_units) + " own units, " +
                                std::to_string(raw.units.size() - own_units) + " neighbouring, " +
                                std::to_string(raw.coords.size()) + " points");
        }
        return raw;
    }

  private:
    /// The own parts, their units' neighbourhood as cells (grown by the
    /// reach), and their points that a unit of a part near could share.
    void load_own_parts(const RegionPlan::Region& region, Neighbourhood& nb, CellSet& cells, int64_t ex,
                        int64_t ey) const
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
        const size_t R = m_plan.level;
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
    static std::vector<uint8_t> units_to_take(size_t i, const RawMap& part, const Neighbourhood& nb)
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

    const RegionPlan& m_plan;
    const std::function<RawMap(size_t)>& m_load;
    const Projection& m_projection;
    const BuildOptions& m_options;
}; // class RegionAssembler

double seconds_since(std::chrono::steady_clock::time_point t0)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

} // namespace

RegionPlan plan_regions(const std::vector<PartSummary>& parts, const std::vector<std::string>& level_names,
                        const Projection& projection, const BuildOptions& options)
{
    RegionPlan plan;
    const size_t nlev = level_names.size(), nparts = parts.size();
    plan.level = region_level(parts, nlev);
    // What every region's map shares: files and classes, numbered as a whole
    // read numbers them (TIGER: every FACES file, then every EDGES file).
    auto& meta = plan.meta;
    meta.kind = nparts > 0 ? parts[0].kind : RawMap::Kind::polygon_rings;
    meta.level_names = level_names;
    plan.class_of.resize(nparts);
    const size_t files_per_part = nparts > 0 ? parts[0].files.size() : 0;
    for (size_t f = 0; f < files_per_part; ++f) {
        for (size_t i = 0; i < nparts; ++i) {
            meta.files.push_back(f < parts[i].files.size() ? parts[i].files[f] : std::string());
        }
    }
    for (size_t i = 0; i < nparts; ++i) {
        join_fields(meta.fields, parts[i].fields);
        meta.named = meta.named || parts[i].named;
        for (const auto& c : parts[i].classes) {
            plan.class_of[i].push_back(meta.intern_class(c));
        }
        plan.boxes.push_back(GridBox{parts[i].lo.lon, parts[i].lo.lat, parts[i].hi.lon, parts[i].hi.lat});
        plan.empty_geometries.push_back(parts[i].empty_geometries);
        plan.empty_codes.push_back(parts[i].empty_codes);
    }
    bool separable = false;
    const auto groups = group_parts(parts, plan.level, nlev, separable);
    plan.whole = !separable || groups.size() < 2;
    if (plan.whole) {
        return plan;
    }
    for (Group& g : make_groups(parts, groups, plan.level)) {
        RegionPlan::Region region;
        region.parts = std::move(g.parts);
        region.own = std::move(g.own);
        // The other parts whose box meets the own parts' box grown by the reach.
        const GridBox own_box = own_box_of(plan, region);
        const auto [ex, ey] = reach_of(own_box, projection, options.halo_m);
        const GridBox near_box = grown(own_box, ex, ey);
        std::vector<uint8_t> own(nparts, 0);
        for (size_t i : region.parts) {
            own[i] = 1;
        }
        for (size_t j = 0; j < nparts; ++j) {
            if (!own[j] && plan.boxes[j].intersects(near_box)) {
                region.near.push_back(j);
            }
        }
        plan.regions.push_back(std::move(region));
    }
    return plan;
}

RegionShare build_planned_region(const RegionPlan& plan, size_t r, const std::function<RawMap(size_t)>& load,
                                 const Projection& projection, const BuildOptions& options, const StoreSink& sink)
{
    RegionShare share;
    const auto t0 = std::chrono::steady_clock::now();
    RawMap raw = RegionAssembler(plan, load, projection, options).assemble(r, share.own_points);
    const double load_s = seconds_since(t0);
    share.map_units = raw.units.size();
    RegionScope scope;
    scope.level = plan.level;
    scope.own = plan.regions[r].own;
    share.result = build_region(std::move(raw), scope, projection, options, sink, share.coarse);
    share.result.seconds.emplace_back("regions_load", load_s);
    return share;
}

BuildResult build_planned_whole(const RegionPlan& plan, const std::function<RawMap(size_t)>& load,
                                const Projection& projection, const BuildOptions& options, const StoreSink& sink)
{
    const size_t nparts = plan.boxes.size();
    Assembly whole(plan.meta, plan.class_of);
    uint64_t empty = 0, empty_codes = 0;
    for (size_t i = 0; i < nparts; ++i) {
        RawMap part = load(i);
        empty += part.empty_geometries;
        empty_codes += part.empty_codes;
        const std::vector<uint8_t> all(part.units.size(), 1);
        whole.add(i, std::move(part), all, true);
    }
    RawMap raw = whole.finish();
    raw.points_read = whole.own_points();
    raw.empty_geometries = empty;
    raw.empty_codes = empty_codes;
    if (options.log != nullptr) {
        options.log->info("building the map whole (one region)");
    }
    return build_map(std::move(raw), projection, options, sink);
}

BuildResult finish_planned(const RegionPlan& plan, std::vector<RegionShare> shares, const Projection& projection,
                           const BuildOptions& options, const StoreSink& sink)
{
    const size_t R = plan.level, nlev = plan.meta.level_names.size();
    BuildResult total;
    total.levels.resize(nlev);
    for (size_t L = 0; L < nlev; ++L) {
        total.levels[L].name = plan.meta.level_names[L];
    }
    RegionOutput coarse_in;
    uint64_t own_points = 0;
    for (RegionShare& share : shares) {
        total.region_map_units += share.map_units;
        own_points += share.own_points;
        add_result(total, std::move(share.result), R + 1, options.max_problem_samples);
        std::move(share.coarse.units.begin(), share.coarse.units.end(), std::back_inserter(coarse_in.units));
        std::move(share.coarse.edges.begin(), share.coarse.edges.end(), std::back_inserter(coarse_in.edges));
        share = RegionShare();
    }
    std::sort(coarse_in.units.begin(), coarse_in.units.end(), [](const RawUnit& a, const RawUnit& b) {
        return std::pair{a.source.file, a.source.feature} < std::pair{b.source.file, b.source.feature};
    });
    const auto t_coarse = std::chrono::steady_clock::now();
    BuildResult coarse =
        build_coarse(plan.meta, std::move(coarse_in.units), coarse_in.edges, R, projection, options, sink);
    for (size_t L = 0; L <= R; ++L) {
        total.levels[L] = coarse.levels[L];
    }
    add_result(total, std::move(coarse), nlev, options.max_problem_samples);
    total.seconds.emplace_back("coarse_levels", seconds_since(t_coarse));
    total.input_vertices = own_points;
    for (const uint64_t e : plan.empty_geometries) {
        total.problems["empty_geometries"] += e;
    }
    for (const uint64_t e : plan.empty_codes) {
        total.problems["empty_codes"] += e;
    }
    return total;
}

void check_each_store_once(const RegionPlan& plan, const std::vector<std::vector<std::string>>& written,
                           const std::vector<std::string>& level_names)
{
    std::set<std::string> seen;
    for (const auto& stores : written) {
        for (const std::string& s : stores) {
            if (!seen.insert(s).second) {
                const size_t slash = s.find('/');
                throw input_error("level '" + s.substr(0, slash) + "': partition '" + s.substr(slash + 1) +
                                  "' has units under two codes of level '" + level_names[plan.level] +
                                  "' in different files: the codes do not nest");
            }
        }
    }
}

size_t planned_levels(const RegionPlan& plan)
{
    const size_t nlev = plan.meta.level_names.size();
    return plan.whole ? nlev : plan.regions.size() * (nlev - plan.level - 1) + plan.level + 1;
}

BuildResult build_by_regions(const std::vector<PartSummary>& parts, const std::function<RawMap(size_t)>& load,
                             const std::vector<std::string>& level_names, const Projection& projection,
                             const BuildOptions& options, const StoreSink& sink)
{
    const RegionPlan plan = plan_regions(parts, level_names, projection, options);
    if (plan.whole) {
        return build_planned_whole(plan, load, projection, options, sink); // build_map calls on_plan
    }
    if (options.on_plan) {
        options.on_plan(planned_levels(plan));
    }
    // Every store once: a partition written twice has units under two codes
    // of the region level in different files.
    std::mutex mutex;
    std::set<std::string> written;
    const StoreSink checked = [&](const chains::ChainStore& s) {
        {
            const std::lock_guard lock(mutex);
            const std::string name = s.level_name + "/" + s.partition;
            if (!written.insert(name).second) {
                check_each_store_once(plan, {{name}, {name}}, level_names);
            }
        }
        sink(s);
    };
    std::vector<RegionShare> shares;
    for (size_t r = 0; r < plan.regions.size(); ++r) {
        shares.push_back(build_planned_region(plan, r, load, projection, options, checked));
    }
    return finish_planned(plan, std::move(shares), projection, options, checked);
}

} // namespace tigerlod::ingest
