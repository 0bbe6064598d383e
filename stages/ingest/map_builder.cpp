#include "stages/ingest/map_builder.hpp"

#include "core/errors.hpp"
#include "core/memory.hpp"
#include "core/parallel.hpp"
#include "core/radix_sort.hpp"
#include "core/segment_grid.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <future>
#include <mutex>
#include <numbers>
#include <numeric>
#include <stdexcept>
#include <tuple>
#include <thread>
#include <unordered_map>

namespace tigerlod::ingest {

namespace {

constexpr uint32_t none = UINT32_MAX;

const std::vector<std::string> kinds = {"crossings",
                                        "touches",
                                        "overlaps",
                                        "overlapping_polygons",
                                        "duplicate_points",
                                        "spikes",
                                        "merged_vertices",
                                        "degenerate_polylines",
                                        "non_nesting_units",
                                        "unreferenced_units",
                                        "internal_points_replaced",
                                        "missing_internal_points",
                                        "empty_geometries",
                                        "snap_repairs",
                                        "duplicate_segments"};

uint64_t splitmix(uint64_t x) noexcept
{
    x += 0x9E3779B97F4A7C15ULL;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
    return x ^ (x >> 31);
}

/// Everything the levels share: interned vertices and cleaned edges.
struct Graph {
    std::vector<uint64_t> keys;  // vertex id -> packed lon/lat
    std::vector<GridPoint> grid; // vertex id -> grid point
    std::vector<uint32_t> verts; // edge i is verts[off[i], off[i+1])
    std::vector<uint64_t> off{0};
    std::vector<uint32_t> left, right, cls;
    std::vector<uint64_t> sid;
    std::vector<SourceRef> src;
    size_t edge_count() const noexcept { return left.size(); }
    std::span<const uint32_t> edge(size_t i) const noexcept { return {verts.data() + off[i], off[i + 1] - off[i]}; }
};

/// A problem found on a worker thread, recorded later in a fixed order so
/// that the report does not depend on the threads.
struct FoundProblem {
    const char* kind;
    double x, y; ///< grid units
    std::string where;
};

class Problems {
  public:
    Problems(BuildResult& r, const Projection& proj, size_t max_samples) : m_r(r), m_proj(proj), m_max(max_samples)
    {
        for (const auto& k : kinds) {
            m_r.problems[k] = 0;
        }
    }
    void count(const std::string& kind, uint64_t n = 1) { m_r.problems[kind] += n; }
    void add(const std::string& kind, double gx, double gy, std::string where)
    {
        count(kind);
        if (m_max > 0) {
            ProblemSample s{kind, 0, 0, std::move(where)};
            m_proj.to_lonlat(gx, gy, s.lon_deg, s.lat_deg);
            keep(std::move(s));
        }
    }
    /// Record `found` in its order.
    void add_all(std::vector<FoundProblem>&& found)
    {
        for (auto& f : found) {
            add(f.kind, f.x, f.y, std::move(f.where));
        }
    }
    void add_lonlat(const std::string& kind, LonLatE6 p, std::string where)
    {
        count(kind);
        if (m_max > 0) {
            keep({kind, p.lon * 1e-6, p.lat * 1e-6, std::move(where)});
        }
    }
    /// The samples kept, in their order.
    void finish() { first_samples(m_r.samples, m_max); }

  private:
    void keep(ProblemSample&& s)
    {
        m_r.samples.push_back(std::move(s));
        if (m_r.samples.size() >= 2 * m_max + 64) {
            first_samples(m_r.samples, m_max);
        }
    }
    BuildResult& m_r;
    const Projection& m_proj;
    size_t m_max;
};

/// What a build counts and reports: everything, for a whole map; for a region
/// (RegionScope), what concerns one of its own codes first: the smallest
/// region-level code among the units around a vertex, on the sides of an edge
/// or a pair of edges, or of a unit. Each such thing then belongs to exactly
/// one region, and that region holds all the units it depends on.
struct Owner {
    std::span<const uint32_t> unit_rank; ///< unit -> region-level code id (LevelCodes::of_unit); empty for a whole map
    std::vector<uint8_t> own_rank;       ///< region-level code id -> own
    std::vector<uint32_t> vertex_rank;

