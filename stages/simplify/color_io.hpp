#pragma once
/// @file color_io.hpp
/// The per-store colouring file tigerlod-color writes and tigerlod-simplify
/// reads (JSON, schema "tigerlod.colors/1"):
///   { "schema", "level", "partition", "eps_m", "metric", "pixel",
///     "tiles": [ { "x0", "y0", "width", "height", "depth",
///                  "chains": [chain ids], "classes": [1..255] } ] }
/// Chains are named by their stable ids, so the file stays valid for the store it was made from.

#include "formats/chains/chain_store.hpp"
#include "stages/simplify/coloring.hpp"
#include "stages/simplify/metric.hpp"

#include <filesystem>
#include <string>

namespace tigerlod::simplify {

std::string colors_to_json(const chains::ChainStore& store, double eps_m, Metric metric, const ColorResult& colors);

/// Parse a colours file for `store`; throws format_error naming `path` and the
/// fault, or usage_error when it was made at another tolerance, metric or pixel size.
ColorResult colors_from_json(const std::filesystem::path& path, const chains::ChainStore& store, double eps_m,
                             Metric metric, double expected_pixel);

} // namespace tigerlod::simplify
