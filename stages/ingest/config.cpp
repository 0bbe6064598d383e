#include "stages/ingest/config.hpp"

#include "core/errors.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <type_traits>
#include <set>

namespace fs = std::filesystem;

namespace tigerlod::ingest {

namespace {

class Ctx {
  public:
    explicit Ctx(fs::path file) : m_file(std::move(file)) {}
    [[noreturn]] void fail(const YAML::Node& node, const std::string& what) const
    {
        std::string where = m_file.string();
        if (node.IsDefined() && node.Mark().line >= 0) {
            where += ":" + std::to_string(node.Mark().line + 1);
        }
        throw config_error(where + ": " + what);
    }
    void check_keys(const YAML::Node& node, const std::string& prefix, const std::set<std::string>& known) const
    {
        if (!node.IsMap()) {
            fail(node, "'" + prefix + "' must be a mapping");
        }
        for (const auto& kv : node) {
            const auto key = kv.first.as<std::string>();
            if (!known.contains(key)) {
                std::string list;
                for (const auto& k : known) {
                    list += (list.empty() ? "" : ", ") + k;
                }
                fail(kv.first,
                     "unknown key '" + (prefix.empty() ? key : prefix + "." + key) + "' (known: " + list + ")");
            }
        }
    }
    template <class T> T get(const YAML::Node& node, const std::string& key, const T& fallback) const
    {
        if (!node[key]) {
            return fallback;
        }
        try {
            return node[key].as<T>();
        } catch (const YAML::Exception&) {
            fail(node[key], "'" + key + "' has the wrong type");
        }
    }
    /// A value of the right type (a scalar, a list or a map of them), or
    /// nothing: fails naming what was wanted.
    template <class T> void expect(const YAML::Node& node, const std::string& key, const std::string& wanted) const
    {
        const YAML::Node value = node[key];
        if (!value) {
            return;
        }
        bool ok = !value.IsNull();
        try {
            if (ok) {
                (void)value.as<T>();
            }
        } catch (const YAML::Exception&) {
            ok = false;
        }
        if constexpr (std::is_same_v<T, std::string>) {
            ok = ok && value.IsScalar();
        }
        if (!ok) {
            fail(value, "'" + key + "' must be " + wanted);
        }
    }
    std::vector<fs::path> paths(const YAML::Node& node, const std::string& key) const
    {
        std::vector<fs::path> out;
        if (!node[key]) {
            return out;
        }
        const auto list = node[key].IsSequence() ? get<std::vector<std::string>>(node, key, {})
                                                 : std::vector<std::string>{get<std::string>(node, key, "")};
        for (size_t i = 0; i < list.size(); ++i) {
            fs::path p = list[i];
            if (p.is_relative()) {
                p = m_file.parent_path() / p;
            }
            p = p.lexically_normal();
            if (!fs::exists(p)) {
                fail(node[key], "dataset." + key + "[" + std::to_string(i) + "]: " + p.string() + ": no such file");
            }
            out.push_back(p);
        }
        return out;
    }