    bool whole() const noexcept { return unit_rank.empty(); }
    uint32_t rank(uint32_t u) const noexcept { return u == no_unit || whole() ? none : unit_rank[u]; }
    bool of_rank(uint32_t r) const noexcept { return whole() || (r != none && own_rank[r] != 0); }
    bool unit(uint32_t u) const noexcept { return whole() || of_rank(rank(u)); }
    bool units(uint32_t a, uint32_t b) const noexcept { return whole() || of_rank(std::min(rank(a), rank(b))); }
    bool vertex(uint32_t v) const noexcept { return whole() || of_rank(vertex_rank[v]); }
};

/// Contiguous ranges of at least 4096 items per thread.
template <class F> void parallel_for(size_t n, unsigned threads, F&& f)
{
    parallel_ranges(n, threads, 4096, std::forward<F>(f));
}

/// Intern and project the vertices, then clean every polyline.
Graph make_graph(RawMap& raw, const Projection& proj, unsigned threads, Problems& problems, Owner& owner)
{
    Graph g;
    // Sort (key, occurrence) by key: vertex ids follow the keys, so they do not
    // depend on the order of the input.
    std::vector<std::pair<uint64_t, uint32_t>> occ(raw.coords.size());
    for (size_t i = 0; i < occ.size(); ++i) {
        occ[i] = {pack_key(raw.coords[i]), static_cast<uint32_t>(i)};
    }
    // The points are in `occ` now, and every later use goes through their
    // vertex ids: freed before the sort, they do not add to its peak.
    release(raw.coords);
    radix_sort_pairs(occ, threads);
    std::vector<uint32_t> id(occ.size());
    size_t unique = 0;
    for (size_t i = 0; i < occ.size(); ++i) {
        unique += i == 0 || occ[i].first != occ[i - 1].first ? 1 : 0;
    }
    g.keys.reserve(unique);
    for (size_t i = 0; i < occ.size(); ++i) {
        if (i == 0 || occ[i].first != occ[i - 1].first) {
            g.keys.push_back(occ[i].first);
        }
        id[occ[i].second] = static_cast<uint32_t>(g.keys.size() - 1);
    }
    release(occ);
    g.grid.resize(g.keys.size());
    std::vector<uint8_t> bad(g.keys.size(), 0);
    std::mutex lat_mutex;
    int32_t lat_lo = INT32_MAX, lat_hi = INT32_MIN;
    parallel_for(g.keys.size(), threads, [&](size_t b, size_t e) {
        int32_t lo = INT32_MAX, hi = INT32_MIN;
        for (size_t v = b; v < e; ++v) {
            const LonLatE6 ll = unpack_key(g.keys[v]);
            lo = std::min(lo, ll.lat);
            hi = std::max(hi, ll.lat);
            auto gp = proj.to_grid(ll.lon * 1e-6, ll.lat * 1e-6);
            if (gp) {
                g.grid[v] = *gp;
            } else {
                bad[v] = 1;
            }
        }
        const std::lock_guard lock(lat_mutex);
        lat_lo = std::min(lat_lo, lo);
        lat_hi = std::max(lat_hi, hi);
    });
    if (auto it = std::find(bad.begin(), bad.end(), 1); it != bad.end()) {
        const auto v = static_cast<uint32_t>(it - bad.begin());
        const LonLatE6 ll = unpack_key(g.keys[v]);
        std::string where = "an input";
        for (size_t p = 0; p < raw.polyline_count(); ++p) {
            bool found = false;
            for (uint64_t k = raw.offsets[p]; k < raw.offsets[p + 1] && !found; ++k) {
                found = id[k] == v;
            }
            if (found) {
                where = raw.where(raw.source[p]);
                break;
            }
        }
        char buf[160];
        std::snprintf(buf, sizeof buf, "coordinate (%.6f, %.6f) is outside the domain of projection ", ll.lon * 1e-6,
                      ll.lat * 1e-6);
        throw input_error(where + ": " + buf + proj.describe());
    }
    // Distinct snapped points that round onto one grid point become one vertex.
    // That needs points closer than a grid cell's diagonal, which the 1e-6
    // degree lattice cannot have where its projected spacing is wider (a 1 cm
    // grid anywhere short of the polar caps): then the search is skipped.
    std::vector<uint32_t> remap(g.keys.size());
    std::iota(remap.begin(), remap.end(), 0U);
    std::vector<uint32_t> merged;
    const double spacing =
        g.keys.empty() ? 0.0 : proj.lattice_separation_m(1e-6, lat_lo * 1e-6, lat_hi * 1e-6) / proj.params().grid_m;
    if (!(spacing > std::numbers::sqrt2)) {
        std::vector<std::pair<uint64_t, uint32_t>> by_grid(g.keys.size());
        for (uint32_t v = 0; v < g.keys.size(); ++v) {
            by_grid[v] = {(uint64_t{static_cast<uint32_t>(g.grid[v].x) ^ 0x80000000U} << 32) |
                              (static_cast<uint32_t>(g.grid[v].y) ^ 0x80000000U),
                          v};
        }
        radix_sort_pairs(by_grid, threads); // the smallest id comes first among equals
        for (size_t i = 1; i < by_grid.size(); ++i) {
            if (by_grid[i].first == by_grid[i - 1].first) {
                const uint32_t v = by_grid[i].second;
                remap[v] = remap[by_grid[i - 1].second];
                if (owner.whole()) {
                    problems.add("merged_vertices", g.grid[v].x, g.grid[v].y, "");
                } else {
                    merged.push_back(v); // counted once the owners of the vertices are known
                }
            }
        }
    }
    // Clean each polyline: repeated points, then p-q-p spikes.
    g.verts.reserve(id.size());
    if (!owner.whole()) {
        owner.vertex_rank.assign(g.keys.size(), none);
        for (size_t p = 0; p < raw.polyline_count(); ++p) {
            const uint32_t r = std::min(owner.rank(raw.left[p]), owner.rank(raw.right[p]));
            for (uint64_t k = raw.offsets[p]; k < raw.offsets[p + 1]; ++k) {
                owner.vertex_rank[id[k]] = std::min(owner.vertex_rank[id[k]], r);
            }
        }
        for (uint32_t v : merged) {
            if (owner.vertex(v)) {
                problems.add("merged_vertices", g.grid[v].x, g.grid[v].y, "");
            }
        }
    }
    std::vector<uint32_t> buf;
    for (size_t p = 0; p < raw.polyline_count(); ++p) {
        const bool mine = owner.units(raw.left[p], raw.right[p]);
        buf.clear();
        for (uint64_t k = raw.offsets[p]; k < raw.offsets[p + 1]; ++k) {
            const uint32_t v = remap[id[k]];
            if (!buf.empty() && buf.back() == v) {
                if (mine) {
                    problems.add("duplicate_points", g.grid[v].x, g.grid[v].y, raw.where(raw.source[p]));
                }
                continue;
            }
            buf.push_back(v);
            while (buf.size() >= 3 && buf[buf.size() - 1] == buf[buf.size() - 3]) {
                const uint32_t q = buf[buf.size() - 2];
                if (mine) {
                    problems.add("spikes", g.grid[q].x, g.grid[q].y, raw.where(raw.source[p]));
                }
                buf.resize(buf.size() - 2);
            }
        }
        while (buf.size() >= 4 && buf.front() == buf.back() && buf[1] == buf[buf.size() - 2]) {
            if (mine) {
                problems.add("spikes", g.grid[buf.front()].x, g.grid[buf.front()].y, raw.where(raw.source[p]));
            }
            buf.erase(buf.begin());
            buf.pop_back();
        }
        if (buf.size() < 2 || (buf.size() < 4 && buf.front() == buf.back())) {
            if (mine) {
                problems.add_lonlat("degenerate_polylines", unpack_key(g.keys[id[raw.offsets[p]]]),
                                    raw.where(raw.source[p]));
            }
            continue;
        }
        g.verts.insert(g.verts.end(), buf.begin(), buf.end());
        g.off.push_back(g.verts.size());
        g.left.push_back(raw.left[p]);
        g.right.push_back(raw.right[p]);
        g.cls.push_back(raw.feature_class[p]);
        g.sid.push_back(raw.source_id[p]);
        g.src.push_back(raw.source[p]);
    }
    release(raw.offsets);
    return g;
}

/// One segment after merge_segments: its vertices (a < b), the units on each
/// side (left of a->b), and the input polyline it came from.
struct Piece {
    std::array<uint32_t, 2> ab;
    uint32_t left, right;
    uint32_t edge;
};

/// Split polygon rings into segments and merge the segments that neighbouring
/// polygons share into one piece with a unit on each side. For a line layer,
/// split the lines and keep one of each set of identical segments (a river
/// stored twice becomes one chain), counted as `duplicate_segments`.
std::vector<Piece> merge_segments(const Graph& g, const RawMap& raw, unsigned threads, Problems& problems,
                                  const Owner& owner)
{
    const bool lines = raw.kind == RawMap::Kind::lines;
    if (g.edge_count() >= (size_t{1} << 31)) {
        throw input_error("more than 2^31 polylines in one map");
    }
    // Segment k of edge i is record off[i] - i + k: its key (a < b), with the
    // edge and whether the edge's unit is on the left of a->b as its value.
    const size_t nrec = g.verts.size() - g.edge_count();
    std::vector<std::pair<uint64_t, uint32_t>> keys(nrec);
    // A few thousand rings of very unequal length: 16 at a time.
    parallel_blocks(g.edge_count(), threads, 16, [&](size_t eb, size_t ee) {
        for (size_t i = eb; i < ee; ++i) {
            const auto e = g.edge(i);
            const bool on_left_of_given = g.left[i] != no_unit;
            const size_t r0 = g.off[i] - i;
            for (size_t k = 0; k + 1 < e.size(); ++k) {
                const bool forward = e[k] < e[k + 1];
                keys[r0 + k] = {(uint64_t{std::min(e[k], e[k + 1])} << 32) | std::max(e[k], e[k + 1]),
                                static_cast<uint32_t>(i * 2 + (forward == on_left_of_given ? 1 : 0))};
            }
        }
    });
    // Sorted by (a, b, edge * 2 + side): each key's records in edge order.
    radix_sort_pairs(keys, threads);
    auto edge_of = [&](size_t j) { return keys[j].second / 2; };
    auto unit_of = [&](size_t j) {
        const uint32_t e = edge_of(j);
        return g.left[e] != no_unit ? g.left[e] : g.right[e];
    };
    // The scan on contiguous parts that start where a key does. A first pass
    // counts each part's pieces, so the second writes them straight into
    // their place in the result (no per-part copies beside the sorted keys);
    // problems are put together in part order afterwards.
    const unsigned nparts = std::max(1U, std::min<unsigned>(threads, static_cast<unsigned>(nrec / 65536 + 1)));
    const std::vector<size_t> bounds = key_aligned_parts(keys, nparts);
    // The records of the key at i: where they end, the units on each side,
    // and whether a side was claimed twice.
    struct Group {
        size_t end;
        uint32_t left, right;
        bool conflict;
    };
    auto group = [&](size_t i) {
        Group gr{i, no_unit, no_unit, false};
        for (; gr.end < nrec && keys[gr.end].first == keys[i].first; ++gr.end) {
            uint32_t& slot = (keys[gr.end].second & 1U) ? gr.left : gr.right;
            if (slot == no_unit) {
                slot = unit_of(gr.end);
            } else {
                gr.conflict = true;
            }
        }
        if (lines) {
            gr.left = gr.right = no_unit;
        }
        return gr;
    };
    // The same polygon on both sides: a slit or spike in its ring, never a boundary.
    auto is_spike = [](const Group& gr) { return gr.left != no_unit && gr.left == gr.right; };
    std::vector<size_t> first_piece(nparts + 1, 0);
    parallel_each(nparts, threads, [&](size_t t) {
        size_t n = 0;
        for (size_t i = bounds[t]; i < bounds[t + 1];) {
            const Group gr = group(i);
            n += is_spike(gr) ? 0 : 1;
            i = gr.end;
        }
        first_piece[t + 1] = n;
    });
    for (unsigned t = 0; t < nparts; ++t) {
        first_piece[t + 1] += first_piece[t];
    }
    std::vector<Piece> out(first_piece[nparts]);
    std::vector<std::vector<FoundProblem>> found(nparts);
    parallel_each(nparts, threads, [&](size_t t) {
        size_t w = first_piece[t];
        for (size_t i = bounds[t]; i < bounds[t + 1];) {
            const Group gr = group(i);
            const size_t j = gr.end;
            const auto a = static_cast<uint32_t>(keys[i].first >> 32), b = static_cast<uint32_t>(keys[i].first);
            const uint32_t first_edge = edge_of(i);
            const GridPoint pa = g.grid[a], pb = g.grid[b];
            const double mx = pa.x + 0.5 * (pb.x - pa.x), my = pa.y + 0.5 * (pb.y - pa.y);
            if (lines) {
                if (j - i > 1) {
                    found[t].push_back({"duplicate_segments", mx, my,
                                        raw.where(g.src[first_edge]) + " " + raw.where(g.src[edge_of(i + 1)])});
                }
            } else if (gr.conflict) {
                uint32_t rank = none;
                for (size_t k = i; k < j; ++k) {
                    rank = std::min(rank, owner.rank(unit_of(k)));
                }
                std::string where;
                for (size_t k = i; k < j && owner.of_rank(rank); ++k) {
                    if (!where.empty()) {
                        where += ' ';
                    }
                    where += raw.where(g.src[edge_of(k)]);
                }
                if (owner.of_rank(rank)) {
                    found[t].push_back({"overlapping_polygons", mx, my, std::move(where)});
                }
            }
            if (is_spike(gr)) {
                if (owner.unit(gr.left)) {
                    found[t].push_back(
                        {"spikes", static_cast<double>(pa.x), static_cast<double>(pa.y), raw.where(g.src[first_edge])});
                }
            } else {
                out[w++] = {{a, b}, gr.left, gr.right, first_edge};
            }
            i = j;
        }
    });
    release(keys);
    for (auto& f : found) {
        problems.add_all(std::move(f));
    }
    return out;
}

/// Join the pieces end to end where exactly two piece ends meet at a vertex
/// and the units on each side and the feature class carry through it: the
/// edges become the runs between junctions (the finest level's chains), which
/// the planarity check and every level then walk instead of single segments.
/// The chains a level builds are the same either way. Pieces are taken in
/// order, so the result depends on nothing but the input.
void join_pieces(Graph& g, const std::vector<Piece>& pieces)
{
    const size_t nv = g.keys.size();
    const auto np = static_cast<uint32_t>(pieces.size());
    // The first two piece ends at each vertex (piece * 2 + 1 if it is b there),
    // and how many there are, saturating at 3.
    std::vector<std::array<uint32_t, 2>> at(nv);
    std::vector<uint8_t> count(nv, 0);
    for (uint32_t p = 0; p < np; ++p) {
        for (uint32_t side = 0; side < 2; ++side) {
            const uint32_t v = pieces[p].ab[side];
            if (count[v] < 2) {
                at[v][count[v]] = p * 2 + side;
            }
            count[v] = static_cast<uint8_t>(std::min(3, count[v] + 1));
        }
    }
    // (left, right) of a piece walked away from its end `end`.
    auto sides_out = [&](uint32_t end) {
        const Piece& p = pieces[end / 2];
        return (end & 1U) ? std::pair{p.right, p.left} : std::pair{p.left, p.right};
    };
    auto cls = [&](uint32_t p) { return g.cls[pieces[p].edge]; };
    // A joint: the ends of two different pieces, walking in along one and out
    // along the other keeps the units on each side, and the class.
    std::vector<uint8_t> joint(nv, 0);
    for (size_t v = 0; v < nv; ++v) {
        if (count[v] != 2) {
            continue;
        }
        const uint32_t a = at[v][0], b = at[v][1];
        if (a / 2 == b / 2 || cls(a / 2) != cls(b / 2)) {
            continue;
        }
        const auto out_a = sides_out(a), out_b = sides_out(b);
        joint[v] = out_a.first == out_b.second && out_a.second == out_b.first;
    }
    Graph out;
    out.keys = std::move(g.keys);
    out.grid = std::move(g.grid);
    out.verts.reserve(pieces.size() + pieces.size() / 8);
    std::vector<uint8_t> visited(np, 0);
    // Walk from the end `end` of its piece through joints; appends one edge.
    auto walk = [&](uint32_t end) {
        const uint32_t first = end / 2;
        const auto [left, right] = sides_out(end);
        out.verts.push_back(pieces[first].ab[end & 1U]);
        for (;;) {
            visited[end / 2] = 1;
            const uint32_t v = pieces[end / 2].ab[(end & 1U) ^ 1U];
            out.verts.push_back(v);
            if (!joint[v]) {
                break;
            }
            const uint32_t arrived = end ^ 1U;
            const uint32_t next = at[v][0] == arrived ? at[v][1] : at[v][0];
            if (visited[next / 2]) {
                break; // around a ring of joints
            }
            end = next;
        }
        out.off.push_back(out.verts.size());
        out.left.push_back(left);
        out.right.push_back(right);
        out.cls.push_back(cls(first));
        out.sid.push_back(0);
        out.src.push_back(g.src[pieces[first].edge]);
    };
    // Runs that end somewhere, from an end that is not a joint; then rings of joints.
    for (uint32_t p = 0; p < np; ++p) {
        if (visited[p]) {
            continue;
        }
        if (!joint[pieces[p].ab[0]]) {
            walk(p * 2);
        } else if (!joint[pieces[p].ab[1]]) {
            walk(p * 2 + 1);
        }
    }
    for (uint32_t p = 0; p < np; ++p) {
        if (!visited[p]) {
            walk(p * 2);
        }
    }
    g = std::move(out);
}

/// Codes of every finest unit at one level, as ids into a sorted code list.
struct LevelCodes {
    std::vector<std::string> codes; // sorted
    std::vector<uint32_t> of_unit;  // finest unit -> code id
    std::vector<uint32_t> parent;   // code id -> parent code id at the level above (none at level 0)
    uint32_t side(uint32_t unit) const noexcept { return unit == no_unit ? none : of_unit[unit]; }
};

/// The codes of every level; units whose code at a level has another parent
/// than the code's first unit gave it go into `non_nesting` as (unit, level).
std::vector<LevelCodes> level_codes(const RawMap& raw, std::vector<std::pair<uint32_t, uint32_t>>& non_nesting)
{
    const size_t nlev = raw.level_names.size();
    std::vector<LevelCodes> out(nlev);
    for (size_t L = 0; L < nlev; ++L) {
        auto& lc = out[L];
        for (const auto& u : raw.units) {
            lc.codes.push_back(u.codes[L]);
        }
        std::sort(lc.codes.begin(), lc.codes.end());
        lc.codes.erase(std::unique(lc.codes.begin(), lc.codes.end()), lc.codes.end());
        lc.of_unit.reserve(raw.units.size());
        for (const auto& u : raw.units) {
            lc.of_unit.push_back(static_cast<uint32_t>(std::lower_bound(lc.codes.begin(), lc.codes.end(), u.codes[L]) -
                                                       lc.codes.begin()));
        }
        lc.parent.assign(lc.codes.size(), none);
        if (L > 0) {
            for (size_t u = 0; u < raw.units.size(); ++u) {
                uint32_t& p = lc.parent[lc.of_unit[u]];
                const uint32_t want = out[L - 1].of_unit[u];
                if (p == none) {
                    p = want;
                } else if (p != want) {
                    non_nesting.emplace_back(static_cast<uint32_t>(u), static_cast<uint32_t>(L));
                }
            }
        }
    }
    return out;
}

/// A chain of one level, over graph vertex ids.
struct LevelChain {
    uint64_t first = 0;
    uint32_t count = 0;
    uint32_t left = none, right = none; // code ids
    uint32_t cls = 0;
    uint64_t id = 0;
    bool ring = false; // a cycle without junctions
    bool problem = false;
    uint32_t owner = none; // partition: parent code id (level > 0) or 0
};

struct Level {
    std::vector<LevelChain> chains;
    std::vector<uint32_t> verts;
    std::vector<uint32_t> junctions; // vertex ids
    std::vector<uint32_t> junction_degree;
    std::vector<uint32_t> chain_of_edge; // edge -> chain, none if not a boundary
    std::span<const uint32_t> chain(const LevelChain& c) const noexcept { return {verts.data() + c.first, c.count}; }
};

/// The vertices where edges end, in increasing order, and the index of each
/// vertex among them (`none` for the others): what the levels' walks need,
/// so that their tables go by edge ends, not by vertices.
struct EdgeEnds {
    std::vector<uint32_t> vertex;
    std::vector<uint32_t> of_vertex;

