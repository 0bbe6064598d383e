#pragma once
/// @file cell_cover.hpp
/// The cells of a square grid that a thick segment touches.

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

namespace tigerlod::simplify {

/// floor(v) as an integer, for |v| < 2^62, without a call into libm.
inline int64_t floor_int(double v) noexcept
{
    const auto t = static_cast<int64_t>(v);
    return double(t) > v ? t - 1 : t;
}

/// Keys for the cells of a box of a grid of side `cell` (origin 0, 0),
/// ordered by x then y and numbered from the box's corner: the keys of a
/// county's cells span 20-odd bits, so a radix sort of them takes two or
/// three passes, where keys of (x, y) offset by 2^31 span 64 bits near an
/// axis of the projection (six passes).
class CellGrid {
  public:
    CellGrid() = default;
    /// The cells of the box [min_x, max_x] x [min_y, max_y] (grid units), and
    /// one more around them for rounding.
    CellGrid(double min_x, double min_y, double max_x, double max_y, double cell) noexcept
        : m_x0(floor_int(min_x / cell) - 1), m_y0(floor_int(min_y / cell) - 1), m_x1(floor_int(max_x / cell) + 1),
          m_y1(floor_int(max_y / cell) + 1)
    {
    }
    bool contains(int64_t x, int64_t y) const noexcept { return x >= m_x0 && x <= m_x1 && y >= m_y0 && y <= m_y1; }
    /// The number of cells: every key is below it.
    uint64_t size() const noexcept
    {
        return m_x1 < m_x0 ? 0 : static_cast<uint64_t>(m_x1 - m_x0 + 1) * static_cast<uint64_t>(m_y1 - m_y0 + 1);
    }
    /// The key of a cell that the box contains.
    uint64_t key(int64_t x, int64_t y) const noexcept
    {
        return static_cast<uint64_t>(x - m_x0) * static_cast<uint64_t>(m_y1 - m_y0 + 1) +
               static_cast<uint64_t>(y - m_y0);
    }

  private:
    int64_t m_x0 = 0, m_y0 = 0, m_x1 = -1, m_y1 = -1;
}; // class CellGrid

/// Calls f(x, y) for every cell of a grid (side `cell`, origin ox, oy) that
/// the r-neighbourhood of segment (ax, ay)-(bx, by) touches, row by row: the
/// part of the segment within the row's band widened by r, widened by r.
/// Conservative, and proportional to the segment's length in cells, not to
/// its bounding box (a long diagonal border at a small cell size covers
/// millions of cells of its box but thousands of its own).
template <class F>
void cover_cells(double ax, double ay, double bx, double by, double r, double cell, double ox, double oy, F&& f)
{
    ax -= ox;
    bx -= ox;
    ay -= oy;
    by -= oy;
    const auto y0 = floor_int((std::min(ay, by) - r) / cell);
    const auto y1 = floor_int((std::max(ay, by) + r) / cell);
    for (int64_t y = y0; y <= y1; ++y) {
        const double lo = double(y) * cell - r, hi = double(y + 1) * cell + r;
        double t0 = 0, t1 = 1;
        const double dy = by - ay;
        if (dy != 0) {
            double ta = (lo - ay) / dy, tb = (hi - ay) / dy;
            if (ta > tb) {
                std::swap(ta, tb);
            }
            t0 = std::max(t0, ta);
            t1 = std::min(t1, tb);
        }
        if (t0 > t1) {
            t0 = t1 = std::clamp(t0, 0.0, 1.0); // rounding at a band's edge: keep one point
        }
        const double xa = ax + t0 * (bx - ax), xb = ax + t1 * (bx - ax);
        const auto x0 = floor_int((std::min(xa, xb) - r) / cell);
        const auto x1 = floor_int((std::max(xa, xb) + r) / cell);
        for (int64_t x = x0; x <= x1; ++x) {
            f(x, y);
        }
    }
}

/// Values grouped by cell key, each cell's in the order they were added:
/// a counting sort through an open-addressing table over the distinct keys
/// (at most half full), so a cell's values are found in one probe or a few.
/// The far rule's grid: a radix sort of its (key, value) pairs and then
/// std::unordered_map lookups took 1.0 s of the tract level at 16 m, this
/// 0.7 s (the conflict graph, which walks every cell once, stays faster with
/// the radix sort).
template <class V> class CellBuckets {
  public:
    /// Groups the values of `pairs` (cell key, value) by key.
    explicit CellBuckets(const std::vector<std::pair<uint64_t, V>>& pairs)
    {
        const size_t size = std::bit_ceil(std::max<size_t>(2 * pairs.size(), 16));
        m_shift = 64 - std::countr_zero(size);
        m_slots.assign(size, Slot{});
        std::vector<uint32_t> slot(pairs.size());
        for (size_t i = 0; i < pairs.size(); ++i) {
            size_t at = slot_of(pairs[i].first);
            while (m_slots[at].count != 0 && m_slots[at].key != pairs[i].first) {
                at = (at + 1) & (size - 1);
            }
            m_slots[at].key = pairs[i].first;
            ++m_slots[at].count;
            slot[i] = static_cast<uint32_t>(at);
        }
        uint32_t sum = 0;
        for (Slot& s : m_slots) {
            s.begin = sum;
            sum += s.count;
        }
        m_values.resize(pairs.size());
        std::vector<uint32_t> fill(size, 0);
        for (size_t i = 0; i < pairs.size(); ++i) {
            m_values[m_slots[slot[i]].begin + fill[slot[i]]++] = pairs[i].second;
        }
    }
    /// The values of cell `key`, in the order added (none if it has none).
    std::span<const V> find(uint64_t key) const noexcept
    {
        for (size_t at = slot_of(key);; at = (at + 1) & (m_slots.size() - 1)) {
            const Slot& s = m_slots[at];
            if (s.count == 0) {
                return {};
            }
            if (s.key == key) {
                return std::span<const V>(m_values).subspan(s.begin, s.count);
            }
        }
    }
    /// f(values) for every cell, in no particular order.
    template <class F> void for_each(F&& f) const
    {
        for (const Slot& s : m_slots) {
            if (s.count != 0) {
                f(std::span<const V>(m_values).subspan(s.begin, s.count));
            }
        }
    }

  private:
    struct Slot {
        uint64_t key = 0;
        uint32_t begin = 0, count = 0; ///< count == 0: empty
    };
    size_t slot_of(uint64_t key) const noexcept
    {
        return static_cast<size_t>((key * 0x9E3779B97F4A7C15ULL) >> m_shift);
    }
    std::vector<Slot> m_slots;
    std::vector<V> m_values;
    int m_shift = 60;
}; // class CellBuckets

} // namespace tigerlod::simplify
