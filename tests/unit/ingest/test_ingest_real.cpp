// Invariants on real data from ../shared/data (skipped with a reason when absent)
// and on the default dataset (us-atlas, fetched by scripts/test into .cache/).
#include "core/errors.hpp"
#include "stages/ingest/config.hpp"
#include "stages/ingest/map_builder.hpp"
#include "stages/ingest/regions.hpp"
#include "stages/ingest/sources.hpp"
#include "../../support/sanitizers.hpp"

#include <gdal.h>
#include <ogr_api.h>

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <tuple>
#include <set>

namespace fs = std::filesystem;
using namespace tigerlod;
using namespace tigerlod::ingest;

namespace {

const fs::path source_dir = TIGERLOD_SOURCE_DIR;
const fs::path shared_data = source_dir.parent_path() / "shared" / "data";

struct Ingested {
    BuildResult result;
    std::vector<chains::ChainStore> stores;
    size_t finest_units = 0;
};

Ingested run_ingest(const fs::path& config, unsigned threads = 2)
{
    const IngestConfig cfg = load_config(config);
    Log log;
    RawMap raw = read_dataset(cfg, threads, log);
    Ingested run;
    run.finest_units = raw.units.size();
    BuildOptions o;
    o.halo_m = cfg.halo_m;
    o.threads = threads;
    std::mutex m; // the sink runs on several threads
    run.result = build_map(std::move(raw), Projection(cfg.projection), o, [&](const chains::ChainStore& s) {
        std::lock_guard lock(m);
        run.stores.push_back(s);
    });
    std::sort(run.stores.begin(), run.stores.end(), [](const auto& x, const auto& y) {
        return std::tie(x.level_index, x.partition) < std::tie(y.level_index, y.partition);
    });
    return run;
}

std::map<std::string, uint64_t> units_per_level(const Ingested& r)
{
    std::map<std::string, uint64_t> out;
    for (const auto& l : r.result.levels) {
        out[l.name] = l.units;
    }
    return out;
}

/// Every constraint point strictly inside its unit, by an exact test against the
/// store's own chains (halo included: a unit's border may belong to a neighbour
/// partition); every unit of each partition has exactly one point. And the
/// partition contract's points: every unit an owned chain bounds has its point
/// in the store, a neighbour's (kind 2) the very point its own store holds.
void expect_points_inside(const Ingested& r)
{
    size_t checked = 0;
    std::map<std::string, GridPoint> own_point; // level/unit -> its internal point
    for (const auto& s : r.stores) {
        for (const auto& cp : s.constraints) {
            if (cp.kind == chains::constraint_internal) {
                own_point[s.level_name + "/" + s.strings[cp.unit]] = cp.p;
            }
        }
    }
    size_t neighbours = 0;
    for (const auto& s : r.stores) {
        std::set<uint32_t> seen;
        for (const auto& cp : s.constraints) {
            EXPECT_TRUE(seen.insert(cp.unit).second) << s.level_name << " " << s.strings[cp.unit];
            if (cp.kind == chains::constraint_neighbour) {
                const auto it = own_point.find(s.level_name + "/" + s.strings[cp.unit]);
                ASSERT_NE(it, own_point.end()) << s.level_name << "/" << s.partition << " " << s.strings[cp.unit];
                EXPECT_EQ(it->second, cp.p) << s.level_name << "/" << s.partition << " " << s.strings[cp.unit];
                ++neighbours;
                continue;
            }
            EXPECT_EQ(chains::unit_location(s, cp.unit, cp.p), PointLocation::inside)
                << s.level_name << "/" << s.partition << " unit " << s.strings[cp.unit];
            ++checked;
        }
        for (const auto& c : s.chains) {
            for (const uint32_t side : {c.left, c.right}) {
                if (!(c.flags & chains::chain_halo) && side != 0) {
                    EXPECT_TRUE(seen.count(side)) << s.level_name << "/" << s.partition << ": chain " << c.id
                                                  << " bounds " << s.strings[side] << ", whose point is missing";
                }
            }
        }
    }
    uint64_t neighbour_points = 0;
    for (const auto& l : r.result.levels) {
        neighbour_points += l.neighbour_points;
    }
    EXPECT_EQ(neighbours, neighbour_points);
    uint64_t units = 0;
    for (const auto& l : r.result.levels) {
        units += l.units;
    }
    EXPECT_EQ(checked, units);
}

void expect_no_topology_problems(const Ingested& r)
{
    for (const char* kind : {"crossings", "touches", "overlaps", "overlapping_polygons", "non_nesting_units",
                             "missing_internal_points", "degenerate_polylines"}) {
        EXPECT_EQ(r.result.problems.at(kind), 0U) << kind;
    }
    for (const auto& s : r.stores) {
        for (const auto& c : s.chains) {
            EXPECT_EQ(c.flags & chains::chain_problem, 0U) << s.level_name << " chain " << c.id;
        }
    }
}

/// Distinct values of `field` (cut to each prefix length) over the features of the layers in `zips`.
std::vector<size_t> distinct_prefixes(const std::vector<fs::path>& zips, const char* field,
                                      const std::vector<size_t>& prefixes)
{
    GDALAllRegister();
    std::vector<std::set<std::string>> sets(prefixes.size());
    for (const auto& z : zips) {
        GDALDatasetH ds = GDALOpenEx(("/vsizip/" + z.string()).c_str(), GDAL_OF_VECTOR, nullptr, nullptr, nullptr);
        EXPECT_NE(ds, nullptr) << z;
        if (ds == nullptr) {
            continue;
        }
        OGRLayerH layer = GDALDatasetGetLayer(ds, 0);
        const int fi = OGR_FD_GetFieldIndex(OGR_L_GetLayerDefn(layer), field);
        OGRFeatureH f;
        while ((f = OGR_L_GetNextFeature(layer)) != nullptr) {
            const std::string v = OGR_F_GetFieldAsString(f, fi);
            for (size_t i = 0; i < prefixes.size(); ++i) {
                sets[i].insert(v.substr(0, prefixes[i]));
            }
            OGR_F_Destroy(f);
        }
        GDALClose(ds);
    }
    std::vector<size_t> out;
    for (const auto& s : sets) {
        out.push_back(s.size());
    }
    return out;
}

} // namespace

