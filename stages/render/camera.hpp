#pragma once
/// @file camera.hpp
/// Camera paths for tigerlod-render: a keyframe file, or one of the built-in
/// paths over a tree (a zoom from the whole tree to its finest unit and
/// back, a pan across neighbours at a fine level, and a jumpy path).

#include "reader/reader.hpp"

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace tigerlod::render {

/// One keyframe of a path file: the view's centre in degrees (NAD83), its
/// scale in ground metres per pixel, and the frames it takes to get there
/// from the keyframe before it.
struct Keyframe {
    double lon = 0, lat = 0, metres_per_pixel = 1;
    uint32_t frames = 60;
};

/// Read a path file:
///
///     # comments and blank lines are skipped
///     LON LAT METRES_PER_PIXEL [FRAMES]
///
/// one keyframe a line, FRAMES (default 60, 1..100000) the frames from the
/// keyframe before (the first keyframe is frame 0 and takes none). Throws
/// input_error naming the file, the line and the fault.
std::vector<Keyframe> read_path_file(const std::filesystem::path& file);

/// The views along keyframes: the centre moves along a straight line in the
/// projection, the scale geometrically. Throws input_error for a keyframe
/// the tree's projection cannot place.
std::vector<reader::View> keyframe_views(const std::vector<Keyframe>& keys, const datatree::Skeleton& s, uint32_t width,
                                         uint32_t height);

/// The built-in paths: "zoom" (from the whole tree down to its finest unit
/// near the centre, and back), "pan" (across the map at the scale of its
/// smallest nodes), "jumpy" (a jump to a random node every 12 frames, small
/// moves between; `seed` picks them). Deterministic.
std::vector<reader::View> builtin_path(const std::string& name, const datatree::Skeleton& s, uint32_t width,
                                       uint32_t height, uint32_t frames, uint32_t seed);

/// The built-in paths' names.
inline const std::vector<std::string> builtin_paths = {"zoom", "pan", "jumpy"};

/// The view that shows all of `box` (grid units), with a margin.
reader::View fit(const datatree::Box& box, uint32_t width, uint32_t height);

} // namespace tigerlod::render