    explicit EdgeEnds(const Graph& g) : of_vertex(g.keys.size(), none)
    {
        for (size_t e = 0; e < g.edge_count(); ++e) {
            const auto ev = g.edge(e);
            of_vertex[ev.front()] = of_vertex[ev.back()] = 0;
        }
        for (uint32_t v = 0; v < of_vertex.size(); ++v) {
            if (of_vertex[v] == 0) {
                of_vertex[v] = static_cast<uint32_t>(vertex.size());
                vertex.push_back(v);
            }
        }
    }
};

Level build_level(const Graph& g, const EdgeEnds& ends, const RawMap& raw, const std::vector<LevelCodes>& lcs, size_t L)
{
    const auto& lc = lcs[L];
    const bool lines = raw.kind == RawMap::Kind::lines;
    auto is_boundary = [&](size_t e) { return lines || lc.side(g.left[e]) != lc.side(g.right[e]); };
    const size_t nends = ends.vertex.size();
    // Incidences of boundary edge ends at the edge ends' vertices (CSR, by end index).
    std::vector<uint32_t> deg(nends, 0);
    std::vector<uint8_t> boundary(g.edge_count(), 0);
    for (size_t e = 0; e < g.edge_count(); ++e) {
        if (is_boundary(e)) {
            boundary[e] = 1;
            const auto ev = g.edge(e);
            ++deg[ends.of_vertex[ev.front()]];
            ++deg[ends.of_vertex[ev.back()]];
        }
    }
    std::vector<uint64_t> start(nends + 1, 0);
    for (size_t k = 0; k < nends; ++k) {
        start[k + 1] = start[k] + deg[k];
    }
    std::vector<uint32_t> inc(start[nends]); // edge * 2 + (0: starts here, 1: ends here)
    {
        std::vector<uint64_t> fill(start.begin(), start.end() - 1);
        for (size_t e = 0; e < g.edge_count(); ++e) {
            if (boundary[e]) {
                const auto ev = g.edge(e);
                inc[fill[ends.of_vertex[ev.front()]]++] = static_cast<uint32_t>(e * 2);
                inc[fill[ends.of_vertex[ev.back()]]++] = static_cast<uint32_t>(e * 2 + 1);
            }
        }
    }
    // Codes (left, right) of an edge walked away from its end `end`.
    auto codes_out = [&](uint32_t in) -> std::pair<uint32_t, uint32_t> {
        const uint32_t e = in / 2;
        const uint32_t l = lc.side(g.left[e]), r = lc.side(g.right[e]);
        return (in & 1U) ? std::pair{r, l} : std::pair{l, r};
    };
    auto is_junction = [&](uint32_t v) {
        const uint32_t k = ends.of_vertex[v];
        if (deg[k] != 2) {
            return true;
        }
        const uint32_t a = inc[start[k]], b = inc[start[k] + 1];
        if (a / 2 == b / 2) {
            return false; // a closed edge alone
        }
        // Walking in along a and out along b must keep the codes on each side.
        const auto out_b = codes_out(b);
        const auto out_a = codes_out(a);
        return !(out_b.first == out_a.second && out_b.second == out_a.first);
    };
    Level lev;
    lev.chain_of_edge.assign(g.edge_count(), none);
    std::vector<uint8_t> visited(g.edge_count(), 0);
    std::vector<uint32_t> cv;
    std::vector<uint32_t> chain_edges;

    auto walk = [&](uint32_t v0, uint32_t first_inc) {
        cv.assign(1, v0);
        chain_edges.clear();
        uint32_t in = first_inc;
        const auto codes = codes_out(first_inc);
        while (true) {
            const uint32_t e = in / 2;
            visited[e] = 1;
            chain_edges.push_back(e);
            const auto ev = g.edge(e);
            if (in & 1U) {
                cv.insert(cv.end(), ev.rbegin() + 1, ev.rend());
            } else {
                cv.insert(cv.end(), ev.begin() + 1, ev.end());
            }
            const uint32_t u = cv.back();
            if (is_junction(u)) {
                break;
            }
            const uint32_t arrived = in ^ 1U;               // the incidence of e at u
            const uint64_t at_u = start[ends.of_vertex[u]]; // u has degree 2: its two incidences
            const uint32_t a = inc[at_u], b = inc[at_u + 1];
            const uint32_t next = a == arrived ? b : a;
            if (visited[next / 2]) {
                break; // back at the start of a ring
            }
            in = next;
        }
        LevelChain c;
        c.left = codes.first;
        c.right = codes.second;
        // Canonical direction and, for rings, start.
        const bool closed = cv.front() == cv.back();
        c.ring = closed && !is_junction(cv.front());
        bool reverse = false;
        if (c.ring) {
            const auto mn = std::min_element(cv.begin(), cv.end() - 1);
            std::rotate(cv.begin(), mn, cv.end() - 1);
            cv.back() = cv.front();
            reverse = cv[cv.size() - 2] < cv[1];
        } else if (!closed) {
            reverse = cv.back() < cv.front();
        } else {
            reverse = cv[cv.size() - 2] < cv[1];
        }
        if (reverse) {
            std::reverse(cv.begin(), cv.end());
            std::swap(c.left, c.right);
        }
        // Dominant feature class by segments; smallest class id on a tie.
        std::unordered_map<uint32_t, uint64_t> votes;
        uint64_t min_sid = UINT64_MAX;
        uint64_t min_seg = UINT64_MAX, min_seg2 = UINT64_MAX;
        const auto id = static_cast<uint32_t>(lev.chains.size());
        for (uint32_t e : chain_edges) {
            votes[g.cls[e]] += g.off[e + 1] - g.off[e] - 1;
            if (g.sid[e] != 0) {
                min_sid = std::min(min_sid, g.sid[e]);
            }
            lev.chain_of_edge[e] = id;
        }
        for (size_t k = 0; k + 1 < cv.size(); ++k) {
            uint64_t a = g.keys[cv[k]], b = g.keys[cv[k + 1]];
            if (b < a) {
                std::swap(a, b);
            }
            if (a < min_seg || (a == min_seg && b < min_seg2)) {
                min_seg = a;
                min_seg2 = b;
            }
        }
        uint64_t best_votes = 0;
        for (const auto& [k, n] : votes) {
            if (n > best_votes || (n == best_votes && k < c.cls)) {
                best_votes = n;
                c.cls = k;
            }
        }
        c.id = min_sid != UINT64_MAX ? min_sid : (splitmix(min_seg ^ splitmix(min_seg2)) >> 1);
        c.first = lev.verts.size();
        c.count = static_cast<uint32_t>(cv.size());
        lev.verts.insert(lev.verts.end(), cv.begin(), cv.end());
        lev.chains.push_back(c);
    };

    for (uint32_t k = 0; k < nends; ++k) {
        const uint32_t v = ends.vertex[k];
        if (deg[k] == 0 || !is_junction(v)) {
            continue;
        }
        lev.junctions.push_back(v);
        lev.junction_degree.push_back(deg[k]);
        for (uint64_t i = start[k]; i < start[k + 1]; ++i) {
            if (!visited[inc[i] / 2]) {
                walk(v, inc[i]);
            }
        }
    }
    for (uint32_t e = 0; e < g.edge_count(); ++e) {
        if (boundary[e] && !visited[e]) {
            walk(g.edge(e).front(), e * 2);
        }
    }
    // Ids unique within the level: on a collision take the next free value, in a
    // deterministic order.
    std::vector<uint32_t> order(lev.chains.size());
    std::iota(order.begin(), order.end(), 0U);
    std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
        const auto& ca = lev.chains[a];
        const auto& cb = lev.chains[b];
        if (ca.id != cb.id) {
            return ca.id < cb.id;
        }
        return std::lexicographical_compare(lev.verts.begin() + static_cast<std::ptrdiff_t>(ca.first),
                                            lev.verts.begin() + static_cast<std::ptrdiff_t>(ca.first + ca.count),
                                            lev.verts.begin() + static_cast<std::ptrdiff_t>(cb.first),
                                            lev.verts.begin() + static_cast<std::ptrdiff_t>(cb.first + cb.count));
    });
    for (size_t i = 1; i < order.size(); ++i) {
        auto& prev = lev.chains[order[i - 1]];
        auto& cur = lev.chains[order[i]];
        if (cur.id <= prev.id) {
            cur.id = prev.id + 1;
        }
    }
    return lev;
}