TEST(IngestReal, FloydCountyLevelsFacesAndPoints)
{
    if (!fs::exists(shared_data / "tiger" / "tl_2020_51063_edges.zip")) {
        GTEST_SKIP() << "../shared/data/tiger is absent: Floyd County tests need it";
    }
    const Ingested r = run_ingest(source_dir / "configs" / "floyd.yaml");
    EXPECT_EQ(units_per_level(r), (std::map<std::string, uint64_t>{
                                      {"state", 1}, {"county", 1}, {"tract", 5}, {"block_group", 12}, {"block", 709}}));
    // Every face is accounted for: all 3,086 read, each bounding some edge.
    EXPECT_EQ(r.finest_units, 3086U);
    EXPECT_EQ(r.result.problems.at("unreferenced_units"), 0U);
    EXPECT_EQ(r.result.input_vertices, 209304U);
    expect_no_topology_problems(r);
    expect_points_inside(r);
    // The county is one closed ring at the county level.
    EXPECT_EQ(r.result.levels[1].chains, 1U);
    EXPECT_EQ(r.result.levels[1].rings, 1U);
}

TEST(IngestReal, FloydIsByteIdenticalAcrossThreadCounts)
{
    if (!fs::exists(shared_data / "tiger" / "tl_2020_51063_edges.zip")) {
        GTEST_SKIP() << "../shared/data/tiger is absent: Floyd County tests need it";
    }
    auto bytes = [](const Ingested& r) {
        std::string all;
        for (const auto& s : r.stores) {
            all += chains::encode(s);
        }
        return all;
    };
    EXPECT_EQ(bytes(run_ingest(source_dir / "configs" / "floyd.yaml", 1)),
              bytes(run_ingest(source_dir / "configs" / "floyd.yaml", 2)));
}

