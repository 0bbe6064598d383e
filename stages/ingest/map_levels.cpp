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

} // namespace tigerlod::ingest::detail
