#pragma once
/// @file radix_sort.hpp
/// Sorts (64-bit key, 32-bit value) pairs by key, then value, in place: beside
/// them, a buffer of at most 1 MB per thread, not a second copy of the array.
///
/// Method. One most-significant-digit pass distributes the pairs in place
/// (American flag sort) into 256 buckets of the keys' range, so each bucket
/// holds a contiguous range of keys. Then each bucket is sorted on its own: a
/// least-significant-digit radix sort, 11 bits a pass, over only the key bits
/// that vary within it, and the runs of equal keys by value. The buckets go to
/// the threads as they come free (one of more than 65,536 pairs is split the
/// same way again, so a thread's buffer stays within 1 MB); the result is the
/// one total order, so it does not depend on the thread count.
///
/// Callers that add pairs with rising values (the usual case: an index) get
/// the stable sort by key: equal keys keep their input order.

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <thread>
#include <utility>
#include <vector>

namespace tigerlod {

namespace detail {

/// f(t) for t in [0, n) on n threads, this one running t = 0.
template <class F> void on_threads(unsigned n, F&& f)
{
    std::vector<std::jthread> pool;
    for (unsigned t = 1; t < n; ++t) {
        pool.emplace_back([&f, t] { f(t); });
    }
    f(0U);
}

using KeyValue = std::pair<uint64_t, uint32_t>;

inline bool key_value_less(const KeyValue& a, const KeyValue& b) noexcept
{
    return a.first < b.first || (a.first == b.first && a.second < b.second);
}

constexpr unsigned top_bits = 8;
constexpr size_t buckets = size_t{1} << top_bits;
constexpr size_t lsd_limit = size_t{1} << 16; // larger buckets are split again: 1 MB of scratch at most

/// The shift that maps keys minus their least onto [0, buckets).
inline unsigned bucket_shift(uint64_t range) noexcept
{
    const auto width = static_cast<unsigned>(std::bit_width(range));
    return width > top_bits ? width - top_bits : 0;
}

/// Moves v[0, n) in place into the buckets of (key - lo) >> shift, whose
/// bounds are `start` (filled from their sizes `sizes`): take the pair at a
/// bucket's head, swap it to its own bucket's head, and so on until a pair
/// belongs where the cycle started (American flag sort).
inline void distribute(KeyValue* v, uint64_t lo, unsigned shift, const std::array<size_t, buckets>& sizes,
                       std::array<size_t, buckets + 1>& start)
{
    start[0] = 0;
    for (size_t b = 0; b < buckets; ++b) {
        start[b + 1] = start[b] + sizes[b];
    }
    auto bucket = [&](const KeyValue& x) { return static_cast<size_t>((x.first - lo) >> shift); };
    std::array<size_t, buckets> head;
    std::copy(start.begin(), start.end() - 1, head.begin());
    for (size_t b = 0; b < buckets; ++b) {
        while (head[b] < start[b + 1]) {
            KeyValue x = v[head[b]];
            for (size_t d = bucket(x); d != b; d = bucket(x)) {
                std::swap(x, v[head[d]++]);
            }
            v[head[b]++] = x;
        }
    }
}

/// Sorts v[0, n) by (key, value), with `scratch` as the other buffer of the LSD passes.
inline void sort_bucket(KeyValue* v, size_t n, std::vector<KeyValue>& scratch)
{
    if (n <= 64) {
        for (size_t i = 1; i < n; ++i) { // insertion sort
            const KeyValue x = v[i];
            size_t j = i;
            for (; j > 0 && key_value_less(x, v[j - 1]); --j) {
                v[j] = v[j - 1];
            }
            v[j] = x;
        }
        return;
    }
    uint64_t ors = 0, ands = ~uint64_t{0}, lo = ~uint64_t{0}, hi = 0;
    for (size_t i = 0; i < n; ++i) {
        ors |= v[i].first;
        ands &= v[i].first;
        lo = std::min(lo, v[i].first);
        hi = std::max(hi, v[i].first);
    }
    if (lo == hi) { // one key: by value
        std::sort(v, v + n, key_value_less);
        return;
    }
    if (n > lsd_limit) {
        const unsigned shift = bucket_shift(hi - lo);
        std::array<size_t, buckets> sizes{};
        for (size_t i = 0; i < n; ++i) {
            ++sizes[(v[i].first - lo) >> shift];
        }
        std::array<size_t, buckets + 1> start;
        distribute(v, lo, shift, sizes, start);
        for (size_t b = 0; b < buckets; ++b) {
            sort_bucket(v + start[b], start[b + 1] - start[b], scratch);
        }
        return;
    }
    uint64_t varying = ors ^ ands;
    constexpr unsigned bits = 11;
    constexpr size_t digits = size_t{1} << bits;
    if (scratch.size() < n) {
        scratch.resize(n);
    }
    KeyValue* src = v;
    KeyValue* dst = scratch.data();
    std::array<size_t, digits> count;
    while (varying != 0) {
        // The next pass starts at the lowest key bit that varies and is not sorted yet.
        const auto shift = static_cast<unsigned>(std::countr_zero(varying));
        count.fill(0);
        for (size_t i = 0; i < n; ++i) {
            ++count[(src[i].first >> shift) & (digits - 1)];
        }
        size_t sum = 0;
        for (size_t& c : count) {
            const size_t k = c;
            c = sum;
            sum += k;
        }
        for (size_t i = 0; i < n; ++i) {
            dst[count[(src[i].first >> shift) & (digits - 1)]++] = src[i];
        }
        std::swap(src, dst);
        varying = shift + bits >= 64 ? 0 : varying & (~uint64_t{0} << (shift + bits));
    }
    if (src != v) {
        std::copy(src, src + n, v);
    }
    // The distribution moved the pairs, so equal keys are in no particular order yet.
    for (size_t i = 0; i < n;) {
        size_t j = i + 1;
        while (j < n && v[j].first == v[i].first) {
            ++j;
        }
        if (j - i > 1) {
            std::sort(v + i, v + j, key_value_less);
        }
        i = j;
    }
}

} // namespace detail

/// Sorts `v` by key, then value (see the file comment), on up to `threads` threads.
inline void radix_sort_pairs(std::vector<std::pair<uint64_t, uint32_t>>& v, unsigned threads = 1)
{
    using detail::KeyValue;
    constexpr size_t min_part = size_t{1} << 17; // below this a thread costs more than it saves
    const size_t n = v.size();
    if (std::is_sorted(v.begin(), v.end(), detail::key_value_less)) {
        return; // added in order (one key and rising values, say): nothing to move
    }
    if (n < 4096) {
        std::sort(v.begin(), v.end(), detail::key_value_less);
        return;
    }
    const auto parts = static_cast<unsigned>(std::clamp<size_t>(n / min_part, 1, std::max(1U, threads)));
    const size_t chunk = (n + parts - 1) / parts;
    auto begin = [&](unsigned t) { return std::min(n, t * chunk); };
    auto end = [&](unsigned t) { return std::min(n, (t + 1) * chunk); };

    // Buckets over the keys' actual range, not their bit pattern: a map's
    // keys often fill a few values of the top bits.
    std::vector<uint64_t> lows(parts, ~uint64_t{0}), highs(parts, 0);
    detail::on_threads(parts, [&](unsigned t) {
        uint64_t lo = ~uint64_t{0}, hi = 0;
        for (size_t i = begin(t); i < end(t); ++i) {
            lo = std::min(lo, v[i].first);
            hi = std::max(hi, v[i].first);
        }
        lows[t] = lo;
        highs[t] = hi;
    });
    const uint64_t lo = *std::min_element(lows.begin(), lows.end());
    const uint64_t hi = *std::max_element(highs.begin(), highs.end());
    if (lo == hi) {
        std::sort(v.begin(), v.end(), detail::key_value_less);
        return;
    }
    const unsigned shift = detail::bucket_shift(hi - lo);
    std::vector<std::array<size_t, detail::buckets>> counts(parts);
    detail::on_threads(parts, [&](unsigned t) {
        auto& c = counts[t];
        c.fill(0);
        for (size_t i = begin(t); i < end(t); ++i) {
            ++c[(v[i].first - lo) >> shift];
        }
    });
    std::array<size_t, detail::buckets> sizes{};
    for (const auto& c : counts) {
        for (size_t b = 0; b < detail::buckets; ++b) {
            sizes[b] += c[b];
        }
    }
    std::array<size_t, detail::buckets + 1> start;
    detail::distribute(v.data(), lo, shift, sizes, start);
    std::atomic<size_t> next{0};
    detail::on_threads(parts, [&](unsigned) {
        std::vector<KeyValue> scratch;
        for (size_t b = next.fetch_add(1); b < detail::buckets; b = next.fetch_add(1)) {
            detail::sort_bucket(v.data() + start[b], start[b + 1] - start[b], scratch);
        }
    });
}

/// Sorts `v` by key, then value, where every key is below `keys` and the
/// values never fall in v's order (pairs added with a rising index, no pair
/// twice): a stable counting sort, O(n + keys) with a second array of the
/// pairs, the order radix_sort_pairs gives. For keys that index a dense grid.
inline void counting_sort_pairs(std::vector<std::pair<uint64_t, uint32_t>>& v, uint64_t keys)
{
    std::vector<size_t> start(keys + 1, 0);
    for (const auto& e : v) {
        ++start[e.first + 1];
    }
    for (uint64_t k = 0; k < keys; ++k) {
        start[k + 1] += start[k];
    }
    std::vector<std::pair<uint64_t, uint32_t>> out(v.size());
    for (const auto& e : v) {
        out[start[e.first]++] = e;
    }
    v = std::move(out);
}

/// Bounds of `n` parts of sorted pairs, about equal in size, each beginning
/// where a key does, so that no key's run is split: n + 1 indices, the first
/// 0 and the last v.size() (a part may be empty). For work on the runs of
/// equal keys spread over threads.
inline std::vector<size_t> key_aligned_parts(const std::vector<std::pair<uint64_t, uint32_t>>& v, size_t n)
{
    n = std::max<size_t>(n, 1);
    std::vector<size_t> bounds(n + 1, v.size());
    bounds[0] = 0;
    for (size_t t = 1; t < n; ++t) {
        size_t b = std::max(bounds[t - 1], v.size() / n * t);
        while (b > 0 && b < v.size() && v[b].first == v[b - 1].first) {
            ++b;
        }
        bounds[t] = b;
    }
    return bounds;
}

} // namespace tigerlod
