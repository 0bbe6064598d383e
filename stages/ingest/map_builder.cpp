#include "stages/ingest/map_builder.hpp"
#include "stages/ingest/map_steps.hpp"

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

using namespace detail;

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

/// Who owns what a build counts: everything for a whole map; for a region,
/// the units under its own region-level codes.
Owner owner_of(const std::vector<LevelCodes>& lcs, const RegionScope* scope)
{
    Owner owner;
    if (scope != nullptr) {
        const auto& lr = lcs[scope->level];
        owner.unit_rank = lr.of_unit;
        for (const auto& c : lr.codes) {
            owner.own_rank.push_back(std::binary_search(scope->own.begin(), scope->own.end(), c) ? 1 : 0);
        }
    }
    return owner;
}

/// A unit of a level in two units of the level before: the config's levels
/// do not nest on this data (a level without its parent's code, levels out
/// of order), and every level below would be built wrong. Throws
/// input_error naming the level, the unit, its two parents and where they are.
void refuse_non_nesting(const RawMap& raw, const std::vector<LevelCodes>& lcs,
                        const std::vector<std::pair<uint32_t, uint32_t>>& non_nesting, const Owner& owner)
{
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
}

/// Polygon layers: a finest code that units of two input files carry, where
/// codes must be unique (reading refuses a code repeated within one file; a
/// code repeated across files is only seen where the files meet, here).
/// In a region's map, only the region's own units are checked: the region
/// that owns a code holds every unit of it.
void refuse_codes_in_two_files(const RawMap& raw, const std::vector<LevelCodes>& lcs, const Owner& owner,
                               const BuildOptions& options)
{
    if (raw.kind != RawMap::Kind::polygon_rings || options.merge_duplicate_codes || lcs.empty()) {
        return;
    }
    const LevelCodes& finest = lcs.back();
    std::vector<uint32_t> first(finest.codes.size(), no_unit);
    for (uint32_t u = 0; u < raw.units.size(); ++u) {
        if (!owner.unit(u)) {
            continue;
        }
        uint32_t& f = first[finest.of_unit[u]];
        if (f == no_unit) {
            f = u;
        } else if (raw.units[f].source.file != raw.units[u].source.file) {
            throw input_error(raw.where(raw.units[u].source) + ": '" + options.code_field + "' " +
                              finest.codes[finest.of_unit[u]] + " is also that of " + raw.where(raw.units[f].source) +
                              ", in another file: give each unit its own code (an input named twice?), or set "
                              "dataset.duplicate_code: merge to make each code one unit in parts");
        }
    }
}

/// The graph's counts for the report: unique vertices, edges, and the units
/// no edge bounds (a problem each).
void count_graph(const Graph& g, const RawMap& raw, const Owner& owner, BuildResult& result, Problems& problems)
{
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
}

/// One planarity check over every edge that bounds something at some level,
/// with safe repairs of crossings that snapping made; the meetings left are
/// problems. Returns the edges in them, sorted.
std::vector<uint32_t> check_planarity(Graph& g, const RawMap& raw, const std::vector<LevelCodes>& lcs,
                                      const Projection& projection, const BuildOptions& options, Problems& problems,
                                      const Owner& owner)
{
    const double max_shift = options.max_snap_shift_m / projection.params().grid_m;
    std::vector<uint32_t> bad_edges;
    for (const auto& f : repair_snap_crossings(g, raw, lcs, max_shift, options.threads, problems, owner)) {
        const char* kind = f.relation == SegmentRelation::cross     ? "crossings"
                           : f.relation == SegmentRelation::overlap ? "overlaps"
                                                                    : "touches";
        const uint32_t rank = std::min({owner.rank(g.left[f.first]), owner.rank(g.right[f.first]),
                                        owner.rank(g.left[f.second]), owner.rank(g.right[f.second])});
        if (owner.of_rank(rank)) {
            // The features at the place (an edge of a line layer may join several).
            problems.add(kind, f.x, f.y,
                         raw.where(g.source_at(f.first, f.first_segment)) + " " +
                             raw.where(g.source_at(f.second, f.second_segment)));
        }
        bad_edges.push_back(f.first);
        bad_edges.push_back(f.second);
    }
    std::sort(bad_edges.begin(), bad_edges.end());
    bad_edges.erase(std::unique(bad_edges.begin(), bad_edges.end()), bad_edges.end());
    return bad_edges;
}

