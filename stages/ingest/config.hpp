#pragma once
/// @file config.hpp
/// The parts of a tigerlod config (YAML) that ingest reads: `name`,
/// `dataset`, `levels`, `projection`, `ingest`. Every key is documented in
/// configs/README.md; unknown keys are errors.

#include "core/metric.hpp"
#include "core/projection.hpp"

#include <filesystem>
#include <string>
#include <vector>

namespace tigerlod::ingest {

/// How one semantic level derives a unit's code: exactly one of the three.
struct LevelSpec {
    std::string name;
    std::string code;                ///< a constant code (one unit, e.g. the nation)
    std::vector<std::string> fields; ///< attributes concatenated (TIGER FACES: STATEFP20, COUNTYFP20, ...)
    int prefix = -1;                 ///< the first N characters of dataset.code_field
};

struct DatasetSpec {
    enum class Kind { tiger, polygons, lines };
    Kind kind = Kind::tiger;
    std::vector<std::filesystem::path> edges, faces, inputs; ///< resolved paths
    std::string layer;                                       ///< layer name when a source holds several
    std::string where;                                       ///< OGR SQL attribute filter ("": every feature)
    std::string code_field;                                  ///< polygons: the finest unit code (e.g. GEOID10)
    std::string class_field;                                 ///< feature class attribute (TIGER: MTFCC)
    std::string intpt_lat_field, intpt_lon_field;            ///< internal point attributes
    std::string name_field;                                  ///< names the finest level's units ("": none)
    std::vector<std::string> attributes;                     ///< further attributes kept for them
    bool skip_empty_codes = false;                           ///< dataset.empty_code: skip (else error)
    bool merge_duplicate_codes = false;                      ///< dataset.duplicate_code: merge (else error)
};

struct IngestConfig {
    std::filesystem::path file; ///< the config file itself
    std::string name;
    DatasetSpec dataset;
    std::vector<LevelSpec> levels;
    ProjectionParams projection;
    double halo_m = 1000.0;
    /// The config's ladder (`simplify`), for --validate's rules: its
    /// smallest and largest tolerance, its largest class scale (1 at least),
    /// its metric.
    double ladder_min_m = 1.0, ladder_max_m = 64.0, ladder_class_scale = 1.0;
    Metric ladder_metric = Metric::l2;
    /// A lines dataset is cut into square grid tiles of this side, in
    /// projected kilometres, each a partition; 0: one partition, `all`.
    double line_tile_km = 10.0;
    unsigned threads = 0; ///< 0: all cores
};

/// Load and validate. Relative paths are resolved against the config file's
/// folder. Throws config_error naming the file, line and key; a missing input
/// file is a config_error too.
IngestConfig load_config(const std::filesystem::path& file);

/// The default levels for TIGER FACES with 2020 codes:
/// state > county > tract > block_group > block.
std::vector<LevelSpec> default_tiger_levels();

} // namespace tigerlod::ingest
