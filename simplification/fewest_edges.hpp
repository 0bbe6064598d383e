#pragma once
/// @file fewest_edges.hpp
/// Step 4 of the simplification (README.md beside this file): the shortest
/// path of one chain over its original edges and the shortcuts not banned.

#include "simplification/candidates.hpp"

#include <cstdint>
#include <functional>
#include <span>
#include <vector>

namespace tigerlod::simplify {

/// A shortcut's state from this value on bans it (simplifier.cpp's states:
/// unknown 0 and good 1 may be taken).
constexpr uint8_t first_banned_state = 2;

/// How fewest_edges_path reads a run of shortcuts from a vertex: one
/// shortcut at a time, or through a tree of range minima (the log of the
/// run's length); `automatic` takes the tree where the runs are long. Both
/// give the same path (tests compare them).
enum class RunReading { automatic, one_by_one, tree };

/// A rule fewest_edges_path asks about a shortcut in state 0 (not yet
/// decided) when, and only when, the path would take it: `allows(from, to)`
/// gives the shortcut `passed` (below first_banned_state, not 0) or
/// `refused` (first_banned_state or above) in `state`, each asked once.
/// The path is then the one found over the shortcuts the rule allows, as if
/// it had been asked about every shortcut first, at the cost of those a
/// shortest path would take ahead of the one it takes at each vertex.
struct LazyRule {
    std::function<bool(uint32_t from, uint32_t to)> allows;
    uint8_t passed = 1;
    uint8_t refused = first_banned_state;
};

/// Fewest-vertex path 0 -> n-1 of a chain of n vertices over its original
/// edges and the shortcuts of `cand` whose `state` (per shortcut id) is
/// below first_banned_state, with at least three edges for a `ring` (so it
/// keeps three vertices); among shortest paths, the lexicographically
/// largest vertex sequence (a total order, so lazy and exhaustive testing
/// choose the same path). `path` gets the vertices, `path_cand` the
/// shortcut id of each edge (UINT32_MAX for an original edge). With a
/// `rule`, the shortcuts in state 0 must also pass it (LazyRule), and
/// `state` records each answer.
void fewest_edges_path(const Candidates& cand, std::span<uint8_t> state, size_t n, bool ring,
                       std::vector<uint32_t>& path, std::vector<uint32_t>& path_cand,
                       RunReading reading = RunReading::automatic, const LazyRule* rule = nullptr);

} // namespace tigerlod::simplify