/// For a region: the codes of each level at and below the region level that
/// it owns (by their region-level code).
OwnedCodes owned_codes(const RawMap& raw, const std::vector<LevelCodes>& lcs, const Owner& owner,
                       const RegionScope& scope)
{
    const size_t nlev = lcs.size();
    OwnedCodes owned(nlev);
    for (size_t L = scope.level; L < nlev; ++L) {
        owned[L].assign(lcs[L].codes.size(), 0);
        for (size_t u = 0; u < raw.units.size(); ++u) {
            if (owner.unit(static_cast<uint32_t>(u))) {
                owned[L][lcs[L].of_unit[u]] = 1;
            }
        }
    }
    return owned;
}

/// For a region: what the coarse levels need, into `out`: the edges between
/// region-level codes that this region owns, and a representative unit per
/// own code.
void hand_on_to_coarse(const Graph& g, const RawMap& raw, const std::vector<LevelCodes>& lcs, const Owner& owner,
                       const RegionScope& scope, const std::vector<uint32_t>& bad_edges, RegionOutput& out)
{
    const auto& lr = lcs[scope.level];
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
        out.edges.push_back(std::move(ce));
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
            out.units.push_back(raw.units[r]);
        }
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
    problems.count("empty_codes", raw.empty_codes);
    auto note = [&](const std::string& what) { log_progress(options, what); };
    auto last = std::chrono::steady_clock::now();
    auto phase = [&](std::string name) {
        const auto now = std::chrono::steady_clock::now();
        result.seconds.emplace_back(std::move(name), std::chrono::duration<double>(now - last).count());
        last = now;
    };
    std::vector<std::pair<uint32_t, uint32_t>> non_nesting;
    const auto lcs = level_codes(raw, non_nesting);
    Owner owner = owner_of(lcs, scope);
    refuse_non_nesting(raw, lcs, non_nesting, owner);
    refuse_codes_in_two_files(raw, lcs, owner, options);
    if (raw.kind == RawMap::Kind::polygon_rings) {
        if (const uint64_t n = raw.share_seam_vertices(); n > 0) {
            note("put " + std::to_string(n) + " points on segments along the meridian 180, where rings meet");
        }
    }
    Graph g = make_graph(raw, projection, options.threads, problems, owner);
    phase("intern_project");
    note("interned and projected " + std::to_string(g.keys.size()) + " vertices");
    if (raw.kind != RawMap::Kind::edges) {
        join_pieces(g, merge_segments(g, raw, options.threads, problems, owner), raw.kind == RawMap::Kind::lines);
    }
    phase("merge_join");
    note("merged shared segments: " + std::to_string(g.edge_count()) + " edges");
    count_graph(g, raw, owner, result, problems);
    const std::vector<uint32_t> bad_edges = check_planarity(g, raw, lcs, projection, options, problems, owner);
    phase("planarity");
    note("checked planarity");

    result.levels.resize(nlev);
    OwnedCodes owned(nlev);
    size_t first = 0;
    if (scope != nullptr) {
        first = scope->level + 1;
        owned = owned_codes(raw, lcs, owner, *scope);
        hand_on_to_coarse(g, raw, lcs, owner, *scope, bad_edges, *out);
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
    if (options.on_plan) {
        options.on_plan(raw.level_names.size());
    }
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
    raw.fields = meta.fields;
    raw.named = meta.named;
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