  private:
    fs::path m_file;
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

IngestConfig load_config(const fs::path& file)
{
    IngestConfig cfg;
    cfg.file = file;
    if (!fs::exists(file)) {
        throw config_error(file.string() + ": no such config file");
    }
    if (fs::is_directory(file)) {
        throw config_error(file.string() + ": is a folder, not a config file");
    }
    YAML::Node root;
    try {
        root = YAML::LoadFile(file.string());
    } catch (const YAML::ParserException& e) {
        throw config_error(file.string() + ":" + std::to_string(e.mark.line + 1) + ": not valid YAML: " + e.msg);
    } catch (const YAML::Exception& e) {
        throw config_error(file.string() + ": cannot read: " + e.what());
    }
    Ctx ctx(file);
    ctx.check_keys(root, "", {"name", "description", "dataset", "levels", "projection", "ingest", "simplify", "pack"});
    if (const YAML::Node simp = root["simplify"]) { // read by the pipeline; the stages validate the values
        ctx.check_keys(simp, "simplify",
                       {"tolerances_m", "metric", "class_scale", "projection_scale", "max_reach", "point_constraints",
                        "points", "lazy", "compliance", "gl", "pixel_fraction", "tile_pixels", "max_classes",
                        "threads"});
        // The pipeline turns these into flags: a value of the wrong type
        // would reach a stage as a malformed flag (a string in the ladder
        // as `--tolerances 1,,4`), or not at all (a boolean).
        for (const char* key : {"projection_scale", "point_constraints", "lazy"}) {
            ctx.get<bool>(simp, key, true);
        }
        ctx.expect<std::vector<double>>(simp, "tolerances_m", "a list of numbers, e.g. [1, 4, 16, 64]");
        ctx.expect<std::map<std::string, double>>(simp, "class_scale", "a map of class to number, e.g. {S1400: 0.5}");
        for (const char* key : {"metric", "points", "compliance", "gl"}) {
            ctx.expect<std::string>(simp, key, "a string");
        }
        ctx.expect<double>(simp, "pixel_fraction", "a number");
        for (const char* key : {"max_reach", "tile_pixels", "max_classes", "threads"}) {
            ctx.expect<int>(simp, key, "an integer");
        }
    }
    if (const YAML::Node pack = root["pack"]) { // read by the pipeline; tigerlod-pack validates the values
        ctx.check_keys(pack, "pack", {"tile_mb", "draco_speed", "threads"});
        ctx.expect<double>(pack, "tile_mb", "a number");
        ctx.expect<int>(pack, "draco_speed", "an integer");
        ctx.expect<int>(pack, "threads", "an integer");
    }
    cfg.name = ctx.get<std::string>(root, "name", "");
    if (cfg.name.empty() || cfg.name.find_first_not_of("abcdefghijklmnopqrstuvwxyz0123456789_-") != std::string::npos) {
        ctx.fail(root["name"], "'name' is required: lowercase letters, digits, '_' and '-'");
    }
    const YAML::Node ds = root["dataset"];
    if (!ds) {
        ctx.fail(root, "'dataset' is required");
    }
    ctx.check_keys(ds, "dataset",
                   {"kind", "edges", "faces", "inputs", "layer", "code_field", "class_field", "intpt_lat_field",
                    "intpt_lon_field", "fetch"});
    const auto kind = ctx.get<std::string>(ds, "kind", "");
    auto& d = cfg.dataset;
    if (kind == "tiger") {
        d.kind = DatasetSpec::Kind::tiger;
        d.edges = ctx.paths(ds, "edges");
        d.faces = ctx.paths(ds, "faces");
        if (d.edges.empty() || d.faces.empty()) {
            ctx.fail(ds, "a tiger dataset needs 'edges' and 'faces' (EDGES alone, as lines without units: "
                         "kind: lines, inputs: [the EDGES files])");
        }
        d.class_field = ctx.get<std::string>(ds, "class_field", "MTFCC");
        d.intpt_lat_field = ctx.get<std::string>(ds, "intpt_lat_field", "INTPTLAT");
        d.intpt_lon_field = ctx.get<std::string>(ds, "intpt_lon_field", "INTPTLON");
    } else if (kind == "polygons" || kind == "lines") {
        d.kind = kind == "polygons" ? DatasetSpec::Kind::polygons : DatasetSpec::Kind::lines;
        d.inputs = ctx.paths(ds, "inputs");
        if (d.inputs.empty()) {
            ctx.fail(ds, "a " + kind + " dataset needs 'inputs'");
        }
        d.code_field = ctx.get<std::string>(ds, "code_field", "");
        if (d.kind == DatasetSpec::Kind::polygons && d.code_field.empty()) {
            ctx.fail(ds, "a polygons dataset needs 'code_field'");
        }
        d.class_field = ctx.get<std::string>(ds, "class_field", "");
        d.intpt_lat_field = ctx.get<std::string>(ds, "intpt_lat_field", "");
        d.intpt_lon_field = ctx.get<std::string>(ds, "intpt_lon_field", "");
    } else {
        ctx.fail(ds["kind"], "'dataset.kind' must be tiger, polygons or lines, got '" + kind + "'");
    }
    d.layer = ctx.get<std::string>(ds, "layer", "");
    if (const YAML::Node fetch = ds["fetch"]) { // used by the pipeline, which fetches before ingest
        ctx.check_keys(fetch, "dataset.fetch", {"npm", "into"});
        if (ctx.get<std::string>(fetch, "npm", "").empty() || ctx.get<std::string>(fetch, "into", "").empty()) {
            ctx.fail(fetch, "'dataset.fetch' needs 'npm' (package@version) and 'into' (a folder)");
        }
    }
    if (d.intpt_lat_field.empty() != d.intpt_lon_field.empty()) {
        ctx.fail(ds, "'intpt_lat_field' and 'intpt_lon_field' go together");
    }

    if (const YAML::Node lv = root["levels"]) {
        if (!lv.IsSequence() || lv.size() == 0) {
            ctx.fail(lv, "'levels' must be a non-empty list");
        }
        for (size_t i = 0; i < lv.size(); ++i) {
            const YAML::Node n = lv[i];
            const std::string where = "levels[" + std::to_string(i) + "]";
            ctx.check_keys(n, where, {"name", "code", "fields", "prefix"});
            LevelSpec s;
            s.name = ctx.get<std::string>(n, "name", "");
            s.code = ctx.get<std::string>(n, "code", "");
            s.fields = ctx.get<std::vector<std::string>>(n, "fields", {});
            s.prefix = ctx.get<int>(n, "prefix", -1);
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

    if (const YAML::Node pj = root["projection"]) {
        ctx.check_keys(pj, "projection",
                       {"kind", "lon0", "lat0", "stdlat1", "stdlat2", "k0", "utm_zone", "utm_north", "false_easting",
                        "false_northing", "grid_m"});
        auto& p = cfg.projection;
        const auto pk = ctx.get<std::string>(pj, "kind", "albers");
        const auto parsed = parse_projection_kind(pk);
        if (!parsed) {
            ctx.fail(pj["kind"], "'projection.kind' must be albers, lcc, tm or utm, got '" + pk + "'");
        }
        p.kind = *parsed;
        p.lon0_deg = ctx.get<double>(pj, "lon0", p.lon0_deg);
        p.lat0_deg = ctx.get<double>(pj, "lat0", p.lat0_deg);
        p.stdlat1_deg = ctx.get<double>(pj, "stdlat1", p.stdlat1_deg);
        p.stdlat2_deg = ctx.get<double>(pj, "stdlat2", p.stdlat2_deg);
        p.k0 = ctx.get<double>(pj, "k0", p.k0);
        p.utm_zone = ctx.get<int>(pj, "utm_zone", p.utm_zone);
        p.utm_north = ctx.get<bool>(pj, "utm_north", p.utm_north);
        p.false_easting_m = ctx.get<double>(pj, "false_easting", p.false_easting_m);
        p.false_northing_m = ctx.get<double>(pj, "false_northing", p.false_northing_m);
        p.grid_m = ctx.get<double>(pj, "grid_m", p.grid_m);
        if (!(p.grid_m >= 1e-4 && p.grid_m <= 1000)) {
            ctx.fail(pj["grid_m"], "'projection.grid_m' must be in [0.0001, 1000]");
        }
    }
    if (const YAML::Node in = root["ingest"]) {
        ctx.check_keys(in, "ingest", {"halo_m", "threads"});
        cfg.halo_m = ctx.get<double>(in, "halo_m", cfg.halo_m);
        const int threads = ctx.get<int>(in, "threads", 0);
        if (threads < 0 || threads > 256) {
            ctx.fail(in["threads"], "'ingest.threads' must be in 0..256 (0: all cores)");
        }
        cfg.threads = static_cast<unsigned>(threads);
        if (!(cfg.halo_m >= 0) || !std::isfinite(cfg.halo_m)) {
            ctx.fail(in["halo_m"], "'ingest.halo_m' must be >= 0");
        }
    }
    return cfg;
}

} // namespace tigerlod::ingest
