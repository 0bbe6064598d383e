#pragma once
/// @file metric.hpp
/// Distance metrics and the exact proximity test behind every candidate.
///
/// Tolerances are integers here: a tolerance of eps grid units is tested as
/// "squared distance <= floor(eps^2)" (L2) or "distance <= floor(eps)" (L1,
/// Linf), always in exact integer arithmetic, so a simplified chain is within
/// its tolerance bit for bit, not up to rounding.

#include "core/geometry.hpp"

#include <cstdint>
#include <optional>
#include <string>

namespace tigerlod {

enum class Metric : uint8_t { l2 = 0, l1 = 1, linf = 2 };

const char* metric_name(Metric m) noexcept;
std::optional<Metric> parse_metric(const std::string& name) noexcept;

/// Radius of the smallest L2 disc holding the metric's unit ball (1 or sqrt 2).
double l2_reach(Metric m) noexcept;

/// The halo a partition's store needs so that partitions simplified apart
/// cannot cross: every chain within eps_i + eps_j of its own, the largest
/// tolerance `eps_max_m` times the largest class scale, each reaching
/// l2_reach(metric) times as far in L2. The one rule for ingest --validate
/// and simplify.
inline double halo_needed_m(double eps_max_m, double max_class_scale, Metric metric) noexcept
{
    return 2 * eps_max_m * max_class_scale * l2_reach(metric);
}

/// A tolerance in grid units with its exact integer threshold.
struct Tolerance {
    double eps = 0;       ///< grid units
    int128 threshold = 0; ///< floor(eps^2) for L2, floor(eps) for L1 and Linf
    Metric metric = Metric::l2;
    Tolerance() = default;
    Tolerance(double eps_grid, Metric m);
};

/// Whether point p lies within the tolerance of the closed segment ab
/// (a may equal b). Exact.
bool within(GridPoint p, GridPoint a, GridPoint b, const Tolerance& tol) noexcept;

/// L2, L1 or Linf distance from p to segment ab, as a double (for
/// reports and the conflict graph; never for decisions that must be exact).
double distance(GridPoint p, GridPoint a, GridPoint b, Metric m) noexcept;

} // namespace tigerlod
