#include "config/schema.hpp"

#include <algorithm>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace tigerlod::config {

namespace {

constexpr double inf = std::numeric_limits<double>::infinity();

Key section(std::string name, std::string doc)
{
    return {std::move(name), Type::mapping, std::move(doc), "", {}, {}, "", true, ""};
}

Key entry(std::string name, Type type, std::string doc, std::string def, Limits limits = {},
          std::vector<std::string> choices = {}, std::string flag = "", std::string stages = "", bool flag_when = true)
{
    return {std::move(name), type,      std::move(doc),   std::move(def), limits, std::move(choices),
            std::move(flag), flag_when, std::move(stages)};
}

constexpr Limits integer(double min, double max = inf)
{
    return {min, max, false, false, true};
}

/// The dataset, its levels, the projection and ingest's section.
std::vector<Key> input_keys()
{
    return {
        entry("name", Type::text, "required; lowercase letters, digits, `_`, `-`; outputs go to `out/<name>/`", ""),
        entry("description", Type::text, "free text", ""),
        entry("regions", Type::codes,
              "regions to rebuild (`scripts/workflow` forces their jobs and what depends on them): unit codes such as "
              "`[51063]`, each naming the stores whose partition begins with it or is part of it",
              "none"),
        section("workflow", "how `pipeline/Snakefile` cuts the run into jobs"),
        entry("workflow.job_mb", Type::number,
              "color and simplify: a job per group of a level's stores whose names share a prefix, the shortest "
              "prefix for which no group holds more than this many MB of stores (pack and verify follow these "
              "groups); ingest's read jobs group the input parts (files, or a county's FACES and EDGES) by their "
              "names the same way, up to 8 times this many MB of input files (reading is that much faster a "
              "byte)",
              "32", {0, 1e6, true}),
        entry("workflow.job_threads", Type::integer,
              "threads of each simplify, pack and verify job (`--threads`; Snakemake runs fewer where it has fewer "
              "cores; a color job takes one, the colouring being one thread): the pipeline's jobs take this, not "
              "`simplify.threads`; outputs do not depend on it. With 1 a run keeps as many jobs going as it has "
              "cores (the 10 M synthetic nation at 1 m-2 km on 2 cores: 292 s, against 368 s with 2); more "
              "shortens the few long jobs of a level held in one store, which a cluster waits on",
              "1", integer(1, 1024)),
        entry("workflow.render", Type::boolean,
              "run the render jobs after pack: the previews (`out/<name>/render/`: the whole tree and the "
              "path's closest view, drawn again for every new tree) and the frame-time experiment "
              "(`out/<name>/frame-times/`); `false` for rebuilds that need the tree verified and nothing drawn",
              "`true`"),
        entry("workflow.frame_times", Type::choice,
              "when the frame-time experiment runs again: `renderer` (when tigerlod-render or the config's "
              "`render` section changed, or its output is missing: it measures the renderer, and takes the same "
              "seconds whatever a rebuild changed) or `tree` (after every new tree too)",
              "`renderer`", {}, {"renderer", "tree"}),
        section("dataset", "what to read"),
        entry("dataset.kind", Type::choice,
              "`tiger` (EDGES + FACES), `polygons` (any polygon layer: tracts, TopoJSON) or `lines` (any line "
              "layer: contours, rivers)",
              "required", {}, {"tiger", "polygons", "lines"}),
        entry("dataset.edges", Type::paths,
              "tiger: TIGER/Line EDGES files (`.zip` is read through `/vsizip/`); a pattern such as "
              "`tl_2020_*_edges.zip` stands for its matches in name order",
              "required for tiger"),
        entry("dataset.faces", Type::paths, "tiger: TIGER/Line FACES files, the same counties as `edges`",
              "required for tiger"),
        entry("dataset.inputs", Type::paths, "polygons, lines: files GDAL reads", "required for those"),
        entry("dataset.layer", Type::text, "the layer to read when a file holds several", "the only layer"),
        entry("dataset.where", Type::text,
              "polygons, lines: only the features this OGR SQL condition selects (`id IN ('156', '392')`, "
              "`STATEFP = '51'`); a file none of whose features it selects is an error; messages still number "
              "features as the file does",
              "every feature"),
        entry("dataset.code_field", Type::text,
              "polygons: the attribute with each unit's finest code (e.g. `GEOID10`, us-atlas `id`)",
              "required for polygons"),
        entry("dataset.empty_code", Type::choice,
              "polygons: a feature whose `code_field` is empty (Natural Earth has some): `error` (ingest stops, "
              "exit 1, with their count and the first three) or `skip` (left out, counted and named on stderr)",
              "`error`", {}, {"error", "skip"}),
        entry("dataset.duplicate_code", Type::choice,
              "polygons: one code on several features of a file (a territory filed under its country's code): "
              "`error` (ingest stops, exit 1, with their count and the first three) or `merge` (one unit in parts, "
              "its borders between them gone, each named on stderr)",
              "`error`", {}, {"error", "merge"}),
        entry("dataset.name_field", Type::text,
              "polygons, tiger: the attribute that names each unit of the finest level (us-atlas and Natural Earth "
              "`name`, TIGER tracts `NAMELSAD`): kept in the Data Tree, the export's `name`",
              "none"),
        entry("dataset.attributes", Type::fields,
              "polygons, tiger: further attributes kept for each unit of the finest level (e.g. `[ALAND, AWATER]`) "
              "and written by tigerlod-export beside its name, as integers or reals where every input file's field "
              "is one; a unit of features merged by `duplicate_code: merge` takes the values of its largest",
              "none"),
        entry("dataset.class_field", Type::text,
              "attribute stored as each chain's feature class (the class covering most of the chain)",
              "tiger: `MTFCC`"),
        entry("dataset.intpt_lat_field", Type::text,
              "attribute with a unit's internal point latitude; a unit without one gets a computed point",
              "tiger: `INTPTLAT`"),
        entry("dataset.intpt_lon_field", Type::text, "the same for longitude; goes with `intpt_lat_field`",
              "tiger: `INTPTLON`"),
        section("dataset.fetch", "`{npm: PACKAGE@VERSION, into: FOLDER}`: the pipeline fetches the package into "
                                 "FOLDER before ingest (the default config's us-atlas)"),
        entry("dataset.fetch.npm", Type::text, "the npm package and version, e.g. `us-atlas@3.0.1`", "required"),
        entry("dataset.fetch.into", Type::text, "the folder it goes into, relative to the config", "required"),
        entry("levels", Type::levels,
              "semantic levels, coarsest first, each unit of a level inside one unit of the level before (ingest "
              "stops with exit 1 naming the level, the unit, its two parents and where they are when the data "
              "says otherwise; a `code` level after the first, or a `prefix` no longer than the one before, is a "
              "config error, under `--validate` too); each `{name, ...}` with exactly one of `code` (a constant: "
              "one unit, e.g. the nation), `fields` (attributes concatenated, TIGER FACES) or `prefix` (the first "
              "N characters of `code_field`)",
              "tiger: state > county > tract > block_group > block with 2020 codes; lines: one level `lines`"),
        section("projection", "the projection onto ingest's integer grid"),
        entry("projection.kind", Type::choice, "the projection", "`albers`", {}, {"albers", "lcc", "tm", "utm"}),
        entry("projection.lon0", Type::number, "central meridian, degrees", "-96", {-180, 180}),
        entry("projection.lat0", Type::number, "latitude of the origin of y, degrees", "23", {-90, 90}),
        entry("projection.stdlat1", Type::number, "first standard parallel (albers, lcc)", "29.5",
              {-90, 90, true, true}),
        entry("projection.stdlat2", Type::number, "second standard parallel (albers, lcc)", "45.5",
              {-90, 90, true, true}),
        entry("projection.k0", Type::number, "scale on the standard parallels or central meridian", "1", {0, 10, true}),
        entry("projection.utm_zone", Type::integer, "utm zone", "", integer(1, 60)),
        entry("projection.utm_north", Type::boolean, "utm: northern hemisphere", "true"),
        entry("projection.false_easting", Type::number, "metres added to x", "0"),
        entry("projection.false_northing", Type::number, "metres added to y", "0"),
        entry("projection.grid_m", Type::number, "integer grid step in metres", "0.01", {0.0001, 1000}),
        section("ingest", "tigerlod-ingest"),
        entry("ingest.halo_m", Type::number, "halo distance in metres: at least twice the largest tolerance", "1000",
              {0, inf}, {}, "halo-m"),
        entry("ingest.line_tile_km", Type::number,
              "lines datasets: the side of the square grid tiles the map is cut into, in projected km, each tile "
              "a partition; a chain is cut where it strays an eighth of a tile out of its tile, and each piece "
              "belongs to the tile of its first vertex (0: one partition, `all`)",
              "10", {0, inf}, {}, "line-tile-km"),
        entry("ingest.threads", Type::integer, "worker threads, 0 for all cores; outputs do not depend on it", "0",
              thread_limits, {}, "threads"),
    };
}

/// The sections of the stages after ingest, and synth's.
std::vector<Key> stage_keys()
{
    const std::string both = "color simplify";
    return {
        section("simplify", "tigerlod-color and tigerlod-simplify"),
        entry("simplify.tolerances_m", Type::numbers,
              "the ladder: increasing tolerances in ground metres, none below `projection.grid_m`; at most half of "
              "`ingest.halo_m`",
              "`[1, 4, 16, 64]`", {0.0001, 1e6}, {}, "tolerances", both),
        entry("simplify.metric", Type::choice, "distance metric of the tolerance", "`l2`", {}, {"l2", "l1", "linf"},
              "metric", both),
        entry("simplify.class_scale", Type::class_map, "feature class -> eps multiplier, e.g. `{S1400: 0.5}`", "none",
              {0, inf, true}, {}, "class-scale", both),
        entry("simplify.projection_scale", Type::boolean,
              "eps in projected metres, not ground metres through the local projection scale", "`true`", {}, {},
              "no-projection-scale", both, false),
        entry("simplify.max_reach", Type::integer, "longest shortcut in vertices (0: no cap)", "0", integer(0), {},
              "max-reach", "simplify"),
        entry("simplify.end_sample", Type::integer,
              "where the tolerance is coarse for a chain's spacing (the hull scan's test), shortcuts start and end "
              "only at the vertices a greedy fit of the chain within eps / R keeps (0: at every vertex): every "
              "rule still tests each one, so the guarantee is the same, with a few vertices more than the minimum "
              "for far less work (`simplification/README.md`, \"Ends at a greedy fit's vertices\")",
              "256", integer(0, 65536), {}, "end-sample", "simplify"),
        entry("simplify.point_constraints", Type::boolean, "the units' internal points and user points may change side",
              "`true`", {}, {}, "no-point-constraints", "simplify", false),
        entry("simplify.points", Type::path,
              "user point constraints: GeoJSON points or CSV with lon,lat (relative to the config)", "none", {}, {},
              "points", "simplify"),
        entry("simplify.lazy", Type::boolean,
              "draw every shortcut the far rule cannot settle in one round, not round by round only those from "
              "vertices of the current shortest paths (the same result, more segments drawn)",
              "`true`", {}, {}, "exhaustive", "simplify", false),
        entry("simplify.shortcut_test", Type::choice,
              "which shortcuts a chain may take: `voronoi` those inside its own eps-Voronoi region, drawn with "
              "OpenGL (the paper), then the exact rules; `exact` the exact rules alone, on the CPU, with no OpenGL "
              "and no colouring: every shortcut that keeps the map planar and the points on their side, at every "
              "LOD and across partitions (fewer vertices; `simplification/README.md`); `auto` `voronoi` where a GPU "
              "draws it through EGL (or `--colors` is given), `exact` elsewhere, where the raster would run on "
              "llvmpipe at 2-4x the exact rules' time for the same guarantee. `--verbose` and the report "
              "(`shortcut_test`, `shortcut_test_choice`) say which ran and why; the pipeline decides once, on the "
              "machine that runs Snakemake, for every job",
              "`auto`", {}, {"auto", "voronoi", "exact"}, "shortcut-test", "simplify"),
        entry("simplify.compliance", Type::choice,
              "how the shortcuts' compliance is read back: `ssbo` sets a flag per shortcut in a storage buffer in one "
              "pass, `readback` is the paper's unique-colour loop (Algorithm 5.1); the same result",
              "`ssbo`", {}, {"ssbo", "readback"}, "compliance", "simplify"),
        entry("simplify.gl", Type::choice,
              "OpenGL backend: `auto` (a GPU through EGL where the machine has one, else OSMesa), `osmesa` "
              "(llvmpipe, everywhere) or `egl` (a GPU, or Mesa's device); the same result, bit for bit",
              "`auto`", {}, {"auto", "osmesa", "egl"}, "gl", "simplify"),
        entry("simplify.pixel_fraction", Type::number, "pixel size as a fraction of the smallest eps", "0.25",
              {0, 0.5, true}, {}, "pixel-fraction", both),
        entry("simplify.tile_pixels", Type::integer, "render tile width and height in pixels", "4096",
              integer(64, 16384), {}, "tile-pixels", both),
        entry("simplify.max_classes", Type::integer, "stencil classes per tile; a tile needing more is split", "255",
              integer(2, 255), {}, "max-classes", both),
        entry("simplify.window_pixels", Type::integer,
              "the framebuffer's width and height: a tile whose tested parts' box is larger is drawn in pieces of "
              "this size (the memory of the raster: 8 bytes a pixel)",
              "1024", integer(8, 16384), {}, "window-pixels", "simplify"),
        entry("simplify.threads", Type::integer, "worker threads, 0 for all cores; outputs do not depend on it", "0",
              thread_limits, {}, "threads", both),
        section("pack", "tigerlod-pack"),
        entry("pack.tile_mb", Type::number, "target tile file size in MiB: a subtree whose payloads fit is one tile",
              "4", {0, 4096, true}, {}, "tile-mb", "pack"),
        entry("pack.draco_speed", Type::integer,
              "Draco encoder speed, 0 (smallest) .. 10 (fastest); no effect on the size of our lossless integer "
              "payloads, measured",
              "0", integer(0, 10), {}, "draco-speed", "pack"),
        entry("pack.threads", Type::integer, "worker threads, 0 for all cores; outputs do not depend on it", "0",
              thread_limits, {}, "threads", "pack"),
        section("verify", "tigerlod-verify (the tolerance contract comes from the tree's manifest, not from here)"),
        entry("verify.max_items", Type::integer, "violations listed one by one at most (all are counted)", "10000",
              integer(0), {}, "max-items", "verify"),
        entry("verify.threads", Type::integer, "worker threads, 0 for all cores; the report does not depend on it", "0",
              thread_limits, {}, "threads", "verify"),
        section("synth",
                "tigerlod-synth: a synthetic nation in TIGER/Line 2020 format, EDGES and FACES per county "
                "(`stages/synth/README.md`); the pipeline runs it before ingest when the config has this section"),
        entry("synth.seed", Type::integer, "the seed: the same seed and keys give the same bytes", "1", integer(0, 1e9),
              {}, "seed", "synth"),
        entry("synth.states", Type::integer, "states, each a connected region of counties", "2", integer(1, 56), {},
              "states", "synth"),
        entry("synth.counties_per_state", Type::integer, "counties per state (fewer where a state has fewer cells)",
              "4", integer(1, 500), {}, "counties-per-state", "synth"),
        entry("synth.target_vertices", Type::integer,
              "vertices to aim at over every EDGES file, each edge counted once (the manifest says how many came)",
              "1000000", integer(1000, 1e9), {}, "target-vertices", "synth"),
        entry("synth.cell_m", Type::number, "the lattice's spacing on the ground, metres: faces are about this wide",
              "400", {20, 20000}, {}, "cell-m", "synth"),
        entry("synth.threads", Type::integer, "worker threads, 0 for all cores; outputs do not depend on it", "0",
              thread_limits, {}, "threads", "synth"),
        section("render", "tigerlod-render: the preview and the frame-time experiment at the end of the pipeline"),
        entry("render.path", Type::text,
              "the camera path: `zoom`, `pan`, `jumpy` (built in) or a keyframe file (`LON LAT METRES_PER_PIXEL "
              "[FRAMES]` a line)",
              "`zoom`", {}, {}, "path", "render"),
        entry("render.frames", Type::integer, "frames of a built-in path", "240", integer(2, 100000), {}, "frames",
              "render"),
        entry("render.mode", Type::choice,
              "which renderers run the path, one after the other (`none`: the two previews alone; the workflow's "
              "frame-time job is then left out)",
              "`all`", {}, {"all", "incore", "ooc-noprefetch", "ooc-prefetch", "none"}, "mode", "render"),
        entry("render.budget_mb", Type::number,
              "out of core: a hard limit on every byte the reader holds, the skeleton included (MiB)", "25",
              {0, 1e6, true}, {}, "budget-mb", "render"),
        entry("render.size", Type::viewport, "the viewport, `WIDTHxHEIGHT` pixels", "`1280x720`", integer(16, 16384),
              {}, "size", "render"),
        entry("render.fps", Type::number,
              "frames a second the camera moves at (each frame starts on its slot; 0: back to back)", "30", {0, 1000},
              {}, "fps", "render"),
        entry("render.disk_latency_ms", Type::number,
              "simulated disk: milliseconds a payload read waits (0: none). On by default: the page cache of a "
              "machine that just wrote the tree would hide its disk",
              "5", {0, 1e4}, {}, "disk-latency-ms", "render"),
        entry("render.disk_mbps", Type::number, "simulated disk: MB/s a payload is read at (0: no limit)", "50",
              {0, 1e6}, {}, "disk-mbps", "render"),
        entry("render.gl", Type::choice,
              "OpenGL backend: `auto` (a GPU through EGL where the machine has one, else OSMesa, as simplify "
              "chooses; `--verbose` and the summary's `gl` say which ran and why), `osmesa` (llvmpipe) or `egl`",
              "`auto`", {}, {"auto", "osmesa", "egl"}, "gl", "render"),
    };
}

std::vector<Key> make_keys()
{
    auto keys = input_keys();
    for (auto& k : stage_keys()) {
        keys.push_back(std::move(k));
    }
    return keys;
}

std::string type_text(const Key& k)
{
    switch (k.type) {
    case Type::text:
        return "text";
    case Type::choice:
        return choices_text(k.choices);
    case Type::integer:
        return k.limits.text().empty() ? "integer" : "integer " + k.limits.text();
    case Type::number:
        return k.limits.text().empty() ? "number" : "number " + k.limits.text();
    case Type::boolean:
        return "true or false";
    case Type::numbers:
        return "increasing numbers " + k.limits.text();
    case Type::class_map:
        return "class: number " + k.limits.text();
    case Type::path:
        return "file";
    case Type::paths:
        return "file or list of files";
    case Type::mapping:
        return "section";
    case Type::levels:
        return "list of levels";
    case Type::codes:
        return "code or list of codes";
    case Type::fields:
        return "list of attribute names";
    case Type::viewport:
        return "`WIDTHxHEIGHT`, each " + k.limits.text();
    }
    return {};
}

} // namespace

