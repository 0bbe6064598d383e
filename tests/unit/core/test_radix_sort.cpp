#include "core/radix_sort.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>

using Items = std::vector<std::pair<uint64_t, uint32_t>>;

namespace {

/// What radix_sort_pairs must give: the pairs in (key, value) order.
Items sorted(Items v)
{
    std::sort(v.begin(), v.end());
    return v;
}

void expect_sorted_on_every_thread_count(const Items& in, const char* what)
{
    const Items want = sorted(in);
    for (unsigned threads : {1U, 2U, 3U, 8U}) {
        Items v = in;
        tigerlod::radix_sort_pairs(v, threads);
        EXPECT_EQ(v, want) << what << ", " << threads << " threads";
    }
}

} // namespace

TEST(RadixSort, RisingValuesGiveTheStableSortByKey)
{
    // Enough pairs for three parts of the parallel passes, with many equal
    // keys (few distinct low bits) and a constant middle digit.
    std::mt19937_64 rng(7);
    Items in(400000);
    for (uint32_t i = 0; i < in.size(); ++i) {
        const uint64_t hi = rng() % 50000, lo = rng() % 300;
        in[i] = {(hi << 48) | (uint64_t{0xABCD} << 16) | lo, i};
    }
    Items stable = in;
    std::stable_sort(stable.begin(), stable.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    EXPECT_EQ(sorted(in), stable);
    expect_sorted_on_every_thread_count(in, "random keys");
    for (size_t n : {size_t{5000}, size_t{4095}}) { // on each side of the switch to std::sort
        Items v(in.begin(), in.begin() + static_cast<std::ptrdiff_t>(n));
        const Items want = sorted(v);
        tigerlod::radix_sort_pairs(v, 2);
        EXPECT_EQ(v, want) << n;
    }
    Items small{{3, 0}, {1, 1}, {3, 2}, {0, 3}};
    tigerlod::radix_sort_pairs(small, 4);
    EXPECT_EQ(small, (Items{{0, 3}, {1, 1}, {3, 0}, {3, 2}}));
}

TEST(RadixSort, EqualKeysEndInValueOrderWhateverTheirInputOrder)
{
    std::mt19937_64 rng(11);
    Items in(300000);
    for (auto& x : in) {
        x = {rng() % 1000, static_cast<uint32_t>(rng())};
    }
    expect_sorted_on_every_thread_count(in, "1,000 keys, random values");
    Items one_key(100000);
    for (auto& x : one_key) {
        x = {42, static_cast<uint32_t>(rng())};
    }
    expect_sorted_on_every_thread_count(one_key, "one key");
}

TEST(RadixSort, SkewedKeysSplitBucketsThatAreTooLarge)
{
    // Nearly every key in one bucket of the whole range (one far outlier), and
    // a dense run of keys that fills one bucket again at the second level: the
    // split buckets must come out sorted like the others.
    std::mt19937_64 rng(3);
    Items in;
    for (uint32_t i = 0; i < 300000; ++i) {
        in.emplace_back(rng() % 200000, i);
    }
    in.emplace_back(~uint64_t{0}, 7);
    in.emplace_back(uint64_t{1} << 40, 8);
    for (uint32_t i = 0; i < 100000; ++i) {
        in.emplace_back(123456 + i % 3, 1000000 - i);
    }
    std::shuffle(in.begin(), in.end(), rng);
    expect_sorted_on_every_thread_count(in, "skewed keys");
}

TEST(KeyAlignedParts, PartsBeginWhereAKeyDoes)
{
    // Keys 1 x3, 2 x1, 5 x4, 7 x2: ten pairs.
    const Items v{{1, 0}, {1, 1}, {1, 2}, {2, 3}, {5, 4}, {5, 5}, {5, 6}, {5, 7}, {7, 8}, {7, 9}};
    // Even cuts at 3, 6 would split key 5's run: the second moves to 8.
    EXPECT_EQ(tigerlod::key_aligned_parts(v, 3), (std::vector<size_t>{0, 3, 8, 10}));
    // A cut inside key 1's run moves past it; two cuts can meet (an empty part).
    EXPECT_EQ(tigerlod::key_aligned_parts(v, 5), (std::vector<size_t>{0, 3, 4, 8, 8, 10}));
    EXPECT_EQ(tigerlod::key_aligned_parts(v, 1), (std::vector<size_t>{0, 10}));
    EXPECT_EQ(tigerlod::key_aligned_parts(Items{}, 2), (std::vector<size_t>{0, 0, 0}));
}