/// Which edges bound something at some level: the ones the planarity check covers.
std::vector<uint8_t> checked_edges(const Graph& g, const RawMap& raw, const std::vector<LevelCodes>& lcs)
{
    std::vector<uint8_t> checked(g.edge_count(), 0);
    for (size_t e = 0; e < g.edge_count(); ++e) {
        bool b = raw.kind == RawMap::Kind::lines;
        for (size_t L = 0; L < lcs.size() && !b; ++L) {
            b = lcs[L].side(g.left[e]) != lcs[L].side(g.right[e]);
        }
        checked[e] = b;
    }
    return checked;
}

/// The segments of the checked edges, and where each lies: (edge, index of its first vertex).
struct SegmentSet {
    std::vector<Segment> segs;
    std::vector<std::pair<uint32_t, uint32_t>> at;
};

/// The segments of the checked edges; with a scope, only those of the edges it
/// flags and those whose box meets one of the `hot` boxes.
SegmentSet segments_of(const Graph& g, const std::vector<uint8_t>& checked, const std::vector<uint8_t>& scope,
                       const std::vector<GridBox>& hot)
{
    SegmentSet s;
    if (scope.empty()) { // all of them: sized once, not grown
        size_t n = 0;
        for (uint32_t e = 0; e < g.edge_count(); ++e) {
            n += checked[e] ? g.off[e + 1] - g.off[e] - 1 : 0;
        }
        s.segs.reserve(n);
        s.at.reserve(n);
    }
    for (uint32_t e = 0; e < g.edge_count(); ++e) {
        if (!checked[e]) {
            continue;
        }
        const auto ev = g.edge(e);
        for (uint32_t k = 0; k + 1 < ev.size(); ++k) {
            const GridPoint a = g.grid[ev[k]], b = g.grid[ev[k + 1]];
            bool take = scope.empty() || scope[e];
            if (!take) {
                GridBox box;
                box.extend(a);
                box.extend(b);
                take = std::any_of(hot.begin(), hot.end(), [&](const GridBox& h) { return h.intersects(box); });
            }
            if (take) {
                s.segs.push_back({a, b, static_cast<uint32_t>(s.at.size())});
                s.at.emplace_back(e, k);
            }
        }
    }
    return s;
}

