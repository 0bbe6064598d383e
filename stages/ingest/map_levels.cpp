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

namespace {

/// Ids unique within the level: on a collision take the next free value,
/// in a deterministic order (by id, then by vertices).
void make_ids_unique(Level& lev)
{
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
}

/// build_level step by step: the boundary edges' incidences at the edge
/// ends, the walks from every junction and then around the rings left, each
/// chain in its canonical direction with its class and id, and the ids made
/// unique.
class LevelWalker {
  public:
    LevelWalker(const Graph& g, const EdgeEnds& ends, const RawMap& raw, const LevelCodes& lc)
        : m_g(g), m_ends(ends), m_lc(lc), m_lines(raw.kind == RawMap::Kind::lines)
    {
        index_boundary_ends();
        m_lev.chain_of_edge.assign(g.edge_count(), none);
        m_visited.assign(g.edge_count(), 0);
    }

    Level run()
    {
        const size_t nends = m_ends.vertex.size();
        for (uint32_t k = 0; k < nends; ++k) {
            const uint32_t v = m_ends.vertex[k];
            if (m_deg[k] == 0 || !is_junction(v)) {
                continue;
            }
            m_lev.junctions.push_back(v);
            m_lev.junction_degree.push_back(m_deg[k]);
            for (uint64_t i = m_start[k]; i < m_start[k + 1]; ++i) {
                if (!m_visited[m_inc[i] / 2]) {
                    walk(v, m_inc[i]);
                }
            }
        }
        for (uint32_t e = 0; e < m_g.edge_count(); ++e) {
            if (m_boundary[e] && !m_visited[e]) {
                walk(m_g.edge(e).front(), e * 2);
            }
        }
        make_ids_unique(m_lev);
        return std::move(m_lev);
    }

  private:
    /// Incidences of boundary edge ends at the edge ends' vertices (CSR, by
    /// end index): edge * 2 + (0: starts here, 1: ends here).
    void index_boundary_ends()
    {
        const auto& g = m_g;
        const size_t nends = m_ends.vertex.size();
        m_deg.assign(nends, 0);
        m_boundary.assign(g.edge_count(), 0);
        for (size_t e = 0; e < g.edge_count(); ++e) {
            if (m_lines || m_lc.side(g.left[e]) != m_lc.side(g.right[e])) {
                m_boundary[e] = 1;
                const auto ev = g.edge(e);
                ++m_deg[m_ends.of_vertex[ev.front()]];
                ++m_deg[m_ends.of_vertex[ev.back()]];
            }
        }
        m_start.assign(nends + 1, 0);
        for (size_t k = 0; k < nends; ++k) {
            m_start[k + 1] = m_start[k] + m_deg[k];
        }
        m_inc.assign(m_start[nends], 0);
        std::vector<uint64_t> fill(m_start.begin(), m_start.end() - 1);
        for (size_t e = 0; e < g.edge_count(); ++e) {
            if (m_boundary[e]) {
                const auto ev = g.edge(e);
                m_inc[fill[m_ends.of_vertex[ev.front()]]++] = static_cast<uint32_t>(e * 2);
                m_inc[fill[m_ends.of_vertex[ev.back()]]++] = static_cast<uint32_t>(e * 2 + 1);
            }
        }
    }

    /// Codes (left, right) of an edge walked away from its end `in`.
    std::pair<uint32_t, uint32_t> codes_out(uint32_t in) const
    {
        const uint32_t e = in / 2;
        const uint32_t l = m_lc.side(m_g.left[e]), r = m_lc.side(m_g.right[e]);
        return (in & 1U) ? std::pair{r, l} : std::pair{l, r};
    }

