#include "core/radix_sort.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>

using Items = std::vector<std::pair<uint64_t, uint32_t>>;

TEST(RadixSort, StableAndTheSameForEveryThreadCount)
{
    // Enough items for three parts of the parallel sort, with many equal keys
    // (few distinct low bits) and a constant middle digit that gets skipped.
    std::mt19937_64 rng(7);
    Items in(400000);
    for (uint32_t i = 0; i < in.size(); ++i) {
        const uint64_t hi = rng() % 50000, lo = rng() % 300;
        in[i] = {(hi << 48) | (uint64_t{0xABCD} << 16) | lo, i};
    }
    Items expect = in;
    std::stable_sort(expect.begin(), expect.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    for (unsigned threads : {1U, 2U, 3U, 8U}) {
        Items v = in;
        tigerlod::radix_sort_by_key(v, threads);
        EXPECT_EQ(v, expect) << threads << " threads";
    }
    for (size_t n : {size_t{5000}, size_t{4095}}) { // on each side of the switch to std::stable_sort
        Items v(in.begin(), in.begin() + static_cast<std::ptrdiff_t>(n));
        Items want = v;
        std::stable_sort(want.begin(), want.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
        tigerlod::radix_sort_by_key(v, 2);
        EXPECT_EQ(v, want) << n;
    }
    Items small{{3, 0}, {1, 1}, {3, 2}, {0, 3}};
    tigerlod::radix_sort_by_key(small, 4);
    EXPECT_EQ(small, (Items{{0, 3}, {1, 1}, {3, 0}, {3, 2}}));
}
