#pragma once
/// @file radix_sort.hpp
/// Stable LSD radix sort of (64-bit key, 32-bit value) pairs by key, 16 bits a
/// pass, skipping the passes whose digit is the same in every key. Equal keys
/// keep their input order, so the result is deterministic.

#include <array>
#include <cstdint>
#include <utility>
#include <vector>

namespace tigerlod {

inline void radix_sort_by_key(std::vector<std::pair<uint64_t, uint32_t>>& v)
{
    if (v.size() < 2) {
        return;
    }
    uint64_t all_or = 0, all_and = ~uint64_t{0};
    for (const auto& e : v) {
        all_or |= e.first;
        all_and &= e.first;
    }
    const uint64_t varying = all_or ^ all_and;
    std::vector<std::pair<uint64_t, uint32_t>> tmp(v.size());
    std::vector<uint32_t> count(1U << 16);
    for (unsigned shift = 0; shift < 64; shift += 16) {
        if (((varying >> shift) & 0xFFFFU) == 0) {
            continue;
        }
        std::fill(count.begin(), count.end(), 0U);
        for (const auto& e : v) {
            ++count[(e.first >> shift) & 0xFFFFU];
        }
        uint32_t sum = 0;
        for (auto& c : count) {
            const uint32_t n = c;
            c = sum;
            sum += n;
        }
        for (const auto& e : v) {
            tmp[count[(e.first >> shift) & 0xFFFFU]++] = e;
        }
        v.swap(tmp);
    }
}

} // namespace tigerlod
