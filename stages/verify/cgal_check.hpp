#pragma once
/// @file cgal_check.hpp
/// A second exact checker of a decoded Data Tree's meetings, sharing no
/// geometry code with verifier.cpp: CGAL's exact kernel for the predicates
/// and its box-intersection sweep (box_intersection_d, Zomorodian and
/// Edelsbrunner 2002) for the candidate pairs. It finds, per level, the
/// chains that cross, touch or overlap at one LOD (a chain meeting itself
/// included) and the pairs of chains that meet at two different LODs, and
/// compares them with what verify reported. The CGAL headers stay in
/// cgal_check.cpp (they are slow to compile).

#include "reader/reader.hpp"
#include "stages/verify/verifier.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace tigerlod::verify {

struct CgalCheck {
    uint64_t segments = 0;     ///< segments decoded, summed over levels and LODs (each chain once per level and LOD)
    uint64_t within_pairs = 0; ///< (level, LOD, chain pair) meetings, input problems left out
    uint64_t across_pairs = 0; ///< (level, chain pair) meetings across two LODs, input problems left out
    uint64_t input_pairs = 0;  ///< (level, chain pair) that already meet at LOD 0
    /// Where it and verify's report differ, in order, at most 20 listed;
    /// empty when they agree.
    std::vector<std::string> disagreements;
    double seconds = 0;
};

/// Decode every node of `tree` at every LOD as a reader would (each chain
/// once per level and LOD, from the first node that shows it) and find its
/// meetings with CGAL, then compare them with `report`, verify's report of
/// the whole tree: its items of kinds crossings, overlaps and
/// self_intersections per (level, LOD, chains), and lod_crossings per
/// (level, chains). Two segments meet unless they are disjoint or share
/// only a point that is an end of both (verify's rule); a pair of chains
/// that meets at LOD 0 is an input problem at every LOD, as verify files
/// it. Across LODs a meeting that one of the two segments also has at the
/// other LOD is that LOD's and is left out, as verify leaves it. Where
/// verify dropped items (--max-items), the counts are compared. CGAL checks
/// every pair of the level, not only those the partition contract leaves
/// to verify: a meeting verify could not see is a disagreement too.
CgalCheck cgal_check(const reader::Tree& tree, const Report& report);

} // namespace tigerlod::verify