    bool is_junction(uint32_t v) const
    {
        const uint32_t k = m_ends.of_vertex[v];
        if (m_deg[k] != 2) {
            return true;
        }
        const uint32_t a = m_inc[m_start[k]], b = m_inc[m_start[k] + 1];
        if (a / 2 == b / 2) {
            return false; // a closed edge alone
        }
        // Walking in along a and out along b must keep the codes on each side.
        const auto out_b = codes_out(b);
        const auto out_a = codes_out(a);
        return !(out_b.first == out_a.second && out_b.second == out_a.first);
    }

    /// The chain from v0 out along `first_inc`, through vertices that are
    /// not junctions, to a junction or back to its start.
    void walk(uint32_t v0, uint32_t first_inc)
    {
        m_cv.assign(1, v0);
        m_chain_edges.clear();
        uint32_t in = first_inc;
        while (true) {
            const uint32_t e = in / 2;
            m_visited[e] = 1;
            m_chain_edges.push_back(e);
            const auto ev = m_g.edge(e);
            if (in & 1U) {
                m_cv.insert(m_cv.end(), ev.rbegin() + 1, ev.rend());
            } else {
                m_cv.insert(m_cv.end(), ev.begin() + 1, ev.end());
            }
            const uint32_t u = m_cv.back();
            if (is_junction(u)) {
                break;
            }
            const uint32_t arrived = in ^ 1U;                   // the incidence of e at u
            const uint64_t at_u = m_start[m_ends.of_vertex[u]]; // u has degree 2: its two incidences
            const uint32_t a = m_inc[at_u], b = m_inc[at_u + 1];
            const uint32_t next = a == arrived ? b : a;
            if (m_visited[next / 2]) {
                break; // back at the start of a ring
            }
            in = next;
        }
        LevelChain c;
        std::tie(c.left, c.right) = codes_out(first_inc);
        canonical_direction(c);
        class_and_id(c);
        c.first = m_lev.verts.size();
        c.count = static_cast<uint32_t>(m_cv.size());
        m_lev.verts.insert(m_lev.verts.end(), m_cv.begin(), m_cv.end());
        m_lev.chains.push_back(c);
    }

    /// The walked chain in its canonical direction and, for a ring, from its
    /// smallest vertex.
    void canonical_direction(LevelChain& c)
    {
        auto& cv = m_cv;
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
    }