const std::vector<Key>& keys()
{
    static const std::vector<Key> table = make_keys();
    return table;
}

const Key* find(std::string_view name)
{
    const auto& t = keys();
    const auto it = std::find_if(t.begin(), t.end(), [&](const Key& k) { return k.name == name; });
    return it == t.end() ? nullptr : &*it;
}

const Key& key(std::string_view name)
{
    const Key* k = find(name);
    if (k == nullptr) {
        throw std::logic_error("config schema has no key '" + std::string(name) + "'");
    }
    return *k;
}

std::optional<std::pair<unsigned, unsigned>> parse_viewport(std::string_view text, const Limits& limits)
{
    // Digits, one 'x', digits: nothing else (no sign, space or suffix).
    const auto number = [&](std::string_view s) -> std::optional<unsigned> {
        if (s.empty() || s.size() > 9 ||
            !std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; })) {
            return std::nullopt;
        }
        const auto n = static_cast<unsigned>(std::stoul(std::string(s)));
        return limits.contains(n) ? std::optional<unsigned>(n) : std::nullopt;
    };
    const auto x = text.find('x');
    if (x == std::string_view::npos) {
        return std::nullopt;
    }
    const auto w = number(text.substr(0, x));
    const auto h = number(text.substr(x + 1));
    if (!w || !h) {
        return std::nullopt;
    }
    return std::pair{*w, *h};
}

