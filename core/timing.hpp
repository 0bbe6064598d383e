#pragma once
/// @file timing.hpp
/// Wall seconds for the timings stages report, on the steady clock.

#include <chrono>

namespace tigerlod {

/// Seconds from `t0` (std::chrono::steady_clock::now()) to now.
inline double seconds_since(std::chrono::steady_clock::time_point t0)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

} // namespace tigerlod