/// Squared distance from p to segment ab, in grid units.
double distance2(GridPoint p, GridPoint a, GridPoint b)
{
    const double dx = static_cast<double>(int64_t{b.x} - a.x), dy = static_cast<double>(int64_t{b.y} - a.y);
    const double px = static_cast<double>(int64_t{p.x} - a.x), py = static_cast<double>(int64_t{p.y} - a.y);
    const double len2 = dx * dx + dy * dy;
    const double t = len2 > 0 ? std::clamp((px * dx + py * dy) / len2, 0.0, 1.0) : 0.0;
    const double ex = px - t * dx, ey = py - t * dy;
    return ex * ex + ey * ey;
}

/// Snapping to the grid can push a vertex that lies within a fraction of the
/// input precision of a segment across it. Where a vertex of a crossing,
/// touching or overlapping pair is a plain pass-through vertex (degree 2 in the
/// whole graph, the same units on each side) and dropping it moves the boundary
/// by at most `max_shift` grid units, drop it, as snap rounding would, and
/// check again. Returns the intersections that remain; repairs are counted.
std::vector<Intersection> repair_snap_crossings(Graph& g, const RawMap& raw, const std::vector<LevelCodes>& lcs,
                                                double max_shift, unsigned threads, Problems& problems,
                                                const Owner& owner)
{
    constexpr int max_rounds = 8;
    // After the first round only what a repair touched can change: the repaired
    // edges, the segments whose boxes meet theirs, and pairs still unresolved.
    std::vector<uint8_t> scope;
    std::vector<GridBox> hot;
    for (int round = 0;; ++round) {
        const SegmentSet s = segments_of(g, checked_edges(g, raw, lcs), scope, hot);
        const std::vector<Intersection> by_segment = find_intersections(s.segs, threads);
        std::vector<Intersection> found = by_segment;
        for (auto& f : found) { // report edges, not segment indices
            f.first = s.at[f.first].first;
            f.second = s.at[f.second].first;
        }
        if (found.empty() || round == max_rounds) {
            return found;
        }
        // Pass-through degree of every vertex in the whole graph.
        std::vector<uint8_t> deg(g.keys.size(), 0);
        auto bump = [&](uint32_t v, int n) { deg[v] = static_cast<uint8_t>(std::min(255, deg[v] + n)); };
        for (size_t e = 0; e < g.edge_count(); ++e) {
            const auto ev = g.edge(e);
            bump(ev.front(), 1);
            bump(ev.back(), 1);
            for (size_t k = 1; k + 1 < ev.size(); ++k) {
                bump(ev[k], 2);
            }
        }
        // Edge ends at the candidate vertices (those of the pairs found, of degree 2),
        // for joining two edges there.
        std::unordered_map<uint32_t, std::vector<uint32_t>> ends; // vertex -> edge*2 + (1 if it ends there)
        for (const auto& f : by_segment) {
            for (uint32_t si : {f.first, f.second}) {
                const auto [e, k] = s.at[si];
                for (uint32_t v : {g.edge(e)[k], g.edge(e)[k + 1]}) {
                    if (deg[v] == 2) {
                        ends.try_emplace(v);
                    }
                }
            }
        }
        for (uint32_t e = 0; e < g.edge_count(); ++e) {
            const auto ev = g.edge(e);
            for (uint32_t side = 0; side < 2; ++side) {
                if (auto it = ends.find(side ? ev.back() : ev.front()); it != ends.end()) {
                    it->second.push_back(e * 2 + side);
                }
            }
        }
        std::vector<uint8_t> touched(g.edge_count(), 0);
        std::vector<std::pair<uint32_t, uint32_t>> drop_interior; // (edge, vertex index)
        std::vector<std::pair<uint32_t, uint32_t>> join;          // (edge ending at v, edge starting at v) as ends
        for (const auto& f : by_segment) {
            struct Candidate {
                double d2;
                uint32_t v;
                uint32_t edge, index; // where v lies (index into the edge)
            };
            std::optional<Candidate> best;
            for (uint32_t si : {f.first, f.second}) {
                const auto [e, k] = s.at[si];
                const auto ev = g.edge(e);
                for (uint32_t idx : {k, k + 1}) {
                    const uint32_t v = ev[idx];
                    if (deg[v] != 2 || touched[e]) {
                        continue;
                    }
                    GridPoint prev, next;
                    if (idx > 0 && idx + 1 < ev.size()) {
                        prev = g.grid[ev[idx - 1]];
                        next = g.grid[ev[idx + 1]];
                        if (ev.size() < 3 || (ev.front() == ev.back() && ev.size() < 5)) {
                            continue;
                        }
                    } else {
                        auto it = ends.find(v);
                        if (it == ends.end() || it->second.size() != 2 || it->second[0] / 2 == it->second[1] / 2) {
                            continue;
                        }
                        const uint32_t a = it->second[0], b = it->second[1];
                        const auto ea = g.edge(a / 2), eb = g.edge(b / 2);
                        prev = g.grid[(a & 1U) ? ea[ea.size() - 2] : ea[1]];
                        next = g.grid[(b & 1U) ? eb[eb.size() - 2] : eb[1]];
                        // The units on each side must carry through v.
                        const bool same_dir = (a & 1U) != (b & 1U);
                        const uint32_t la = g.left[a / 2], ra = g.right[a / 2];
                        const uint32_t lb = same_dir ? g.left[b / 2] : g.right[b / 2];
                        const uint32_t rb = same_dir ? g.right[b / 2] : g.left[b / 2];
                        if (la != lb || ra != rb || touched[a / 2] || touched[b / 2] || prev == next) {
                            continue;
                        }
                    }
                    // Dropping v must resolve this pair: its replacement segment may meet the
                    // pair's other segment at a shared end point only.
                    const Segment& other = s.segs[si == f.first ? f.second : f.first];
                    const SegmentRelation after = segment_relation(prev, next, other.a, other.b);
                    if (after != SegmentRelation::disjoint && after != SegmentRelation::shared_endpoint) {
                        continue;
                    }
                    const double d2 = distance2(g.grid[v], prev, next);
                    if (d2 <= max_shift * max_shift && (!best || d2 < best->d2 || (d2 == best->d2 && v < best->v))) {
                        best = Candidate{d2, v, e, idx};
                    }
                }
            }
            if (!best) {
                continue;
            }
            const auto ev = g.edge(best->edge);
            const GridPoint at = g.grid[best->v];
            if (owner.units(g.left[best->edge], g.right[best->edge])) {
                problems.add("snap_repairs", at.x, at.y, raw.where(g.src[best->edge]));
            }
            if (best->index > 0 && best->index + 1 < ev.size()) {
                drop_interior.emplace_back(best->edge, best->index);
                touched[best->edge] = 1;
            } else {
                const auto& two = ends.at(best->v);
                join.emplace_back(two[0], two[1]);
                touched[two[0] / 2] = touched[two[1] / 2] = 1;
            }
        }
        if (drop_interior.empty() && join.empty()) {
            return found;
        }
        // Rebuild the edges with the repairs applied, in the same order.
        std::vector<int64_t> drop_at(g.edge_count(), -1);
        for (auto [e, idx] : drop_interior) {
            drop_at[e] = idx;
        }
        std::vector<int64_t> joined_with(g.edge_count(), -1); // first edge -> end code of the second
        std::vector<uint8_t> absorbed(g.edge_count(), 0);
        for (auto [a, b] : join) {
            const uint32_t first = std::min(a / 2, b / 2);
            const uint32_t second_end = a / 2 == first ? b : a;
            const uint32_t first_end = a / 2 == first ? a : b;
            joined_with[first] = static_cast<int64_t>(second_end) * 2 + (first_end & 1U);
            absorbed[second_end / 2] = 1;
        }
        std::vector<uint8_t> unresolved(g.edge_count(), 0);
        for (const auto& f : found) {
            unresolved[f.first] = unresolved[f.second] = 1;
        }
        scope.clear();
        hot.clear();
        Graph out;
        out.keys = std::move(g.keys);
        out.grid = std::move(g.grid);
        std::vector<uint32_t> pts;
        for (uint32_t e = 0; e < g.edge_count(); ++e) {
            if (absorbed[e]) {
                continue;
            }
            const bool repaired = drop_at[e] >= 0 || joined_with[e] >= 0;
            scope.push_back(repaired || unresolved[e]);
            const auto ev = g.edge(e);
            pts.assign(ev.begin(), ev.end());
            uint32_t left = g.left[e], right = g.right[e];
            uint64_t sid = g.sid[e];
            size_t new_segment = 0; // where the repair put a new segment: pts[new_segment, +1]
            if (drop_at[e] >= 0) {
                pts.erase(pts.begin() + drop_at[e]);
                new_segment = static_cast<size_t>(drop_at[e]) - 1;
            } else if (joined_with[e] >= 0) {
                const auto code = static_cast<uint64_t>(joined_with[e]);
                const bool first_ends_at_v = (code & 1U) != 0;
                const uint32_t second_end = static_cast<uint32_t>(code >> 1);
                if (!first_ends_at_v) { // make this edge end at v
                    std::reverse(pts.begin(), pts.end());
                    std::swap(left, right);
                }
                const auto sv = g.edge(second_end / 2);
                pts.pop_back(); // v
                new_segment = pts.size() - 1;
                if (second_end & 1U) {
                    pts.insert(pts.end(), sv.rbegin() + 1, sv.rend());
                } else {
                    pts.insert(pts.end(), sv.begin() + 1, sv.end());
                }
                const uint64_t other = g.sid[second_end / 2];
                sid = sid == 0 ? other : (other == 0 ? sid : std::min(sid, other));
            }
            if (repaired) {
                // Only the new segment can meet segments it did not meet before;
                // the rest of the edge is in scope anyway.
                GridBox box;
                box.extend(out.grid[pts[new_segment]]);
                box.extend(out.grid[pts[new_segment + 1]]);
                hot.push_back(box);
            }
            out.verts.insert(out.verts.end(), pts.begin(), pts.end());
            out.off.push_back(out.verts.size());
            out.left.push_back(left);
            out.right.push_back(right);
            out.cls.push_back(g.cls[e]);
            out.sid.push_back(sid);
            out.src.push_back(g.src[e]);
        }
        g = std::move(out);
    }
}

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

