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

} // namespace tigerlod::ingest::detail
