#include "stages/ingest/ingest_stage.hpp"

#include "core/digest.hpp"
#include "core/errors.hpp"
#include "config/schema.hpp"
#include "core/fs.hpp"
#include "core/manifest.hpp"
#include "core/memory.hpp"
#include "formats/chains/chain_store.hpp"
#include "stages/ingest/config.hpp"
#include "stages/ingest/map_builder.hpp"
#include "stages/ingest/regions.hpp"
#include "stages/ingest/sources.hpp"

#include <GeographicLib/Config.h>
#include <nlohmann/json.hpp>
#include <yaml-cpp/yaml.h>

#include <atomic>
#include <cstdlib>
#include <cstdio>
#include <future>
#include <sstream>
#include <thread>
#ifdef __GLIBC__
#include <malloc.h>
#endif

namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

namespace tigerlod::ingest {

namespace {

/// A partition code as a file name: letters, digits, '_' and '-' pass, anything else is %XX.
std::string file_name(const std::string& code)
{
    std::string out;
    for (unsigned char ch : code) {
        if (std::isalnum(ch) || ch == '_' || ch == '-') {
            out += static_cast<char>(ch);
        } else {
            char buf[4];
            std::snprintf(buf, sizeof buf, "%%%02X", ch);
            out += buf;
        }
    }
    return out.empty() ? "%" : out;
}

json level_spec_json(const LevelSpec& l)
{
    json j;
    j["name"] = l.name;
    if (!l.code.empty()) {
        j["code"] = l.code;
    }
    if (!l.fields.empty()) {
        j["fields"] = l.fields;
    }
    if (l.prefix > 0) {
        j["prefix"] = l.prefix;
    }
    return j;
}

} // namespace

void IngestStage::add_args(ArgSet& args)
{
    args.positional("CONFIG", &m_config, "the config file (YAML; keys in configs/README.md)");
    args.positional("OUTPUT", &m_output, "the output folder, written under a temporary name and renamed on success");
    args.group("Ingest");
    args.add("overwrite", &m_overwrite, "replace OUTPUT if it exists");
    args.add("validate", &m_validate,
             "resolve the config, open every input and check its layers and fields, print the resolved\n"
             "      options, and exit without reading features or writing anything");
    config::add_option(args, "ingest.halo_m", &m_halo_m);
    args.describe_default("halo-m", "the config's ingest.halo_m, else 1000");
    config::add_option(args, "ingest.line_tile_km", &m_line_tile_km);
    args.describe_default("line-tile-km", "the config's ingest.line_tile_km, else 10");
    config::add_option(args, "ingest.threads", &m_threads);
    args.describe_default("threads", "the config's ingest.threads, else 0");
    args.add("max-problem-samples", &m_max_problem_samples, "problems listed with their location in the report", "N",
             Limits{0, std::numeric_limits<double>::infinity(), false, false, true});
    args.add("whole-map", &m_whole_map,
             "build a polygons dataset of several files, or a TIGER dataset of several counties, as one\n"
             "      map in memory, not region by region\n"
             "      (the same output; memory then follows the dataset, not its largest region)");
}

std::vector<std::string> IngestStage::versions() const
{
    return {gdal_version(), std::string("GeographicLib ") + GEOGRAPHICLIB_VERSION_STRING,
            chains::format_version_text()};
}

std::string IngestStage::help_notes() const
{
    return "\nOutputs (in OUTPUT):\n"
           "  <level>/<partition>.tlc  chain stores (formats/chains/SPEC.md)\n"
           "  ingest-report.json       counts per level and problems by kind (deterministic)\n"
           "  manifest.json            inputs with SHA-256, resolved options, version (deterministic)\n"
           "  ingest-timings.json      seconds, vertices per second, peak memory (varies by run)\n"
           "A summary goes to stdout. Problems found in the data (crossings, overlaps, repaired\n"
           "spikes...) are counted and located in the report; chains involved carry the problem flag.\n";
}

namespace {

using InputFiles = std::vector<std::pair<fs::path, const char*>>;

/// The files ingest reads, with their role in the manifest: the config, then FACES, EDGES, other inputs.
InputFiles input_files_of(const IngestConfig& cfg)
{
    std::vector<std::pair<fs::path, const char*>> input_files{{cfg.file, "config"}};
    for (const auto& p : cfg.dataset.faces) {
        input_files.emplace_back(p, "faces");
    }
    for (const auto& p : cfg.dataset.edges) {
        input_files.emplace_back(p, "edges");
    }
    for (const auto& p : cfg.dataset.inputs) {
        input_files.emplace_back(p, "input");
    }
    return input_files;
}

/// What the build gave, with the points read and when reading ended (the log's clock).
struct Built {
    BuildResult result;
    uint64_t points_read = 0;
    double t_read = 0;
};

/// Read the dataset and build the map: region by region when it comes in
/// several files (each read once and put aside on disk in `scratch`), else
/// whole. Every store goes to `sink`.
Built read_and_build(const IngestConfig& cfg, const Projection& projection, const BuildOptions& options,
                     const StoreSink& sink, const fs::path& scratch, bool whole_map, const Log& log)
{
    Built built;
    auto& result = built.result;
    auto& points_read = built.points_read;
    auto& t_read = built.t_read;
    const unsigned threads = options.threads;
    const bool tiger = cfg.dataset.kind == DatasetSpec::Kind::tiger;
    const bool by_parts =
        !whole_map && ((cfg.dataset.kind == DatasetSpec::Kind::polygons && cfg.dataset.inputs.size() > 1) ||
                       (tiger && cfg.dataset.faces.size() > 1 && cfg.dataset.faces.size() == cfg.dataset.edges.size()));
    if (by_parts) {
        // Region by region: each file read once and put aside on disk, inside
        // the output folder (removed before it is renamed into place).
        const fs::path aside = scratch;
        fs::create_directories(aside);
        auto part_path = [&](size_t i) { return aside / (std::to_string(i) + ".raw"); };
        std::vector<PartSummary> parts(tiger ? cfg.dataset.faces.size() : cfg.dataset.inputs.size());
        const auto put_aside = [&](size_t i, RawMap&& part) {
            parts[i] = summarize_part(part);
            write_raw(part, part_path(i));
        };
        if (tiger) {
            read_tiger_parts(cfg, threads, log, put_aside);
        } else {
            read_polygon_parts(cfg, threads, log, put_aside);
        }
#ifdef __GLIBC__
        malloc_trim(0);
#endif
        t_read = log.elapsed_s();
        for (const auto& p : parts) {
            points_read += p.points_read;
        }
        log.info("read " + std::to_string(points_read) + " points from " + std::to_string(parts.size()) +
                 (tiger ? " counties" : " files"));
        std::vector<std::string> level_names;
        for (const auto& l : cfg.levels) {
            level_names.push_back(l.name);
        }
        result = build_by_regions(
            parts, [&](size_t i) { return read_raw(part_path(i)); }, level_names, projection, options, sink);
        // TIGER: an edge on a county border is in both counties' files; the
        // build counts its points once, as a whole read does.
        points_read = result.input_vertices;
        fs::remove_all(aside);
    } else {
        RawMap raw = read_dataset(cfg, threads, log);
#ifdef __GLIBC__
        // What the readers freed goes back to the system before the build's peak
        // (tract set: 125 -> 83 MB resident after reading, the peak 8-10 MB lower).
        malloc_trim(0);
#endif
        t_read = log.elapsed_s();
        points_read = raw.points_read;
        log.info("read " + std::to_string(points_read) + " points, " + std::to_string(raw.polyline_count()) +
                 " polylines, " + std::to_string(raw.units.size()) + " units");
        result = build_map(std::move(raw), projection, options, sink);
    }
    return built;
}

/// ingest-report.json.
json report_json(const IngestConfig& cfg, const Projection& projection, const BuildResult& result,
                 uint64_t stores_written)
{
    json report;
    report["schema"] = "tigerlod.ingest-report/1";
    report["config"] = cfg.name;
    report["projection"] = projection.describe();
    report["input_vertices"] = result.input_vertices;
    report["unique_vertices"] = result.unique_vertices;
    report["edges"] = result.edges;
    report["stores"] = stores_written;
    json levels = json::array();
    for (const auto& l : result.levels) {
        levels.push_back({{"name", l.name},
                          {"units", l.units},
                          {"chains", l.chains},
                          {"rings", l.rings},
                          {"vertices", l.vertices},
                          {"junctions", l.junctions},
                          {"partitions", l.partitions},
                          {"halo_chains", l.halo_chains},
                          {"constraint_points", l.constraint_points},
                          {"neighbour_points", l.neighbour_points},
                          {"computed_internal_points", l.computed_internal_points}});
        if (cfg.dataset.kind == DatasetSpec::Kind::lines) {
            levels.back()["tile_cuts"] = l.tile_cuts;
        }
    }
    report["levels"] = levels;
    json problems = json::object();
    for (const auto& [k, v] : result.problems) {
        problems[k] = v;
    }
    report["problems"] = problems;
    json samples = json::array();
    for (const auto& s : result.samples) {
        samples.push_back({{"kind", s.kind}, {"lon", s.lon_deg}, {"lat", s.lat_deg}, {"where", s.where}});
    }
    report["problem_samples"] = samples;
    return report;
}

/// manifest.json: the inputs with their SHA-256 (`sha`, in input_files order) and the resolved options.
json manifest_json(const IngestConfig& cfg, const Projection& projection, const InputFiles& input_files,
                   const std::vector<std::string>& sha, const std::vector<std::string>& libraries,
                   int max_problem_samples)
{
    json manifest = new_manifest("ingest", libraries);
    json inputs = json::array();
    for (size_t i = 0; i < input_files.size(); ++i) {
        const auto& [p, role] = input_files[i];
        inputs.push_back({{"role", role},
                          {"path", p.lexically_relative(cfg.file.parent_path()).string()},
                          {"bytes", fs::file_size(p)},
                          {"sha256", sha[i]}});
    }
    manifest["inputs"] = inputs;
    json levels_spec = json::array();
    for (const auto& l : cfg.levels) {
        levels_spec.push_back(level_spec_json(l));
    }
    manifest["options"] = {{"levels", levels_spec},
                           {"projection", projection.describe()},
                           {"halo_m", cfg.halo_m},
                           {"max_problem_samples", max_problem_samples}};
    if (cfg.dataset.kind == DatasetSpec::Kind::lines) {
        manifest["options"]["line_tile_km"] = cfg.line_tile_km;
    }
    return manifest;
}

/// ingest-timings.json, the only output that varies between runs.
json timings_json(const Built& built, double t0, double t_build, unsigned threads)
{
    const auto& result = built.result;
    const double t_read = built.t_read;
    const uint64_t points_read = built.points_read;
    const double seconds = t_build - t0;
    json phases = json::object();
    for (const auto& [phase, s] : result.seconds) {
        phases[phase] = s;
    }
    json timings = {{"read_s", t_read - t0},
                    {"build_s", t_build - t_read},
                    {"build_phases_s", phases},
                    {"region_map_units", result.region_map_units},
                    {"total_s", seconds},
                    {"threads", threads},
                    {"vertices_per_s", seconds > 0 ? static_cast<double>(points_read) / seconds : 0.0},
                    {"peak_rss_mb", peak_rss_mb()}};
    return timings;
}

/// The lines on stdout.
void print_summary(const IngestConfig& cfg, const Built& built, double seconds, uint64_t stores_written,
                   const std::string& output)
{
    const auto& result = built.result;
    const uint64_t points_read = built.points_read;
    std::printf("ingest %s: %llu input vertices in %.2f s (%.2f M/s), %llu stores in %s\n", cfg.name.c_str(),
                static_cast<unsigned long long>(points_read), seconds,
                seconds > 0 ? static_cast<double>(points_read) / seconds / 1e6 : 0.0,
                static_cast<unsigned long long>(stores_written), output.c_str());
    std::printf("  %-12s %8s %8s %7s %10s %9s %6s\n", "level", "units", "chains", "rings", "vertices", "junctions",
                "parts");
    for (const auto& l : result.levels) {
        std::printf("  %-12s %8llu %8llu %7llu %10llu %9llu %6llu\n", l.name.c_str(),
                    static_cast<unsigned long long>(l.units), static_cast<unsigned long long>(l.chains),
                    static_cast<unsigned long long>(l.rings), static_cast<unsigned long long>(l.vertices),
                    static_cast<unsigned long long>(l.junctions), static_cast<unsigned long long>(l.partitions));
    }
    std::string found;
    for (const auto& [k, v] : result.problems) {
        if (v != 0) {
            found += " " + k + "=" + std::to_string(v);
        }
    }
    std::printf("  problems:%s\n", found.empty() ? " none" : found.c_str());
}

} // namespace

int IngestStage::run(const StageContext& ctx)
{
    IngestConfig cfg = load_config(m_config);
    if (m_halo_m >= 0) {
        cfg.halo_m = m_halo_m;
    }
    if (m_line_tile_km >= 0) {
        if (cfg.dataset.kind != DatasetSpec::Kind::lines) {
            throw usage_error("--line-tile-km applies to lines datasets only");
        }
        cfg.line_tile_km = m_line_tile_km;
    }
    if (cfg.dataset.kind == DatasetSpec::Kind::lines && cfg.line_tile_km > 0 &&
        cfg.line_tile_km * 1000.0 < 8 * cfg.projection.grid_m) {
        std::ostringstream msg;
        msg << cfg.file.string() << ": 'ingest.line_tile_km' (" << cfg.line_tile_km
            << ") is below 8 steps of the grid (projection.grid_m " << cfg.projection.grid_m << " m); 0 cuts no tiles";
        throw config_error(msg.str());
    }
    if (m_threads >= 0) {
        cfg.threads = static_cast<unsigned>(m_threads);
    }
    const unsigned threads = cfg.threads == 0 ? std::max(1U, std::thread::hardware_concurrency()) : cfg.threads;
    const Projection projection(cfg.projection);
    ctx.log.info("config " + cfg.file.string() + ": " + projection.describe());
    if (m_validate) {
        validate_dataset(cfg);
        std::printf("%s: valid; dataset %s, %zu input files, levels", cfg.file.c_str(), cfg.name.c_str(),
                    cfg.dataset.edges.size() + cfg.dataset.faces.size() + cfg.dataset.inputs.size());
        for (const auto& l : cfg.levels) {
            std::printf(" %s", l.name.c_str());
        }
        std::printf("; projection %s; halo %g m; %u threads\n", projection.describe().c_str(), cfg.halo_m, threads);
        return exit_ok;
    }
    // The manifest's input digests are computed beside the work, not after it.
    const InputFiles input_files = input_files_of(cfg);
    auto digests = std::async(std::launch::async, [&input_files] {
        std::vector<std::string> out;
        for (const auto& f : input_files) {
            out.push_back(sha256_file(f.first));
        }
        return out;
    });
    std::vector<fs::path> reads{m_config};
    for (const auto& f : input_files) {
        reads.emplace_back(f.first);
    }
    OutputDir out(m_output, m_overwrite, reads);
    // Stores of unchanged regions keep their times: the engine reruns only the others' jobs.
    out.keep_times_of_unchanged_files(".tlc");
    log_removed_leftovers(ctx.log, out.removed_leftovers());
    for (const auto& l : cfg.levels) {
        fs::create_directories(out.path() / l.name);
    }
    std::atomic<uint64_t> stores{0};
    BuildOptions options;
    options.halo_m = cfg.halo_m;
    options.line_tile_m = cfg.line_tile_km * 1000.0;
    options.threads = threads;
    options.max_problem_samples = static_cast<size_t>(m_max_problem_samples);
    options.log = &ctx.log;
    const StoreSink sink = [&](const chains::ChainStore& s) {
        // Inside the output folder, renamed into place whole at the end.
        write_file(out.path() / s.level_name / (file_name(s.partition) + ".tlc"), chains::encode(s));
        ++stores;
    };

    const double t0 = ctx.log.elapsed_s();
    // Parts put aside go inside the output folder (removed before it is renamed into place).
    const Built built = read_and_build(cfg, projection, options, sink, out.path() / ".parts", m_whole_map, ctx.log);
    const double t_build = ctx.log.elapsed_s();
    write_file_atomic(out.path() / "ingest-report.json",
                      report_json(cfg, projection, built.result, stores.load()).dump(2) + "\n");
    write_file_atomic(
        out.path() / "manifest.json",
        manifest_text(manifest_json(cfg, projection, input_files, digests.get(), versions(), m_max_problem_samples)));
    write_file_atomic(out.path() / "ingest-timings.json", timings_json(built, t0, t_build, threads).dump(2) + "\n");
    out.commit();
    print_summary(cfg, built, t_build - t0, stores.load(), m_output);
    return exit_ok;
}

} // namespace tigerlod::ingest
