#pragma once
/// @file tolerances.hpp
/// The part of the simplification that needs no OpenGL, shared by
/// tigerlod-color, tigerlod-simplify and tigerlod-verify: the options, the
/// tolerance of each chain (the contract simplify keeps and verify checks),
/// the halo segments within reach of a partition, the stencil colouring of a
/// store (the paper's Section 5.1 draws each chain's eps-Voronoi region in
/// the stencil buffer, so the map must be 255-colourable: chains whose
/// eps-neighbourhoods can meet get different classes, per render tile), and
/// the point part of the partition contract.

#include "formats/chains/chain_store.hpp"
#include "simplification/coloring.hpp"
#include "core/metric.hpp"

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace tigerlod::simplify {

/// A user point constraint in lon/lat degrees.
struct LonLat {
    double lon = 0, lat = 0;
};

struct SimplifyOptions {
    Metric metric = Metric::l2;
    std::map<std::string, double> class_scale; ///< eps multiplier by feature class
    bool projection_scale = true;              ///< eps in ground metres through the local projection scale
    uint32_t max_reach = 0;                    ///< cap on a shortcut's reach in vertices (0: none)
    /// Where the tolerance is coarse for a chain's spacing, shortcuts end
    /// only at the vertices a greedy fit within eps / end_sample keeps
    /// (candidates.hpp; 0: at every vertex).
    uint32_t end_sample = 0;
    /// The most proximate shortcuts a chain may have: a chain of n vertices
    /// with more (a coast of millions of vertices at kilometres) is scanned
    /// again with its reach capped at max(2, this / n), so that it has at
    /// most max(this, n), and counted in reach_capped_chains. The default
    /// is what a 32-bit shortcut id can number; tests set less.
    uint64_t max_chain_shortcuts = UINT32_MAX;
    bool point_constraints = true; ///< units' internal points and user points keep their side
    std::vector<LonLat> user_points;
    bool lazy = true;       ///< test only shortcuts on shortest paths
    bool clip_tests = true; ///< draw only the parts of a shortcut that can fail (near_parts.hpp); off for tests
    bool far_rule = true;   ///< accept shortcuts far from every other chain without the raster; off for tests
    ColorOptions color;
    unsigned threads = 1;
    /// Runs GL work on the thread that owns the context, waiting for it:
    /// given, simplify_store hands every use of the Raster to it (several
    /// stores can then be simplified at once); empty, it calls the Raster itself.
    std::function<void(const std::function<void()>&)> gl_thread;
};

/// The tolerance of each chain of `store` in grid units for `eps_m` ground metres.
std::vector<double> chain_tolerances(const chains::ChainStore& store, double eps_m, const SimplifyOptions& opt);

/// What chain_tolerances multiplies a tolerance by, per chain of a store,
/// worked out once for a ladder: the projection's scale costs a
/// GeographicLib call a chain (a quarter of a verify job's time on the
/// synthetic nation's blocks, at each of 8 LODs).
class ChainScales {
  public:
    ChainScales(const chains::ChainStore& store, const SimplifyOptions& opt);
    /// chain_tolerances(store, eps_m, opt), bit for bit.
    std::vector<double> tolerances(double eps_m) const;

  private:
    double m_grid_m;
    /// Per chain, the class's scale and the projection's, 1 where none (x * 1 is x exactly).
    std::vector<double> m_class, m_projection;
}; // class ChainScales

/// Per point of `store`, whether the segment starting there takes part:
/// every owned segment, and the halo segments within `reach` grid units of
/// an owned one. The halo holds whole chains with any part near the
/// partition (a kilometre, say), most of whose length is out of reach at
/// any tolerance of the ladder; colouring, gridding and drawing it cost as
/// much as the owned chains did. Decided by cells, so some farther segments
/// stay in and none within reach is left out. Empty when the store has no
/// halo: every segment takes part.
std::vector<uint8_t> segments_in_reach(const chains::ChainStore& store, double reach);

/// Where `store` breaks the point part of the partition contract
/// (formats/chains/SPEC.md, "The partition contract"): the first unit, in
/// chain order, that an owned chain bounds and of which the store holds no
/// internal point (its own, or a neighbour's). Empty when it holds. Without
/// that point a shortcut could cut the unit's point off, and the store alone
/// cannot tell.
std::optional<std::string> partition_contract_fault(const chains::ChainStore& store);

/// The colouring's options with the metric the simplification uses.
ColorOptions color_options(const SimplifyOptions& opt);

/// How far from an owned chain a halo segment can matter at the chain
/// tolerances `eps` (grid units), in grid units: for segments_in_reach.
double halo_reach(std::span<const double> eps, const SimplifyOptions& opt);

/// The part of `keep` (from segments_in_reach) for chain `c`: empty if all of it takes part.
std::span<const uint8_t> keep_of(const std::vector<uint8_t>& keep, const chains::ChainInfo& c);

/// Colour `store` given its chains' tolerances `eps` (chain_tolerances) and
/// the segments in reach (`keep`, segments_in_reach). Throws input_error
/// naming the tile's centre in lon/lat when a tile at the smallest size
/// still needs more classes than ColorOptions::max_classes.
ColorResult color_chains(const chains::ChainStore& store, std::span<const double> eps, const std::vector<uint8_t>& keep,
                         const SimplifyOptions& opt);

/// Colour `store` at `eps_m` (what tigerlod-color writes): color_chains
/// with the store's tolerances and segments in reach.
ColorResult color_store(const chains::ChainStore& store, double eps_m, const SimplifyOptions& opt);

} // namespace tigerlod::simplify
