#pragma once
/// @file color_io.hpp
/// A colouring as the colours file holds it (formats/colors/SPEC.md), and
/// back: chain indices of a store to and from its stable chain ids.

#include "formats/chains/chain_store.hpp"
#include "simplification/coloring.hpp"
#include "core/metric.hpp"

#include <filesystem>
#include <string>

namespace tigerlod::simplify {

std::string colors_to_json(const chains::ChainStore& store, double eps_m, Metric metric, const ColorResult& colors);

/// Read a colours file for `store`; throws format_error naming `path` and the
/// fault (colors::decode, or a chain id the store does not hold), or
/// usage_error when it cannot be opened or was made at another tolerance,
/// metric or pixel size.
ColorResult colors_from_json(const std::filesystem::path& path, const chains::ChainStore& store, double eps_m,
                             Metric metric, double expected_pixel);

} // namespace tigerlod::simplify