TEST(IngestReal, TwentyStateTracts)
{
    const fs::path dir = shared_data / "tiger" / "tracts2010";
    if (!fs::exists(dir)) {
        GTEST_SKIP() << "../shared/data/tiger/tracts2010 is absent: the 20-state tract test needs it";
    }
    std::vector<fs::path> zips;
    for (const auto& e : fs::directory_iterator(dir)) {
        zips.push_back(e.path());
    }
    ASSERT_EQ(zips.size(), 20U);
    const auto want = distinct_prefixes(zips, "GEOID10", {2, 5, 11});
    const Ingested r = run_ingest(source_dir / "configs" / "tracts2010.yaml");
    EXPECT_EQ(units_per_level(r), (std::map<std::string, uint64_t>{
                                      {"nation", 1}, {"state", want[0]}, {"county", want[1]}, {"tract", want[2]}}));
    EXPECT_EQ(want[2], 6606U);
    EXPECT_EQ(r.result.input_vertices, 3807105U);
    // One vertex of a Kansas tract (20051072600) lies 0.2 cm from a segment it is pushed across by the
    // 1 cm grid; the repair drops the 1e-6 degree stub next to it (a 0.11 m move).
    EXPECT_EQ(r.result.problems.at("snap_repairs"), 1U);
    expect_no_topology_problems(r);
    expect_points_inside(r);
}

