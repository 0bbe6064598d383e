#include "stages/ingest/config.hpp"

#include "config/config_file.hpp"
#include "core/errors.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <glob.h>
#include <cmath>
#include <map>
#include <type_traits>
#include <set>

namespace fs = std::filesystem;

namespace tigerlod::ingest {

namespace {

/// Typed reads of keys the schema has already checked, and what only ingest
/// knows (which keys a dataset kind needs, that its files exist, levels).
class Reader {
  public:
    explicit Reader(const config::ConfigFile& cfg) : m_cfg(cfg) {}
    [[noreturn]] void fail(const YAML::Node& at, const std::string& what) const { m_cfg.fail(at, what); }
    YAML::Node node(const std::string& key) const { return m_cfg.node(key); }
    template <class T> T get(const std::string& key, const T& fallback) const
    {
        const YAML::Node n = m_cfg.node(key);
        return n.IsDefined() && !n.IsNull() ? n.as<T>() : fallback;
    }
    std::vector<fs::path> paths(const std::string& key) const
    {
        const YAML::Node n = m_cfg.node(key);
        std::vector<fs::path> out;
        if (!n.IsDefined() || n.IsNull()) {
            return out;
        }
        const auto list =
            n.IsSequence() ? n.as<std::vector<std::string>>() : std::vector<std::string>{n.as<std::string>()};
        for (size_t i = 0; i < list.size(); ++i) {
            const fs::path p = m_cfg.resolve(list[i]);
            if (list[i].find_first_of("*?[") != std::string::npos) {
                // A pattern: its matches in name order (a nation's 3,000 counties).
                glob_t g{};
                const int rc = ::glob(p.c_str(), 0, nullptr, &g);
                for (size_t k = 0; rc == 0 && k < g.gl_pathc; ++k) {
                    out.emplace_back(g.gl_pathv[k]);
                }
                globfree(&g);
                if (rc != 0) {
                    fail(n.IsSequence() ? n[i] : n,
                         key + "[" + std::to_string(i) + "]: " + p.string() + ": the pattern matches no file");
                }
                continue;
            }
            if (!fs::exists(p)) {
                fail(n.IsSequence() ? n[i] : n, key + "[" + std::to_string(i) + "]: " + p.string() + ": no such file");
            }
            out.push_back(p);
        }
        return out;
    }

