#include "simplification/fewest_edges.hpp"

#include <algorithm>
#include <bit>
#include <cstring>
#include <utility>

namespace tigerlod::simplify {

namespace {

/// The smallest value over a range of positions, the largest position among
/// equals: a tree of (value, position) keys over positions 0..n-1, all at
/// UINT32_MAX / 2 (infinity for shortest_path) until set.
class MinTree {
  public:
    explicit MinTree(size_t n)
        : m_size(std::bit_ceil(std::max<size_t>(n, 1))), m_keys(2 * m_size, key(UINT32_MAX / 2, 0))
    {
        for (size_t i = 0; i < m_size; ++i) {
            m_keys[m_size + i] = key(UINT32_MAX / 2, static_cast<uint32_t>(i));
        }
        for (size_t i = m_size; i-- > 1;) {
            m_keys[i] = std::min(m_keys[2 * i], m_keys[2 * i + 1]);
        }
    }
    void set(uint32_t at, uint32_t value) noexcept
    {
        size_t i = m_size + at;
        m_keys[i] = key(value, at);
        for (i >>= 1; i >= 1; i >>= 1) {
            m_keys[i] = std::min(m_keys[2 * i], m_keys[2 * i + 1]);
        }
    }
    /// (value, position) of the smallest value in [lo, hi], the largest position among equals.
    std::pair<uint32_t, uint32_t> min(uint32_t lo, uint32_t hi) const noexcept
    {
        uint64_t best = UINT64_MAX;
        for (size_t l = m_size + lo, r = m_size + size_t{hi} + 1; l < r; l >>= 1, r >>= 1) {
            if (l & 1) {
                best = std::min(best, m_keys[l++]);
            }
            if (r & 1) {
                best = std::min(best, m_keys[--r]);
            }
        }
        return {static_cast<uint32_t>(best >> 32), UINT32_MAX - static_cast<uint32_t>(best)};
    }

