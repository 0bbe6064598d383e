#pragma once
/// @file parallel.hpp
/// The ways tigerlod splits work over threads. Results must not depend
/// on the split: callers write to per-index or per-range slots only.

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace tigerlod {

/// Run f(begin, end) on up to `threads` contiguous ranges covering [0, n),
/// each of at least `min_chunk` items (one range, on this thread, when n is small).
template <class F> void parallel_ranges(size_t n, unsigned threads, size_t min_chunk, F&& f)
{
    threads = std::max(1U, std::min<unsigned>(threads, static_cast<unsigned>(std::max<size_t>(1, n / min_chunk))));
    if (threads == 1) {
        f(size_t{0}, n);
        return;
    }
    std::vector<std::thread> pool;
    const size_t chunk = (n + threads - 1) / threads;
    for (unsigned t = 0; t < threads; ++t) {
        const size_t b = std::min(n, t * chunk), e = std::min(n, b + chunk);
        pool.emplace_back([&f, b, e] { f(b, e); });
    }
    for (auto& th : pool) {
        th.join();
    }
}

/// Run f(i) for every i in [0, n) on up to `threads` threads taking the next
/// index as they finish: for items of very unequal cost.
template <class F> void parallel_each(size_t n, unsigned threads, F&& f)
{
    threads = std::max(1U, std::min<unsigned>(threads, static_cast<unsigned>(std::max<size_t>(n, 1))));
    if (threads == 1) {
        for (size_t i = 0; i < n; ++i) {
            f(i);
        }
        return;
    }
    // Every item runs; of the exceptions thrown, the one of the lowest index
    // is rethrown here, so which error a run reports does not depend on the threads.
    std::atomic<size_t> next{0};
    std::mutex m;
    std::exception_ptr error;
    size_t error_index = SIZE_MAX;
    {
        std::vector<std::jthread> pool;
        for (unsigned t = 0; t < threads; ++t) {
            pool.emplace_back([&] {
                for (size_t i; (i = next.fetch_add(1)) < n;) {
                    try {
                        f(i);
                    } catch (...) {
                        std::lock_guard lock(m);
                        if (i < error_index) {
                            error_index = i;
                            error = std::current_exception();
                        }
                    }
                }
            });
        }
    }
    if (error) {
        std::rethrow_exception(error);
    }
}

/// Run f(begin, end) over [0, n) in blocks of `block` items, each block taken
/// by the next free thread: for a few thousand items of unequal cost, too few
/// for parallel_ranges' minimum chunk.
template <class F> void parallel_blocks(size_t n, unsigned threads, size_t block, F&& f)
{
    parallel_each((n + block - 1) / block, threads, [&](size_t i) { f(i * block, std::min(n, (i + 1) * block)); });
}

} // namespace tigerlod
