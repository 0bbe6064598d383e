#pragma once
/// @file memory.hpp
/// Giving memory back while a stage runs.

namespace tigerlod {

/// Frees a container's storage now. `v = {}` does not: for std::vector it
/// assigns an empty initializer list, which keeps the capacity.
template <class C> void release(C& c) noexcept
{
    C().swap(c);
}

} // namespace tigerlod