void add_option(ArgSet& args, std::string_view name, ArgSet::Target target)
{
    const Key& k = key(name);
    std::string value_name;
    switch (k.type) {
    case Type::integer:
        value_name = "N";
        break;
    case Type::number:
        value_name = "X";
        break;
    case Type::numbers:
    case Type::class_map:
        value_name = "LIST";
        break;
    case Type::path:
        value_name = "FILE";
        break;
    case Type::choice:
        value_name = "NAME";
        break;
    case Type::text:
        value_name = "TEXT";
        break;
    case Type::viewport:
        value_name = "WxH";
        break;
    default:
        break;
    }
    std::string help;
    for (const char c : k.doc) {
        if (c != '`') {
            help += c;
        }
    }
    help += "\n      config: " + k.name;
    if (k.type == Type::boolean) {
        help += std::string(": ") + (k.flag_when ? "true" : "false");
    } else if (k.type == Type::choice) {
        help += ", one of " + choices_text(k.choices);
    } else if (!k.limits.text().empty()) {
        help += (k.type == Type::numbers || k.type == Type::viewport ? ", each " : ", ") + k.limits.text();
    }
    args.add(k.flag, target, help, value_name, k.type == Type::integer || k.type == Type::number ? k.limits : Limits{},
             k.type == Type::choice ? k.choices : std::vector<std::string>{});
}

