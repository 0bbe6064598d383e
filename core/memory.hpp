#pragma once
/// @file memory.hpp
/// Giving memory back while a stage runs, and how much it took.

#include <sys/resource.h>

namespace tigerlod {

/// The process's peak resident memory so far, in MiB (getrusage's maxrss),
/// for a stage's timings file.
inline double peak_rss_mb() noexcept
{
    rusage ru{};
    getrusage(RUSAGE_SELF, &ru);
    return static_cast<double>(ru.ru_maxrss) / 1024.0;
}

/// Frees a container's storage now. `v = {}` does not: for std::vector it
/// assigns an empty initializer list, which keeps the capacity.
template <class C> void release(C& c) noexcept
{
    C().swap(c);
}

} // namespace tigerlod