namespace {

/// A build region by region, as the stage does it: each part read once and
/// put aside on disk, read back by the regions that need it.
struct Regional {
    BuildResult result;
    std::map<std::string, std::string> stores; // level/partition -> encoded
};

Regional run_by_regions(const fs::path& config)
{
    const IngestConfig cfg = load_config(config);
    const fs::path aside = fs::temp_directory_path() / ("tigerlod-regions-test-" + std::to_string(::getpid()));
    fs::create_directories(aside);
    auto part_path = [&](size_t i) { return aside / (std::to_string(i) + ".raw"); };
    const bool tiger = cfg.dataset.kind == DatasetSpec::Kind::tiger;
    std::vector<PartSummary> parts(tiger ? cfg.dataset.faces.size() : cfg.dataset.inputs.size());
    const auto put_aside = [&](size_t i, RawMap&& part) {
        parts[i] = summarize_part(part);
        write_raw(part, part_path(i));
    };
    Log log;
    if (tiger) {
        read_tiger_parts(cfg, 2, log, put_aside);
    } else {
        read_polygon_parts(cfg, 2, log, put_aside);
    }
    std::vector<std::string> names;
    for (const auto& l : cfg.levels) {
        names.push_back(l.name);
    }
    BuildOptions o;
    o.halo_m = cfg.halo_m;
    o.threads = 2;
    std::mutex m;
    Regional out;
    out.result = build_by_regions(
        parts, [&](size_t i) { return read_raw(part_path(i)); }, names, Projection(cfg.projection), o,
        [&](const chains::ChainStore& s) {
            const std::lock_guard lock(m);
            out.stores[s.level_name + "/" + s.partition] = chains::encode(s);
        });
    fs::remove_all(aside);
    return out;
}

/// The same stores byte for byte, the same report.
void expect_same(const Regional& got, const Ingested& whole)
{
    const BuildResult& r = got.result;
    ASSERT_EQ(got.stores.size(), whole.stores.size());
    for (const auto& s : whole.stores) {
        const std::string name = s.level_name + "/" + s.partition;
        ASSERT_TRUE(got.stores.count(name)) << name;
        EXPECT_TRUE(got.stores.at(name) == chains::encode(s)) << name;
    }
    EXPECT_EQ(r.problems, whole.result.problems);
    ASSERT_EQ(r.samples.size(), whole.result.samples.size());
    for (size_t i = 0; i < r.samples.size(); ++i) {
        EXPECT_EQ(r.samples[i].where, whole.result.samples[i].where);
    }
    EXPECT_EQ(r.input_vertices, whole.result.input_vertices);
    EXPECT_EQ(r.unique_vertices, whole.result.unique_vertices);
    EXPECT_EQ(r.edges, whole.result.edges);
    ASSERT_EQ(r.levels.size(), whole.result.levels.size());
    for (size_t L = 0; L < r.levels.size(); ++L) {
        const auto& a = r.levels[L];
        const auto& b = whole.result.levels[L];
        EXPECT_EQ(std::tie(a.units, a.chains, a.rings, a.vertices, a.junctions, a.partitions, a.halo_chains,
                           a.constraint_points, a.computed_internal_points),
                  std::tie(b.units, b.chains, b.rings, b.vertices, b.junctions, b.partitions, b.halo_chains,
                           b.constraint_points, b.computed_internal_points))
            << a.name;
    }
}

bool built_by_regions(const BuildResult& r)
{
    return std::any_of(r.seconds.begin(), r.seconds.end(), [](const auto& p) { return p.first == "regions_load"; });
}

/// Floyd County's FACES and EDGES split into made-up counties as TIGER splits
/// a state: tract t's faces go to county 901 + t % 3 (COUNTYFP20 rewritten),
/// and each edge to the file of every county with a face on one of its sides,
/// so an edge on a county border is in both files. Shapefiles in `dir`; the
/// config lists the counties' FACES in order and their EDGES in `edge_order`.
/// With `blocks`, the config's levels are state > county > block and its halo
/// 100 m: a region then takes only part of its neighbours (the blocks near its
/// own and those that share a point with them), not every tract of theirs.
fs::path split_floyd(const fs::path& dir, const std::vector<int>& edge_order, bool blocks = false)
{
    GDALAllRegister();
    fs::create_directories(dir);
    auto open = [](const fs::path& zip) {
        GDALDatasetH ds = GDALOpenEx(("/vsizip/" + zip.string()).c_str(), GDAL_OF_VECTOR, nullptr, nullptr, nullptr);
        EXPECT_NE(ds, nullptr) << zip;
        return ds;
    };
    GDALDriverH shp = GDALGetDriverByName("ESRI Shapefile");
    // One output layer per county with the input's fields.
    auto create = [&](OGRLayerH in, const std::string& name, std::vector<GDALDatasetH>& out) {
        std::vector<OGRLayerH> layers;
        for (int c = 0; c < 3; ++c) {
            const fs::path path = dir / (name + "_" + std::to_string(901 + c) + ".shp");
            GDALDatasetH ds = GDALCreate(shp, path.c_str(), 0, 0, 0, GDT_Unknown, nullptr);
            OGRLayerH l = GDALDatasetCreateLayer(ds, path.stem().c_str(), OGR_L_GetSpatialRef(in),
                                                 OGR_FD_GetGeomType(OGR_L_GetLayerDefn(in)), nullptr);
            OGRFeatureDefnH defn = OGR_L_GetLayerDefn(in);
            for (int i = 0; i < OGR_FD_GetFieldCount(defn); ++i) {
                OGR_L_CreateField(l, OGR_FD_GetFieldDefn(defn, i), 1);
            }
            out.push_back(ds);
            layers.push_back(l);
        }
        return layers;
    };
    auto copy_to = [](OGRLayerH to, OGRFeatureH f) {
        OGRFeatureH g = OGR_F_Create(OGR_L_GetLayerDefn(to));
        OGR_F_SetFrom(g, f, 1);
        EXPECT_EQ(OGR_L_CreateFeature(to, g), OGRERR_NONE);
        OGR_F_Destroy(g);
    };
    std::map<int64_t, int> county_of_face;
    std::vector<GDALDatasetH> outs;
    {
        GDALDatasetH in = open(shared_data / "tiger" / "tl_2020_51063_faces.zip");
        OGRLayerH layer = GDALDatasetGetLayer(in, 0);
        const auto out = create(layer, "faces", outs);
        OGRFeatureDefnH defn = OGR_L_GetLayerDefn(layer);
        const int tfid = OGR_FD_GetFieldIndex(defn, "TFID");
        const int county = OGR_FD_GetFieldIndex(defn, "COUNTYFP20");
        const int tract = OGR_FD_GetFieldIndex(defn, "TRACTCE20");
        std::map<std::string, int> tract_index;
        OGRFeatureH f;
        while ((f = OGR_L_GetNextFeature(layer)) != nullptr) {
            const std::string t = OGR_F_GetFieldAsString(f, tract);
            const int c = tract_index.emplace(t, static_cast<int>(tract_index.size())).first->second % 3;
            county_of_face[OGR_F_GetFieldAsInteger64(f, tfid)] = c;
            OGR_F_SetFieldString(f, county, std::to_string(901 + c).c_str());
            copy_to(out[static_cast<size_t>(c)], f);
            OGR_F_Destroy(f);
        }
        EXPECT_EQ(tract_index.size(), 5U);
        GDALClose(in);
    }
    {
        GDALDatasetH in = open(shared_data / "tiger" / "tl_2020_51063_edges.zip");
        OGRLayerH layer = GDALDatasetGetLayer(in, 0);
        const auto out = create(layer, "edges", outs);
        OGRFeatureDefnH defn = OGR_L_GetLayerDefn(layer);
        const int sides[2] = {OGR_FD_GetFieldIndex(defn, "TFIDL"), OGR_FD_GetFieldIndex(defn, "TFIDR")};
        OGRFeatureH f;
        while ((f = OGR_L_GetNextFeature(layer)) != nullptr) {
            std::set<int> counties;
            for (int i : sides) {
                if (auto it = county_of_face.find(OGR_F_GetFieldAsInteger64(f, i)); it != county_of_face.end()) {
                    counties.insert(it->second);
                }
            }
            EXPECT_FALSE(counties.empty());
            for (int c : counties) {
                copy_to(out[static_cast<size_t>(c)], f);
            }
            OGR_F_Destroy(f);
        }
        GDALClose(in);
    }
    for (GDALDatasetH ds : outs) {
        GDALClose(ds);
    }
    std::ifstream floyd(source_dir / "configs" / "floyd.yaml");
    std::string line, yaml;
    while (std::getline(floyd, line)) {
        if (line.rfind("  edges:", 0) == 0) {
            yaml += "  edges: [";
            for (size_t k = 0; k < edge_order.size(); ++k) {
                yaml += (k ? ", " : "") + (dir / ("edges_" + std::to_string(901 + edge_order[k]) + ".shp")).string();
            }
            yaml += "]\n";
        } else if (line.rfind("  faces:", 0) == 0) {
            yaml += "  faces: [" + (dir / "faces_901.shp").string() + ", " + (dir / "faces_902.shp").string() + ", " +
                    (dir / "faces_903.shp").string() + "]\n";
        } else if (blocks && line.rfind("  halo_m:", 0) == 0) {
            yaml += "  halo_m: 100\n";
        } else if (!blocks || (line.find("name: tract") == std::string::npos &&
                               line.find("name: block_group") == std::string::npos)) {
            yaml += line + "\n";
        }
    }
    const fs::path config = dir / "split.yaml";
    std::ofstream(config) << yaml;
    return config;
}

} // namespace

