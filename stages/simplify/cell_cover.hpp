#pragma once
/// @file cell_cover.hpp
/// The cells of a square grid that a thick segment touches.

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

namespace tigerlod::simplify {

/// One 64-bit key for cell (x, y), ordered by x then y; for cell coordinates
/// within +-2^31.
inline uint64_t cell_key(int64_t x, int64_t y) noexcept
{
    return (static_cast<uint64_t>(x + (int64_t{1} << 31)) << 32) | static_cast<uint32_t>(y + (int64_t{1} << 31));
}

/// Calls f(x, y) for every cell of a grid (side `cell`, origin ox, oy) that
/// the r-neighbourhood of segment (ax, ay)-(bx, by) touches, row by row: the
/// part of the segment within the row's band widened by r, widened by r.
/// Conservative, and proportional to the segment's length in cells, not to
/// its bounding box (a long diagonal border at a small cell size covers
/// millions of cells of its box but thousands of its own).
/// floor(v) as an integer, for |v| < 2^62, without a call into libm.
inline int64_t floor_int(double v) noexcept
{
    const auto t = static_cast<int64_t>(v);
    return double(t) > v ? t - 1 : t;
}

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

/// Where each cell's run starts and ends in a list of (cell key, value)
/// pairs sorted by key, found in one probe or a few: an open-addressing
/// table over the distinct keys, at most half full. std::unordered_map
/// took most of the far rule's lookups (a node per cell, a division per probe).
class CellRuns {
  public:
    template <class Pair> explicit CellRuns(const std::vector<Pair>& sorted)
    {
        size_t distinct = 0;
        for (size_t i = 0; i < sorted.size(); ++i) {
            distinct += (i == 0 || sorted[i].first != sorted[i - 1].first) ? 1 : 0;
        }
        const size_t size = std::bit_ceil(std::max<size_t>(2 * distinct, 16));
        m_shift = 64 - std::countr_zero(size);
        m_slots.assign(size, Slot{});
        for (size_t b = 0; b < sorted.size();) {
            size_t e = b + 1;
            while (e < sorted.size() && sorted[e].first == sorted[b].first) {
                ++e;
            }
            size_t at = slot_of(sorted[b].first);
            while (m_slots[at].end != 0) {
                at = (at + 1) & (size - 1);
            }
            m_slots[at] = {sorted[b].first, static_cast<uint32_t>(b), static_cast<uint32_t>(e)};
            b = e;
        }
    }
    /// [begin, end) of `key`'s run in the list; begin == end if it has none.
    std::pair<uint32_t, uint32_t> find(uint64_t key) const noexcept
    {
        for (size_t at = slot_of(key);; at = (at + 1) & (m_slots.size() - 1)) {
            const Slot& s = m_slots[at];
            if (s.end == 0) {
                return {0, 0};
            }
            if (s.key == key) {
                return {s.begin, s.end};
            }
        }
    }

  private:
    struct Slot {
        uint64_t key = 0;
        uint32_t begin = 0, end = 0; ///< end == 0: empty (a run ends after its first entry)
    };
    /// A row (the low half of a key) hashed, plus the column: the cells of a
    /// row that a query visits one after the other sit in nearby slots.
    size_t slot_of(uint64_t key) const noexcept
    {
        const uint64_t row = ((key & 0xffffffffULL) * 0x9E3779B97F4A7C15ULL) >> m_shift;
        return static_cast<size_t>((row + (key >> 32)) & (m_slots.size() - 1));
    }
    std::vector<Slot> m_slots;
    int m_shift = 60;
};

} // namespace tigerlod::simplify
