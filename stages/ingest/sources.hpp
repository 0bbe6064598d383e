#pragma once
/// @file sources.hpp
/// Readers for the inputs a config names, through GDAL (zipped shapefiles via
/// /vsizip/, TopoJSON, GeoPackage, anything OGR reads). Each throws
/// input_error naming the file, the layer or feature, and the fault.

#include "core/log.hpp"
#include "stages/ingest/config.hpp"
#include "stages/ingest/raw_map.hpp"

#include <functional>
#include <span>

namespace tigerlod::ingest {

/// Read the dataset of `cfg` into a RawMap, coordinates snapped to 1e-6
/// degrees. Polygon and line files are read on up to `threads` threads; the
/// result is the same for any thread count. `on_file(points)`, if given, is
/// called as each input file is read (dataset_files of them), from any thread.
RawMap read_dataset(const IngestConfig& cfg, unsigned threads, const Log& log,
                    const std::function<void(uint64_t points)>& on_file = {});
/// The files read_dataset reads: every FACES and EDGES file, or every input.
size_t dataset_files(const IngestConfig& cfg);

/// Read a polygons dataset file by file on up to `threads` threads, handing
/// each file's part (file index 0 in it) to `take` on the thread that read it,
/// in no particular order. Throws the first error in file order. `only`, if
/// not empty, lists the files to read (the others are not opened).
void read_polygon_parts(const IngestConfig& cfg, unsigned threads, const Log& log,
                        const std::function<void(size_t, RawMap&&)>& take, std::span<const size_t> only = {});

/// Read a TIGER dataset county by county on up to `threads` threads: part i
/// holds FACES file i (file index 0 in it) and EDGES file i (file index 1),
/// the sides whose faces it does not hold listed in RawMap::foreign. Handed to
/// `take` as read_polygon_parts does. The config must list as many FACES
/// files as EDGES files (the region build checks that they pair). `only` as
/// read_polygon_parts.
void read_tiger_parts(const IngestConfig& cfg, unsigned threads, const Log& log,
                      const std::function<void(size_t, RawMap&&)>& take, std::span<const size_t> only = {});

/// Open every input of `cfg` and check its layer, geometry type and fields,
/// reading no features. Throws input_error as read_dataset would.
void validate_dataset(const IngestConfig& cfg);

/// Throws config_error naming `projection.grid_m` (and a grid that fits)
/// when a map spanning `span_x` by `span_y` steps of `grid_m` is wider than
/// a Data Tree node holds (2^31 - 1 steps): `where` and `what` name the
/// config and the map in the message.
void check_grid_span(const std::string& where, double grid_m, double span_x, double span_y, const std::string& what);

/// Versions of the libraries the readers use, for --version.
std::string gdal_version();

} // namespace tigerlod::ingest