TEST(IngestReal, TwentyStateTractsRegionByRegionAreTheWholeBuild)
{
    if (!fs::exists(shared_data / "tiger" / "tracts2010")) {
        GTEST_SKIP() << "../shared/data/tiger/tracts2010 is absent: the 20-state tract test needs it";
    }
#if TIGERLOD_SANITIZED
    // 33 s under ASan: the Floyd splits below run the same region code
    // under the sanitizers; the dev pass runs the 20 states.
    GTEST_SKIP() << "under the sanitizers the Floyd splits run the region code; the dev pass runs the 20 states";
#endif
    const fs::path config = source_dir / "configs" / "tracts2010.yaml";
    const Regional r = run_by_regions(config);
    EXPECT_TRUE(built_by_regions(r.result));
    expect_same(r, run_ingest(config));
}

TEST(IngestReal, TigerCountiesRegionByRegionAreTheWholeBuild)
{
    if (!fs::exists(shared_data / "tiger" / "tl_2020_51063_edges.zip")) {
        GTEST_SKIP() << "../shared/data/tiger is absent: Floyd County tests need it";
    }
    const fs::path dir = fs::temp_directory_path() / ("tigerlod-split-test-" + std::to_string(::getpid()));
    const fs::path config = split_floyd(dir, {0, 1, 2});
    const Ingested whole = run_ingest(config);
    // Three counties of the made-up split: the region level is the county.
    EXPECT_EQ(units_per_level(whole),
              (std::map<std::string, uint64_t>{
                  {"state", 1}, {"county", 3}, {"tract", 5}, {"block_group", 12}, {"block", 709}}));
    EXPECT_EQ(whole.finest_units, 3086U);
    EXPECT_EQ(whole.result.input_vertices, 209304U); // each border edge once
    expect_no_topology_problems(whole);
    expect_points_inside(whole);
    const Regional r = run_by_regions(config);
    EXPECT_TRUE(built_by_regions(r.result));
    // Each county's neighbours come whole (their tracts are within reach).
    EXPECT_EQ(r.result.region_map_units, 3 * whole.finest_units);
    expect_same(r, whole);
    fs::remove_all(dir);
}