    /// The chain's feature class (the dominant one by segments; the
    /// smallest class id on a tie) and id (the smallest source id of its
    /// edges, else a hash of its smallest segment); its edges marked as its.
    void class_and_id(LevelChain& c)
    {
        const auto& g = m_g;
        std::unordered_map<uint32_t, uint64_t> votes;
        uint64_t min_sid = UINT64_MAX;
        uint64_t min_seg = UINT64_MAX, min_seg2 = UINT64_MAX;
        const auto id = static_cast<uint32_t>(m_lev.chains.size());
        for (uint32_t e : m_chain_edges) {
            votes[g.cls[e]] += g.off[e + 1] - g.off[e] - 1;
            if (g.sid[e] != 0) {
                min_sid = std::min(min_sid, g.sid[e]);
            }
            m_lev.chain_of_edge[e] = id;
        }
        for (size_t k = 0; k + 1 < m_cv.size(); ++k) {
            uint64_t a = g.keys[m_cv[k]], b = g.keys[m_cv[k + 1]];
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
    }

    const Graph& m_g;
    const EdgeEnds& m_ends;
    const LevelCodes& m_lc;
    const bool m_lines;
    std::vector<uint32_t> m_deg;     ///< boundary edge ends at each edge end's vertex
    std::vector<uint8_t> m_boundary; ///< per edge
    std::vector<uint64_t> m_start;   ///< CSR offsets into m_inc, per edge end
    std::vector<uint32_t> m_inc;
    std::vector<uint8_t> m_visited;      ///< per edge
    std::vector<uint32_t> m_cv;          ///< the chain being walked: its vertices
    std::vector<uint32_t> m_chain_edges; ///< and its edges
    Level m_lev;
}; // class LevelWalker

} // namespace

Level build_level(const Graph& g, const EdgeEnds& ends, const RawMap& raw, const std::vector<LevelCodes>& lcs, size_t L)
{
    return LevelWalker(g, ends, raw, lcs[L]).run();
}

uint64_t cut_at_tiles(Level& lev, const Graph& g, const TileGrid& grid)
{
    Level out;
    out.verts.reserve(lev.verts.size());
    out.chains.reserve(lev.chains.size());
    std::vector<uint32_t> cut_vertices;
    std::vector<size_t> cuts;
    for (const auto& c : lev.chains) {
        const auto cv = lev.chain(c);
        // The vertices where the walk strays out of its current tile.
        cuts.assign(1, 0);
        auto tile = grid.tile(g.grid[cv.front()]);
        for (size_t k = 1; k + 1 < cv.size(); ++k) {
            if (grid.strays(g.grid[cv[k]], tile)) {
                cuts.push_back(k);
                tile = grid.tile(g.grid[cv[k]]);
            }
        }
        // A ring (closed, no junction on it) may be cut anywhere; a chain
        // closed at a junction keeps that junction as its ends, as an open one.
        std::vector<uint32_t> walk(cv.begin(), cv.end());
        if (c.ring) {
            // Around a closed chain the walk goes on past its first vertex:
            // that one is a cut only if it strays from the tile the walk ends in.
            if (!grid.strays(g.grid[cv.front()], tile)) {
                cuts.erase(cuts.begin());
            }
            if (cuts.size() < 2) {
                cuts.assign(1, 0); // whole
            } else {
                // From the first cut around to it again.
                walk.assign(cv.begin() + static_cast<std::ptrdiff_t>(cuts.front()), cv.end() - 1);
                walk.insert(walk.end(), cv.begin(), cv.begin() + static_cast<std::ptrdiff_t>(cuts.front()) + 1);
                const size_t shift = cuts.front();
                for (size_t& k : cuts) {
                    k -= shift;
                }
            }
        }
        cuts.push_back(walk.size() - 1);
        for (size_t p = 0; p + 1 < cuts.size(); ++p) {
            LevelChain piece = c;
            piece.first = out.verts.size();
            piece.count = static_cast<uint32_t>(cuts[p + 1] - cuts[p] + 1);
            piece.ring = c.ring && cuts.size() == 2;
            if (p > 0) {
                piece.id = splitmix(c.id ^ splitmix(p)) >> 1;
            }
            if (cuts.size() > 2) {
                cut_vertices.push_back(walk[cuts[p]]);
            }
            out.verts.insert(out.verts.end(), walk.begin() + static_cast<std::ptrdiff_t>(cuts[p]),
                             walk.begin() + static_cast<std::ptrdiff_t>(cuts[p + 1]) + 1);
            out.chains.push_back(piece);
        }
    }
    // A cut vertex of an open chain is an end of two pieces; of a ring, too
    // (the walk starts at one): each is a junction of degree 2.
    std::sort(cut_vertices.begin(), cut_vertices.end());
    cut_vertices.erase(std::unique(cut_vertices.begin(), cut_vertices.end()), cut_vertices.end());
    std::vector<std::pair<uint32_t, uint32_t>> junctions; // (vertex, degree), the level's and the cuts
    for (size_t k = 0; k < lev.junctions.size(); ++k) {
        junctions.emplace_back(lev.junctions[k], lev.junction_degree[k]);
    }
    uint64_t cuts_made = 0;
    for (uint32_t v : cut_vertices) {
        if (!std::binary_search(lev.junctions.begin(), lev.junctions.end(), v)) {
            junctions.emplace_back(v, 2);
            ++cuts_made;
        }
    }
    std::sort(junctions.begin(), junctions.end());
    for (const auto& [v, degree] : junctions) {
        out.junctions.push_back(v);
        out.junction_degree.push_back(degree);
    }
    make_ids_unique(out);
    lev = std::move(out);
    return cuts_made;
}

} // namespace tigerlod::ingest::detail