void log_progress(const BuildOptions& options, const std::string& what)
{
    if (options.log != nullptr) {
        options.log->info(what);
    }
}

/// One level: its chains, partitions, halos, internal points and stores.
/// Codes of each level that a build owns (for a region: those under its own
/// region-level codes); an empty list owns every code of its level.
using OwnedCodes = std::vector<std::vector<uint8_t>>;

LevelStats process_level(const Graph& g, const EdgeEnds& ends, const RawMap& raw, const std::vector<LevelCodes>& lcs,
                         size_t L, const std::vector<uint32_t>& bad_edges, const Projection& projection,
                         const BuildOptions& options, const Owner& owner, const OwnedCodes& owned,
                         std::vector<FoundProblem>& problems, const StoreSink& sink)
{
    const size_t nlev = lcs.size();
    auto owns = [&](size_t level, uint32_t code) { return owned[level].empty() || owned[level][code] != 0; };
    // Cells of at least 100 m: a halo of 0 then holds the chains that come
    // within about that, and the search stays fast.
    const double halo_grid = std::max(options.halo_m, 100.0) / projection.params().grid_m;
    auto note = [&](const std::string& what) { log_progress(options, what); };
    Level lev = build_level(g, ends, raw, lcs, L);
    note("level " + raw.level_names[L] + ": built chains");
    for (uint32_t e : bad_edges) {
        if (lev.chain_of_edge[e] != none) {
            lev.chains[lev.chain_of_edge[e]].problem = true;
        }
    }
    const auto& lc = lcs[L];
    // Partitions: the parent unit; a chain between two parents belongs to the smaller code.
    uint32_t npart = 1;
    std::vector<std::string> part_names{"all"};
    if (L > 0) {
        part_names = lcs[L - 1].codes;
        npart = static_cast<uint32_t>(part_names.size());
    }
    auto parent = [&](uint32_t code) { return L == 0 ? 0U : lc.parent[code]; };
    auto owns_part = [&](uint32_t part) { return L == 0 || owns(L - 1, part); };
    for (auto& c : lev.chains) {
        uint32_t o = none;
        for (uint32_t side : {c.left, c.right}) {
            if (side != none) {
                o = std::min(o, parent(side));
            }
        }
        c.owner = o == none ? 0 : o;
    }
    // Halo: chains of other partitions that bound one of the partition's units or
    // come within the halo distance of its chains, found on cells at least as
    // large as the distance.
    std::vector<std::vector<uint32_t>> halo(npart);
    if (npart > 1) {
        std::vector<SegmentRef> refs;
        size_t nrefs = 0;
        for (const auto& c : lev.chains) {
            nrefs += c.count - 1;
        }
        refs.reserve(nrefs);
        for (uint32_t ci = 0; ci < lev.chains.size(); ++ci) {
            const auto& c = lev.chains[ci];
            // A border between two parts bounds both: the other part's units need it.
            uint32_t also = none;
            for (uint32_t side : {c.left, c.right}) {
                if (side != none && parent(side) != c.owner) {
                    also = parent(side);
                }
            }
            const auto cv = lev.chain(c);
            for (size_t k = 0; k + 1 < cv.size(); ++k) {
                refs.push_back({g.grid[cv[k]], g.grid[cv[k + 1]], ci, c.owner, also});
            }
        }
        for (const auto& [chain, part] : find_near(refs, halo_grid, options.threads)) {
            halo[part].push_back(chain);
        }
    }
    // Units of each partition and their boundary segments.
    std::vector<std::vector<uint32_t>> unit_chains(lc.codes.size());
    for (uint32_t ci = 0; ci < lev.chains.size(); ++ci) {
        const auto& c = lev.chains[ci];
        if (c.left != none) {
            unit_chains[c.left].push_back(ci);
        }
        if (c.right != none && c.right != c.left) {
            unit_chains[c.right].push_back(ci);
        }
    }
    // The representative finest unit of each code: the heaviest with a given point.
    std::vector<uint32_t> rep(lc.codes.size(), none);
    for (uint32_t u = 0; u < raw.units.size(); ++u) {
        if (!raw.units[u].intpt) {
            continue;
        }
        uint32_t& r = rep[lc.of_unit[u]];
        if (r == none || raw.units[u].weight > raw.units[r].weight) {
            r = u;
        }
    }
    LevelStats st;
    st.name = raw.level_names[L];
    for (uint32_t code = 0; code < lc.codes.size() && raw.kind != RawMap::Kind::lines; ++code) {
        st.units += owns(L, code) ? 1 : 0;
    }
    for (uint32_t part = 0; part < npart; ++part) {
        st.partitions += owns_part(part) ? 1 : 0;
    }
    // Internal points, unit by unit on the worker threads; problems are
    // recorded afterwards in code order.
    struct UnitPoint {
        std::optional<GridPoint> pt;
        std::optional<GridPoint> rejected; // a given point not strictly inside
        bool computed = false;
        GridPoint near;
    };
    const size_t npoints = raw.kind == RawMap::Kind::lines ? 0 : lc.codes.size();
    std::vector<UnitPoint> unit_points(npoints);
    // The partition contract (formats/chains/SPEC.md): a store holds the
    // internal point of every unit that one of its own chains bounds, whoever
    // owns the unit, so that a shortcut never cuts a neighbour's point off.
    // The build has those units whole: a region takes the whole neighbouring
    // units within reach (regions.hpp), and a unit touching an owned chain is.
    std::vector<uint8_t> needed(npoints, 0);
    for (uint32_t code = 0; code < npoints; ++code) {
        needed[code] = owns(L, code) ? 1 : 0;
    }
    std::vector<std::pair<uint32_t, uint32_t>> neighbours; // (partition, unit of another partition its chain bounds)
    for (const auto& c : lev.chains) {
        if (npoints == 0 || !owns_part(c.owner)) {
            continue;
        }
        for (uint32_t side : {c.left, c.right}) {
            if (side != none && parent(side) != c.owner) {
                needed[side] = 1;
                neighbours.emplace_back(c.owner, side);
            }
        }
    }
    std::sort(neighbours.begin(), neighbours.end());
    neighbours.erase(std::unique(neighbours.begin(), neighbours.end()), neighbours.end());
    // A few thousand units whose cost varies with their boundary: 64 at a time.
    parallel_blocks(npoints, options.threads, 64, [&](size_t b, size_t e) {
        std::vector<std::pair<GridPoint, GridPoint>> useg;
        for (size_t code = b; code < e; ++code) {
            if (!needed[code]) {
                continue;
            }
            useg.clear();
            for (uint32_t ci : unit_chains[code]) {
                const auto cv = lev.chain(lev.chains[ci]);
                for (size_t k = 0; k + 1 < cv.size(); ++k) {
                    useg.push_back({g.grid[cv[k]], g.grid[cv[k + 1]]});
                }
            }
            UnitPoint& up = unit_points[code];
            up.near = useg.empty() ? GridPoint{} : useg.front().first;
            if (rep[code] != none) {
                const LonLatE6 ll = *raw.units[rep[code]].intpt;
                up.pt = projection.to_grid(ll.lon * 1e-6, ll.lat * 1e-6);
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
    std::vector<std::vector<chains::ConstraintPoint>> part_points(npart);
    for (uint32_t code = 0; code < npoints; ++code) {
        if (!owns(L, code)) {
            continue;
        }
        const UnitPoint& up = unit_points[code];
        if (up.rejected) {
            problems.push_back({"internal_points_replaced", double(up.rejected->x), double(up.rejected->y),
                                raw.where(raw.units[rep[code]].source) + " (" + st.name + " " + lc.codes[code] + ")"});
        }
        st.computed_internal_points += up.computed;
        if (!up.pt) {
            problems.push_back(
                {"missing_internal_points", double(up.near.x), double(up.near.y), st.name + " " + lc.codes[code]});
            continue;
        }
        part_points[parent(code)].push_back({code, chains::constraint_internal, *up.pt});
    }
    // Each partition's neighbour points: the units of other partitions that its chains bound.
    std::vector<std::vector<chains::ConstraintPoint>> neighbour_points(npart);
    for (const auto& [part, unit] : neighbours) {
        if (unit_points[unit].pt) {
            neighbour_points[part].push_back({unit, chains::constraint_neighbour, *unit_points[unit].pt});
        }
    }
    // One store per partition, built, encoded and handed to the sink on the
    // worker threads, each taking the next partition as it finishes one.
    // Chains in order of id (unique within the level), so that a store's
    // strings come in an order that depends on its content alone.
    std::vector<std::vector<uint32_t>> own(npart);
    for (uint32_t ci = 0; ci < lev.chains.size(); ++ci) {
        const auto& c = lev.chains[ci];
        if (!owns_part(c.owner)) {
            continue;
        }
        own[c.owner].push_back(ci);
        st.chains += 1;
        st.rings += c.ring ? 1 : 0;
        st.vertices += c.count;
    }
    auto by_id = [&](uint32_t a, uint32_t b) { return lev.chains[a].id < lev.chains[b].id; };
    for (uint32_t part = 0; part < npart; ++part) {
        if (!owns_part(part)) {
            continue;
        }
        std::sort(own[part].begin(), own[part].end(), by_id);
        std::sort(halo[part].begin(), halo[part].end(), by_id);
        st.halo_chains += halo[part].size();
        st.constraint_points += part_points[part].size();
        st.neighbour_points += neighbour_points[part].size();
    }
    parallel_each(npart, options.threads, [&](size_t part) {
        std::vector<GridPoint> pts;
        if (!owns_part(static_cast<uint32_t>(part)) || (own[part].empty() && part_points[part].empty())) {
            return;
        }
        chains::ChainStore s;
        s.level_index = static_cast<uint32_t>(L);
        s.level_count = static_cast<uint32_t>(nlev);
        s.level_name = st.name;
        s.partition = part_names[part];
        s.projection = projection.params();
        s.halo_m = options.halo_m;
        std::unordered_map<uint32_t, uint32_t> sidx;
        auto str = [&](uint32_t code) {
            if (code == none) {
                return 0U;
            }
            auto [it, added] = sidx.try_emplace(code, 0U);
            if (added) {
                it->second = s.intern(lc.codes[code]);
            }
            return it->second;
        };
        std::vector<uint32_t> cls_idx(raw.classes.size(), none);
        auto add = [&](uint32_t ci, bool is_halo) {
            const auto& c = lev.chains[ci];
            const auto cv = lev.chain(c);
            pts.clear();
            for (uint32_t v : cv) {
                pts.push_back(g.grid[v]);
            }
            if (cls_idx[c.cls] == none) {
                cls_idx[c.cls] = s.intern(raw.classes[c.cls]);
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
        for (uint32_t ci : own[part]) {
            add(ci, false);
        }
        for (uint32_t ci : halo[part]) {
            add(ci, true);
        }
        // Junctions at the ends of the partition's own chains.
        std::vector<uint32_t> chain_ends;
        for (uint32_t ci : own[part]) {
            const auto cv = lev.chain(lev.chains[ci]);
            chain_ends.push_back(cv.front());
            chain_ends.push_back(cv.back());
        }
        std::sort(chain_ends.begin(), chain_ends.end());
        chain_ends.erase(std::unique(chain_ends.begin(), chain_ends.end()), chain_ends.end());
        for (uint32_t v : chain_ends) {
            auto it = std::lower_bound(lev.junctions.begin(), lev.junctions.end(), v);
            if (it != lev.junctions.end() && *it == v) {
                const auto k = static_cast<size_t>(it - lev.junctions.begin());
                s.junctions.push_back({g.keys[v], g.grid[v], lev.junction_degree[k]});
            }
        }
        for (const auto* points : {&part_points[part], &neighbour_points[part]}) {
            for (const auto& cp : *points) {
                s.constraints.push_back({str(cp.unit), cp.kind, cp.p});
            }
        }
        s.canonicalize();
        sink(s);
    });
    for (uint32_t v : lev.junctions) {
        st.junctions += owner.vertex(v) ? 1 : 0;
    }
    note("level " + st.name + ": " + std::to_string(st.chains) + " chains in " + std::to_string(st.partitions) +
         " partitions");
    return st;
}

} // namespace

namespace {

/// Levels [first, end), the coarser ones one after another on a thread of their
/// own beside the finest (as a rule the largest, and not busy on every thread
/// throughout); their problems are recorded in level order afterwards.
void build_levels(const Graph& g, const RawMap& raw, const std::vector<LevelCodes>& lcs, size_t first, size_t end,
                  const std::vector<uint32_t>& bad_edges, const Projection& projection, const BuildOptions& options,
                  const Owner& owner, const OwnedCodes& owned, BuildResult& result, Problems& problems,
                  const StoreSink& sink)
{
    std::vector<std::vector<FoundProblem>> found(end);
    const EdgeEnds ends(g);
    auto level = [&](size_t L) {
        result.levels[L] =
            process_level(g, ends, raw, lcs, L, bad_edges, projection, options, owner, owned, found[L], sink);
    };
    if (end > first) {
        // The future's destructor waits for the coarse levels if the finest throws.
        auto coarse = std::async(std::launch::async, [&] {
            for (size_t L = first; L + 1 < end; ++L) {
                level(L);
            }
        });
        level(end - 1);
        coarse.get();
    }
    for (auto& level_found : found) {
        problems.add_all(std::move(level_found));
    }
}

/// A whole map, or with `scope` one region of it (its levels finer than the
/// region level, and in `out` what the coarse levels need).
BuildResult build(RawMap raw, const Projection& projection, const BuildOptions& options, const StoreSink& sink,
                  const RegionScope* scope, RegionOutput* out)
{
    BuildResult result;
    Problems problems(result, projection, options.max_problem_samples);
    const size_t nlev = raw.level_names.size();
    result.input_vertices = raw.points_read;
    problems.count("empty_geometries", raw.empty_geometries);
    auto note = [&](const std::string& what) { log_progress(options, what); };
    auto last = std::chrono::steady_clock::now();
    auto phase = [&](std::string name) {
        const auto now = std::chrono::steady_clock::now();
        result.seconds.emplace_back(std::move(name), std::chrono::duration<double>(now - last).count());
        last = now;
    };
    std::vector<std::pair<uint32_t, uint32_t>> non_nesting;
    const auto lcs = level_codes(raw, non_nesting);
    Owner owner;
    if (scope != nullptr) {
        const auto& lr = lcs[scope->level];
        owner.unit_rank = lr.of_unit;
        for (const auto& c : lr.codes) {
            owner.own_rank.push_back(std::binary_search(scope->own.begin(), scope->own.end(), c) ? 1 : 0);
        }
    }
    // A unit of a level in two units of the level before: the config's
    // levels do not nest on this data (a level without its parent's code,
    // levels out of order), and every level below would be built wrong.
    for (auto [u, L] : non_nesting) {
        if (!owner.unit(u)) {
            continue;
        }
        const auto& here = lcs[L];
        const auto& up = lcs[L - 1];
        size_t v = 0; // the first unit that gave the code its parent
        while (here.of_unit[v] != here.of_unit[u] || up.of_unit[v] == up.of_unit[u]) {
            ++v;
        }
        auto at = [&](size_t w) {
            std::string s = raw.where(raw.units[w].source);
            if (const auto& p = raw.units[w].intpt) {
                char buf[64];
                std::snprintf(buf, sizeof buf, " near %.6f, %.6f", p->lon * 1e-6, p->lat * 1e-6);
                s += buf;
            }
            return s;
        };
        throw input_error("level '" + raw.level_names[L] + "' does not nest in level '" + raw.level_names[L - 1] +
                          "': its unit " + here.codes[here.of_unit[u]] + " lies in " + raw.level_names[L - 1] + " " +
                          up.codes[up.of_unit[v]] + " (" + at(v) + ") and in " + raw.level_names[L - 1] + " " +
                          up.codes[up.of_unit[u]] + " (" + at(u) + "); each unit must lie in one unit of the level " +
                          "before: check the order of the levels and their fields or prefixes");
    }
    Graph g = make_graph(raw, projection, options.threads, problems, owner);
    phase("intern_project");
    note("interned and projected " + std::to_string(g.keys.size()) + " vertices");
    if (raw.kind != RawMap::Kind::edges) {
        join_pieces(g, merge_segments(g, raw, options.threads, problems, owner));
    }
    phase("merge_join");
    note("merged shared segments: " + std::to_string(g.edge_count()) + " edges");
    for (uint32_t v = 0; v < g.keys.size(); ++v) {
        result.unique_vertices += owner.vertex(v) ? 1 : 0;
    }
    for (size_t e = 0; e < g.edge_count(); ++e) {
        result.edges += owner.units(g.left[e], g.right[e]) ? 1 : 0;
    }
    {
        std::vector<uint8_t> used(raw.units.size(), 0);
        for (size_t e = 0; e < g.edge_count(); ++e) {
            for (uint32_t u : {g.left[e], g.right[e]}) {
                if (u != no_unit) {
                    used[u] = 1;
                }
            }
        }
        for (size_t u = 0; u < raw.units.size(); ++u) {
            if (!used[u] && owner.unit(static_cast<uint32_t>(u))) {
                problems.add_lonlat("unreferenced_units", raw.units[u].intpt.value_or(LonLatE6{}),
                                    raw.where(raw.units[u].source));
            }
        }
    }
    // One planarity check over every edge that bounds something at some level,
    // with safe repairs of crossings that snapping made.
    const double max_shift = options.max_snap_shift_m / projection.params().grid_m;
    std::vector<uint32_t> bad_edges;
    for (const auto& f : repair_snap_crossings(g, raw, lcs, max_shift, options.threads, problems, owner)) {
        const char* kind = f.relation == SegmentRelation::cross     ? "crossings"
                           : f.relation == SegmentRelation::overlap ? "overlaps"
                                                                    : "touches";
        const uint32_t rank = std::min({owner.rank(g.left[f.first]), owner.rank(g.right[f.first]),
                                        owner.rank(g.left[f.second]), owner.rank(g.right[f.second])});
        if (owner.of_rank(rank)) {
            problems.add(kind, f.x, f.y, raw.where(g.src[f.first]) + " " + raw.where(g.src[f.second]));
        }
        bad_edges.push_back(f.first);
        bad_edges.push_back(f.second);
    }
    phase("planarity");
    note("checked planarity");
    std::sort(bad_edges.begin(), bad_edges.end());
    bad_edges.erase(std::unique(bad_edges.begin(), bad_edges.end()), bad_edges.end());

    result.levels.resize(nlev);
    OwnedCodes owned(nlev);
    size_t first = 0;
    if (scope != nullptr) {
        // Codes at the region level and below go by their region-level code.
        first = scope->level + 1;
        for (size_t L = scope->level; L < nlev; ++L) {
            owned[L].assign(lcs[L].codes.size(), 0);
            for (size_t u = 0; u < raw.units.size(); ++u) {
                if (owner.unit(static_cast<uint32_t>(u))) {
                    owned[L][lcs[L].of_unit[u]] = 1;
                }
            }
        }
        // What the coarse levels need: the edges between region-level codes
        // that this region owns, and a representative unit per own code.
        const auto& lr = lcs[scope->level];
        for (size_t e = 0; e < g.edge_count(); ++e) {
            const uint32_t l = lr.side(g.left[e]), r = lr.side(g.right[e]);
            if (l == r || !owner.units(g.left[e], g.right[e])) {
                continue;
            }
            CoarseEdge ce;
            for (uint32_t v : g.edge(e)) {
                ce.keys.push_back(g.keys[v]);
                ce.points.push_back(g.grid[v]);
            }
            ce.left = l == none ? std::string() : lr.codes[l];
            ce.right = r == none ? std::string() : lr.codes[r];
            ce.cls = g.cls[e];
            ce.sid = g.sid[e];
            ce.src = g.src[e];
            ce.problem = std::binary_search(bad_edges.begin(), bad_edges.end(), static_cast<uint32_t>(e));
            out->edges.push_back(std::move(ce));
        }
        std::vector<uint32_t> rep(lr.codes.size(), none);
        for (uint32_t u = 0; u < raw.units.size(); ++u) {
            if (!owner.unit(u)) {
                continue;
            }
            uint32_t& r = rep[lr.of_unit[u]];
            const auto& cand = raw.units[u];
            if (r == none || (cand.intpt && (!raw.units[r].intpt || cand.weight > raw.units[r].weight))) {
                r = u;
            }
        }
        for (uint32_t r : rep) {
            if (r != none) {
                out->units.push_back(raw.units[r]);
            }
        }
        for (size_t L = 0; L < first; ++L) {
            result.levels[L].name = raw.level_names[L];
        }
    }
    build_levels(g, raw, lcs, first, nlev, bad_edges, projection, options, owner, owned, result, problems, sink);
    phase("levels");
    problems.finish();
    return result;
}

} // namespace

void first_samples(std::vector<ProblemSample>& samples, size_t max)
{
    auto before = [](const ProblemSample& a, const ProblemSample& b) {
        return std::tie(a.kind, a.lon_deg, a.lat_deg, a.where) < std::tie(b.kind, b.lon_deg, b.lat_deg, b.where);
    };
    if (samples.size() > max) {
        std::nth_element(samples.begin(), samples.begin() + static_cast<std::ptrdiff_t>(max), samples.end(), before);
        samples.resize(max);
    }
    std::sort(samples.begin(), samples.end(), before);
}

BuildResult build_map(RawMap raw, const Projection& projection, const BuildOptions& options, const StoreSink& sink)
{
    return build(std::move(raw), projection, options, sink, nullptr, nullptr);
}

BuildResult build_region(RawMap raw, const RegionScope& scope, const Projection& projection,
                         const BuildOptions& options, const StoreSink& sink, RegionOutput& out)
{
    return build(std::move(raw), projection, options, sink, &scope, &out);
}

BuildResult build_coarse(const RawMap& meta, std::vector<RawUnit> units, const std::vector<CoarseEdge>& edges,
                         size_t level, const Projection& projection, const BuildOptions& options, const StoreSink& sink)
{
    BuildResult result;
    Problems problems(result, projection, options.max_problem_samples);
    RawMap raw;
    raw.kind = meta.kind;
    raw.level_names = meta.level_names;
    raw.files = meta.files;
    raw.classes = meta.classes;
    raw.units = std::move(units);
    // The units stand for their region-level codes.
    std::unordered_map<std::string, uint32_t> unit_of_code;
    for (uint32_t u = 0; u < raw.units.size(); ++u) {
        unit_of_code.try_emplace(raw.units[u].codes[level], u);
    }
    auto unit_of = [&](const std::string& code) {
        if (code.empty()) {
            return no_unit;
        }
        auto it = unit_of_code.find(code);
        if (it == unit_of_code.end()) {
            throw std::logic_error("region build: no unit for code " + code);
        }
        return it->second;
    };
    // Vertex ids follow the keys, as a whole map's do.
    Graph g;
    for (const auto& e : edges) {
        g.keys.insert(g.keys.end(), e.keys.begin(), e.keys.end());
    }
    std::sort(g.keys.begin(), g.keys.end());
    g.keys.erase(std::unique(g.keys.begin(), g.keys.end()), g.keys.end());
    g.grid.resize(g.keys.size());
    std::vector<uint32_t> bad_edges;
    for (const auto& e : edges) {
        for (size_t k = 0; k < e.keys.size(); ++k) {
            const auto v =
                static_cast<uint32_t>(std::lower_bound(g.keys.begin(), g.keys.end(), e.keys[k]) - g.keys.begin());
            g.grid[v] = e.points[k];
            g.verts.push_back(v);
        }
        if (e.problem) {
            bad_edges.push_back(static_cast<uint32_t>(g.edge_count()));
        }
        g.off.push_back(g.verts.size());
        g.left.push_back(unit_of(e.left));
        g.right.push_back(unit_of(e.right));
        g.cls.push_back(e.cls);
        g.sid.push_back(e.sid);
        g.src.push_back(e.src);
    }
    std::vector<std::pair<uint32_t, uint32_t>> non_nesting; // the regions report these
    const auto lcs = level_codes(raw, non_nesting);
    result.levels.resize(raw.level_names.size());
    build_levels(g, raw, lcs, 0, level + 1, bad_edges, projection, options, Owner{}, OwnedCodes(raw.level_names.size()),
                 result, problems, sink);
    problems.finish();
    return result;
}

} // namespace tigerlod::ingest