TEST(IngestReal, TigerCountiesRegionByRegionTakePartOfTheirNeighboursAndAreTheWholeBuild)
{
    if (!fs::exists(shared_data / "tiger" / "tl_2020_51063_edges.zip")) {
        GTEST_SKIP() << "../shared/data/tiger is absent: Floyd County tests need it";
    }
    const fs::path dir = fs::temp_directory_path() / ("tigerlod-split-blocks-test-" + std::to_string(::getpid()));
    const fs::path config = split_floyd(dir, {0, 1, 2}, true);
    const Ingested whole = run_ingest(config);
    EXPECT_EQ(units_per_level(whole), (std::map<std::string, uint64_t>{{"state", 1}, {"county", 3}, {"block", 709}}));
    expect_no_topology_problems(whole);
    const Regional r = run_by_regions(config);
    EXPECT_TRUE(built_by_regions(r.result));
    EXPECT_GT(r.result.region_map_units, whole.finest_units);
    EXPECT_LT(r.result.region_map_units, 3 * whole.finest_units - 500);
    expect_same(r, whole);
    fs::remove_all(dir);
}

TEST(IngestReal, TigerEdgesNotPairedWithTheirFacesAreBuiltWhole)
{
    if (!fs::exists(shared_data / "tiger" / "tl_2020_51063_edges.zip")) {
        GTEST_SKIP() << "../shared/data/tiger is absent: Floyd County tests need it";
    }
    // County 903's EDGES listed first: no part holds the faces of all its edges.
    const fs::path dir = fs::temp_directory_path() / ("tigerlod-unpaired-test-" + std::to_string(::getpid()));
    const fs::path config = split_floyd(dir, {2, 0, 1});
    const Regional r = run_by_regions(config);
    EXPECT_FALSE(built_by_regions(r.result));
    expect_same(r, run_ingest(config));
    fs::remove_all(dir);
}

