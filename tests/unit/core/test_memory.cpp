#include "core/memory.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <utility>
#include <vector>

// Stages free their large arrays between phases to bound their peak memory;
// `v = {}` looks like that but keeps the capacity.
TEST(Release, FreesTheStorageThatAssigningBracesKeeps)
{
    std::vector<std::pair<uint64_t, uint32_t>> kept(1000, {1, 2});
    kept = {};
    EXPECT_EQ(kept.size(), 0U); // its capacity is the library's choice: libstdc++ keeps all of it

    std::vector<std::pair<uint64_t, uint32_t>> freed(1000, {1, 2});
    tigerlod::release(freed);
    EXPECT_EQ(freed.size(), 0U);
    EXPECT_EQ(freed.capacity(), 0U);
    freed.push_back({3, 4}); // still usable
    EXPECT_EQ(freed.front().first, 3U);
}
