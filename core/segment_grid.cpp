#include "core/segment_grid.hpp"

#include "core/radix_sort.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <stdexcept>
#include <thread>

namespace tigerlod {

namespace {

struct Grid {
    int64_t ox = 0, oy = 0, c = 1;

    template <class F> void cover(GridPoint a, GridPoint b, int dilate, F&& f) const
    {
        const int64_t x0 = std::min<int64_t>(a.x, b.x) - ox, x1 = std::max<int64_t>(a.x, b.x) - ox;
        const int64_t y0 = std::min<int64_t>(a.y, b.y) - oy, y1 = std::max<int64_t>(a.y, b.y) - oy;
        const int64_t cx0 = x0 / c, cx1 = x1 / c;
        auto emit_column = [&](int64_t cx, int64_t lo, int64_t hi) {
            lo = std::max(lo, y0);
            hi = std::min(hi, y1);
            const int64_t cy0 = lo / c, cy1 = hi / c;
            for (int64_t dx = -dilate; dx <= dilate; ++dx) {
                for (int64_t cy = cy0 - dilate; cy <= cy1 + dilate; ++cy) {
                    f(key(cx + dx, cy));
                }
            }
        };
        if (cx0 == cx1) {
            emit_column(cx0, y0, y1);
            return;
        }
        const double ax = static_cast<double>(a.x - ox), ay = static_cast<double>(a.y - oy);
        const double slope = static_cast<double>(int64_t{b.y} - a.y) / static_cast<double>(int64_t{b.x} - a.x);
        for (int64_t cx = cx0; cx <= cx1; ++cx) {
            const double xa = static_cast<double>(std::max(x0, cx * c));
            const double xb = static_cast<double>(std::min(x1, (cx + 1) * c));
            const double ya = ay + (xa - ax) * slope, yb = ay + (xb - ax) * slope;
            emit_column(cx, static_cast<int64_t>(std::floor(std::min(ya, yb))) - 1,
                        static_cast<int64_t>(std::ceil(std::max(ya, yb))) + 1);
        }
    }
    static uint64_t key(int64_t cx, int64_t cy) noexcept
    {
        // Cells are offset by one so that a dilation never goes negative.
        return (static_cast<uint64_t>(cx + 1) << 32) | static_cast<uint64_t>(cy + 1);
    }
};

template <class S> Grid make_grid(const std::vector<S>& segs, double min_cell)
{
    Grid g;
    int64_t mx = INT64_MAX, my = INT64_MAX;
    double total = 0;
    for (const auto& s : segs) {
        mx = std::min<int64_t>({mx, s.a.x, s.b.x});
        my = std::min<int64_t>({my, s.a.y, s.b.y});
        total += static_cast<double>(std::max(std::abs(int64_t{s.b.x} - s.a.x), std::abs(int64_t{s.b.y} - s.a.y)));
    }
    g.ox = segs.empty() ? 0 : mx;
    g.oy = segs.empty() ? 0 : my;
    const double mean = segs.empty() ? 1.0 : total / static_cast<double>(segs.size());
    // Twice the mean segment length keeps about two cells per segment; a cell of
    // at least 2 grid units keeps cell indices of a 32-bit grid within 31 bits.
    g.c = static_cast<int64_t>(std::max({2.0 * mean, min_cell, 2.0}));
    return g;
}

} // namespace

namespace {

/// The pairs that meet among the segments listed in `entries` (cell,
/// segment) by cell, but those `skip(i, j)` leaves out (asked before any
/// geometry: it is the cheap test).
template <class Skip>
std::vector<Intersection> meeting_pairs(const std::vector<Segment>& segs,
                                        std::vector<std::pair<uint64_t, uint32_t>>& entries, Skip skip,
                                        unsigned threads)
{
    // Sorted by (cell, segment): each cell lists its segments in order. A segment enters a cell once, as the cover
    // never repeats one.
    radix_sort_pairs(entries, threads);
    // Runs of whole cells, taken by the threads one after another.
    threads = std::max(1U, threads);
    const size_t nruns = std::min<size_t>(entries.size(), size_t{threads} * 64);
    const std::vector<size_t> run_start = key_aligned_parts(entries, nruns);
    std::vector<std::vector<Intersection>> found(threads);
    std::atomic<size_t> next_run{0};
    auto work = [&](unsigned t) {
        for (size_t run = next_run++; run < nruns; run = next_run++) {
            const size_t run_end = run_start[run + 1];
            for (size_t i = run_start[run]; i < run_end; ++i) {
                const Segment& s = segs[entries[i].second];
                for (size_t j = i + 1; j < run_end && entries[j].first == entries[i].first; ++j) {
                    const Segment& r = segs[entries[j].second];
                    if (skip(entries[i].second, entries[j].second)) {
                        continue;
                    }
                    if (std::max(s.a.x, s.b.x) < std::min(r.a.x, r.b.x) ||
                        std::max(r.a.x, r.b.x) < std::min(s.a.x, s.b.x) ||
                        std::max(s.a.y, s.b.y) < std::min(r.a.y, r.b.y) ||
                        std::max(r.a.y, r.b.y) < std::min(s.a.y, s.b.y)) {
                        continue;
                    }
                    const SegmentRelation rel = segment_relation(s.a, s.b, r.a, r.b);
                    if (rel == SegmentRelation::disjoint || rel == SegmentRelation::shared_endpoint) {
                        continue;
                    }
                    Intersection x;
                    x.first = std::min(entries[i].second, entries[j].second);
                    x.second = std::max(entries[i].second, entries[j].second);
                    x.relation = rel;
                    if (rel == SegmentRelation::cross) {
                        // Only a location for the report: doubles are precise enough.
                        auto cross = [](GridPoint o, GridPoint p, GridPoint q) {
                            return static_cast<double>(p.x - int64_t{o.x}) * static_cast<double>(q.y - int64_t{o.y}) -
                                   static_cast<double>(p.y - int64_t{o.y}) * static_cast<double>(q.x - int64_t{o.x});
                        };
                        const double d1 = cross(r.a, r.b, s.a), d2 = cross(r.a, r.b, s.b);
                        const double along = d1 / (d1 - d2);
                        x.x = s.a.x + along * (s.b.x - s.a.x);
                        x.y = s.a.y + along * (s.b.y - s.a.y);
                    } else {
                        // A touch or overlap has an end point of one on the other.
                        GridPoint at = s.a;
                        for (auto [p, q1, q2] : {std::tuple{s.a, r.a, r.b}, std::tuple{s.b, r.a, r.b},
                                                 std::tuple{r.a, s.a, s.b}, std::tuple{r.b, s.a, s.b}}) {
                            if (orientation(q1, q2, p) == 0 && in_span(q1, q2, p) && p != q1 && p != q2) {
                                at = p;
                                break;
                            }
                        }
                        x.x = at.x;
                        x.y = at.y;
                    }
                    found[t].push_back(x);
                }
            }
        }
    };
    std::vector<std::thread> pool;
    for (unsigned t = 1; t < threads; ++t) {
        pool.emplace_back(work, t);
    }
    work(0);
    for (auto& th : pool) {
        th.join();
    }
    std::vector<Intersection> all;
    for (auto& f : found) {
        all.insert(all.end(), f.begin(), f.end());
    }
    std::sort(all.begin(), all.end(), [](const Intersection& p, const Intersection& q) {
        return p.first != q.first ? p.first < q.first : p.second < q.second;
    });
    all.erase(std::unique(all.begin(), all.end(),
                          [](const Intersection& p, const Intersection& q) {
                              return p.first == q.first && p.second == q.second;
                          }),
              all.end());
    return all;
}

/// Every segment in every cell it passes through, as (cell, segment).
std::vector<std::pair<uint64_t, uint32_t>> every_entry(const std::vector<Segment>& segs)
{
    const Grid grid = make_grid(segs, 1.0);
    // Sized exactly (a counting pass): the entries are this check's peak memory.
    size_t nentries = 0;
    for (const auto& sg : segs) {
        grid.cover(sg.a, sg.b, 0, [&](uint64_t) { ++nentries; });
    }
    std::vector<std::pair<uint64_t, uint32_t>> entries;
    entries.reserve(nentries);
    for (uint32_t i = 0; i < segs.size(); ++i) {
        grid.cover(segs[i].a, segs[i].b, 0, [&](uint64_t k) { entries.emplace_back(k, i); });
    }
    return entries;
}

} // namespace

std::vector<Intersection> find_intersections(const std::vector<Segment>& segs, unsigned threads)
{
    if (segs.size() < 2) {
        return {};
    }
    auto entries = every_entry(segs);
    return meeting_pairs(
        segs, entries, [](uint32_t, uint32_t) { return false; }, threads);
}

std::vector<Intersection> find_intersections(const std::vector<Segment>& segs, std::span<const uint8_t> is_new,
                                             unsigned threads)
{
    if (is_new.size() != segs.size()) {
        throw std::invalid_argument("find_intersections: one flag per segment expected");
    }
    if (segs.size() < 2) {
        return {};
    }
    // The same cells as the whole check: the pairs found cannot depend on
    // which segments are new.
    const Grid grid = make_grid(segs, 1.0);
    // The new segments' entries first; the cells they pass through follow from them.
    std::vector<std::pair<uint64_t, uint32_t>> entries;
    for (uint32_t i = 0; i < segs.size(); ++i) {
        if (is_new[i]) {
            grid.cover(segs[i].a, segs[i].b, 0, [&](uint64_t k) { entries.emplace_back(k, i); });
        }
    }
    if (entries.empty()) {
        return {};
    }
    std::vector<uint64_t> cells(entries.size());
    for (size_t e = 0; e < entries.size(); ++e) {
        cells[e] = entries[e].first;
    }
    std::sort(cells.begin(), cells.end());
    cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
    // Old segments enter only those cells (a range test on the key first:
    // most of the map is nowhere near). The order of the entries does not
    // matter: meeting_pairs sorts them by (cell, segment).
    const uint64_t first = cells.front(), last = cells.back();
    for (uint32_t i = 0; i < segs.size(); ++i) {
        if (is_new[i]) {
            continue;
        }
        grid.cover(segs[i].a, segs[i].b, 0, [&](uint64_t k) {
            if (k >= first && k <= last && std::binary_search(cells.begin(), cells.end(), k)) {
                entries.emplace_back(k, i);
            }
        });
    }
    return meeting_pairs(
        segs, entries, [&](uint32_t i, uint32_t j) { return !is_new[i] && !is_new[j]; }, threads);
}

std::vector<Intersection> find_intersections_between(const std::vector<Segment>& segs, std::span<const uint32_t> layer,
                                                     std::span<const uint32_t> group, unsigned threads)
{
    if (layer.size() != segs.size() || group.size() != segs.size()) {
        throw std::invalid_argument("find_intersections_between: one layer and one group per segment expected");
    }
    if (segs.size() < 2) {
        return {};
    }
    auto entries = every_entry(segs);
    return meeting_pairs(
        segs, entries, [&](uint32_t i, uint32_t j) { return layer[i] == layer[j] || group[i] == group[j]; }, threads);
}

std::vector<std::pair<uint32_t, uint32_t>> find_near(const std::vector<SegmentRef>& segs, double distance,
                                                     unsigned threads)
{
    if (segs.empty()) {
        return {};
    }
    // Cells exactly `distance` wide (at least 2 units), on lines at multiples of
    // the width: which pairs come out depends on the two chains alone, not on
    // the other segments, so a map built region by region gets the same.
    Grid grid = make_grid(segs, 1.0);
    grid.c = static_cast<int64_t>(std::max(2.0, std::ceil(distance)));
    auto align = [&](int64_t o) { return (o >= 0 ? o / grid.c : -((-o + grid.c - 1) / grid.c)) * grid.c; };
    grid.ox = align(grid.ox);
    grid.oy = align(grid.oy);
    // The cells each chain passes through (consecutive segments mostly share
    // one), computed once: chain group g spans segs[seg_start[g], seg_start[g+1])
    // and cells[cell_start[g], cell_start[g+1]).
    std::vector<size_t> seg_start, cell_start;
    std::vector<uint64_t> cells;
    for (size_t i = 0; i < segs.size();) {
        seg_start.push_back(i);
        cell_start.push_back(cells.size());
        const auto first = static_cast<std::ptrdiff_t>(cells.size());
        // Cells are at least `distance` wide and segments mostly far shorter:
        // a segment inside the cell that the last one covered alone adds
        // nothing, which two comparisons tell without covering it.
        int64_t in_x0 = 1, in_x1 = 0, in_y0 = 1, in_y1 = 0; // empty
        auto inside = [&](GridPoint p) { return p.x >= in_x0 && p.x <= in_x1 && p.y >= in_y0 && p.y <= in_y1; };
        for (; i < segs.size() && segs[i].chain == segs[seg_start.back()].chain; ++i) {
            if (inside(segs[i].a) && inside(segs[i].b)) {
                continue;
            }
            uint64_t only = 0;
            int emitted = 0;
            grid.cover(segs[i].a, segs[i].b, 0, [&](uint64_t k) {
                only = k;
                ++emitted;
                if (cells.size() == static_cast<size_t>(first) || cells.back() != k) {
                    cells.push_back(k);
                }
            });
            if (emitted == 1) {
                const int64_t cx = static_cast<int64_t>(only >> 32) - 1,
                              cy = static_cast<int64_t>(only & 0xFFFFFFFFU) - 1;
                in_x0 = grid.ox + cx * grid.c;
                in_x1 = in_x0 + grid.c - 1;
                in_y0 = grid.oy + cy * grid.c;
                in_y1 = in_y0 + grid.c - 1;
            } else {
                in_x0 = in_y0 = 1;
                in_x1 = in_y1 = 0;
            }
        }
        std::sort(cells.begin() + first, cells.end());
        cells.erase(std::unique(cells.begin() + first, cells.end()), cells.end());
    }
    seg_start.push_back(segs.size());
    cell_start.push_back(cells.size());
    const size_t groups = seg_start.size() - 1;
    // Cells within reach (one cell around, cells being at least `distance` wide)
    // of the segments that bound each part.
    std::vector<std::pair<uint64_t, uint32_t>> reach;
    std::vector<uint64_t> around;
    for (size_t gi = 0; gi < groups; ++gi) {
        const SegmentRef& c = segs[seg_start[gi]];
        around.clear();
        for (size_t n = cell_start[gi]; n < cell_start[gi + 1]; ++n) {
            for (uint64_t dx = 0; dx < 3; ++dx) {
                for (uint64_t dy = 0; dy < 3; ++dy) {
                    around.push_back(cells[n] + (dx << 32) + dy - (uint64_t{1} << 32) - 1);
                }
            }
        }
        std::sort(around.begin(), around.end());
        around.erase(std::unique(around.begin(), around.end()), around.end());
        for (uint64_t k : around) {
            reach.emplace_back(k, c.part);
            if (c.also != UINT32_MAX) {
                reach.emplace_back(k, c.also);
            }
        }
    }
    radix_sort_pairs(reach, threads);
    std::vector<std::pair<uint32_t, uint32_t>> result; // (chain, part)
    std::vector<uint32_t> parts;
    for (size_t gi = 0; gi < groups; ++gi) {
        const SegmentRef& c = segs[seg_start[gi]];
        parts.clear();
        for (size_t n = cell_start[gi]; n < cell_start[gi + 1]; ++n) {
            auto it =
                std::lower_bound(reach.begin(), reach.end(), cells[n],
                                 [](const std::pair<uint64_t, uint32_t>& e, uint64_t key) { return e.first < key; });
            for (; it != reach.end() && it->first == cells[n]; ++it) {
                if (it->second != c.part) {
                    parts.push_back(it->second);
                }
            }
        }
        std::sort(parts.begin(), parts.end());
        parts.erase(std::unique(parts.begin(), parts.end()), parts.end());
        for (uint32_t part : parts) {
            result.emplace_back(c.chain, part);
        }
    }
    std::sort(result.begin(), result.end());
    result.erase(std::unique(result.begin(), result.end()), result.end());
    return result;
}

} // namespace tigerlod
