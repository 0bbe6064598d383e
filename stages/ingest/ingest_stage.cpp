#include "stages/ingest/ingest_stage.hpp"

#include "core/digest.hpp"
#include "core/bytes.hpp"
#include "core/errors.hpp"
#include "config/schema.hpp"
#include "core/fs.hpp"
#include "core/manifest.hpp"
#include "core/memory.hpp"
#include "core/progress.hpp"
#include "formats/chains/chain_store.hpp"
#include "stages/ingest/config.hpp"
#include "stages/ingest/map_builder.hpp"
#include "stages/ingest/region_share.hpp"
#include "stages/ingest/regions.hpp"
#include "stages/ingest/sources.hpp"

#include <GeographicLib/Config.h>
#include <nlohmann/json.hpp>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <mutex>
#include <set>
#include <cstdlib>
#include <cstdio>
#include <future>
#include <map>
#include <numeric>
#include <optional>
#include <span>
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

/// Every level's spec, in order.
json levels_json(const IngestConfig& cfg)
{
    json levels = json::array();
    for (const auto& l : cfg.levels) {
        levels.push_back(level_spec_json(l));
    }
    return levels;
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
    args.group("Ingest in jobs (the workflow's: each also runs by hand)");
    args.add("parts", &m_parts, "the jobs' folder: the parts put aside, the plan, each region's spec and share", "DIR");
    args.add("list", &m_list,
             "list the dataset's parts (a polygon file, or a TIGER county's FACES and EDGES) in\n"
             "      DIR/reads.json, with their names and sizes, for the read jobs; nothing is read");
    args.add("read", &m_read,
             "read the parts of --select and put them aside in DIR, with what the plan needs of them in\n"
             "      DIR/reads/NAME.sum",
             "NAME");
    args.add("select", &m_select, "the parts --read reads, by their numbers in DIR/reads.json: `0-4,7`", "PARTS");
    args.add("plan", &m_plan,
             "plan the jobs from the parts: those a read job put aside (while their files have not\n"
             "      changed since) and the others read here; DIR/plan.json lists the jobs (a region each, or\n"
             "      one job `whole`); OUTPUT is not touched");
    args.add("region", &m_region,
             "build the stores of one planned job (`r-<code>` or `whole`) into OUTPUT in place, a store\n"
             "      whose bytes did not change keeping its time; its share goes to DIR/shares/JOB.share",
             "JOB");
    args.add("finish", &m_finish,
             "after every job: the coarse levels from the regions' shares, the report and the manifest;\n"
             "      stores no job wrote are removed. OUTPUT is then what a whole run writes, byte for byte");
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
           "spikes...) are counted and located in the report; chains involved carry the problem flag.\n"
           "\nIn jobs (the workflow's), the same OUTPUT, byte for byte:\n"
           "  tigerlod-ingest --list --parts DIR CONFIG OUTPUT       optional: DIR/reads.json lists the parts\n"
           "  tigerlod-ingest --read NAME --select PARTS --parts DIR CONFIG OUTPUT\n"
           "                                                         optional, for groups of parts in any order\n"
           "  tigerlod-ingest --plan --parts DIR CONFIG OUTPUT       once; DIR/plan.json lists the jobs\n"
           "  tigerlod-ingest --region JOB --parts DIR CONFIG OUTPUT  for each job, in any order\n"
           "  tigerlod-ingest --finish --parts DIR CONFIG OUTPUT     after every job\n"
           "DIR holds parts/<sha256>.raw (the inputs' parts read once), reads/<name>.sum, jobs/<job>.json\n"
           "(a region's spec: its parts' digests; rewritten only when it changes), shares/<job>.share,\n"
           "index.json and plan.json.\n";
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

/// What a run reads, which its outputs must not replace: the config, the
/// inputs, and `more`.
std::vector<fs::path> reads_of(const std::string& config, const InputFiles& input_files,
                               const std::vector<fs::path>& more = {})
{
    std::vector<fs::path> reads{config};
    reads.insert(reads.end(), more.begin(), more.end());
    for (const auto& f : input_files) {
        reads.emplace_back(f.first);
    }
    return reads;
}

/// SHA-256 of each input file, in input_files order.
std::vector<std::string> digests_of(const InputFiles& input_files)
{
    std::vector<std::string> out;
    for (const auto& f : input_files) {
        out.push_back(sha256_file(f.first));
    }
    return out;
}

/// Ingest's progress (--progress): the files read, then the levels built
/// (each region's and the coarse ones, as the build plans them), each a bar
/// of its own, or JSON lines with unit "files", then "levels".
class IngestProgress {
  public:
    explicit IngestProgress(ProgressMode mode) : m_mode(mode) {}
    /// A callback for `files` files read, each with its points.
    std::function<void(uint64_t)> reading(size_t files)
    {
        m_read.emplace(m_mode, "ingest", files, "files", "points");
        return [this](uint64_t points) { m_read->advance(points); };
    }
    /// Makes `options` report the levels built.
    void building(BuildOptions& options)
    {
        options.on_plan = [this](size_t levels) { m_build.emplace(m_mode, "ingest", levels, "levels", "chains"); };
        options.on_level = [this](uint64_t chains) {
            if (m_build) {
                m_build->advance(chains);
            }
        };
    }

  private:
    ProgressMode m_mode;
    std::optional<Progress> m_read, m_build;
};

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
                     const StoreSink& sink, const fs::path& scratch, bool whole_map, const Log& log,
                     IngestProgress& progress)
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
        const auto read = progress.reading(parts.size());
        const auto put_aside = [&](size_t i, RawMap&& part) {
            parts[i] = summarize_part(part);
            write_raw(part, part_path(i));
            read(parts[i].points_read);
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
        RawMap raw = read_dataset(cfg, threads, log, progress.reading(dataset_files(cfg)));
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
    manifest["options"] = {{"levels", levels_json(cfg)},
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

struct IngestStage::Resolved {
    const IngestConfig& cfg;
    const Projection& projection;
    unsigned threads;
};

namespace {

// Ingest in jobs ------------------------------------------------------------
//
// DIR (--parts) holds what the jobs hand on: parts/<i>.raw (each input part
// put aside by --plan, rewritten only when its bytes change), jobs/<job>.json
// (a job's spec: everything its stores depend on beside the parts, and the
// parts' digests; rewritten only when it changes, so that a workflow engine
// following times reruns exactly the jobs whose inputs changed), plan.json
// (the jobs, rewritten by every plan), index.json (what the finish needs:
// the shared files and classes, the input digests of the manifest) and
// shares/<job>.share (a job's counts and coarse edges, region_share.hpp).

constexpr const char* spec_schema = "tigerlod.ingest-job/1";
constexpr const char* index_schema = "tigerlod.ingest-index/2"; // 2: empty_codes

/// Whether the dataset is read part by part (several polygon files, or a
/// TIGER dataset of several counties whose EDGES and FACES pair).
bool read_by_parts(const IngestConfig& cfg)
{
    const bool tiger = cfg.dataset.kind == DatasetSpec::Kind::tiger;
    return (cfg.dataset.kind == DatasetSpec::Kind::polygons && cfg.dataset.inputs.size() > 1) ||
           (tiger && cfg.dataset.faces.size() > 1 && cfg.dataset.faces.size() == cfg.dataset.edges.size());
}

BuildOptions build_options(const IngestConfig& cfg, unsigned threads, int max_problem_samples, const Log& log)
{
    BuildOptions options;
    options.halo_m = cfg.halo_m;
    options.line_tile_m = cfg.line_tile_km * 1000.0;
    options.threads = threads;
    options.max_problem_samples = static_cast<size_t>(max_problem_samples);
    options.merge_duplicate_codes = cfg.dataset.merge_duplicate_codes;
    options.code_field = cfg.dataset.code_field;
    options.log = &log;
    return options;
}

/// The options a job's stores depend on: a job refuses a plan made with others.
json job_options_json(const IngestConfig& cfg, const Projection& projection, int max_problem_samples)
{
    return {{"levels", levels_json(cfg)},
            {"projection", projection.describe()},
            {"halo_m", cfg.halo_m},
            {"line_tile_km", cfg.line_tile_km},
            {"max_problem_samples", max_problem_samples}};
}

/// A part put aside, named by the digest of its bytes: a read job and the
/// plan write the same name for the same part, whatever its number.
fs::path part_file(const fs::path& dir, const std::string& sha256)
{
    return dir / "parts" / (sha256 + ".raw");
}
fs::path reads_file(const fs::path& dir, const std::string& name)
{
    return dir / "reads" / (name + ".sum");
}
fs::path spec_file(const fs::path& dir, const std::string& job)
{
    return dir / "jobs" / (job + ".json");
}
fs::path share_file(const fs::path& dir, const std::string& job)
{
    return dir / "shares" / (job + ".share");
}

std::string sha256_of(std::string_view bytes)
{
    Sha256 h;
    h.update(std::as_bytes(std::span(bytes.data(), bytes.size())));
    return h.hex_digest();
}

/// A job file's JSON; `bytes` (if given) gets the bytes it was parsed from.
json read_json(const fs::path& path, const char* what, const char* schema, std::string* bytes = nullptr)
{
    std::error_code ec;
    if (!fs::is_regular_file(path, ec)) {
        throw usage_error(path.string() + " is missing: " + what);
    }
    json j;
    try {
        std::string text = read_file(path);
        j = json::parse(text);
        if (bytes != nullptr) {
            *bytes = std::move(text);
        }
    } catch (const json::exception& e) {
        throw input_error(path.string() + ": not JSON: " + e.what());
    }
    if (!j.is_object() || j.value("schema", "") != schema) {
        throw input_error(path.string() + ": not a " + schema + " file");
    }
    return j;
}

/// The plan's shared part as JSON (spec and index), and back.
void put_meta(json& j, const RegionPlan& plan)
{
    j["level"] = plan.level;
    j["levels"] = plan.meta.level_names;
    j["kind"] = static_cast<int>(plan.meta.kind);
    j["files"] = plan.meta.files;
    j["classes"] = plan.meta.classes;
    if (plan.meta.has_attributes()) { // written only when named: older plans keep their bytes
        json fields = json::array();
        for (const auto& f : plan.meta.fields) {
            fields.push_back({f.name, static_cast<int>(f.type)});
        }
        j["unit_fields"] = {{"named", plan.meta.named}, {"fields", fields}};
    }
    j["nparts"] = plan.boxes.size();
}

RegionPlan get_meta(const json& j, const fs::path& file)
{
    RegionPlan plan;
    try {
        plan.level = j.at("level").get<size_t>();
        plan.meta.level_names = j.at("levels").get<std::vector<std::string>>();
        plan.meta.kind = static_cast<RawMap::Kind>(j.at("kind").get<int>());
        plan.meta.files = j.at("files").get<std::vector<std::string>>();
        plan.meta.classes = j.at("classes").get<std::vector<std::string>>();
        if (j.contains("unit_fields")) {
            plan.meta.named = j.at("unit_fields").at("named").get<bool>();
            for (const auto& f : j.at("unit_fields").at("fields")) {
                const int t = f.at(1).get<int>();
                if (t < 0 || t > static_cast<int>(chains::AttributeType::real)) {
                    throw input_error(file.string() + ": unknown attribute type " + std::to_string(t));
                }
                plan.meta.fields.push_back({f.at(0).get<std::string>(), static_cast<chains::AttributeType>(t)});
            }
        }
        const auto n = j.at("nparts").get<size_t>();
        plan.boxes.resize(n);
        plan.class_of.resize(n);
    } catch (const json::exception& e) {
        throw input_error(file.string() + ": " + e.what());
    }
    return plan;
}

/// Stores written into an ingest output in place, each through a temporary
/// name and only where its bytes changed; the names written.
class InPlaceStores {
  public:
    /// `finish`: an exclusive lock on OUTPUT (the finish removes what no job
    /// wrote), else a shared one (region jobs side by side).
    InPlaceStores(const fs::path& out, const std::vector<fs::path>& reads, bool finish) : m_out(out)
    {
        refuse_to_replace_inputs(out, reads);
        m_lock.emplace(out, "tigerlod-ingest", finish ? FolderLock::Mode::exclusive : FolderLock::Mode::shared);
        std::error_code ec;
        if (fs::exists(out / "manifest.json", ec)) {
            try {
                (void)read_manifest(out, "ingest");
            } catch (const input_error& e) {
                throw usage_error(std::string(e.what()) +
                                  "; --region and --finish update a tigerlod-ingest output in place, and nothing else");
            }
        }
        fs::create_directories(out, ec);
        if (ec) {
            throw environment_error(out.string() + ": cannot create folder: " + ec.message());
        }
    }
    void write(const chains::ChainStore& s)
    {
        const fs::path folder = m_out / s.level_name;
        {
            const std::lock_guard lock(m_mutex);
            if (m_folders.insert(folder).second) {
                fs::create_directories(folder);
                (void)remove_dead_leftovers(folder);
            }
        }
        const bool wrote = write_file_if_changed(folder / (file_name(s.partition) + ".tlc"), chains::encode(s));
        const std::lock_guard lock(m_mutex);
        m_names.push_back(s.level_name + "/" + s.partition);
        m_rewritten += wrote ? 1 : 0;
    }
    /// The folders written into, synced once each; the names, sorted.
    std::vector<std::string> close()
    {
        for (const auto& f : m_folders) {
            sync_to_disk(f);
        }
        std::sort(m_names.begin(), m_names.end());
        return m_names;
    }
    size_t rewritten() const noexcept { return m_rewritten; }

  private:
    fs::path m_out;
    std::optional<FolderLock> m_lock;
    std::mutex m_mutex;
    std::set<fs::path> m_folders;
    std::vector<std::string> m_names;
    size_t m_rewritten = 0;
};

/// Where a store named "level/partition" lies in an ingest output.
fs::path store_path(const fs::path& out, const std::string& name)
{
    const size_t slash = name.find('/');
    return out / name.substr(0, slash) / (file_name(name.substr(slash + 1)) + ".tlc");
}

/// A file's size and modification time (ns); {UINT64_MAX, 0} if it is not there.
std::pair<uint64_t, int64_t> stamp_of(const fs::path& file)
{
    std::error_code ec;
    const auto size = fs::file_size(file, ec);
    if (ec) {
        return {UINT64_MAX, 0};
    }
    const auto t = fs::last_write_time(file, ec);
    if (ec) {
        return {UINT64_MAX, 0};
    }
    return {static_cast<uint64_t>(size),
            static_cast<int64_t>(std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count())};
}

/// A planned job and its spec.
using JobSpecs = std::vector<std::pair<std::string, json>>;

/// The plan: the jobs whose stores were changed or removed since they ran
/// (by hand, or a disk's fault), each with the store and why.
std::map<std::string, std::pair<std::string, std::string>> damaged_jobs(const fs::path& dir, const fs::path& out,
                                                                        const JobSpecs& specs)
{
    std::map<std::string, std::pair<std::string, std::string>> damaged;
    for (const auto& [job, spec] : specs) {
        const fs::path file = share_file(dir, job);
        std::error_code ec;
        if (!fs::is_regular_file(file, ec)) {
            continue;
        }
        std::string store, why;
        try {
            const std::string bytes = read_file(file);
            const RegionJobShare head =
                decode_share_head(std::as_bytes(std::span(bytes.data(), bytes.size())), file.string());
            for (size_t i = 0; i < head.stores.size() && why.empty(); ++i) {
                const auto [size, mtime] = stamp_of(store_path(out, head.stores[i]));
                if (size != head.store_bytes[i] || mtime != head.store_mtimes[i]) {
                    store = head.stores[i];
                    why = size == UINT64_MAX ? "is missing" : "changed since the job wrote it";
                }
            }
        } catch (const Error& e) {
            why = std::string("its share cannot be read: ") + e.what();
        }
        if (!why.empty()) {
            damaged.emplace(job, std::pair{store, why});
        }
    }
    return damaged;
}

/// The finish: every `.tlc` under a level folder that no job wrote, and
/// every folder of a level the config no longer has, removed.
size_t remove_stale_stores(const fs::path& out, const IngestConfig& cfg, const std::set<std::string>& written)
{
    std::set<std::string> levels;
    for (const auto& l : cfg.levels) {
        levels.insert(l.name);
    }
    std::set<std::string> files; // level/file name
    for (const auto& w : written) {
        const size_t slash = w.find('/');
        files.insert(w.substr(0, slash) + "/" + file_name(w.substr(slash + 1)) + ".tlc");
    }
    size_t removed = remove_dead_leftovers(out).size();
    std::vector<fs::path> entries;
    for (const auto& e : fs::directory_iterator(out)) {
        entries.push_back(e.path());
    }
    std::sort(entries.begin(), entries.end());
    for (const fs::path& dir : entries) {
        const std::string name = dir.filename().string();
        if (!fs::is_directory(dir) || name.starts_with(".")) {
            continue;
        }
        if (!levels.contains(name)) {
            fs::remove_all(dir);
            ++removed;
            continue;
        }
        removed += remove_dead_leftovers(dir).size();
        for (const auto& e : fs::directory_iterator(dir)) {
            const std::string file = e.path().filename().string();
            if (file.ends_with(".tlc") && !files.contains(name + "/" + file)) {
                fs::remove(e.path());
                ++removed;
            }
        }
    }
    return removed;
}

/// The plan: the part files of other parts, and the specs and shares of jobs
/// it no longer has, removed.
void remove_unplanned_files(const fs::path& dir, const std::vector<std::string>& part_sha, const JobSpecs& specs)
{
    std::set<std::string> keep_files;
    for (const auto& sha : part_sha) {
        keep_files.insert(part_file(dir, sha).filename().string());
    }
    for (const auto& [job, spec] : specs) {
        keep_files.insert(job + ".json");
        keep_files.insert(job + ".share");
    }
    for (const char* sub : {"parts", "jobs", "shares"}) {
        for (const auto& e : fs::directory_iterator(dir / sub)) {
            const std::string entry = e.path().filename().string();
            if (e.is_regular_file() && !keep_files.contains(entry) &&
                (entry.ends_with(".raw") || entry.ends_with(".json") || entry.ends_with(".share"))) {
                fs::remove(e.path());
            }
        }
    }
}

/// The plan's specs, each written only where its bytes change. A job whose
/// stores were changed or removed since it ran (`damaged`) gets a spec that
/// says so (`repair`): its new bytes rerun it, and it writes them again. The
/// spec keeps saying so until something else in it changes. Returns the
/// specs written.
size_t write_specs(const fs::path& dir, const fs::path& out, JobSpecs& specs,
                   const std::map<std::string, std::pair<std::string, std::string>>& damaged, const Log& log)
{
    size_t written = 0;
    for (auto& [job, spec] : specs) {
        const fs::path file = spec_file(dir, job);
        if (auto it = damaged.find(job); it != damaged.end()) {
            const auto& [store, why] = it->second;
            log.info("job " + job + " runs again: " + (store.empty() ? why : "its store " + store + " " + why));
            std::string repair = store + " " + why;
            if (!store.empty()) {
                const auto [size, mtime] = stamp_of(store_path(out, store));
                repair += " (" + std::to_string(size) + " bytes, time " + std::to_string(mtime) + ")";
            }
            spec["repair"] = repair;
        } else {
            std::error_code ec;
            if (fs::is_regular_file(file, ec)) {
                try {
                    json old = json::parse(read_file(file));
                    old.erase("repair");
                    if (old == spec) {
                        continue; // the same spec, repaired or not: kept as it is
                    }
                } catch (const std::exception&) {
                    // not a spec: written again below
                }
            }
        }
        written += write_file_if_changed(file, spec.dump(1) + "\n") ? 1 : 0;
    }
    sync_to_disk(dir / "jobs");
    return written;
}

/// How a dataset's parts are read: what a part's units and codes depend on
/// beside its files (a read job's parts serve a plan only under the same).
std::string reading_of(const IngestConfig& cfg)
{
    const DatasetSpec& d = cfg.dataset;
    json j{{"kind", static_cast<int>(d.kind)},
           {"layer", d.layer},
           {"code_field", d.code_field},
           {"class_field", d.class_field},
           {"intpt_lat_field", d.intpt_lat_field},
           {"intpt_lon_field", d.intpt_lon_field},
           {"levels", levels_json(cfg)}};
    if (!d.name_field.empty() || !d.attributes.empty()) { // written only when named: older specs keep their bytes
        j["name_field"] = d.name_field;
        j["attributes"] = d.attributes;
    }
    return j.dump();
}

/// The number of parts a dataset is read in (0: it is read by its one job).
size_t part_count(const IngestConfig& cfg)
{
    if (!read_by_parts(cfg)) {
        return 0;
    }
    return cfg.dataset.kind == DatasetSpec::Kind::tiger ? cfg.dataset.faces.size() : cfg.dataset.inputs.size();
}

/// The files of part i: a TIGER county's FACES and EDGES, or a polygon file.
std::vector<fs::path> files_of_part(const IngestConfig& cfg, size_t i)
{
    if (cfg.dataset.kind == DatasetSpec::Kind::tiger) {
        return {cfg.dataset.faces[i], cfg.dataset.edges[i]};
    }
    return {cfg.dataset.inputs[i]};
}

/// --select: part numbers and ranges, `0-4,7`, each below `nparts`; sorted, once each.
std::vector<size_t> parse_selection(const std::string& text, size_t nparts)
{
    std::vector<size_t> out;
    auto fail = [&](const std::string& why) { throw usage_error("--select '" + text + "': " + why); };
    auto number = [&](std::string_view t) {
        size_t v = 0;
        if (t.empty() || t.size() > 18 ||
            !std::all_of(t.begin(), t.end(), [](char c) { return c >= '0' && c <= '9'; })) {
            fail("'" + std::string(t) + "' is not a part number");
        }
        for (const char c : t) {
            v = v * 10 + static_cast<size_t>(c - '0');
        }
        if (v >= nparts) {
            fail("part " + std::to_string(v) + " is not in this dataset (it has " + std::to_string(nparts) +
                 " parts, from 0)");
        }
        return v;
    };
    std::string_view rest(text);
    while (!rest.empty()) {
        const size_t comma = rest.find(',');
        const std::string_view item = rest.substr(0, comma);
        rest = comma == std::string_view::npos ? std::string_view{} : rest.substr(comma + 1);
        const size_t dash = item.find('-');
        const size_t lo = number(item.substr(0, dash));
        const size_t hi = dash == std::string_view::npos ? lo : number(item.substr(dash + 1));
        if (hi < lo) {
            fail("the range " + std::string(item) + " runs backwards");
        }
        for (size_t i = lo; i <= hi; ++i) {
            out.push_back(i);
        }
    }
    if (out.empty()) {
        fail("no parts");
    }
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
}

/// Read the parts `only` (part numbers) and put each aside under its digest
/// (written only where it is new), with its summary and its files' stamps,
/// taken before the read (so that a file changed while it was read does not
/// match them). `rewritten` counts the part files written.
std::vector<PartRead> read_parts(const IngestConfig& cfg, const fs::path& dir, unsigned threads, const Log& log,
                                 std::span<const size_t> only, size_t& rewritten, ProgressMode mode)
{
    Progress progress(mode, "ingest", only.size(), "files", "points");
    std::vector<PartRead> got(only.size());
    std::vector<size_t> slot(part_count(cfg), SIZE_MAX);
    for (size_t k = 0; k < only.size(); ++k) {
        slot[only[k]] = k;
        got[k].part = only[k];
        for (const fs::path& f : files_of_part(cfg, only[k])) {
            const auto [size, mtime] = stamp_of(f);
            got[k].files.push_back(FileStamp{f.string(), size, mtime, {}});
        }
    }
    std::atomic<size_t> wrote{0};
    const auto put_aside = [&](size_t i, RawMap&& part) {
        PartRead& p = got[slot[i]];
        p.summary = summarize_part(part);
        progress.advance(p.summary.points_read);
        const std::string bytes = encode_raw(part);
        part = RawMap();
        p.sha256 = sha256_of(bytes);
        wrote += write_file_if_changed(part_file(dir, p.sha256), bytes) ? 1 : 0;
        for (auto& f : p.files) {
            f.sha256 = sha256_file(f.path);
        }
    };
    if (cfg.dataset.kind == DatasetSpec::Kind::tiger) {
        read_tiger_parts(cfg, threads, log, put_aside, only);
    } else {
        read_polygon_parts(cfg, threads, log, put_aside, only);
    }
    sync_to_disk(dir / "parts");
    rewritten += wrote.load();
    return got;
}

/// The plan: the parts that read jobs put aside (DIR/reads/*.sum), each
/// where its files still have the stamps the job saw and its part file is
/// there; `have[i]` says which were found. A file that is not a read job's
/// of this version, and one none of whose parts is still current, is
/// removed (a read job writes it again). Returns the parts taken.
size_t take_reads(const IngestConfig& cfg, const fs::path& dir, std::vector<PartRead>& got, std::vector<uint8_t>& have,
                  const Log& log)
{
    const fs::path folder = dir / "reads";
    std::error_code ec;
    if (!fs::is_directory(folder, ec)) {
        return 0;
    }
    std::map<std::vector<std::string>, size_t> part_of;
    for (size_t i = 0; i < got.size(); ++i) {
        std::vector<std::string> key;
        for (const fs::path& f : files_of_part(cfg, i)) {
            key.push_back(f.string());
        }
        part_of.emplace(std::move(key), i);
    }
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(folder)) {
        if (e.is_regular_file() && e.path().extension() == ".sum") {
            files.push_back(e.path());
        }
    }
    std::sort(files.begin(), files.end());
    const std::string reading = reading_of(cfg);
    size_t taken = 0;
    for (const fs::path& file : files) {
        ReadJob job;
        try {
            const std::string bytes = read_file(file);
            job = decode_reads(std::as_bytes(std::span(bytes.data(), bytes.size())), file.string());
        } catch (const Error& e) {
            log.info(file.string() + " removed: " + e.what());
            fs::remove(file, ec);
            continue;
        }
        if (job.reading != reading) {
            log.info(file.string() + " removed: read with other dataset fields or levels");
            fs::remove(file, ec);
            continue;
        }
        bool current = false;
        for (auto& p : job.parts) {
            std::vector<std::string> key;
            for (const auto& f : p.files) {
                key.push_back(f.path);
            }
            const auto it = part_of.find(key);
            if (it == part_of.end() || have[it->second] != 0 || !fs::is_regular_file(part_file(dir, p.sha256), ec) ||
                !std::all_of(p.files.begin(), p.files.end(), [](const FileStamp& f) {
                    return stamp_of(f.path) == std::pair{f.bytes, f.mtime_ns};
                })) {
                continue;
            }
            current = true;
            p.part = it->second;
            got[it->second] = std::move(p);
            have[it->second] = 1;
            ++taken;
        }
        if (!current) {
            log.info(file.string() + " removed: none of its parts is current");
            fs::remove(file, ec);
        }
    }
    return taken;
}

} // namespace

int IngestStage::run_list(const StageContext& ctx, const Resolved& r)
{
    const IngestConfig& cfg = r.cfg;
    const fs::path dir(m_parts);
    const InputFiles input_files = input_files_of(cfg);
    refuse_to_replace_inputs(dir, reads_of(m_config, input_files));
    fs::create_directories(dir);
    const size_t nparts = part_count(cfg);
    json parts = json::array();
    uint64_t total = 0;
    for (size_t i = 0; i < nparts; ++i) {
        const std::vector<fs::path> files = files_of_part(cfg, i);
        uint64_t bytes = 0;
        json names = json::array();
        for (const fs::path& f : files) {
            std::error_code ec;
            const auto size = fs::file_size(f, ec);
            if (ec) {
                throw input_error(f.string() + ": cannot be read: " + ec.message());
            }
            bytes += size;
            names.push_back(f.string());
        }
        total += bytes;
        // The name: the first file's name up to its first dot (dc.shp.zip: dc).
        const std::string base = files.front().filename().string();
        parts.push_back(
            json{{"part", i}, {"name", file_name(base.substr(0, base.find('.')))}, {"bytes", bytes}, {"files", names}});
    }
    const json listing{
        {"schema", "tigerlod.ingest-reads/1"}, {"mode", nparts > 0 ? "parts" : "direct"}, {"parts", parts}};
    write_file_atomic(dir / "reads.json", listing.dump(1) + "\n");
    ctx.log.info("listed " + std::to_string(nparts) + " parts");
    std::printf("ingest list %s: %zu parts, %.1f MB%s, in %s\n", cfg.name.c_str(), nparts,
                static_cast<double>(total) / 1e6, nparts > 0 ? "" : " (the dataset is read by its one job)",
                (dir / "reads.json").c_str());
    return exit_ok;
}

int IngestStage::run_read(const StageContext& ctx, const Resolved& r)
{
    const IngestConfig& cfg = r.cfg;
    const fs::path dir(m_parts);
    if (!std::all_of(m_read.begin(), m_read.end(),
                     [](unsigned char c) { return std::isalnum(c) || c == '-' || c == '_' || c == '%'; })) {
        throw usage_error("--read '" + m_read + "': a read job's name is letters, digits, '-', '_' and '%'");
    }
    const size_t nparts = part_count(cfg);
    if (nparts == 0) {
        throw usage_error("--read: " + cfg.file.string() +
                          "'s dataset is one file, or a line layer: its one job reads it, there are no parts to read");
    }
    if (m_select.empty()) {
        throw usage_error("--read needs --select PARTS (the part numbers in --list's reads.json)");
    }
    const std::vector<size_t> only = parse_selection(m_select, nparts);
    refuse_to_replace_inputs(dir, reads_of(m_config, input_files_of(cfg)));
    for (const char* sub : {"parts", "reads"}) {
        fs::create_directories(dir / sub);
        (void)remove_dead_leftovers(dir / sub);
    }
    const double t0 = ctx.log.elapsed_s();
    size_t rewritten = 0;
    std::vector<PartRead> got = read_parts(cfg, dir, r.threads, ctx.log, only, rewritten, ctx.progress);
    uint64_t points = 0;
    for (const auto& p : got) {
        points += p.summary.points_read;
    }
    const size_t count = got.size();
    write_file_atomic(reads_file(dir, m_read), encode_reads(ReadJob{reading_of(cfg), std::move(got)}));
    std::printf("ingest read %s %s: %zu parts (%zu rewritten), %llu points, %.2f s, in %s\n", cfg.name.c_str(),
                m_read.c_str(), count, rewritten, static_cast<unsigned long long>(points), ctx.log.elapsed_s() - t0,
                reads_file(dir, m_read).c_str());
    return exit_ok;
}

int IngestStage::run_plan(const StageContext& ctx, const Resolved& r)
{
    const IngestConfig& cfg = r.cfg;
    const fs::path dir(m_parts);
    const InputFiles input_files = input_files_of(cfg);
    const std::vector<fs::path> reads = reads_of(m_config, input_files);
    refuse_to_replace_inputs(dir, reads);
    for (const char* sub : {"parts", "jobs", "shares"}) {
        fs::create_directories(dir / sub);
        (void)remove_dead_leftovers(dir / sub);
    }
    const BuildOptions options = build_options(cfg, r.threads, m_max_problem_samples, ctx.log);
    const json opts = job_options_json(cfg, r.projection, m_max_problem_samples);
    std::vector<std::string> level_names;
    for (const auto& l : cfg.levels) {
        level_names.push_back(l.name);
    }
    const double t0 = ctx.log.elapsed_s();
    JobSpecs specs;
    RegionPlan plan;
    std::string mode;
    std::vector<std::string> input_digests, sha;
    uint64_t points_read = 0;
    const size_t nparts = part_count(cfg);
    size_t rewritten = 0, from_reads = 0;
    if (nparts > 0) {
        // The parts the read jobs put aside, and the others read here.
        std::vector<PartRead> got(nparts);
        std::vector<uint8_t> have(nparts, 0);
        from_reads = take_reads(cfg, dir, got, have, ctx.log);
        std::vector<size_t> rest;
        for (size_t i = 0; i < nparts; ++i) {
            if (have[i] == 0) {
                rest.push_back(i);
            }
        }
        if (!rest.empty()) {
            std::vector<PartRead> here = read_parts(cfg, dir, r.threads, ctx.log, rest, rewritten, ctx.progress);
            for (auto& p : here) {
                got[p.part] = std::move(p);
            }
        }
        // The manifest's digests in input_files order: the config, then each
        // part's first file (FACES, or the polygon file), then TIGER's EDGES.
        input_digests.push_back(sha256_file(cfg.file));
        for (size_t f = 0; f < got.front().files.size(); ++f) {
            for (const auto& p : got) {
                input_digests.push_back(p.files[f].sha256);
            }
        }
        std::vector<PartSummary> parts(nparts);
        sha.resize(nparts);
        for (size_t i = 0; i < nparts; ++i) {
            parts[i] = std::move(got[i].summary);
            sha[i] = std::move(got[i].sha256);
            points_read += parts[i].points_read;
        }
        got.clear();
        plan = plan_regions(parts, level_names, r.projection, options);
        auto part_json = [&](size_t i) {
            const GridBox& b = plan.boxes[i];
            return json{{"part", i},
                        {"sha256", sha[i]},
                        {"box", {b.min_x, b.min_y, b.max_x, b.max_y}},
                        {"classes", plan.class_of[i]}};
        };
        auto spec_of = [&](const std::string& job, const std::string& spec_mode, const std::vector<size_t>& take) {
            json j{{"schema", spec_schema}, {"job", job}, {"mode", spec_mode}, {"options", opts}};
            put_meta(j, plan);
            json pj = json::array();
            for (size_t i : take) {
                pj.push_back(part_json(i));
            }
            j["parts"] = pj;
            return j;
        };
        if (plan.whole) {
            mode = "whole";
            std::vector<size_t> all(nparts);
            std::iota(all.begin(), all.end(), size_t{0});
            specs.emplace_back("whole", spec_of("whole", "whole", all));
        } else {
            mode = "regions";
            for (const auto& region : plan.regions) {
                const std::string job = "r-" + file_name(region.own.front());
                std::vector<size_t> take = region.parts;
                take.insert(take.end(), region.near.begin(), region.near.end());
                std::sort(take.begin(), take.end());
                json j = spec_of(job, "region", take);
                j["region"] = {{"parts", region.parts}, {"own", region.own}, {"near", region.near}};
                specs.emplace_back(job, std::move(j));
            }
        }
    } else {
        // One file (or lines): the whole job reads the inputs itself; its
        // spec names their digests, so it changes when they do.
        mode = "direct";
        plan.meta.level_names = level_names;
        json j{{"schema", spec_schema}, {"job", "whole"}, {"mode", "direct"}, {"options", opts}};
        input_digests = digests_of(input_files);
        j["inputs"] = input_digests;
        specs.emplace_back("whole", std::move(j));
    }
    remove_unplanned_files(dir, sha, specs);
    const auto damaged = damaged_jobs(dir, m_output, specs);
    const size_t specs_changed = write_specs(dir, m_output, specs, damaged, ctx.log);
    json jobs = json::array();
    for (const auto& [job, spec] : specs) {
        jobs.push_back(job);
    }
    json index{{"schema", index_schema}, {"mode", mode}, {"jobs", jobs}, {"options", opts}};
    put_meta(index, plan);
    index["empty_geometries"] = plan.empty_geometries;
    index["empty_codes"] = plan.empty_codes;
    index["points_read"] = points_read;
    index["inputs"] = input_digests;
    write_file_if_changed(dir / "index.json", index.dump(1) + "\n");
    write_file_atomic(dir / "plan.json", json{{"schema", "tigerlod.ingest-plan/1"}, {"jobs", jobs}}.dump(1) + "\n");
    std::printf("ingest plan %s: %zu parts (%zu from read jobs, %zu read here, %zu rewritten), %zu jobs (%zu specs "
                "changed, %zu with a store changed since)%s, %.2f s, in %s\n",
                cfg.name.c_str(), nparts, from_reads, nparts - from_reads, rewritten, specs.size(), specs_changed,
                damaged.size(),
                mode == "regions" ? (", regions of level '" + level_names[plan.level] + "'").c_str()
                                  : (mode == "whole" ? ", one map" : ", read by the job"),
                ctx.log.elapsed_s() - t0, dir.c_str());
    return exit_ok;
}

int IngestStage::run_region(const StageContext& ctx, const Resolved& r)
{
    const IngestConfig& cfg = r.cfg;
    const fs::path dir(m_parts);
    const std::string& job = m_region;
    if (job.empty() || !std::all_of(job.begin(), job.end(), [](unsigned char c) {
            return std::isalnum(c) || c == '-' || c == '_' || c == '%';
        })) {
        throw usage_error("--region '" + job + "': a job's name is letters, digits, '-', '_' and '%'");
    }
    const fs::path spec_path = spec_file(dir, job);
    std::string spec_bytes;
    const json spec = read_json(
        spec_path,
        ("no job '" + job + "' in the plan: run --plan first (" + (dir / "plan.json").string() + " lists the jobs)")
            .c_str(),
        spec_schema, &spec_bytes);
    const std::string spec_sha = sha256_of(spec_bytes);
    if (spec.at("options") != job_options_json(cfg, r.projection, m_max_problem_samples)) {
        throw usage_error(spec_path.string() + ": planned with other options (" + spec.at("options").dump() +
                          "); run --plan again");
    }
    IngestProgress progress(ctx.progress);
    BuildOptions options = build_options(cfg, r.threads, m_max_problem_samples, ctx.log);
    progress.building(options);
    const InputFiles input_files = input_files_of(cfg);
    InPlaceStores out(m_output, reads_of(m_config, input_files, {dir}), false);
    const StoreSink sink = [&](const chains::ChainStore& s) { out.write(s); };
    const double t0 = ctx.log.elapsed_s();
    RegionJobShare share;
    share.job = job;
    share.spec_sha256 = spec_sha;
    const std::string mode = spec.value("mode", "");
    if (mode == "direct") {
        if (spec.at("inputs") != json(digests_of(input_files))) {
            throw usage_error(spec_path.string() + ": the inputs changed since the plan; run --plan again");
        }
        RawMap raw = read_dataset(cfg, r.threads, ctx.log, progress.reading(dataset_files(cfg)));
        share.points_read = raw.points_read;
        share.share.result = build_map(std::move(raw), r.projection, options, sink);
    } else if (mode == "whole" || mode == "region") {
        RegionPlan plan = get_meta(spec, spec_path);
        plan.whole = mode == "whole";
        std::vector<std::string> sha(plan.boxes.size());
        try {
            for (const auto& p : spec.at("parts")) {
                const auto i = p.at("part").get<size_t>();
                const auto b = p.at("box").get<std::vector<int64_t>>();
                if (i >= plan.boxes.size() || b.size() != 4) {
                    throw input_error(spec_path.string() + ": a part out of range");
                }
                plan.boxes[i] = GridBox{b[0], b[1], b[2], b[3]};
                plan.class_of[i] = p.at("classes").get<std::vector<uint32_t>>();
                sha[i] = p.at("sha256").get<std::string>();
                if (sha[i].size() != 64 ||
                    !std::all_of(sha[i].begin(), sha[i].end(), [](unsigned char c) { return std::isxdigit(c) != 0; })) {
                    throw input_error(spec_path.string() + ": part " + std::to_string(i) + "'s digest is not SHA-256");
                }
            }
            if (!plan.whole) {
                const json& rj = spec.at("region");
                RegionPlan::Region region;
                region.parts = rj.at("parts").get<std::vector<size_t>>();
                region.own = rj.at("own").get<std::vector<std::string>>();
                region.near = rj.at("near").get<std::vector<size_t>>();
                plan.regions.push_back(std::move(region));
            }
        } catch (const json::exception& e) {
            throw input_error(spec_path.string() + ": " + e.what());
        }
        const std::function<RawMap(size_t)> load = [&](size_t i) {
            if (i >= sha.size() || sha[i].empty()) {
                throw input_error(spec_path.string() + ": part " + std::to_string(i) + " is not in the job's spec");
            }
            const fs::path file = part_file(dir, sha[i]);
            const std::string bytes = read_file(file);
            if (sha256_of(bytes) != sha[i]) {
                throw usage_error(file.string() + ": the part changed since the plan; run --plan again");
            }
            return decode_raw(std::as_bytes(std::span(bytes.data(), bytes.size())), file.string());
        };
        if (!plan.whole) {                                                  // a whole plan's build_map calls it
            options.on_plan(plan.meta.level_names.size() - plan.level - 1); // the region's finer levels
        }
        if (plan.whole) {
            share.share.result = build_planned_whole(plan, load, r.projection, options, sink);
            share.points_read = share.share.result.input_vertices;
        } else {
            share.share = build_planned_region(plan, 0, load, r.projection, options, sink);
        }
    } else {
        throw input_error(spec_path.string() + ": unknown mode '" + mode + "'");
    }
    share.stores = out.close();
    for (const auto& store : share.stores) {
        const auto [size, mtime] = stamp_of(store_path(m_output, store));
        share.store_bytes.push_back(size);
        share.store_mtimes.push_back(mtime);
    }
    fs::create_directories(dir / "shares");
    write_file_atomic(share_file(dir, job), encode_share(share));
    std::printf("ingest %s %s: %zu stores (%zu rewritten) in %.2f s, %s\n", cfg.name.c_str(), job.c_str(),
                share.stores.size(), out.rewritten(), ctx.log.elapsed_s() - t0, m_output.c_str());
    return exit_ok;
}

int IngestStage::run_finish(const StageContext& ctx, const Resolved& r)
{
    const IngestConfig& cfg = r.cfg;
    const fs::path dir(m_parts);
    const fs::path index_path = dir / "index.json";
    const json index = read_json(index_path, "run --plan first", index_schema);
    if (index.at("options") != job_options_json(cfg, r.projection, m_max_problem_samples)) {
        throw usage_error(index_path.string() + ": planned with other options; run --plan and the jobs again");
    }
    const double t0 = ctx.log.elapsed_s();
    const auto jobs = index.at("jobs").get<std::vector<std::string>>();
    std::vector<RegionJobShare> shares;
    std::vector<std::vector<std::string>> written;
    for (const auto& job : jobs) {
        const fs::path file = share_file(dir, job);
        std::error_code ec;
        if (!fs::is_regular_file(file, ec)) {
            throw usage_error(file.string() + " is missing: run --region " + job + " first");
        }
        const std::string bytes = read_file(file);
        RegionJobShare share = decode_share(std::as_bytes(std::span(bytes.data(), bytes.size())), file.string());
        if (share.job != job || share.spec_sha256 != sha256_of(read_file(spec_file(dir, job)))) {
            throw usage_error(file.string() + ": built from an older plan of the job; run --region " + job + " again");
        }
        written.push_back(share.stores);
        shares.push_back(std::move(share));
    }
    const std::string mode = index.at("mode").get<std::string>();
    RegionPlan plan = get_meta(index, index_path);
    plan.whole = mode != "regions";
    plan.empty_geometries = index.at("empty_geometries").get<std::vector<uint64_t>>();
    plan.empty_codes = index.at("empty_codes").get<std::vector<uint64_t>>();
    check_each_store_once(plan, written, plan.meta.level_names);
    const InputFiles input_files = input_files_of(cfg);
    InPlaceStores out(m_output, reads_of(m_config, input_files, {dir}), true);
    Built built;
    if (plan.whole) {
        if (shares.size() != 1) {
            throw input_error(index_path.string() + ": a whole plan of " + std::to_string(shares.size()) + " jobs");
        }
        built.result = std::move(shares.front().share.result);
        built.points_read = shares.front().points_read;
    } else {
        std::vector<RegionShare> parts;
        for (auto& s : shares) {
            parts.push_back(std::move(s.share));
        }
        IngestProgress progress(ctx.progress);
        BuildOptions options = build_options(cfg, r.threads, m_max_problem_samples, ctx.log);
        progress.building(options);
        options.on_plan(plan.level + 1); // the coarse levels, down to the region level
        built.result = finish_planned(plan, std::move(parts), r.projection, options,
                                      [&](const chains::ChainStore& s) { out.write(s); });
        built.points_read = built.result.input_vertices;
    }
    std::set<std::string> all;
    for (const auto& w : written) {
        all.insert(w.begin(), w.end());
    }
    const auto coarse = out.close();
    check_each_store_once(plan, {std::vector<std::string>(all.begin(), all.end()), coarse}, plan.meta.level_names);
    all.insert(coarse.begin(), coarse.end());
    const size_t removed = remove_stale_stores(m_output, cfg, all);
    const auto digests = index.at("inputs").get<std::vector<std::string>>();
    if (digests.size() != input_files.size()) {
        throw usage_error(index_path.string() + ": planned for other inputs; run --plan and the jobs again");
    }
    const fs::path output(m_output);
    write_file_atomic(output / "ingest-report.json",
                      report_json(cfg, r.projection, built.result, all.size()).dump(2) + "\n");
    write_file_atomic(output / "manifest.json", manifest_text(manifest_json(cfg, r.projection, input_files, digests,
                                                                            versions(), m_max_problem_samples)));
    const double t_end = ctx.log.elapsed_s();
    built.t_read = t0;
    write_file_atomic(output / "ingest-timings.json", timings_json(built, t0, t_end, r.threads).dump(2) + "\n");
    if (removed > 0) {
        ctx.log.info("removed " + std::to_string(removed) + " stores and folders no job wrote");
    }
    print_summary(cfg, built, t_end - t0, all.size(), m_output);
    return exit_ok;
}

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
        // The rules color and simplify hold the config's own ladder to
        // (simplify::check_ladder; they would refuse it later): no
        // tolerance below the grid step, and the halo rule.
        if (cfg.ladder_min_m < cfg.projection.grid_m) {
            std::ostringstream msg;
            msg << cfg.file.string() << ": simplify.tolerances_m's smallest, " << cfg.ladder_min_m
                << " m, is below projection.grid_m (" << cfg.projection.grid_m
                << " m): give tolerances of one grid step or more";
            throw config_error(msg.str());
        }
        if (const double need = halo_needed_m(cfg.ladder_max_m, cfg.ladder_class_scale, cfg.ladder_metric);
            cfg.halo_m < need) {
            std::ostringstream msg;
            msg << cfg.file.string() << ": 'ingest.halo_m' (" << cfg.halo_m << " m) is below the " << need
                << " m that simplify.tolerances_m's largest, " << cfg.ladder_max_m
                << " m, needs (twice it, times the largest class scale and the " << metric_name(cfg.ladder_metric)
                << " metric's reach) so that partitions simplified apart cannot cross: raise ingest.halo_m or "
                   "lower the ladder";
            throw config_error(msg.str());
        }
        validate_dataset(cfg);
        std::printf("%s: valid; dataset %s, %zu input files, levels", cfg.file.c_str(), cfg.name.c_str(),
                    cfg.dataset.edges.size() + cfg.dataset.faces.size() + cfg.dataset.inputs.size());
        for (const auto& l : cfg.levels) {
            std::printf(" %s", l.name.c_str());
        }
        std::printf("; projection %s; halo %g m; %u threads\n", projection.describe().c_str(), cfg.halo_m, threads);
        return exit_ok;
    }
    const int modes = (m_list ? 1 : 0) + (m_read.empty() ? 0 : 1) + (m_plan ? 1 : 0) + (m_region.empty() ? 0 : 1) +
                      (m_finish ? 1 : 0);
    if (modes > 1) {
        throw usage_error("--list, --read, --plan, --region and --finish are steps of their own: give one");
    }
    if (!m_select.empty() && m_read.empty()) {
        throw usage_error("--select goes with --read");
    }
    if (modes == 1 || !m_parts.empty()) {
        if (modes == 0) {
            throw usage_error("--parts goes with --list, --read, --plan, --region or --finish");
        }
        if (m_parts.empty()) {
            throw usage_error("--list, --read, --plan, --region and --finish need --parts DIR");
        }
        if (m_whole_map) {
            throw usage_error("--whole-map builds in one process; the jobs' plan decides by the data");
        }
        const Resolved r{cfg, projection, threads};
        try {
            return m_list              ? run_list(ctx, r)
                   : !m_read.empty()   ? run_read(ctx, r)
                   : m_plan            ? run_plan(ctx, r)
                   : !m_region.empty() ? run_region(ctx, r)
                                       : run_finish(ctx, r);
        } catch (const json::exception& e) {
            // A spec, index or plan with a field missing or of another type.
            throw input_error(m_parts + ": a job file is not what this version of tigerlod-ingest writes (" + e.what() +
                              "); run --plan again");
        }
    }
    // The manifest's input digests are computed beside the work, not after it.
    const InputFiles input_files = input_files_of(cfg);
    auto digests = std::async(std::launch::async, [&input_files] { return digests_of(input_files); });
    const std::vector<fs::path> reads = reads_of(m_config, input_files);
    OutputDir out(m_output, m_overwrite, reads);
    // Stores of unchanged regions keep their times: the engine reruns only the others' jobs.
    out.keep_times_of_unchanged_files(".tlc");
    log_removed_leftovers(ctx.log, out.removed_leftovers());
    for (const auto& l : cfg.levels) {
        fs::create_directories(out.path() / l.name);
    }
    std::atomic<uint64_t> stores{0};
    IngestProgress progress(ctx.progress);
    BuildOptions options = build_options(cfg, threads, m_max_problem_samples, ctx.log);
    progress.building(options);
    const StoreSink sink = [&](const chains::ChainStore& s) {
        // Inside the output folder, renamed into place whole at the end.
        write_file(out.path() / s.level_name / (file_name(s.partition) + ".tlc"), chains::encode(s));
        ++stores;
    };

    const double t0 = ctx.log.elapsed_s();
    // Parts put aside go inside the output folder (removed before it is renamed into place).
    const Built built =
        read_and_build(cfg, projection, options, sink, out.path() / ".parts", m_whole_map, ctx.log, progress);
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
