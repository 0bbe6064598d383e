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

} // namespace

namespace {

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

} // namespace

namespace {

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

} // namespace

namespace {

/// Pass-through degree of every vertex in the whole graph (at most 255).
std::vector<uint8_t> pass_through_degrees(const Graph& g)
{
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
    return deg;
}

/// Edge ends at the candidate vertices (those of the pairs found, of
/// degree 2), for joining two edges there: vertex -> edge*2 + (1 if it ends there).
std::unordered_map<uint32_t, std::vector<uint32_t>> ends_at_candidates(const Graph& g, const SegmentSet& s,
                                                                       const std::vector<Intersection>& by_segment,
                                                                       const std::vector<uint8_t>& deg)
{
    std::unordered_map<uint32_t, std::vector<uint32_t>> ends;
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
    return ends;
}

/// A vertex whose dropping resolves a pair, and where it lies.
struct Candidate {
    double d2; ///< squared distance it moves the boundary, grid units
    uint32_t v;
    uint32_t edge, index; ///< where v lies (index into the edge)
};

/// The repairs of one round: interior vertices dropped (edge, vertex
/// index), and pairs of edges joined at a vertex dropped (as edge ends).
struct Repairs {
    std::vector<std::pair<uint32_t, uint32_t>> drop_interior;
    std::vector<std::pair<uint32_t, uint32_t>> join;
};

/// The best vertex to drop for the meeting pair `f`: a pass-through vertex
/// of either segment, on an edge not touched this round, whose dropping
/// resolves the pair and moves the boundary least (at most max_shift; ties
/// to the smaller vertex id).
std::optional<Candidate> best_vertex(const Graph& g, const SegmentSet& s, const Intersection& f,
                                     const std::vector<uint8_t>& deg,
                                     const std::unordered_map<uint32_t, std::vector<uint32_t>>& ends,
                                     const std::vector<uint8_t>& touched, double max_shift)
{
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
    return best;
}

/// Choose this round's repairs, at most one per pair and none on an edge a
/// repair already touched; each is counted (and sampled) as a snap repair.
Repairs choose_repairs(const Graph& g, const RawMap& raw, const SegmentSet& s,
                       const std::vector<Intersection>& by_segment, double max_shift, Problems& problems,
                       const Owner& owner)
{
    const std::vector<uint8_t> deg = pass_through_degrees(g);
    const auto ends = ends_at_candidates(g, s, by_segment, deg);
    std::vector<uint8_t> touched(g.edge_count(), 0);
    Repairs r;
    for (const auto& f : by_segment) {
        const auto best = best_vertex(g, s, f, deg, ends, touched, max_shift);
        if (!best) {
            continue;
        }
        const auto ev = g.edge(best->edge);
        const GridPoint at = g.grid[best->v];
        if (owner.units(g.left[best->edge], g.right[best->edge])) {
            problems.add("snap_repairs", at.x, at.y, raw.where(g.src[best->edge]));
        }
        if (best->index > 0 && best->index + 1 < ev.size()) {
            r.drop_interior.emplace_back(best->edge, best->index);
            touched[best->edge] = 1;
        } else {
            const auto& two = ends.at(best->v);
            r.join.emplace_back(two[0], two[1]);
            touched[two[0] / 2] = touched[two[1] / 2] = 1;
        }
    }
    return r;
}

/// Rebuild the edges with the repairs applied, in the same order; `scope`
/// and `hot` become what the next round checks: the repaired and unresolved
/// edges, and the boxes of the new segments.
void apply_repairs(Graph& g, const Repairs& repairs, const std::vector<EdgeMeeting>& found, std::vector<uint8_t>& scope,
                   std::vector<GridBox>& hot)
{
    const auto& drop_interior = repairs.drop_interior;
    const auto& join = repairs.join;
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
    const bool with_runs = !g.run_off.empty();
    if (with_runs) {
        out.run_off.push_back(0);
    }
    // Edge e's runs in the order of its vertices (one when it has one source).
    auto runs_in_order = [&](uint32_t e) {
        const auto r = g.runs_of(e);
        return r.empty() ? std::vector<SourceRun>{{0, g.src[e]}} : std::vector<SourceRun>(r.begin(), r.end());
    };
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
        size_t new_segment = 0;      // where the repair put a new segment: pts[new_segment, +1]
        std::vector<SourceRun> runs; // a repaired edge's, rebuilt; the others' are copied as they are
        if (with_runs && repaired) {
            runs = runs_in_order(e);
        }
        if (drop_at[e] >= 0) {
            pts.erase(pts.begin() + drop_at[e]);
            new_segment = static_cast<size_t>(drop_at[e]) - 1;
            // Segments idx-1 and idx become one (idx-1's source); those after move down.
            const auto idx = static_cast<uint32_t>(drop_at[e]);
            for (auto& r : runs) {
                r.first = r.first <= idx ? r.first : r.first - 1;
            }
        } else if (joined_with[e] >= 0) {
            const auto code = static_cast<uint64_t>(joined_with[e]);
            const bool first_ends_at_v = (code & 1U) != 0;
            const uint32_t second_end = static_cast<uint32_t>(code >> 1);
            const auto m1 = static_cast<uint32_t>(pts.size() - 1);
            if (!first_ends_at_v) { // make this edge end at v
                std::reverse(pts.begin(), pts.end());
                std::swap(left, right);
                runs = with_runs ? reversed_runs(runs, m1) : runs;
            }
            const auto sv = g.edge(second_end / 2);
            pts.pop_back(); // v
            new_segment = pts.size() - 1;
            if (second_end & 1U) {
                pts.insert(pts.end(), sv.rbegin() + 1, sv.rend());
            } else {
                pts.insert(pts.end(), sv.begin() + 1, sv.end());
            }
            if (with_runs) {
                // The first's last segment and the second's first become one
                // (the first's source); the second's others follow.
                const auto m2 = static_cast<uint32_t>(sv.size() - 1);
                std::vector<SourceRun> second = runs_in_order(second_end / 2);
                if (second_end & 1U) {
                    second = reversed_runs(second, m2);
                }
                for (auto r : second) {
                    r.first = std::max(r.first, 1U) + m1 - 1;
                    runs.push_back(r);
                }
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
        if (with_runs && repaired) {
            runs = canonical_runs(std::move(runs), static_cast<uint32_t>(pts.size() - 1));
            if (runs.size() > 1 || (runs.size() == 1 && !same_source(runs[0].src, g.src[e]))) {
                out.runs.insert(out.runs.end(), runs.begin(), runs.end());
            }
        } else if (with_runs) {
            const auto kept = g.runs_of(e);
            out.runs.insert(out.runs.end(), kept.begin(), kept.end());
        }
        if (with_runs) {
            out.run_off.push_back(out.runs.size());
        }
    }
    g = std::move(out);
}

} // namespace

std::vector<EdgeMeeting> repair_snap_crossings(Graph& g, const RawMap& raw, const std::vector<LevelCodes>& lcs,
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
        std::vector<EdgeMeeting> found(by_segment.size());
        for (size_t i = 0; i < found.size(); ++i) { // report edges and their segments
            const Intersection& f = by_segment[i];
            found[i].relation = f.relation;
            found[i].x = f.x;
            found[i].y = f.y;
            found[i].first = s.at[f.first].first;
            found[i].first_segment = s.at[f.first].second;
            found[i].second = s.at[f.second].first;
            found[i].second_segment = s.at[f.second].second;
        }
        if (found.empty() || round == max_rounds) {
            return found;
        }
        const Repairs repairs = choose_repairs(g, raw, s, by_segment, max_shift, problems, owner);
        if (repairs.drop_interior.empty() && repairs.join.empty()) {
            return found;
        }
        apply_repairs(g, repairs, found, scope, hot);
    }
}

} // namespace tigerlod::ingest::detail