std::string reference_markdown()
{
    std::ostringstream out;
    out << "# Config keys\n\n"
           "<!-- Generated from config/schema.cpp by scripts/config-doc; a test fails when they differ. -->\n\n"
           "A config is one YAML file. Relative paths are resolved against the config\n"
           "file's folder. Every key is checked when a config is read, by tigerlod-ingest\n"
           "(`--validate` checks without reading data) and by every stage given\n"
           "`--config FILE`: an unknown key, a value of the wrong type or out of range is\n"
           "an error (exit 2) naming the file, line and key.\n\n"
           "The stages take their section with `--config FILE` (tigerlod-color and\n"
           "tigerlod-simplify `simplify`, tigerlod-pack `pack`, tigerlod-verify `verify`,\n"
           "tigerlod-render `render`;\n"
           "tigerlod-ingest reads the whole file, its CONFIG argument); an option given on\n"
           "the command line wins over the config's (a `false` that became a flag, like\n"
           "`projection_scale: false` as `--no-projection-scale`, stays). The pipeline\n"
           "passes the config to every stage and nothing else. The column `option` names\n"
           "the stage option a key becomes.\n";
    const std::string header = "| key | meaning | values | default | option |\n|---|---|---|---|---|\n";
    out << "\n## Top level\n\n" << header;
    for (const Key& k : keys()) {
        if (k.type == Type::mapping && k.name.find('.') == std::string::npos) {
            out << "\n## `" << k.name << "`: " << k.doc << "\n\n" << header;
            continue;
        }
        const std::string when = k.type == Type::boolean && !k.flag.empty()
                                     ? std::string("`") + (k.flag_when ? "true" : "false") + "`: "
                                     : std::string();
        out << "| `" << k.name << "` | " << when << k.doc << " | " << type_text(k) << " | " << k.default_text << " | ";
        if (!k.flag.empty()) {
            out << "`--" << k.flag << "`";
        }
        out << " |\n";
    }
    out << "\nPartitions: level k is partitioned by the units of level k-1 (tracts by\n"
           "county); the top level is one partition, `all`. A chain between two partitions\n"
           "belongs to the one with the smaller code and is in the other's halo. A `lines`\n"
           "dataset is partitioned by grid tiles (`ingest.line_tile_km`).\n\n"
           "The Data Tree goes to `out/<name>/tree/` and is updated in place on the next\n"
           "run: tiles whose content did not change are kept, the skeleton is swapped\n"
           "atomically, and tiles the new skeleton no longer names are removed.\n";
    return out.str();
}

} // namespace tigerlod::config