  private:
    static uint64_t key(uint32_t value, uint32_t at) noexcept { return uint64_t{value} << 32 | (UINT32_MAX - at); }
    size_t m_size;
    std::vector<uint64_t> m_keys;
}; // class MinTree

} // namespace

void fewest_edges_path(const Candidates& cand, std::span<uint8_t> state, size_t n, bool ring,
                       std::vector<uint32_t>& path, std::vector<uint32_t>& path_cand, RunReading reading,
                       const LazyRule* rule)
{
    // Layer r holds the fewest edges to n-1 using at least r of them. An
    // open chain needs no layer beyond 0: every path from 0 to n-1 > 0 has
    // an edge (a second layer computed the same values again).
    const uint32_t R = ring ? 3 : 0;
    constexpr uint32_t inf = UINT32_MAX / 2;
    std::vector<uint32_t> f((R + 1) * n, inf), next((R + 1) * n, 0), via((R + 1) * n, UINT32_MAX);
    auto at = [n](uint32_t r, size_t v) { return r * n + v; };
    // Where runs are long (hundreds of vertices at coarse tolerances), per
    // layer the minimum over a range of vertices of (f, farthest first), a
    // tree over the vertices filled as v goes down: a run of shortcuts from
    // v costs the log of its length, not its length. Short runs are read
    // one by one: the tree's upkeep costs more there (the 10 m contours at
    // 64 m, rings found again after each ban: 1.45 -> 6.0 store-seconds
    // with the tree; the tract set at 2000 m 1.73 -> 1.22).
    constexpr size_t tree_min_run = 48;
    const bool by_tree = reading == RunReading::tree ||
                         (reading == RunReading::automatic && cand.size() >= tree_min_run * cand.runs().size());
    std::vector<MinTree> best_in(by_tree ? R + 1 : 0, MinTree(by_tree ? n : 0));
    // The banned shortcuts (state first_banned_state or worse), in id order: a run
    // is queried in the pieces between them.
    std::vector<uint32_t> banned;
    if (by_tree) {
        const uint8_t* st = state.data();
        const size_t m = state.size();
        size_t i = 0;
        for (; i + 8 <= m; i += 8) {
            uint64_t word;
            std::memcpy(&word, st + i, 8);
            if ((word & 0xFEFEFEFEFEFEFEFEULL) == 0) {
                continue; // eight usable (unknown or good: 0 or 1)
            }
            for (size_t k = i; k < i + 8; ++k) {
                if (st[k] >= first_banned_state) {
                    banned.push_back(static_cast<uint32_t>(k));
                }
            }
        }
        for (; i < m; ++i) {
            if (st[i] >= first_banned_state) {
                banned.push_back(static_cast<uint32_t>(i));
            }
        }
    }
    f[at(0, n - 1)] = 0;
    for (uint32_t r = 0; r < best_in.size(); ++r) {
        best_in[r].set(static_cast<uint32_t>(n - 1), f[at(r, n - 1)]);
    }
    // Pieces of a run still to read (tree): a shortcut the rule refuses
    // splits its piece in two, the farther read first.
    std::vector<std::pair<uint32_t, uint32_t>> pieces;
    for (size_t vv = n - 1; vv-- > 0;) {
        const auto v = static_cast<uint32_t>(vv);
        const auto runs = cand.runs_from(v);
        // Whether shortcut `id` from v to `to` may be taken; the rule decides
        // one not yet decided (refused here and in later layers alike).
        auto usable = [&](uint32_t id, uint32_t to) {
            uint8_t& s = state[id];
            if (s == 0 && rule) {
                s = rule->allows(v, to) ? rule->passed : rule->refused;
            }
            return s < first_banned_state;
        };
        for (uint32_t r = 0; r <= R; ++r) {
            const uint32_t rr = r > 0 ? r - 1 : 0;
            uint32_t best = inf, bk = 0, bc = UINT32_MAX;
            // Candidates from v, farthest first; ties keep the farthest.
            auto take = [&](uint32_t lo, uint32_t hi, uint32_t id_lo) {
                if (!rule) {
                    const auto [fk, k] = best_in[rr].min(lo, hi);
                    if (fk + 1 < best) {
                        best = fk + 1;
                        bk = k;
                        bc = id_lo + (k - lo);
                    }
                    return;
                }
                pieces.assign(1, {lo, hi});
                while (!pieces.empty()) {
                    const auto [l, h] = pieces.back();
                    pieces.pop_back();
                    const auto [fk, k] = best_in[rr].min(l, h);
                    if (fk + 1 >= best) {
                        continue; // nothing in the piece is better
                    }
                    const uint32_t id = id_lo + (k - lo);
                    if (usable(id, k)) {
                        best = fk + 1;
                        bk = k;
                        bc = id;
                        continue;
                    }
                    // The minimum is the farthest of its value: beyond it all
                    // are worse, before it as good or worse; both are read.
                    if (k > l) {
                        pieces.emplace_back(l, k - 1);
                    }
                    if (k < h) {
                        pieces.emplace_back(k + 1, h);
                    }
                }
            };
            for (size_t q = runs.size(); q-- > 0;) {
                const auto& run = runs[q];
                const uint32_t id0 = cand.run_id(cand.first_run(v) + q);
                if (!by_tree) {
                    for (uint32_t k = run.hi + 1; k-- > run.lo;) {
                        if (f[at(rr, k)] + 1 < best && usable(id0 + (k - run.lo), k)) {
                            best = f[at(rr, k)] + 1;
                            bk = k;
                            bc = id0 + (k - run.lo);
                        }
                    }
                    continue;
                }
                const uint32_t id_hi = id0 + (run.hi - run.lo);
                // The banned ids of the run, from the last: the pieces between them.
                auto it = std::upper_bound(banned.begin(), banned.end(), id_hi);
                uint32_t hi = run.hi;
                while (it != banned.begin() && *(it - 1) >= id0) {
                    const uint32_t k_banned = run.lo + (*--it - id0);
                    if (k_banned < hi) {
                        take(k_banned + 1, hi, id0 + (k_banned + 1 - run.lo));
                    }
                    if (k_banned == run.lo) {
                        hi = UINT32_MAX; // nothing left below it
                        break;
                    }
                    hi = k_banned - 1;
                }
                if (hi != UINT32_MAX && hi >= run.lo) {
                    take(run.lo, hi, id0);
                }
            }
            if (f[at(rr, v + 1)] + 1 < best) {
                best = f[at(rr, v + 1)] + 1;
                bk = v + 1;
                bc = UINT32_MAX;
            }
            f[at(r, v)] = best;
            next[at(r, v)] = bk;
            via[at(r, v)] = bc;
        }
        for (uint32_t r = 0; r < best_in.size(); ++r) {
            best_in[r].set(v, f[at(r, v)]);
        }
    }
    path.clear();
    path_cand.clear();
    uint32_t v = 0, r = R;
    path.push_back(0);
    while (v != n - 1) {
        const uint32_t k = next[at(r, v)];
        path_cand.push_back(via[at(r, v)]);
        r = r > 0 ? r - 1 : 0;
        v = k;
        path.push_back(v);
    }
}

} // namespace tigerlod::simplify
