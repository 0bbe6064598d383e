#pragma once
/// @file radix_sort.hpp
/// Stable LSD radix sort of (64-bit key, 32-bit value) pairs by key, 16 bits a
/// pass, skipping the passes whose digit is the same in every key. Equal keys
/// keep their input order, so the result is deterministic, and the same for
/// any thread count: each thread counts and scatters a contiguous part, and
/// the parts' places in every bucket follow their order.

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
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

} // namespace detail

inline void radix_sort_by_key(std::vector<std::pair<uint64_t, uint32_t>>& v, unsigned threads = 1)
{
    using Item = std::pair<uint64_t, uint32_t>;
    constexpr size_t digits = size_t{1} << 16;
    constexpr size_t min_part = size_t{1} << 17; // below this a thread costs more than it saves
    const size_t n = v.size();
    if (n < 2) {
        return;
    }
    if (n < 4096) { // the same order, without clearing 64 K counters a pass
        std::stable_sort(v.begin(), v.end(), [](const Item& a, const Item& b) { return a.first < b.first; });
        return;
    }
    const auto parts = static_cast<unsigned>(std::clamp<size_t>(n / min_part, 1, std::max(1U, threads)));
    const size_t chunk = (n + parts - 1) / parts;
    auto begin = [&](unsigned t) { return std::min(n, t * chunk); };
    auto end = [&](unsigned t) { return std::min(n, (t + 1) * chunk); };

    std::vector<uint64_t> ors(parts, 0), ands(parts, ~uint64_t{0});
    detail::on_threads(parts, [&](unsigned t) {
        uint64_t o = 0, a = ~uint64_t{0};
        for (size_t i = begin(t); i < end(t); ++i) {
            o |= v[i].first;
            a &= v[i].first;
        }
        ors[t] = o;
        ands[t] = a;
    });
    uint64_t all_or = 0, all_and = ~uint64_t{0};
    for (unsigned t = 0; t < parts; ++t) {
        all_or |= ors[t];
        all_and &= ands[t];
    }
    const uint64_t varying = all_or ^ all_and;
    // The other buffer is left uninitialised (pairs of integers need no
    // construction): its pages are first touched by the scatter, on every
    // thread, instead of being zeroed here on one.
    struct Release {
        void operator()(Item* p) const noexcept { ::operator delete(p); }
    };
    const std::unique_ptr<Item, Release> other(static_cast<Item*>(::operator new(n * sizeof(Item))));
    Item* src = v.data();
    Item* dst = other.get();
    std::vector<std::vector<size_t>> count(parts, std::vector<size_t>(digits));
    for (unsigned shift = 0; shift < 64; shift += 16) {
        if (((varying >> shift) & 0xFFFFU) == 0) {
            continue;
        }
        detail::on_threads(parts, [&](unsigned t) {
            auto& c = count[t];
            std::fill(c.begin(), c.end(), size_t{0});
            for (size_t i = begin(t); i < end(t); ++i) {
                ++c[(src[i].first >> shift) & 0xFFFFU];
            }
        });
        size_t sum = 0;
        for (size_t d = 0; d < digits; ++d) {
            for (unsigned t = 0; t < parts; ++t) {
                const size_t k = count[t][d];
                count[t][d] = sum;
                sum += k;
            }
        }
        detail::on_threads(parts, [&](unsigned t) {
            auto& c = count[t];
            for (size_t i = begin(t); i < end(t); ++i) {
                dst[c[(src[i].first >> shift) & 0xFFFFU]++] = src[i];
            }
        });
        std::swap(src, dst);
    }
    if (src != v.data()) { // an odd number of passes
        detail::on_threads(parts, [&](unsigned t) { std::copy(src + begin(t), src + end(t), v.data() + begin(t)); });
    }
}

} // namespace tigerlod