TEST(IngestReal, DefaultDatasetUsAtlas)
{
    const fs::path file = source_dir / ".cache" / "npm" / "us-atlas-3.0.1" / "counties-10m.json";
    if (!fs::exists(file)) {
        GTEST_SKIP() << ".cache/npm/us-atlas-3.0.1 is absent: run scripts/fetch-npm us-atlas@3.0.1 "
                        ".cache/npm/us-atlas-3.0.1 (scripts/test does)";
    }
    const Ingested r = run_ingest(source_dir / "configs" / "demo.yaml");
    // 3,231 counties, one without geometry; 56 states and territories.
    EXPECT_EQ(r.result.problems.at("empty_geometries"), 1U);
    EXPECT_EQ(units_per_level(r), (std::map<std::string, uint64_t>{{"nation", 1}, {"state", 56}, {"county", 3230}}));
    EXPECT_EQ(r.result.problems.at("missing_internal_points"), 0U);
    expect_points_inside(r);
}

TEST(IngestReal, FloydLinearWaterAsALineLayerLosesNoSegment)
{
    const fs::path zip = shared_data / "tiger" / "tl_2020_51063_linearwater.zip";
    if (!fs::exists(zip)) {
        GTEST_SKIP() << "../shared/data/tiger is absent: the line layer test needs it";
    }
    const fs::path dir = fs::temp_directory_path() / ("tigerlod-test-linearwater-" + std::to_string(::getpid()));
    fs::create_directories(dir);
    std::ofstream(dir / "water.yaml") << "name: water\ndataset:\n  kind: lines\n  inputs: [" << zip.string()
                                      << "]\n  class_field: MTFCC\n";
    const Ingested r = run_ingest(dir / "water.yaml");
    fs::remove_all(dir);
    ASSERT_EQ(r.stores.size(), 1U);
    const auto& s = r.stores[0];
    // Every distinct input segment, as snapped and projected, is in exactly one chain.
    const IngestConfig cfg = [&] {
        IngestConfig c;
        c.dataset.kind = DatasetSpec::Kind::lines;
        c.dataset.inputs = {zip};
        c.levels = {{"lines", "", {}, -1}};
        return c;
    }();
    Log log;
    const RawMap raw = read_dataset(cfg, 1, log);
    const Projection proj(cfg.projection);
    std::set<std::pair<GridPoint, GridPoint>> input, output;
    for (size_t p = 0; p < raw.polyline_count(); ++p) {
        for (uint64_t k = raw.offsets[p]; k + 1 < raw.offsets[p + 1]; ++k) {
            const auto a = *proj.to_grid(raw.coords[k].lon * 1e-6, raw.coords[k].lat * 1e-6);
            const auto b = *proj.to_grid(raw.coords[k + 1].lon * 1e-6, raw.coords[k + 1].lat * 1e-6);
            if (a != b) {
                input.insert(std::minmax(a, b));
            }
        }
    }
    size_t segments = 0;
    for (const auto& c : s.chains) {
        const auto pts = s.chain_points(c);
        EXPECT_EQ((c.flags & chains::chain_closed) != 0, pts.front() == pts.back());
        for (size_t k = 0; k + 1 < pts.size(); ++k) {
            EXPECT_TRUE(output.insert(std::minmax(pts[k], pts[k + 1])).second) << "segment in two chains";
            ++segments;
        }
    }
    // Nothing in this layer needs a repair (a spike or a snap repair would
    // change segments, and was a silent skip of the next check before).
    EXPECT_EQ(r.result.problems.at("spikes"), 0U);
    EXPECT_EQ(r.result.problems.at("snap_repairs"), 0U);
    EXPECT_EQ(output, input);
    EXPECT_EQ(segments, output.size());
    EXPECT_GT(r.result.levels[0].chains, 100U);
    for (const auto& j : s.junctions) {
        EXPECT_NE(j.degree, 2U);
    }
}
