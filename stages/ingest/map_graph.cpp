#include "stages/ingest/map_steps.hpp"
#include "stages/ingest/sources.hpp"

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

namespace tigerlod::ingest::detail {

namespace {

/// Intern the snapped points: sort (key, occurrence) by key, so that vertex
/// ids follow the keys and do not depend on the order of the input. Returns
/// each occurrence's vertex id; the points themselves are released.
std::vector<uint32_t> intern_vertices(RawMap& raw, Graph& g, unsigned threads)
{
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
    return id;
}

/// Project every vertex onto the grid; returns the range of latitudes
/// (1e-6 degrees). Throws input_error naming the input of the first vertex
/// outside the projection's domain.
std::pair<int32_t, int32_t> project_vertices(Graph& g, const RawMap& raw, const std::vector<uint32_t>& id,
                                             const Projection& proj, unsigned threads)
{
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
    // A Data Tree node holds 32-bit steps across: the map's span must fit.
    GridBox box;
    for (const GridPoint p : g.grid) {
        box.extend(p);
    }
    if (!box.empty()) {
        check_grid_span("the config", proj.params().grid_m, double(box.max_x - box.min_x),
                        double(box.max_y - box.min_y), "the map");
    }
    return {lat_lo, lat_hi};
}

/// Distinct snapped points that round onto one grid point become one vertex
/// (the smallest id): returns each vertex's replacement; `merged` gets the
/// vertices merged away, counted later for a region, now for a whole map.
/// That needs points closer than a grid cell's diagonal, which the 1e-6
/// degree lattice cannot have where its projected spacing is wider (a 1 cm
/// grid anywhere short of the polar caps): then the search is skipped.
std::vector<uint32_t> merge_grid_twins(const Graph& g, const Projection& proj, std::pair<int32_t, int32_t> lat,
                                       unsigned threads, Problems& problems, const Owner& owner,
                                       std::vector<uint32_t>& merged)
{
    const auto [lat_lo, lat_hi] = lat;
    std::vector<uint32_t> remap(g.keys.size());
    std::iota(remap.begin(), remap.end(), 0U);
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
    return remap;
}

/// For a region: each vertex's rank (the smallest region-level code of the
/// polylines through it), then the merged vertices it owns counted.
void rank_vertices(Owner& owner, const RawMap& raw, const std::vector<uint32_t>& id, const Graph& g,
                   const std::vector<uint32_t>& merged, Problems& problems)
{
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
}

/// Clean each polyline (repeated points, then p-q-p spikes, then a closed
/// one's spike at its start) into the graph's edges; a polyline left with
/// too few points is a degenerate one.
void clean_polylines(Graph& g, const RawMap& raw, const std::vector<uint32_t>& id, const std::vector<uint32_t>& remap,
                     Problems& problems, const Owner& owner)
{
    g.verts.reserve(id.size());
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
}

} // namespace

Graph make_graph(RawMap& raw, const Projection& proj, unsigned threads, Problems& problems, Owner& owner)
{
    Graph g;
    const std::vector<uint32_t> id = intern_vertices(raw, g, threads);
    const auto lat = project_vertices(g, raw, id, proj, threads);
    std::vector<uint32_t> merged;
    const std::vector<uint32_t> remap = merge_grid_twins(g, proj, lat, threads, problems, owner, merged);
    rank_vertices(owner, raw, id, g, merged, problems);
    clean_polylines(g, raw, id, remap, problems, owner);
    release(raw.offsets);
    return g;
}

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
    // whether a side was claimed twice, and whether they are one ring's.
    struct Group {
        size_t end;
        uint32_t left, right;
        bool conflict, one_ring;
    };
    auto group = [&](size_t i) {
        Group gr{i, no_unit, no_unit, false, true};
        for (; gr.end < nrec && keys[gr.end].first == keys[i].first; ++gr.end) {
            gr.one_ring = gr.one_ring && edge_of(gr.end) == edge_of(i);
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
    // The same polygon on both sides, never a boundary: a slit or spike in
    // its ring, or an edge that two of its parts share (the halves of a
    // unit that a source cut at the antimeridian), which is inside it.
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
                if (gr.one_ring && owner.unit(gr.left)) {
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

std::vector<SourceRun> reversed_runs(std::span<const SourceRun> runs, uint32_t m)
{
    // Run i covers segments [first_i, first_{i+1}); the other way round it
    // covers [m - first_{i+1}, m - first_i).
    std::vector<SourceRun> out;
    out.reserve(runs.size());
    for (size_t i = runs.size(); i-- > 0;) {
        const uint32_t end = i + 1 < runs.size() ? runs[i + 1].first : m;
        out.push_back({m - std::min(end, m), runs[i].src});
    }
    return out;
}

std::vector<SourceRun> canonical_runs(std::vector<SourceRun> runs, uint32_t m)
{
    std::vector<SourceRun> out;
    for (const SourceRun& r : runs) {
        if (r.first >= m) {
            break; // sorted: no segment left for these
        }
        if (!out.empty() && out.back().first == r.first) {
            out.back() = r; // the earlier run has no segment left
        } else {
            out.push_back(r);
        }
        while (out.size() >= 2 && same_source(out[out.size() - 2].src, out.back().src)) {
            out.pop_back();
        }
    }
    if (!out.empty()) {
        out.front().first = 0;
    }
    return out;
}

SourceRef Graph::source_at(size_t i, uint32_t segment) const noexcept
{
    const auto r = runs_of(i);
    const auto after =
        std::upper_bound(r.begin(), r.end(), segment, [](uint32_t s, const SourceRun& run) { return s < run.first; });
    return after == r.begin() ? src[i] : std::prev(after)->src;
}

void join_pieces(Graph& g, const std::vector<Piece>& pieces, bool keep_runs)
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
    if (keep_runs) {
        out.run_off.push_back(0);
    }
    std::vector<SourceRun> runs;
    // Walk from the end `end` of its piece through joints; appends one edge.
    auto walk = [&](uint32_t end) {
        const uint32_t first = end / 2;
        const auto [left, right] = sides_out(end);
        out.verts.push_back(pieces[first].ab[end & 1U]);
        runs.clear();
        for (uint32_t segment = 0;; ++segment) {
            visited[end / 2] = 1;
            const SourceRef here = g.src[pieces[end / 2].edge];
            if (keep_runs && (runs.empty() || !same_source(runs.back().src, here))) {
                runs.push_back({segment, here});
            }
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
        if (keep_runs) {
            if (runs.size() > 1) {
                out.runs.insert(out.runs.end(), runs.begin(), runs.end());
            }
            out.run_off.push_back(out.runs.size());
        }
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

} // namespace tigerlod::ingest::detail