  private:
    const config::ConfigFile& m_cfg;
};

} // namespace

std::vector<LevelSpec> default_tiger_levels()
{
    return {{"state", "", {"STATEFP20"}, -1},
            {"county", "", {"STATEFP20", "COUNTYFP20"}, -1},
            {"tract", "", {"STATEFP20", "COUNTYFP20", "TRACTCE20"}, -1},
            {"block_group", "", {"STATEFP20", "COUNTYFP20", "TRACTCE20", "BLKGRPCE20"}, -1},
            {"block", "", {"STATEFP20", "COUNTYFP20", "TRACTCE20", "BLOCKCE20"}, -1}};
}

/// The `dataset` section: its kind, files and fields, checked.
DatasetSpec read_dataset_section(const Reader& ctx, const YAML::Node& root)
{
    DatasetSpec d;
    const YAML::Node ds = root["dataset"];
    if (!ds) {
        ctx.fail(root, "'dataset' is required");
    }
    const auto kind = ctx.get<std::string>("dataset.kind", "");
    if (kind == "tiger") {
        d.kind = DatasetSpec::Kind::tiger;
        d.edges = ctx.paths("dataset.edges");
        d.faces = ctx.paths("dataset.faces");
        if (d.edges.empty() || d.faces.empty()) {
            ctx.fail(ds, "a tiger dataset needs 'edges' and 'faces' (EDGES alone, as lines without units: "
                         "kind: lines, inputs: [the EDGES files])");
        }
        d.class_field = ctx.get<std::string>("dataset.class_field", "MTFCC");
        d.intpt_lat_field = ctx.get<std::string>("dataset.intpt_lat_field", "INTPTLAT");
        d.intpt_lon_field = ctx.get<std::string>("dataset.intpt_lon_field", "INTPTLON");
    } else if (kind == "polygons" || kind == "lines") {
        d.kind = kind == "polygons" ? DatasetSpec::Kind::polygons : DatasetSpec::Kind::lines;
        d.inputs = ctx.paths("dataset.inputs");
        if (d.inputs.empty()) {
            ctx.fail(ds, "a " + kind + " dataset needs 'inputs'");
        }
        d.code_field = ctx.get<std::string>("dataset.code_field", "");
        if (d.kind == DatasetSpec::Kind::polygons && d.code_field.empty()) {
            ctx.fail(ds, "a polygons dataset needs 'code_field'");
        }
        d.class_field = ctx.get<std::string>("dataset.class_field", "");
        d.intpt_lat_field = ctx.get<std::string>("dataset.intpt_lat_field", "");
        d.intpt_lon_field = ctx.get<std::string>("dataset.intpt_lon_field", "");
        d.skip_empty_codes = ctx.get<std::string>("dataset.empty_code", "error") == "skip"; // a choice of the schema
        d.merge_duplicate_codes = ctx.get<std::string>("dataset.duplicate_code", "error") == "merge";
    } else {
        ctx.fail(ds, "'dataset.kind' is required: tiger, polygons or lines");
    }
    d.layer = ctx.get<std::string>("dataset.layer", "");
    d.where = ctx.get<std::string>("dataset.where", "");
    if (!d.where.empty() && d.kind == DatasetSpec::Kind::tiger) {
        ctx.fail(ds["where"], "'dataset.where' applies to polygons and lines datasets (TIGER's FACES and EDGES "
                              "must stay whole to close their faces)");
    }
    if (const YAML::Node fetch = ds["fetch"]) { // used by the pipeline, which fetches before ingest
        if (ctx.get<std::string>("dataset.fetch.npm", "").empty() ||
            ctx.get<std::string>("dataset.fetch.into", "").empty()) {
            ctx.fail(fetch, "'dataset.fetch' needs 'npm' (package@version) and 'into' (a folder)");
        }
    }
    d.name_field = ctx.get<std::string>("dataset.name_field", "");
    d.attributes = ctx.get<std::vector<std::string>>("dataset.attributes", {}); // none twice: the schema
    if ((!d.name_field.empty() || !d.attributes.empty()) && d.kind == DatasetSpec::Kind::lines) {
        ctx.fail(ds[d.name_field.empty() ? "attributes" : "name_field"],
                 "'dataset.name_field' and 'dataset.attributes' apply to units: polygons and tiger datasets");
    }
    if (std::find(d.attributes.begin(), d.attributes.end(), d.name_field) != d.attributes.end()) {
        ctx.fail(ds["attributes"], "'dataset.attributes' names the name_field '" + d.name_field + "' again");
    }
    if (d.intpt_lat_field.empty() != d.intpt_lon_field.empty()) {
        ctx.fail(ds, "'intpt_lat_field' and 'intpt_lon_field' go together");
    }
    return d;
}

IngestConfig load_config(const fs::path& file)
{
    const auto loaded = config::ConfigFile::load(file); // every key known, typed, in range
    const Reader ctx(loaded);
    IngestConfig cfg;
    cfg.file = file;
    const YAML::Node& root = loaded.root();
    cfg.name = ctx.get<std::string>("name", "");
    if (cfg.name.empty() || cfg.name.find_first_not_of("abcdefghijklmnopqrstuvwxyz0123456789_-") != std::string::npos) {
        ctx.fail(root["name"], "'name' is required: lowercase letters, digits, '_' and '-'");
    }
    cfg.dataset = read_dataset_section(ctx, root);
    const DatasetSpec& d = cfg.dataset;

    if (const YAML::Node lv = root["levels"]) {
        for (size_t i = 0; i < lv.size(); ++i) {
            const YAML::Node n = lv[i];
            const std::string where = "levels[" + std::to_string(i) + "]";
            if (!n.IsMap()) {
                ctx.fail(n, where + " must be a mapping {name, code | fields | prefix}");
            }
            for (const auto& kv : n) {
                const auto key = kv.first.as<std::string>();
                if (key != "name" && key != "code" && key != "fields" && key != "prefix") {
                    ctx.fail(kv.first, "unknown key '" + where + "." + key + "' (known: code, fields, name, prefix)");
                }
            }
            LevelSpec s;
            try {
                s.name = n["name"] ? n["name"].as<std::string>() : "";
                s.code = n["code"] ? n["code"].as<std::string>() : "";
                s.fields = n["fields"] ? n["fields"].as<std::vector<std::string>>() : std::vector<std::string>{};
                s.prefix = n["prefix"] ? n["prefix"].as<int>() : -1;
            } catch (const YAML::Exception&) {
                ctx.fail(n, where + ": 'name' and 'code' must be strings, 'fields' a list of strings, "
                                    "'prefix' an integer");
            }
            if (s.name.empty() ||
                s.name.find_first_not_of("abcdefghijklmnopqrstuvwxyz0123456789_") != std::string::npos) {
                ctx.fail(n, where + ".name is required: lowercase letters, digits and '_'");
            }
            const int ways = (!s.code.empty()) + (!s.fields.empty()) + (s.prefix >= 0);
            if (d.kind != DatasetSpec::Kind::lines && ways != 1) {
                ctx.fail(n, where + " needs exactly one of 'code', 'fields', 'prefix'");
            }
            if (s.prefix >= 0 && d.kind != DatasetSpec::Kind::polygons) {
                ctx.fail(n, where + ".prefix applies to polygons datasets only");
            }
            if (s.prefix == 0) {
                ctx.fail(n, where + ".prefix must be >= 1; use 'code' for a level with one unit");
            }
            for (const auto& prev : cfg.levels) {
                if (prev.name == s.name) {
                    ctx.fail(n, where + ": level '" + s.name + "' appears twice");
                }
            }
            cfg.levels.push_back(s);
        }
        if (d.kind == DatasetSpec::Kind::lines && cfg.levels.size() != 1) {
            ctx.fail(lv, "a lines dataset has exactly one level");
        }
        // Levels go from the coarsest to the finest, each nesting in the one
        // before: what the config alone can show (the data shows the rest,
        // ingest's check of nesting).
        for (size_t i = 1; i < cfg.levels.size(); ++i) {
            const LevelSpec& a = cfg.levels[i - 1];
            const LevelSpec& b = cfg.levels[i];
            const std::string where = "levels[" + std::to_string(i) + "]";
            if (!b.code.empty()) {
                ctx.fail(lv[i], where + " ('" + b.name + "') has a 'code': a level of one unit must be the first, " +
                                    "since levels go from the coarsest to the finest");
            }
            if (a.prefix >= 0 && b.prefix >= 0 && b.prefix <= a.prefix) {
                ctx.fail(lv[i], where + ".prefix " + std::to_string(b.prefix) + " is not longer than " + a.name +
                                    "'s " + std::to_string(a.prefix) +
                                    ": levels go from the coarsest to the finest, each nesting in the one before");
            }
        }
    } else if (d.kind == DatasetSpec::Kind::tiger) {
        cfg.levels = default_tiger_levels();
    } else if (d.kind == DatasetSpec::Kind::lines) {
        cfg.levels = {{"lines", "", {}, -1}};
    } else {
        ctx.fail(root, "a polygons dataset needs 'levels'");
    }

    auto& p = cfg.projection;
    p.kind = *parse_projection_kind(ctx.get<std::string>("projection.kind", "albers")); // a choice of the schema
    p.lon0_deg = ctx.get<double>("projection.lon0", p.lon0_deg);
    p.lat0_deg = ctx.get<double>("projection.lat0", p.lat0_deg);
    p.stdlat1_deg = ctx.get<double>("projection.stdlat1", p.stdlat1_deg);
    p.stdlat2_deg = ctx.get<double>("projection.stdlat2", p.stdlat2_deg);
    p.k0 = ctx.get<double>("projection.k0", p.k0);
    p.utm_zone = ctx.get<int>("projection.utm_zone", p.utm_zone);
    p.utm_north = ctx.get<bool>("projection.utm_north", p.utm_north);
    p.false_easting_m = ctx.get<double>("projection.false_easting", p.false_easting_m);
    p.false_northing_m = ctx.get<double>("projection.false_northing", p.false_northing_m);
    p.grid_m = ctx.get<double>("projection.grid_m", p.grid_m);
    cfg.halo_m = ctx.get<double>("ingest.halo_m", cfg.halo_m);
    if (const auto ladder = ctx.get<std::vector<double>>("simplify.tolerances_m", {}); !ladder.empty()) {
        cfg.ladder_min_m = ladder.front();
        cfg.ladder_max_m = ladder.back(); // the schema checked that it increases
    }
    cfg.ladder_metric = parse_metric(ctx.get<std::string>("simplify.metric", "l2")).value_or(Metric::l2);
    for (const auto& [cls, f] : ctx.get<std::map<std::string, double>>("simplify.class_scale", {})) {
        cfg.ladder_class_scale = std::max(cfg.ladder_class_scale, f);
    }
    cfg.line_tile_km = ctx.get<double>("ingest.line_tile_km", cfg.line_tile_km);
    if (root["ingest"] && root["ingest"]["line_tile_km"] && d.kind != DatasetSpec::Kind::lines) {
        ctx.fail(root["ingest"]["line_tile_km"], "'ingest.line_tile_km' applies to lines datasets only");
    }
    cfg.threads = static_cast<unsigned>(ctx.get<int>("ingest.threads", 0));
    return cfg;
}

} // namespace tigerlod::ingest
