#pragma once
/// @file stage_options.hpp
/// Options shared by tigerlod-color and tigerlod-simplify, and the layout of
/// their inputs and outputs.

#include "core/manifest.hpp"
#include "formats/chains/chain_store.hpp"
#include "core/stage.hpp"
#include "simplification/tolerances.hpp"

#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace tigerlod::simplify {

/// A chain store of the input: INPUT/<level>/<partition>.tlc.
struct StoreFile {
    std::string level;
    std::string partition; ///< the file name's stem
    std::filesystem::path path;
    std::string projection; ///< the projection ingest wrote every store in (its report)
};

class CommonOptions {
  public:
    void add(ArgSet& args);
    /// Validate and resolve; throws usage_error naming the option.
    void initialize(const std::string& stage);

    /// The options of this run that shape color's outputs (simplify's too),
    /// for manifest.json: the ladder, the tolerance rule, the rendering
    /// options and the level. Never the thread count.
    nlohmann::ordered_json manifest_options() const;
    /// Throws usage_error unless `colors`, tigerlod-color's manifest, was made
    /// with these options (its ladder holding every tolerance of this run),
    /// and input_error unless it was made from `ingest`.
    void check_colors(const Manifest& colors, const Manifest& ingest) const;

    std::vector<double> tolerances; ///< increasing, > 0, metres
    SimplifyOptions options;
    std::string input, output, level;
    bool overwrite = false;
    /// `--partitions`: the stores to work on (select_stores), OUTPUT updated
    /// in place; empty: every store, OUTPUT written whole.
    std::string partitions;
    std::string report;  ///< `--report FILE`: with --partitions, this job's report
    bool finish = false; ///< `--finish`: after partition jobs (stage_output.hpp)
    /// OUTPUT is updated in place (--partitions or --finish), not written whole.
    bool in_place() const noexcept { return !partitions.empty() || finish; }

  private:
    std::string m_tolerances = "1,4,16,64";
    std::string m_metric = "l2";
    std::string m_class_scale;
    bool m_no_projection_scale = false;
    double m_pixel_fraction = 0.25;
    int m_tile_pixels = 4096;
    int m_max_classes = 255;
    int m_threads = 0;
}; // class CommonOptions

/// The tolerance contract simplify's manifest records (metric, class scale,
/// projection scale, point constraints and the user points themselves), as
/// tigerlod-verify needs it: a SimplifyOptions with those set. Throws
/// input_error naming the manifest if one is missing or malformed.
SimplifyOptions tolerance_contract(const nlohmann::ordered_json& simplify_options, const std::string& where);

/// Folder name of a tolerance: "eps-1m", "eps-0.5m" (the chain-store format's).
using chains::tolerance_dir;

/// Parse `--class-scale` (CLASS=FACTOR,...; FACTOR > 0). Throws usage_error naming `stage`.
std::map<std::string, double> parse_class_scale(const std::string& list, const std::string& stage);

/// The stores under `input`, sorted by (level, partition); only `level` if not empty.
/// Throws usage_error if `input` is not a folder or holds no store, and
/// input_error if they are not the stores ingest wrote there: its report
/// missing, a level folder it did not write, a level with a store more or
/// fewer than it wrote.
std::vector<StoreFile> list_stores(const std::filesystem::path& input, const std::string& level);

/// Throws input_error if `store`, read from `file`, is not the store its place
/// names (another partition's under this name) or is in another projection
/// or grid than ingest wrote the others in.
void check_store(const chains::ChainStore& store, const StoreFile& file);

/// The ladder's rules that need the store, one check for color and
/// simplify (the range is checked where the ladder is read): usage_error
/// naming `file` if the smallest tolerance is below the store's grid step,
/// or if the store is a partition whose halo is narrower than the largest
/// tolerance needs (halo_needed_m).
void check_ladder(const chains::ChainStore& store, const StoreFile& file, const std::vector<double>& tolerances,
                  const SimplifyOptions& options);

/// Read user point constraints: GeoJSON (Point / MultiPoint features) or CSV
/// with lon and lat columns (header names lon/lng/longitude/x and lat/latitude/y).
/// Throws input_error naming the file and line or feature.
std::vector<LonLat> read_points(const std::string& path);

} // namespace tigerlod::simplify
