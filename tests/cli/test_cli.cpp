// The executables as a user runs them: --help, success writing nothing to
// stderr, determinism, and every kind of bad input failing with the
// documented exit code, a message naming the file and fault, and nothing
// half-written.
#include "config/schema.hpp"
#include "formats/chains/chain_store.hpp"
#include "gl/context.hpp"
#include "../support/processes.hpp"

#include <cpl_conv.h>
#include <gdal.h>
#include <ogr_api.h>
#include <ogr_srs_api.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <sys/wait.h>

namespace fs = std::filesystem;

namespace {

const fs::path bin_dir = TIGERLOD_BIN_DIR;

struct Result {
    int code = -1;
    std::string out, err;
};

std::string slurp(const fs::path& p)
{
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

class Cli : public ::testing::Test {
  protected:
    void SetUp() override
    {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        // The process id too: two builds' tests (a clone's CI beside a
        // checkout's) must not share a folder.
        m_dir = fs::temp_directory_path() /
                (std::string("tigerlod-cli-") + info->name() + "-" + std::to_string(::getpid()));
        fs::remove_all(m_dir);
        fs::create_directories(m_dir);
        GDALAllRegister();
    }
    void TearDown() override { fs::remove_all(m_dir); }

    Result run(const std::string& tool, const std::string& args)
    {
        const std::string cmd = (bin_dir / ("tigerlod-" + tool)).string() + " " + args + " >" +
                                (m_dir / "stdout").string() + " 2>" + (m_dir / "stderr").string();
        const int status = std::system(cmd.c_str());
        Result r;
        r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
        r.out = slurp(m_dir / "stdout");
        r.err = slurp(m_dir / "stderr");
        return r;
    }

    /// Write a shapefile of `type` with the given fields and features (WKT, then one value per field).
    void write_shp(const fs::path& path, OGRwkbGeometryType type, const std::vector<std::string>& fields,
                   const std::vector<std::vector<std::string>>& features,
                   const std::map<std::string, OGRFieldType>& types = {})
    {
        GDALDriverH drv = GDALGetDriverByName("ESRI Shapefile");
        GDALDatasetH ds = GDALCreate(drv, path.c_str(), 0, 0, 0, GDT_Unknown, nullptr);
        ASSERT_NE(ds, nullptr);
        OGRSpatialReferenceH srs = OSRNewSpatialReference(nullptr);
        OSRImportFromEPSG(srs, 4269);
        OSRSetAxisMappingStrategy(srs, OAMS_TRADITIONAL_GIS_ORDER);
        OGRLayerH layer = GDALDatasetCreateLayer(ds, path.stem().c_str(), srs, type, nullptr);
        for (const auto& f : fields) {
            const bool is_int = f == "TLID" || f == "TFIDL" || f == "TFIDR" || f == "TFID";
            const auto given = types.find(f);
            OGRFieldDefnH fd = OGR_Fld_Create(f.c_str(), given != types.end() ? given->second
                                                         : is_int             ? OFTInteger64
                                                                              : OFTString);
            ASSERT_EQ(OGR_L_CreateField(layer, fd, TRUE), OGRERR_NONE);
            OGR_Fld_Destroy(fd);
        }
        for (const auto& values : features) {
            OGRFeatureH feat = OGR_F_Create(OGR_L_GetLayerDefn(layer));
            OGRGeometryH g = nullptr;
            char* wkt = const_cast<char*>(values[0].c_str());
            OGR_G_CreateFromWkt(&wkt, srs, &g);
            OGR_F_SetGeometryDirectly(feat, g);
            for (size_t i = 1; i < values.size(); ++i) {
                OGR_F_SetFieldString(feat, static_cast<int>(i - 1), values[i].c_str());
            }
            ASSERT_EQ(OGR_L_CreateFeature(layer, feat), OGRERR_NONE);
            OGR_F_Destroy(feat);
        }
        OSRDestroySpatialReference(srs);
        GDALClose(ds);
    }

    /// Zip the files of a shapefile (or any files) into `zip`.
    void zip(const fs::path& zip_path, const std::vector<fs::path>& files)
    {
        void* z = CPLCreateZip(zip_path.c_str(), nullptr);
        ASSERT_NE(z, nullptr);
        for (const auto& f : files) {
            const std::string data = slurp(f);
            CPLCreateFileInZip(z, f.filename().c_str(), nullptr);
            CPLWriteFileInZip(z, data.data(), static_cast<int>(data.size()));
            CPLCloseFileInZip(z);
        }
        CPLCloseZip(z);
    }
    std::vector<fs::path> shp_files(const fs::path& shp)
    {
        std::vector<fs::path> out;
        for (const char* ext : {".shp", ".shx", ".dbf", ".prj"}) {
            out.push_back(fs::path(shp).replace_extension(ext));
        }
        return out;
    }

    /// A county of three faces (A; B1 north of B2) as TIGER EDGES and FACES zips.
    /// A small TIGER county as EDGES and FACES shapefiles, zipped; `types`
    /// overrides the type of named fields (TLID stored as text, ...).
    void make_tiger(const std::string& tag = "", const std::map<std::string, OGRFieldType>& types = {})
    {
        auto p = [](double x, double y) {
            std::ostringstream o;
            o.precision(10);
            o << (-96.0 + 0.001 * x) << " " << (40.0 + 0.001 * y);
            return o.str();
        };
        auto line = [&](std::initializer_list<std::pair<double, double>> pts) {
            std::string s = "LINESTRING (";
            for (auto [x, y] : pts) {
                if (s.back() != '(') {
                    s += ',';
                }
                s += p(x, y);
            }
            return s + ")";
        };
        const std::vector<std::string> ef = {"TLID", "TFIDL", "TFIDR", "MTFCC"};
        m_edges = {{line({{0, 0}, {1, 0}}), "1", "101", "900", "F"}, {line({{1, 0}, {2, 0}}), "2", "103", "900", "F"},
                   {line({{2, 0}, {2, 1}}), "3", "103", "900", "F"}, {line({{2, 1}, {2, 2}}), "4", "102", "900", "F"},
                   {line({{2, 2}, {1, 2}}), "5", "102", "900", "F"}, {line({{1, 2}, {0, 2}}), "6", "101", "900", "F"},
                   {line({{0, 2}, {0, 0}}), "7", "101", "900", "F"}, {line({{1, 0}, {1, 1}}), "8", "101", "103", "F"},
                   {line({{1, 1}, {1, 2}}), "9", "101", "102", "F"}, {line({{1, 1}, {2, 1}}), "10", "102", "103", "F"}};
        write_shp(m_dir / ("edges" + tag + ".shp"), wkbLineString, ef, m_edges, types);
        auto poly = [&](double x0, double y0, double x1, double y1) {
            return "POLYGON ((" + p(x0, y0) + "," + p(x0, y1) + "," + p(x1, y1) + "," + p(x1, y0) + "," + p(x0, y0) +
                   "))";
        };
        m_faces = {{poly(0, 0, 1, 2), "101", "51", "063", "920100", "1", "1000", "+40.0010", "-095.9995", "5"},
                   {poly(1, 1, 2, 2), "102", "51", "063", "920200", "1", "1001", "+40.0015", "-095.9985", "5"},
                   {poly(1, 0, 2, 1), "103", "51", "063", "920200", "2", "2000", "+40.0005", "-095.9985", "5"}};
        write_shp(m_dir / ("faces" + tag + ".shp"), wkbPolygon, m_face_fields, m_faces, types);
        zip(m_dir / ("edges" + tag + ".zip"), shp_files(m_dir / ("edges" + tag + ".shp")));
        zip(m_dir / ("faces" + tag + ".zip"), shp_files(m_dir / ("faces" + tag + ".shp")));
    }

    fs::path config(const std::string& body)
    {
        const fs::path p = m_dir / "config.yaml";
        std::ofstream(p) << "name: t\n" << body;
        return p;
    }
    fs::path tiger_config(const std::string& edges = "edges.zip", const std::string& faces = "faces.zip",
                          const std::string& extra = "")
    {
        return config("dataset:\n  kind: tiger\n  edges: [" + edges + "]\n  faces: [" + faces + "]\n" + extra);
    }

    /// A failure: the code, a message fragment, nothing in or beside the output folder.
    void expect_failure(const Result& r, int code, const std::string& fragment)
    {
        EXPECT_EQ(r.code, code) << r.err;
        EXPECT_NE(r.err.find(fragment), std::string::npos) << "stderr: " << r.err;
        EXPECT_NE(r.err.find("tigerlod-"), std::string::npos) << r.err;
        EXPECT_FALSE(fs::exists(m_dir / "out"));
        for (const auto& e : fs::directory_iterator(m_dir)) {
            EXPECT_EQ(e.path().filename().string().find("out.tmp-"), std::string::npos) << e.path();
        }
    }
    std::string out() const { return (m_dir / "out").string(); }

    fs::path m_dir;
    std::vector<std::vector<std::string>> m_edges; ///< WKT, TLID, TFIDL, TFIDR, MTFCC
    std::vector<std::vector<std::string>> m_faces; ///< WKT, then m_face_fields
    const std::vector<std::string> m_face_fields = {"TFID",      "STATEFP20", "COUNTYFP20", "TRACTCE20", "BLKGRPCE20",
                                                    "BLOCKCE20", "INTPTLAT",  "INTPTLON",   "ATOTAL"};
};

} // namespace

TEST_F(Cli, HelpAndVersion)
{
    // Every tool: help, its library and format versions, and errors named
    // once ("tigerlod-pack: ...", not "tigerlod-pack: pack: ...").
    const std::map<std::string, std::vector<std::string>> versions = {
        {"ingest", {"GDAL ", "GeographicLib ", "chain store format "}},
        {"dump", {"chain store format ", "Data Tree format "}},
        {"color", {"GeographicLib ", "chain store format "}},
        {"simplify", {"OSMesa API ", "GeographicLib ", "chain store format "}},
        {"pack", {"Draco ", "chain store format ", "Data Tree format "}},
        {"export", {"GDAL ", "Data Tree format "}},
        {"verify", {"GDAL ", "GeographicLib ", "chain store format ", "Data Tree format "}},
        {"synth", {"GDAL ", "zlib "}},
        {"serve", {"cpp-httplib ", "Data Tree format "}}};
    for (const auto& [tool, libs] : versions) {
        SCOPED_TRACE(tool);
        const Result h = run(tool, "--help");
        EXPECT_EQ(h.code, 0);
        EXPECT_EQ(h.out.rfind("Usage: tigerlod-" + tool, 0), 0U) << h.out;
        EXPECT_NE(h.out.find("Exit codes: 0"), std::string::npos);
        EXPECT_TRUE(h.err.empty());
        const Result v = run(tool, "--version");
        EXPECT_EQ(v.code, 0);
        EXPECT_EQ(v.out.rfind("tigerlod-" + tool + " 0.1.0\n", 0), 0U) << v.out;
        for (const auto& lib : libs) {
            EXPECT_NE(v.out.find("\n  " + lib), std::string::npos) << lib << " in " << v.out;
        }
        expect_failure(run(tool, "--no-such-option"), 2, "unknown option '--no-such-option'");
        const Result bad = run(tool, "--no-such-option");
        EXPECT_EQ(bad.err.find("tigerlod-" + tool + ": " + tool + ": "), std::string::npos) << bad.err;
    }
    expect_failure(run("ingest", ""), 2, "missing argument CONFIG");
}

TEST_F(Cli, EveryStageSucceedsWritingNothingToStderr)
{
    make_tiger();
    const std::string in = (m_dir / "in").string(), colors = (m_dir / "colors").string(),
                      simp = (m_dir / "simp").string(), tree = (m_dir / "tree").string();
    const std::vector<std::pair<std::string, std::string>> runs = {
        {"ingest", tiger_config().string() + " " + in},
        {"color", in + " " + colors + " --tolerances 8"},
        {"simplify", in + " " + simp + " --tolerances 8 --colors " + colors},
        {"pack", in + " " + simp + " " + tree},
        {"verify", tree + " " + in + " " + (m_dir / "verify").string()},
        {"export", tree + " " + (m_dir / "x.gpkg").string() + " --level tract"},
        {"dump", tree + " --node 51063"}};
    for (const auto& [tool, args] : runs) {
        const Result r = run(tool, args);
        EXPECT_EQ(r.code, 0) << tool << ": " << r.err;
        EXPECT_TRUE(r.err.empty()) << tool << ": " << r.err;
        EXPECT_FALSE(r.out.empty()) << tool;
    }
}

TEST_F(Cli, IngestSucceedsQuietlyAndDeterministically)
{
    make_tiger();
    const auto cfg = tiger_config();
    const Result r = run("ingest", cfg.string() + " " + out() + " --threads 1");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(r.err.empty()) << r.err;
    EXPECT_NE(r.out.find("problems: none"), std::string::npos) << r.out;
    for (const char* f : {"ingest-report.json", "manifest.json", "ingest-timings.json", "state/all.tlc",
                          "tract/51063.tlc", "block/510639202001.tlc"}) {
        EXPECT_TRUE(fs::exists(m_dir / "out" / f)) << f;
    }
    const std::string report = slurp(m_dir / "out" / "ingest-report.json");
    EXPECT_NE(report.find("\"crossings\": 0"), std::string::npos);
    // Same inputs, other thread count: byte-identical outputs (timings aside).
    const Result again = run("ingest", cfg.string() + " " + (m_dir / "out2").string() + " --threads 2");
    ASSERT_EQ(again.code, 0);
    for (const auto& e : fs::recursive_directory_iterator(m_dir / "out")) {
        if (e.is_regular_file() && e.path().filename() != "ingest-timings.json") {
            const auto rel = fs::relative(e.path(), m_dir / "out");
            EXPECT_EQ(slurp(e.path()), slurp(m_dir / "out2" / rel)) << rel;
        }
    }
    // An existing output is kept unless --overwrite.
    const Result exists = run("ingest", cfg.string() + " " + out());
    EXPECT_EQ(exists.code, 2);
    EXPECT_NE(exists.err.find("exists. Use --overwrite to replace it."), std::string::npos);
    EXPECT_EQ(run("ingest", cfg.string() + " " + out() + " --overwrite").code, 0);
    // dump prints a store as sorted text.
    const Result d = run("dump", (m_dir / "out" / "tract" / "51063.tlc").string());
    EXPECT_EQ(d.code, 0);
    EXPECT_EQ(d.out.rfind("chain-store 1.3\nlevel 2/5 tract\npartition 51063\n", 0), 0U) << d.out;
}

TEST_F(Cli, MissingInputFile)
{
    make_tiger();
    expect_failure(run("ingest", tiger_config("nope.zip").string() + " " + out()), 2, "nope.zip: no such file");
    expect_failure(run("ingest", (m_dir / "no-config.yaml").string() + " " + out()), 2, "no such config file");
}

TEST_F(Cli, ZipWithoutTheExpectedLayer)
{
    make_tiger();
    std::ofstream(m_dir / "readme.txt") << "not a shapefile\n";
    zip(m_dir / "empty.zip", {m_dir / "readme.txt"});
    expect_failure(run("ingest", tiger_config("empty.zip").string() + " " + out()), 1,
                   "empty.zip: cannot open as a vector dataset (TIGER EDGES)");
    // The FACES zip given as EDGES: a layer of the wrong kind.
    expect_failure(run("ingest", tiger_config("faces.zip").string() + " " + out()), 1,
                   "faces.zip layer 'faces': geometry type is Polygon, TIGER EDGES need line strings");
}

TEST_F(Cli, WrongGeometryType)
{
    make_tiger();
    write_shp(m_dir / "points.shp", wkbPoint, {"TLID", "TFIDL", "TFIDR"}, {{"POINT (-96 40)", "1", "2", "3"}});
    zip(m_dir / "points.zip", shp_files(m_dir / "points.shp"));
    expect_failure(run("ingest", tiger_config("points.zip").string() + " " + out()), 1,
                   "layer 'points': geometry type is Point, TIGER EDGES need line strings");
}

TEST_F(Cli, FacesWithoutAConfiguredAttribute)
{
    make_tiger();
    const auto cfg = tiger_config("edges.zip", "faces.zip", "levels:\n  - {name: district, fields: [VTDST20]}\n");
    expect_failure(run("ingest", cfg.string() + " " + out()), 1,
                   "layer 'faces': no field 'VTDST20' (level 'district')");
}

TEST_F(Cli, TruncatedShp)
{
    make_tiger();
    const auto size = fs::file_size(m_dir / "edges.shp");
    fs::resize_file(m_dir / "edges.shp", size - 30);
    expect_failure(run("ingest", tiger_config("edges.shp").string() + " " + out()), 1, "edges.shp:9: Error in fread()");
}

TEST_F(Cli, CorruptDbf)
{
    make_tiger();
    const auto size = fs::file_size(m_dir / "edges.dbf");
    fs::resize_file(m_dir / "edges.dbf", size - 40);
    expect_failure(run("ingest", tiger_config("edges.shp").string() + " " + out()), 1, "failed on DBF file");
}

TEST_F(Cli, CoordinatesOutsideTheProjectionsDomain)
{
    make_tiger();
    const auto cfg = tiger_config("edges.zip", "faces.zip", "projection: {kind: tm, lon0: 30}\n");
    expect_failure(run("ingest", cfg.string() + " " + out()), 1,
                   "edges.zip:0: coordinate (-96.000000, 40.000000) is outside the domain of projection tm lon0=30");
}

TEST_F(Cli, ConfigErrors)
{
    make_tiger();
    expect_failure(
        run("ingest", tiger_config("edges.zip", "faces.zip", "ingest: {halo_m: 5, nope: 1}\n").string() + " " + out()),
        2, "config.yaml:6: unknown key 'ingest.nope' (known: halo_m, line_tile_km, threads)");
    expect_failure(run("ingest", config("dataset: {kind: tiger\n").string() + " " + out()), 2, "not valid YAML");
    expect_failure(run("ingest", config("dataset: {kind: raster}\n").string() + " " + out()), 2,
                   "'dataset.kind' must be tiger, polygons or lines, got 'raster'");
    expect_failure(
        run("ingest", tiger_config("edges.zip", "faces.zip", "projection: {grid_m: -1}\n").string() + " " + out()), 2,
        "'projection.grid_m' must be in");
    expect_failure(run("ingest", tiger_config().string() + " " + out() + " --halo-m -3"), 2,
                   "option '--halo-m' must be >= 0");
    expect_failure(
        run("ingest", tiger_config("edges.zip", "faces.zip", "ingest: {line_tile_km: 5}\n").string() + " " + out()), 2,
        "config.yaml:6: 'ingest.line_tile_km' applies to lines datasets only");
    expect_failure(run("ingest", tiger_config().string() + " " + out() + " --line-tile-km 5"), 2,
                   "--line-tile-km applies to lines datasets only");
    // A line layer's tiles: a side below the grid's resolution, or not a size at all.
    const auto lines = [&](const std::string& ingest) {
        return config("dataset: {kind: lines, inputs: [edges.zip]}\n" + ingest).string();
    };
    expect_failure(run("ingest", lines("ingest: {line_tile_km: 0.00001}\n") + " " + out()), 2,
                   "'ingest.line_tile_km' (1e-05) is below 8 steps of the grid");
    expect_failure(run("ingest", lines("") + " " + out() + " --line-tile-km 0.00001"), 2,
                   "'ingest.line_tile_km' (1e-05) is below 8 steps of the grid");
    expect_failure(run("ingest", lines("ingest: {line_tile_km: -2}\n") + " " + out()), 2,
                   "'ingest.line_tile_km' must be >= 0");
    expect_failure(run("ingest", lines("ingest: {line_tile_km: ten}\n") + " " + out()), 2,
                   "'ingest.line_tile_km' must be a number");
    expect_failure(run("ingest", lines("") + " " + out() + " --line-tile-km -1"), 2,
                   "option '--line-tile-km' must be >= 0");
}

TEST_F(Cli, DumpRejectsACorruptStore)
{
    make_tiger();
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + out()).code, 0);
    const fs::path store = m_dir / "out" / "county" / "51.tlc";
    std::string bytes = slurp(store);
    bytes[bytes.size() / 2] ^= 0x20;
    std::ofstream(m_dir / "bad.tlc", std::ios::binary) << bytes;
    const Result r = run("dump", (m_dir / "bad.tlc").string());
    EXPECT_EQ(r.code, 1);
    EXPECT_NE(r.err.find("bad.tlc: checksum mismatch (corrupt file)"), std::string::npos) << r.err;
    EXPECT_TRUE(r.out.empty());
    // Missing: a usage error like any other stage's missing input (was 3).
    const Result missing = run("dump", (m_dir / "none.tlc").string());
    EXPECT_EQ(missing.code, 2);
    EXPECT_NE(missing.err.find("none.tlc: no such file or folder"), std::string::npos) << missing.err;
}

TEST_F(Cli, EdgesSharedByTwoCountyFilesAreDeduplicatedByTlid)
{
    make_tiger();
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + out()).code, 0);
    // The same map split into two files that both hold the edges between A and B
    // (TLIDs 8 and 9), each knowing only its own side's face, as neighbouring
    // counties' files do.
    std::vector<std::vector<std::string>> west, east;
    for (auto e : m_edges) {
        const int tlid = std::stoi(e[1]);
        if (tlid == 8 || tlid == 9) {
            auto w = e, x = e;
            w[3] = "999999"; // face unknown to this file: outside
            x[2] = "999999";
            west.push_back(w);
            east.push_back(x);
        } else if (e[2] == "101") {
            west.push_back(e);
        } else {
            east.push_back(e);
        }
    }
    const std::vector<std::string> ef = {"TLID", "TFIDL", "TFIDR", "MTFCC"};
    write_shp(m_dir / "west.shp", wkbLineString, ef, west);
    write_shp(m_dir / "east.shp", wkbLineString, ef, east);
    const Result r = run("ingest", tiger_config("west.shp, east.shp").string() + " " + (m_dir / "split").string());
    ASSERT_EQ(r.code, 0) << r.err;
    // The faces split the same way too, one FACES file per EDGES file: built
    // region by region (the tracts 920100 and 920200), each file's unknown
    // face (999999) found in the other file's copy, as the whole read finds it.
    write_shp(m_dir / "west_faces.shp", wkbPolygon, m_face_fields, {m_faces[0]});
    write_shp(m_dir / "east_faces.shp", wkbPolygon, m_face_fields, {m_faces[1], m_faces[2]});
    const Result by_county =
        run("ingest", tiger_config("west.shp, east.shp", "west_faces.shp, east_faces.shp").string() + " " +
                          (m_dir / "counties").string() + " --verbose");
    ASSERT_EQ(by_county.code, 0) << by_county.err;
    EXPECT_NE(by_county.err.find("region 51063920100"), std::string::npos) << by_county.err;
    size_t stores = 0;
    for (const auto& e : fs::recursive_directory_iterator(m_dir / "out")) {
        if (e.path().extension() == ".tlc") {
            const auto rel = fs::relative(e.path(), m_dir / "out");
            EXPECT_EQ(slurp(e.path()), slurp(m_dir / "split" / rel)) << rel;
            EXPECT_EQ(slurp(e.path()), slurp(m_dir / "counties" / rel)) << rel;
            ++stores;
        }
    }
    EXPECT_GT(stores, 0U);
    EXPECT_EQ(slurp(m_dir / "out" / "ingest-report.json"), slurp(m_dir / "counties" / "ingest-report.json"));
}

TEST_F(Cli, ValidateChecksInputsAndWritesNothing)
{
    make_tiger();
    const Result ok = run("ingest", "--validate " + tiger_config().string() + " " + out());
    EXPECT_EQ(ok.code, 0) << ok.err;
    EXPECT_NE(ok.out.find("valid; dataset t, 2 input files, levels state county tract block_group block"),
              std::string::npos)
        << ok.out;
    EXPECT_TRUE(ok.err.empty());
    EXPECT_FALSE(fs::exists(m_dir / "out"));
    const auto bad = tiger_config("edges.zip", "faces.zip", "levels:\n  - {name: district, fields: [VTDST20]}\n");
    expect_failure(run("ingest", "--validate " + bad.string() + " " + out()), 1,
                   "layer 'faces': no field 'VTDST20' (level 'district')");
}

TEST_F(Cli, EveryValidatedConfigKeyRejectsBadValues)
{
    make_tiger();
    const std::vector<std::pair<std::string, std::string>> cases = {
        {"levels:\n  - {name: county, prefix: 5}\n", "levels[0].prefix applies to polygons datasets only"},
        {"levels:\n  - {name: a, fields: [STATEFP20]}\n  - {name: a, fields: [COUNTYFP20]}\n",
         "levels[1]: level 'a' appears twice"},
        {"levels:\n  - {name: a, code: US, fields: [STATEFP20]}\n",
         "levels[0] needs exactly one of 'code', 'fields', 'prefix'"},
        {"levels:\n  - {name: Bad-Name, code: US}\n", "levels[0].name is required"},
        {"levels: []\n", "'levels' must be a non-empty list"},
        {"projection: {kind: mercator}\n", "'projection.kind' must be albers, lcc, tm or utm, got 'mercator'"},
        {"projection: {kind: utm, utm_zone: 61}\n", "'projection.utm_zone' must be in 1..60"},
        {"projection: {stdlat1: 95}\n", "'projection.stdlat1' must be in (-90, 90)"},
        {"projection: {lat0: abc}\n", "'projection.lat0' must be a number"},
        {"ingest: {threads: -1}\n", "'ingest.threads' must be in 0..1024"},
        {"ingest: {halo_m: -5}\n", "'ingest.halo_m' must be >= 0"},
        {"projection: {nope: 1}\n", "unknown key 'projection.nope'"},
        {"simplify: {tolerance: [1]}\n", "unknown key 'simplify.tolerance'"},
        {"simplify: {lazy: sometimes}\n", "'simplify.lazy' must be true or false"},
        {"pack: {tile_size: 4}\n", "unknown key 'pack.tile_size'"},
        {"regions: {county: 51063}\n", "'regions' must be a code or a list of codes, e.g. [51063, 51067]"},
        {"workflow: {job_mb: 0}\n", "'workflow.job_mb' must be in (0, 1e+06]"},
        {"workflow: {job_threads: 1.5}\n", "'workflow.job_threads' must be an integer"},
        {"workflow: {jobs: 4}\n", "unknown key 'workflow.jobs'"},
        {"workflow: {render: maybe}\n", "'workflow.render' must be true or false"},
        // Values the pipeline turns into flags: the wrong type would reach a
        // stage as a malformed flag (`--tolerances 1,,4`) or not at all.
        {"simplify: {tolerances_m: [1, x, 4]}\n",
         "'simplify.tolerances_m' must be a list of numbers, e.g. [1, 4, 16, 64]"},
        {"simplify: {tolerances_m: [1, ~, 4]}\n", "'simplify.tolerances_m' must be a list of numbers"},
        {"simplify: {tolerances_m: 4}\n", "'simplify.tolerances_m' must be a list of numbers"},
        {"simplify: {class_scale: [S1400]}\n", "'simplify.class_scale' must be a map of class to number"},
        {"simplify: {class_scale: {S1400: half}}\n", "'simplify.class_scale' must be a map of class to number"},
        {"simplify: {metric: [l2]}\n", "'simplify.metric' must be l2, l1 or linf"},
        {"simplify: {max_reach: 2.5}\n", "'simplify.max_reach' must be an integer"},
        {"simplify: {pixel_fraction: a}\n", "'simplify.pixel_fraction' must be a number"},
        {"pack: {tile_mb: big}\n", "'pack.tile_mb' must be a number"},
        {"pack: {threads: ~}\n", "'pack.threads' must be an integer"},
        // Checked where the config is read (file and line), not left to
        // render's option parser to blame `--size`.
        {"render: {size: big}\n", "'render.size' must be WIDTHxHEIGHT, each in 16..16384 (got 'big')"},
        {"render: {size: 10x10}\n", "'render.size' must be WIDTHxHEIGHT, each in 16..16384 (got '10x10')"},
        {"render: {size: [1280, 720]}\n", "'render.size' must be WIDTHxHEIGHT, each in 16..16384"},
    };
    for (const auto& [extra, fragment] : cases) {
        SCOPED_TRACE(extra);
        expect_failure(run("ingest", tiger_config("edges.zip", "faces.zip", extra).string() + " " + out()), 2,
                       fragment);
    }
    const std::vector<std::pair<std::string, std::string>> datasets = {
        {"dataset:\n  kind: polygons\n  inputs: [faces.zip]\nlevels:\n  - {name: a, prefix: 2}\n",
         "a polygons dataset needs 'code_field'"},
        {"dataset:\n  kind: polygons\n  inputs: [faces.zip]\n  code_field: TFID\n",
         "a polygons dataset needs 'levels'"},
        {"dataset:\n  kind: lines\n  inputs: [edges.zip]\n  fetch: {npm: x@1}\n",
         "'dataset.fetch' needs 'npm' (package@version) and 'into' (a folder)"},
        {"dataset:\n  kind: lines\n  inputs: [edges.zip]\n  intpt_lat_field: Y\n",
         "'intpt_lat_field' and 'intpt_lon_field' go together"},
        {"dataset:\n  kind: tiger\n  edges: [edges.zip]\n", "a tiger dataset needs 'edges' and 'faces'"},
        {"dataset:\n  kind: lines\n  inputs: []\n", "a lines dataset needs 'inputs'"},
        {"dataset:\n  kind: lines\n  inputs: [edges.zip]\nlevels:\n  - {name: a}\n  - {name: b}\n",
         "a lines dataset has exactly one level"},
    };
    for (const auto& [body, fragment] : datasets) {
        SCOPED_TRACE(body);
        expect_failure(run("ingest", config(body).string() + " " + out()), 2, fragment);
    }
    expect_failure(run("ingest", config("dataset: {kind: tiger, edges: [edges.zip], faces: [faces.zip]}\n").string() +
                                     " " + out() + " --threads 2000"),
                   2, "option '--threads' must be in 0..1024");
    expect_failure(run("ingest", tiger_config().string() + " " + out() + " --threads two"), 2,
                   "option '--threads' needs a number, got 'two'");
    expect_failure(run("ingest", tiger_config().string() + " " + out() + " --max-problem-samples -1"), 2,
                   "option '--max-problem-samples' must be >= 0");
    std::ofstream(m_dir / "noname.yaml") << "dataset: {kind: tiger}\n";
    expect_failure(run("ingest", (m_dir / "noname.yaml").string() + " " + out()), 2, "'name' is required");
}

TEST_F(Cli, LineAndPolygonLayersWithMissingFields)
{
    make_tiger();
    expect_failure(
        run("ingest",
            config("dataset:\n  kind: lines\n  inputs: [edges.zip]\n  class_field: NOPE\n").string() + " " + out()),
        1, "layer 'edges': no field 'NOPE' (dataset.class_field)");
    expect_failure(run("ingest", config("dataset:\n  kind: polygons\n  inputs: [faces.zip]\n  code_field: GEOID\n"
                                        "levels:\n  - {name: a, prefix: 2}\n")
                                         .string() +
                                     " " + out()),
                   1, "layer 'faces': no field 'GEOID' (dataset.code_field)");
    expect_failure(run("ingest", config("dataset:\n  kind: polygons\n  inputs: [edges.zip]\n  code_field: TLID\n"
                                        "levels:\n  - {name: a, prefix: 2}\n")
                                         .string() +
                                     " " + out()),
                   1, "geometry type is Line String, a polygons dataset needs polygons");
}

// dataset.name_field and dataset.attributes: a field the layer lacks is bad
// data (exit 1) naming the layer, the field and the key; on a lines dataset,
// or a field named twice, the config is refused (exit 2) before any input is read.
TEST_F(Cli, UnitNamesAndAttributesThatCannotBeHadAreRefused)
{
    make_tiger();
    const std::string polygons = "dataset:\n  kind: polygons\n  inputs: [faces.zip]\n  code_field: TFID\n";
    const std::string levels = "levels:\n  - {name: a, prefix: 2}\n";
    expect_failure(run("ingest", config(polygons + "  name_field: NOPE\n" + levels).string() + " " + out()), 1,
                   "layer 'faces': no field 'NOPE' (dataset.name_field)");
    expect_failure(
        run("ingest", config(polygons + "  attributes: [STATEFP20, NOPE2]\n" + levels).string() + " " + out()), 1,
        "layer 'faces': no field 'NOPE2' (dataset.attributes)");
    expect_failure(
        run("ingest",
            config("dataset:\n  kind: lines\n  inputs: [edges.zip]\n  name_field: FULLNAME\n").string() + " " + out()),
        2, "'dataset.name_field' and 'dataset.attributes' apply to units: polygons and tiger datasets");
    expect_failure(
        run("ingest", config(polygons + "  name_field: TFID\n  attributes: [TFID]\n" + levels).string() + " " + out()),
        2, "'dataset.attributes' names the name_field 'TFID' again");
    EXPECT_FALSE(fs::exists(out()));
}

TEST_F(Cli, FieldsOfAWrongTypeAreRefusedNotReadAsZero)
{
    // Read as they are, a TLID stored as text or a TFID as a date come out
    // as 0 and ingest built a wrong map with exit 0: now exit 1, naming the
    // file, the field, the type found and the type wanted, nothing written.
    const std::vector<std::tuple<std::string, OGRFieldType, std::string>> cases = {
        {"TLID", OFTString, "edges.zip layer 'edges': field 'TLID' is String, but TLID, the edge id needs an integer"},
        {"TFIDL", OFTDate, "field 'TFIDL' is Date, but TFIDL, the face on the left needs an integer"},
        {"TFIDR", OFTString, "field 'TFIDR' is String, but TFIDR, the face on the right needs an integer"},
        {"TFID", OFTString, "faces.zip layer 'faces': field 'TFID' is String, but TFID, the face id needs an integer"},
        {"STATEFP20", OFTReal, "field 'STATEFP20' is Real, but level 'state' needs text or an integer"},
        {"INTPTLAT", OFTDate, "field 'INTPTLAT' is Date, but dataset.intpt_lat_field needs a number"},
        {"MTFCC", OFTReal, "field 'MTFCC' is Real, but dataset.class_field needs text or an integer"},
    };
    for (const auto& [field, type, message] : cases) {
        SCOPED_TRACE(field);
        make_tiger("", {{field, type}});
        expect_failure(run("ingest", tiger_config().string() + " " + out()), 1, message);
    }
    // The same files with their usual types: exit 0.
    make_tiger();
    EXPECT_EQ(run("ingest", tiger_config().string() + " " + out()).code, 0) << slurp(m_dir / "stderr");
}

TEST_F(Cli, EdgesAndFacesThatDoNotBelongTogetherAreRefused)
{
    // FACES without face 103: edges 2 and 3 bound only 103 and the world
    // outside (900), and ingest built a map without them with exit 0.
    make_tiger();
    m_faces.erase(m_faces.begin() + 2);
    write_shp(m_dir / "faces.shp", wkbPolygon, m_face_fields, m_faces);
    zip(m_dir / "faces.zip", shp_files(m_dir / "faces.shp"));
    expect_failure(run("ingest", tiger_config().string() + " " + out()), 1,
                   "edges.zip layer 'edges': 2 of 10 edges name no face of faces.zip on either side (e.g. TLID 2 "
                   "(TFIDL 103, TFIDR 900) at -95.999000, 40.000000; TLID 3 (TFIDL 103, TFIDR 900) at -95.998000, "
                   "40.000000): FACES is incomplete or of another county");
    // Another county's FACES (no TFID in common): "0 stores" and exit 0 before.
    make_tiger();
    for (auto& f : m_faces) {
        f[1] = std::to_string(std::stoi(f[1]) + 1000);
    }
    write_shp(m_dir / "faces.shp", wkbPolygon, m_face_fields, m_faces);
    zip(m_dir / "faces.zip", shp_files(m_dir / "faces.shp"));
    expect_failure(run("ingest", tiger_config().string() + " " + out()), 1,
                   "edges.zip layer 'edges' and faces.zip share no face");
}

TEST_F(Cli, AFaceWhoseBoundaryDoesNotCloseIsRefused)
{
    // EDGES without edge 10 (between faces 102 and 103): both open, ingest
    // exited 0 and a later stage failed.
    make_tiger();
    m_edges.pop_back();
    const std::vector<std::string> ef = {"TLID", "TFIDL", "TFIDR", "MTFCC"};
    write_shp(m_dir / "edges.shp", wkbLineString, ef, m_edges);
    zip(m_dir / "edges.zip", shp_files(m_dir / "edges.shp"));
    expect_failure(run("ingest", tiger_config().string() + " " + out()), 1,
                   "edges.zip: the boundary of face TFID 102 (faces.zip:1) does not close: 2 loose ends, the first at "
                   "(-95.999000, 40.001000): an edge is missing");
}

TEST_F(Cli, LevelsThatDoNotNestAreRefused)
{
    make_tiger();
    // A block-group level without the tract's code: block group 1 of the
    // county holds faces of tracts 920100 and 920200. Before, ingest counted
    // it under non_nesting_units and every stage after exited 0.
    const std::string no_tract = "levels:\n  - {name: county, fields: [STATEFP20, COUNTYFP20]}\n"
                                 "  - {name: tract, fields: [STATEFP20, COUNTYFP20, TRACTCE20]}\n"
                                 "  - {name: block_group, fields: [STATEFP20, COUNTYFP20, BLKGRPCE20]}\n";
    expect_failure(run("ingest", tiger_config("edges.zip", "faces.zip", no_tract).string() + " " + out()), 1,
                   "level 'block_group' does not nest in level 'tract': its unit 510631 lies in tract 51063920100 "
                   "(faces.zip:0 near -95.999500, 40.001000) and in tract 51063920200 (faces.zip:1 near "
                   "-95.998500, 40.001500)");
    // What the config alone shows, with --validate too: prefixes that do not
    // grow, a level of one unit that is not the first.
    const std::string polygons = "dataset:\n  kind: polygons\n  inputs: [faces.zip]\n  code_field: TFID\n";
    const fs::path shrinking = config(polygons + "levels:\n  - {name: a, prefix: 3}\n  - {name: b, prefix: 1}\n");
    expect_failure(run("ingest", shrinking.string() + " " + out()), 2,
                   "levels[1].prefix 1 is not longer than a's 3: levels go from the coarsest to the finest");
    expect_failure(run("ingest", shrinking.string() + " " + out() + " --validate"), 2, "levels[1].prefix 1");
    const fs::path late_code = config(polygons + "levels:\n  - {name: a, prefix: 1}\n  - {name: all, code: X}\n");
    expect_failure(run("ingest", late_code.string() + " " + out()), 2,
                   "levels[1] ('all') has a 'code': a level of one unit must be the first");
}

TEST_F(Cli, PolygonFilesWithABadOneLeaveNothingBehind)
{
    // Several polygon files go region by region: the good first file is put
    // aside inside the temporary output before the second fails.
    make_tiger();
    make_tiger("b");
    const auto size = fs::file_size(m_dir / "facesb.shp");
    fs::resize_file(m_dir / "facesb.shp", size - 30);
    const std::string levels = "  code_field: TFID\nlevels:\n  - {name: a, prefix: 1}\n  - {name: b, prefix: 3}\n";
    expect_failure(
        run("ingest", config("dataset:\n  kind: polygons\n  inputs: [faces.zip, facesb.shp]\n" + levels).string() +
                          " " + out() + " --threads 1"),
        1, "facesb.shp:");
    expect_failure(
        run("ingest",
            config("dataset:\n  kind: polygons\n  inputs: [faces.zip, edges.zip]\n" + levels).string() + " " + out()),
        1, "edges.zip layer 'edges': geometry type is Line String, a polygons dataset needs polygons");
}

TEST_F(Cli, TigerCountiesWithABadOneLeaveNothingBehind)
{
    // One FACES file per EDGES file goes county by county: the good first
    // county is put aside inside the temporary output before the second fails.
    make_tiger();
    make_tiger("b");
    const auto size = fs::file_size(m_dir / "edgesb.shp");
    fs::resize_file(m_dir / "edgesb.shp", size - 30);
    expect_failure(run("ingest", tiger_config("edges.zip, edgesb.shp", "faces.zip, facesb.zip").string() + " " + out() +
                                     " --threads 1"),
                   1, "edgesb.shp:9: Error in fread()");
    const auto dbf = fs::file_size(m_dir / "facesb.dbf");
    fs::resize_file(m_dir / "facesb.dbf", dbf - 40);
    expect_failure(run("ingest", tiger_config("edges.zip, edges.zip", "faces.zip, facesb.shp").string() + " " + out()),
                   1, "failed on DBF file");
}

TEST_F(Cli, ColorAndSimplifyRunTheLadderDeterministically)
{
    make_tiger();
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + (m_dir / "in").string()).code, 0);
    const std::string in = (m_dir / "in").string(), colors = (m_dir / "colors").string(),
                      simp = (m_dir / "simp").string();
    const Result c = run("color", in + " " + colors + " --tolerances 1,8");
    ASSERT_EQ(c.code, 0) << c.err;
    EXPECT_TRUE(c.err.empty()) << c.err;
    EXPECT_TRUE(fs::exists(m_dir / "colors" / "color-report.json"));
    EXPECT_TRUE(fs::exists(m_dir / "colors" / "eps-8m" / "tract" / "51063.colors.json"));
    const Result s = run("simplify", in + " " + simp + " --tolerances 1,8 --colors " + colors + " --threads 1");
    ASSERT_EQ(s.code, 0) << s.err;
    EXPECT_TRUE(s.err.empty()) << s.err;
    EXPECT_NE(s.out.find("eps 8 m:"), std::string::npos) << s.out;
    const std::string report = slurp(m_dir / "simp" / "simplify-report.json");
    for (const char* key : {"\"eps_m\"", "\"input_vertices\"", "\"output_vertices\"", "\"candidates\"",
                            "\"drawn_segments\"", "\"drawn_pixels\"", "\"tents_drawn\"", "\"banned\"",
                            "\"self_intersection_repairs\"", "\"seconds\"", "\"far_rule\"", "\"tiles\""}) {
        EXPECT_NE(report.find(key), std::string::npos) << key;
    }
    // Computing the colours itself, on two threads, testing every candidate
    // in one round, gives the same stores.
    const Result s2 =
        run("simplify", in + " " + (m_dir / "simp2").string() + " --tolerances 1,8 --threads 2 --exhaustive");
    ASSERT_EQ(s2.code, 0) << s2.err;
    for (const auto& e : fs::recursive_directory_iterator(m_dir / "simp")) {
        if (e.is_regular_file() && e.path().extension() == ".tlc") {
            const auto rel = fs::relative(e.path(), m_dir / "simp");
            EXPECT_EQ(slurp(e.path()), slurp(m_dir / "simp2" / rel)) << rel;
        }
    }
    const Result d = run("dump", (m_dir / "simp" / "eps-8m" / "block" / "510639202001.tlc").string());
    EXPECT_EQ(d.code, 0);
    EXPECT_NE(d.out.find("simplified eps_m=8 metric=0"), std::string::npos) << d.out;
    // Colours made at other options, or from another ingest output, are
    // refused by their manifest before anything is read.
    const std::string simp3 = (m_dir / "simp3").string();
    expect_failure(run("simplify", in + " " + simp3 + " --tolerances 2 --colors " + colors), 2,
                   "has no colours at tolerance 2.0 m (its ladder: [1.0,8.0])");
    expect_failure(run("simplify", in + " " + simp3 + " --tolerances 8 --tile-pixels 2048 --colors " + colors), 2,
                   "was made with tile_pixels 4096, this run has 2048");
    expect_failure(run("simplify", in + " " + simp3 + " --tolerances 8 --class-scale S1400=2 --colors " + colors), 2,
                   "was made with class_scale {}, this run has {\"S1400\":2.0}");
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + (m_dir / "in2").string() + " --halo-m 900").code, 0);
    expect_failure(run("simplify", (m_dir / "in2").string() + " " + simp3 + " --tolerances 8 --colors " + colors), 1,
                   "colors was made by tigerlod-color from another ingest output than " + (m_dir / "in2").string());
    EXPECT_FALSE(fs::exists(m_dir / "simp3"));
    // The manifests say the same whatever the threads.
    EXPECT_EQ(slurp(m_dir / "simp" / "manifest.json").substr(0, 200),
              slurp(m_dir / "simp2" / "manifest.json").substr(0, 200));
}

TEST_F(Cli, SimplifyWithTheExactRulesAloneDrawsNothingAndVerifiesClean)
{
    using json = nlohmann::json;
    make_tiger();
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + (m_dir / "in").string()).code, 0);
    const std::string in = (m_dir / "in").string();
    const std::string exact = (m_dir / "exact").string(), voronoi = (m_dir / "voronoi").string();
    const Result e = run("simplify", in + " " + exact + " --tolerances 1,8 --shortcut-test exact --threads 1");
    ASSERT_EQ(e.code, 0) << e.err;
    EXPECT_TRUE(e.err.empty()) << e.err;
    EXPECT_NE(e.out.find("on none (--shortcut-test exact)"), std::string::npos) << e.out;
    const Result v = run("simplify", in + " " + voronoi + " --tolerances 1,8 --shortcut-test voronoi --threads 1");
    ASSERT_EQ(v.code, 0) << v.err;
    const json re = json::parse(slurp(m_dir / "exact" / "simplify-report.json"));
    const json rv = json::parse(slurp(m_dir / "voronoi" / "simplify-report.json"));
    EXPECT_EQ(re["gl"], "none (--shortcut-test exact)");
    EXPECT_EQ(re["options"]["shortcut_test"], "exact");
    EXPECT_EQ(re["options"]["shortcut_test_choice"], "given");
    EXPECT_EQ(rv["options"]["shortcut_test"], "voronoi");
    EXPECT_NE(rv["gl"].get<std::string>().find("OpenGL"), std::string::npos) << rv["gl"];
    // The default, auto: the raster where a GPU draws it, the exact rules
    // elsewhere; --verbose, the report and the manifest say which and why.
    const bool gpu = tigerlod::gl::Context::gpu_device_node();
    const Result au = run("simplify", in + " " + (m_dir / "auto").string() + " --tolerances 1,8 --threads 1 --verbose");
    ASSERT_EQ(au.code, 0) << au.err;
    const json ra = json::parse(slurp(m_dir / "auto" / "simplify-report.json"));
    const std::string took = ra["options"]["shortcut_test"];
    EXPECT_EQ(json::parse(slurp(m_dir / "auto" / "manifest.json"))["options"]["shortcut_test"], took);
    EXPECT_EQ(ra["options"]["shortcut_test_choice"].get<std::string>().rfind("auto: ", 0), 0U) << ra["options"];
    EXPECT_NE(au.err.find("simplify: --shortcut-test auto: " + took + " ("), std::string::npos) << au.err;
    if (!gpu) {
        EXPECT_EQ(took, "exact") << "no GPU device node here, so the raster would run on llvmpipe";
        EXPECT_EQ(ra["gl"].get<std::string>().rfind("none (--shortcut-test auto took exact: no GPU device node", 0), 0U)
            << ra["gl"];
        EXPECT_EQ(ra["tolerances"][0]["drawn_segments"], 0);
    }
    // With --colors, auto makes the raster test those colours ask for.
    ASSERT_EQ(run("color", in + " " + (m_dir / "colors18").string() + " --tolerances 1,8").code, 0);
    ASSERT_EQ(run("simplify", in + " " + (m_dir / "autocolors").string() + " --tolerances 1,8 --threads 1 --colors " +
                                  (m_dir / "colors18").string())
                  .code,
              0);
    const json rc = json::parse(slurp(m_dir / "autocolors" / "simplify-report.json"));
    EXPECT_EQ(rc["options"]["shortcut_test"], "voronoi");
    EXPECT_EQ(rc["options"]["shortcut_test_choice"], "auto: --colors gives the raster its classes");
    EXPECT_EQ(json::parse(slurp(m_dir / "exact" / "manifest.json"))["options"]["shortcut_test"], "exact");
    for (size_t t = 0; t < 2; ++t) {
        const json& a = re["tolerances"][t];
        EXPECT_EQ(a["drawn_segments"], 0) << "nothing is drawn";
        EXPECT_EQ(a["tiles"], 0) << "nothing is coloured";
        EXPECT_EQ(a["banned"]["raster"], 0);
        // This small map gives the raster nothing to turn down, so the
        // stores are the eps-Voronoi test's, byte for byte (where it does,
        // the exact rules keep fewer vertices: tests/maps, test_simplify_real).
        EXPECT_EQ(rv["tolerances"][t]["banned"]["raster"], 0);
    }
    // Two threads, the same bytes; and the tree verifies clean, every LOD
    // against every other.
    const Result e2 =
        run("simplify", in + " " + (m_dir / "exact2").string() + " --tolerances 1,8 --shortcut-test exact --threads 2");
    ASSERT_EQ(e2.code, 0) << e2.err;
    size_t stores = 0;
    for (const auto& f : fs::recursive_directory_iterator(m_dir / "exact")) {
        if (f.is_regular_file() && f.path().extension() == ".tlc") {
            const auto rel = fs::relative(f.path(), m_dir / "exact");
            EXPECT_EQ(slurp(f.path()), slurp(m_dir / "exact2" / rel)) << rel;
            EXPECT_EQ(slurp(f.path()), slurp(m_dir / "voronoi" / rel)) << rel;
            EXPECT_EQ(slurp(f.path()), slurp(m_dir / "auto" / rel)) << rel;
            EXPECT_EQ(slurp(f.path()), slurp(m_dir / "autocolors" / rel)) << rel;
            ++stores;
        }
    }
    EXPECT_GT(stores, 2U);
    const std::string tree = (m_dir / "tree").string();
    ASSERT_EQ(run("pack", in + " " + exact + " " + tree).code, 0);
    const Result vf = run("verify", tree + " " + in + " " + (m_dir / "verify").string());
    EXPECT_EQ(vf.code, 0) << vf.out << vf.err;
    // The test is a choice of two, and the colours are the raster's.
    expect_failure(run("simplify", in + " " + (m_dir / "bad").string() + " --shortcut-test exactly"), 2,
                   "must be auto, voronoi or exact");
    ASSERT_EQ(run("color", in + " " + (m_dir / "colors").string() + " --tolerances 8").code, 0);
    expect_failure(run("simplify", in + " " + (m_dir / "bad").string() + " --tolerances 8 --shortcut-test exact " +
                                       "--colors " + (m_dir / "colors").string()),
                   2, "'--shortcut-test exact' makes no such test");
    EXPECT_FALSE(fs::exists(m_dir / "bad"));
}

TEST_F(Cli, ColorAndSimplifyByPartitionsWriteTheWholeRunsBytes)
{
    // The workflow's jobs: each stage on some stores, updating OUTPUT in
    // place, then --finish; the folders are a whole run's, byte for byte.
    make_tiger();
    const std::string in = (m_dir / "in").string();
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + in).code, 0);
    const std::string wc = (m_dir / "wc").string(), ws = (m_dir / "ws").string();
    ASSERT_EQ(run("color", in + " " + wc + " --tolerances 1,8").code, 0);
    ASSERT_EQ(run("simplify", in + " " + ws + " --tolerances 1,8 --colors " + wc).code, 0);
    const std::string pc = (m_dir / "pc").string(), ps = (m_dir / "ps").string();
    for (const std::string sel : {"block/*,block_group/*", "county/*,state/*,tract/5106*"}) {
        const Result c = run("color", in + " " + pc + " --tolerances 1,8 --partitions '" + sel + "' --report " +
                                          (m_dir / "share.json").string());
        ASSERT_EQ(c.code, 0) << c.err;
        EXPECT_FALSE(fs::exists(m_dir / "pc" / "color-report.json")) << "a job's share went into OUTPUT";
        EXPECT_TRUE(fs::exists(m_dir / "share.json"));
    }
    // Before --finish a store without its files is named; after it, none.
    std::ofstream(m_dir / "list") << "block/*\nblock_group/*\ncounty/*\nstate/*\n";
    ASSERT_EQ(run("simplify",
                  in + " " + ps + " --tolerances 1,8 --colors " + pc + " --partitions @" + (m_dir / "list").string())
                  .code,
              0)
        << slurp(m_dir / "stderr");
    Result f = run("simplify", in + " " + ps + " --tolerances 1,8 --colors " + pc + " --finish");
    EXPECT_EQ(f.code, 2);
    EXPECT_NE(f.err.find("eps-1m/tract/51063.tlc is missing: the job of tract/51063 has not run"), std::string::npos)
        << f.err;
    ASSERT_EQ(run("simplify", in + " " + ps + " --tolerances 1,8 --colors " + pc + " --partitions tract/51063").code,
              0);
    // A store and a tolerance the run no longer has are removed by --finish.
    fs::copy_file(m_dir / "ps" / "eps-1m" / "tract" / "51063.tlc", m_dir / "ps" / "eps-1m" / "tract" / "51999.tlc");
    fs::create_directories(m_dir / "ps" / "eps-2m" / "tract");
    ASSERT_EQ(run("color", in + " " + pc + " --tolerances 1,8 --finish").code, 0) << slurp(m_dir / "stderr");
    f = run("simplify", in + " " + ps + " --tolerances 1,8 --colors " + pc + " --finish");
    ASSERT_EQ(f.code, 0) << f.err;
    for (const auto& [whole, parts] : {std::pair{m_dir / "wc", m_dir / "pc"}, std::pair{m_dir / "ws", m_dir / "ps"}}) {
        size_t files = 0;
        for (const auto& e : fs::recursive_directory_iterator(parts)) {
            const auto rel = fs::relative(e.path(), parts);
            if (e.is_regular_file() && rel.filename().string().find("-report") == std::string::npos) {
                ++files;
                EXPECT_TRUE(fs::exists(whole / rel)) << "not in a whole run's folder: " << rel;
                EXPECT_EQ(slurp(e.path()), slurp(whole / rel)) << rel;
            }
        }
        for (const auto& e : fs::recursive_directory_iterator(whole)) {
            const auto rel = fs::relative(e.path(), whole);
            EXPECT_TRUE(e.is_directory() || rel.filename().string().find("-report") != std::string::npos ||
                        fs::exists(parts / rel))
                << "missing after the jobs: " << rel;
        }
        EXPECT_GT(files, 10U);
    }
    // Bad selections, options and folders: exit 2, nothing written.
    const std::string o = (m_dir / "o").string();
    auto bad = [&](const std::string& tool, const std::string& args, const std::string& fragment) {
        const Result r = run(tool, in + " " + args);
        EXPECT_EQ(r.code, 2) << r.err;
        EXPECT_NE(r.err.find(fragment), std::string::npos) << r.err;
    };
    bad("color", o + " --partitions tract/99999", "option '--partitions' has 'tract/99999', which matches no chain");
    bad("color", o + " --partitions tract", "has 'tract'; expected LEVEL/PARTITION, LEVEL/PREFIX* or LEVEL/*");
    bad("color", o + " --partitions 'zone/*'", "has 'zone/*', which matches no chain store");
    bad("color", o + " --report r.json", "option '--report' goes with '--partitions'");
    bad("color", o + " --finish --partitions 'tract/*'", "options '--finish' and '--partitions' exclude each other");
    bad("simplify", pc + " --tolerances 1,8 --partitions 'tract/*'",
        "written by tigerlod-color, not tigerlod-simplify");
    EXPECT_FALSE(fs::exists(m_dir / "o"));
    const Result missing = run("color", in + " " + o + " --partitions @" + (m_dir / "nolist").string());
    EXPECT_EQ(missing.code, 1) << missing.err;
    EXPECT_NE(missing.err.find("nolist: cannot read the list of --partitions"), std::string::npos) << missing.err;
}

TEST_F(Cli, PackByPartitionsWritesTheWholeRunsTree)
{
    // The workflow's pack: a plan, jobs on some stores writing part files,
    // then --finish: the tree a whole pack writes, byte for byte.
    make_tiger();
    const std::string in = (m_dir / "in").string(), simp = (m_dir / "simp").string();
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + in).code, 0);
    ASSERT_EQ(run("simplify", in + " " + simp + " --tolerances 1,8").code, 0);
    const std::string whole = (m_dir / "whole").string(), tree = (m_dir / "tree").string();
    const std::string parts = (m_dir / "parts").string();
    ASSERT_EQ(run("pack", in + " " + simp + " " + whole).code, 0);
    const std::string with = " --parts " + parts + " " + in + " " + simp + " " + tree;
    // Before the plan, a job says what to run first.
    expect_failure(run("pack", "--partitions 'tract/*'" + with), 2, "plan.json is missing: run tigerlod-pack --plan");
    ASSERT_EQ(run("pack", "--plan" + with).code, 0) << slurp(m_dir / "stderr");
    EXPECT_FALSE(fs::exists(m_dir / "tree")) << "--plan wrote into OUTPUT";
    const auto plan_time = fs::last_write_time(m_dir / "parts" / "plan.json");
    ASSERT_EQ(run("pack", "--plan" + with).code, 0);
    EXPECT_EQ(fs::last_write_time(m_dir / "parts" / "plan.json"), plan_time) << "an unchanged plan was rewritten";
    {
        // A plan of another ingest output is refused: a neighbour it lacks would be missed.
        const std::string text = slurp(m_dir / "parts" / "plan.json");
        auto j = nlohmann::json::parse(text);
        j["ingest"] = "0123";
        std::ofstream(m_dir / "parts" / "plan.json") << j.dump();
        expect_failure(run("pack", "--partitions 'tract/*'" + with), 2,
                       "is the plan of another tigerlod-ingest output");
        std::ofstream(m_dir / "parts" / "plan.json") << text.substr(0, text.size() / 2);
        expect_failure(run("pack", "--partitions 'tract/*'" + with), 1, "plan.json: not a tigerlod pack plan");
        std::ofstream(m_dir / "parts" / "plan.json") << text;
    }
    // The progress of a job and of --finish, as JSON lines: (done, total) of the last, in stores.
    auto last_progress = [&](const Result& r) {
        std::pair<size_t, size_t> last{0, 0};
        std::istringstream lines(r.err);
        for (std::string line; std::getline(lines, line);) {
            const auto j = nlohmann::json::parse(line);
            EXPECT_EQ(j.at("stage"), "pack");
            EXPECT_EQ(j.at("unit"), "stores");
            last = {j.at("done").get<size_t>(), j.at("total").get<size_t>()};
        }
        return last;
    };
    size_t fine = 0, all = 0;
    for (const auto& e : fs::recursive_directory_iterator(m_dir / "in")) {
        if (e.path().extension() == ".tlc") {
            ++all;
            const std::string level = e.path().parent_path().filename().string();
            fine += level == "block" || level == "block_group" ? 1 : 0;
        }
    }
    const Result job = run("pack", "--partitions 'block/*,block_group/*' --progress json --report " +
                                       (m_dir / "share.json").string() + with);
    ASSERT_EQ(job.code, 0) << job.err;
    EXPECT_EQ(last_progress(job), (std::pair<size_t, size_t>{fine, fine}));
    EXPECT_FALSE(fs::exists(m_dir / "tree")) << "a job wrote into OUTPUT";
    EXPECT_NE(slurp(m_dir / "share.json").find("tigerlod.pack-share/1"), std::string::npos);
    // A store without its part is named by --finish, and nothing is written.
    expect_failure(run("pack", "--finish" + with), 2, "the pack job of county/");
    EXPECT_FALSE(fs::exists(m_dir / "tree"));
    std::ofstream(m_dir / "list") << "county/*\nstate/*\ntract/*\n";
    ASSERT_EQ(run("pack", "--partitions @" + (m_dir / "list").string() + with).code, 0) << slurp(m_dir / "stderr");
    // A part of a store ORIGINAL no longer has is removed by --finish.
    fs::copy_file(m_dir / "parts" / "tract" / "51063.tlp", m_dir / "parts" / "tract" / "51999.tlp");
    const Result finish = run("pack", "--finish --progress json" + with);
    ASSERT_EQ(finish.code, 0) << finish.err;
    EXPECT_EQ(last_progress(finish), (std::pair<size_t, size_t>{all, all}));
    EXPECT_FALSE(fs::exists(m_dir / "parts" / "tract" / "51999.tlp"));
    size_t files = 0;
    for (const auto& e : fs::recursive_directory_iterator(m_dir / "whole")) {
        const auto rel = fs::relative(e.path(), m_dir / "whole");
        if (e.is_regular_file() && rel != "pack-report.json") {
            ++files;
            EXPECT_EQ(slurp(e.path()), slurp(m_dir / "tree" / rel)) << rel;
        }
    }
    EXPECT_GE(files, 3U);
    // A part whose stores changed since is stale: --finish names it and the
    // job to run again, and leaves the tree as it was.
    const std::string skeleton = slurp(m_dir / "tree" / "skeleton.tls");
    ASSERT_EQ(run("simplify", in + " " + simp + " --tolerances 1,8 --overwrite --metric l1").code, 0);
    expect_failure(run("pack", "--finish" + with), 2, "changed since it was packed; run tigerlod-pack --partitions");
    EXPECT_EQ(slurp(m_dir / "tree" / "skeleton.tls"), skeleton);
    // Parts packed at another Draco speed or ladder are refused.
    ASSERT_EQ(run("simplify", in + " " + simp + " --tolerances 1,8 --overwrite").code, 0);
    ASSERT_EQ(run("pack", "--draco-speed 5 --partitions 'tract/51063'" + with).code, 0);
    expect_failure(run("pack", "--finish" + with), 2, "51063.tlp: packed with other options or tolerances");
    // A damaged part is named.
    ASSERT_EQ(run("pack", "--partitions 'tract/51063'" + with).code, 0);
    {
        std::string bytes = slurp(m_dir / "parts" / "tract" / "51063.tlp");
        bytes[30] = static_cast<char>(bytes[30] ^ 0x20);
        std::ofstream(m_dir / "parts" / "tract" / "51063.tlp", std::ios::binary) << bytes;
    }
    expect_failure(run("pack", "--finish" + with), 1, "51063.tlp: checksum mismatch in a pack part file");
    // Options that do not go together.
    expect_failure(run("pack", "--plan --finish" + with), 2, "'--plan', '--partitions' and '--finish' exclude");
    expect_failure(run("pack", "--finish " + in + " " + simp + " " + out()), 2, "'--finish' needs '--parts DIR'");
    expect_failure(run("pack", "--parts " + parts + " " + in + " " + simp + " " + out()), 2,
                   "'--parts' goes with '--plan', '--partitions' or '--finish'");
    expect_failure(run("pack", "--report r.json " + in + " " + simp + " " + out()), 2,
                   "'--report' goes with '--partitions'");
    expect_failure(run("pack", "--partitions tract/99999" + with), 2, "'tract/99999', which matches no chain store");
    expect_failure(run("pack", "--tolerances 1,4 " + in + " " + simp + " " + out()), 2,
                   "simplified at 1, 8 m, the tolerances given (--tolerances, simplify.tolerances_m) are 1, 4 m");
}

TEST_F(Cli, VerifyByPartitionsMergesToTheWholeRunsReport)
{
    // The workflow's verify: jobs on some stores' nodes writing shares, then
    // --finish: the whole run's report, field for field but the seconds.
    make_tiger();
    const std::string in = (m_dir / "in").string(), simp = (m_dir / "simp").string();
    const std::string tree = (m_dir / "tree").string(), parts = (m_dir / "parts").string();
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + in).code, 0);
    ASSERT_EQ(run("simplify", in + " " + simp + " --tolerances 1,8").code, 0);
    ASSERT_EQ(run("pack", in + " " + simp + " " + tree).code, 0);
    ASSERT_EQ(run("pack", "--plan --parts " + parts + " " + in + " " + simp + " " + tree).code, 0);
    ASSERT_EQ(run("verify", tree + " " + in + " " + (m_dir / "whole").string()).code, 0) << slurp(m_dir / "stderr");
    const std::string plan = " --plan " + parts + "/plan.json ";
    const std::string a = (m_dir / "a.json").string(), b = (m_dir / "b.json").string();
    const std::string tail = " " + tree + " " + in + " " + (m_dir / "unused").string();
    const Result job =
        run("verify", "--partitions 'block/*,block_group/*'" + plan + "--progress json --report " + a + tail);
    ASSERT_EQ(job.code, 0) << job.err;
    {
        // A job's progress: each LOD of the levels of its stores.
        std::pair<size_t, size_t> last{0, 0};
        std::istringstream lines(job.err);
        for (std::string line; std::getline(lines, line);) {
            const auto j = nlohmann::json::parse(line);
            EXPECT_EQ(j.at("unit"), "level LODs");
            last = {j.at("done").get<size_t>(), j.at("total").get<size_t>()};
        }
        EXPECT_EQ(last, (std::pair<size_t, size_t>{6, 6})); // blocks and block groups at LODs 0, 1 and 8 m
    }
    ASSERT_EQ(run("verify", "--partitions 'county/*,state/*,tract/*'" + plan + "--report " + b + tail).code, 0)
        << slurp(m_dir / "stderr");
    EXPECT_FALSE(fs::exists(m_dir / "unused")) << "a job wrote OUTPUT";
    const std::string merged = (m_dir / "merged").string();
    expect_failure(run("verify", "--finish --shares " + a + tail), 2, "is in no share: its verify job has not run");
    expect_failure(run("verify", "--finish --shares " + a + "," + b + "," + a + tail), 2, "is in two shares");
    expect_failure(run("verify", "--finish --shares " + a + "," + (m_dir / "nowhere.json").string() + tail), 2,
                   "nowhere.json: no such share (its verify job has not run)");
    expect_failure(run("verify", "--finish --shares @" + (m_dir / "nolist").string() + tail), 1,
                   "nolist: cannot read the list of --shares");
    std::ofstream(m_dir / "cut.json") << slurp(b).substr(0, 100);
    expect_failure(run("verify", "--finish --shares " + a + "," + (m_dir / "cut.json").string() + tail), 1,
                   "cut.json: not a verify share");
    ASSERT_EQ(run("verify", "--finish --shares " + a + "," + b + " " + tree + " " + in + " " + merged).code, 0)
        << slurp(m_dir / "stderr");
    auto without_seconds = [](const fs::path& p) {
        auto j = nlohmann::json::parse(slurp(p));
        j.erase("seconds");
        j.erase("segments_per_second");
        j.erase("ground_seconds");
        return j;
    };
    EXPECT_EQ(without_seconds(m_dir / "whole" / "verify-report.json"),
              without_seconds(m_dir / "merged" / "verify-report.json"));
    // A tree repacked from other stores: the shares of its old nodes are stale.
    ASSERT_EQ(run("simplify", in + " " + simp + " --tolerances 1,400 --overwrite").code, 0);
    ASSERT_EQ(run("pack", in + " " + simp + " " + tree).code, 0);
    expect_failure(run("verify", "--finish --shares " + a + "," + b + tail), 2,
                   "has changed since it was checked; run its verify job again");
    // Options that do not go together.
    expect_failure(run("verify", "--partitions 'tract/*' --report " + a + tail), 2,
                   "'--partitions' needs '--plan FILE' and '--report FILE'");
    expect_failure(run("verify", "--partitions 'tract/*'" + plan + "--report " + a + " --compare " + a + tail), 2,
                   "'--compare' goes with a whole run or '--finish'");
    expect_failure(run("verify", "--finish" + tail), 2, "'--finish' and '--shares LIST' go together");
    expect_failure(run("verify", "--cgal --partitions 'tract/*'" + plan + "--report " + a + tail), 2,
                   "'--cgal' checks the whole tree: with a whole run or '--finish', not '--partitions'");
    expect_failure(run("verify", "--partitions 'tract/99999'" + plan + "--report " + a + tail), 2,
                   "'tract/99999', which matches no chain store");
}

TEST_F(Cli, ProgressAsJsonLinesForAnEngine)
{
    make_tiger();
    const std::string in = (m_dir / "in").string();
    // Ingest: its files read (FACES and EDGES), then its levels built, each
    // phase rising to its total; every line one object.
    const Result ingest = run("ingest", tiger_config().string() + " " + in + " --progress json");
    ASSERT_EQ(ingest.code, 0) << ingest.err;
    {
        std::istringstream lines(ingest.err);
        std::map<std::string, std::pair<size_t, size_t>> last; // unit -> (done, total)
        std::vector<std::string> order;
        for (std::string line; std::getline(lines, line);) {
            const auto j = nlohmann::json::parse(line);
            EXPECT_EQ(j.at("stage"), "ingest");
            const std::string unit = j.at("unit");
            if (order.empty() || order.back() != unit) {
                order.push_back(unit);
            }
            auto& [done, total] = last[unit];
            EXPECT_GT(j.at("done").get<size_t>(), done) << unit;
            done = j.at("done").get<size_t>();
            total = j.at("total").get<size_t>();
        }
        EXPECT_EQ(order, (std::vector<std::string>{"files", "levels"}));
        EXPECT_EQ(last["files"], (std::pair<size_t, size_t>{2, 2}));  // one county's FACES and EDGES
        EXPECT_EQ(last["levels"], (std::pair<size_t, size_t>{5, 5})); // state to block
    }
    for (const std::string tool : {"color", "simplify"}) {
        SCOPED_TRACE(tool);
        const Result r = run(tool, in + " " + (m_dir / tool).string() + " --tolerances 8 --progress json");
        ASSERT_EQ(r.code, 0) << r.err;
        std::istringstream lines(r.err);
        size_t objects = 0, last_done = 0, total = 0;
        for (std::string line; std::getline(lines, line);) {
            const auto j = nlohmann::json::parse(line); // every line one object
            EXPECT_EQ(j.at("stage"), tool);
            EXPECT_EQ(j.at("unit"), "stores");
            EXPECT_GT(j.at("done").get<size_t>(), last_done);
            last_done = j.at("done").get<size_t>();
            total = j.at("total").get<size_t>();
            ++objects;
        }
        EXPECT_GE(objects, 1U);
        EXPECT_EQ(last_done, total) << "the last line is the end";
        size_t stores = 0;
        for (const auto& e : fs::recursive_directory_iterator(m_dir / "in")) {
            stores += e.path().extension() == ".tlc" ? 1 : 0;
        }
        EXPECT_EQ(total, stores) << "every store of the input";
    }
    // The stages after simplify: each its own unit of work, the last line the end.
    auto json_lines = [&](const Result& r, const std::string& stage, const std::string& unit) {
        std::istringstream lines(r.err);
        size_t objects = 0, last_done = 0, total = 0;
        for (std::string line; std::getline(lines, line);) {
            const auto j = nlohmann::json::parse(line);
            EXPECT_EQ(j.at("stage"), stage);
            EXPECT_EQ(j.at("unit"), unit);
            EXPECT_GT(j.at("done").get<size_t>(), last_done);
            last_done = j.at("done").get<size_t>();
            total = j.at("total").get<size_t>();
            ++objects;
        }
        EXPECT_GE(objects, 1U) << stage;
        EXPECT_EQ(last_done, total) << stage << ": the last line is the end";
        return total;
    };
    const std::string tree = (m_dir / "tree").string();
    const Result pack = run("pack", in + " " + (m_dir / "simplify").string() + " " + tree + " --progress json");
    ASSERT_EQ(pack.code, 0) << pack.err;
    size_t stores = 0;
    for (const auto& e : fs::recursive_directory_iterator(m_dir / "in")) {
        stores += e.path().extension() == ".tlc" ? 1 : 0;
    }
    EXPECT_EQ(json_lines(pack, "pack", "stores"), stores);
    const Result verify = run("verify", tree + " " + in + " " + (m_dir / "verify").string() + " --progress json");
    ASSERT_EQ(verify.code, 0) << verify.err;
    const auto report = nlohmann::json::parse(std::ifstream(m_dir / "verify" / "verify-report.json"));
    EXPECT_EQ(json_lines(verify, "verify", "level LODs"),
              report.at("by_level_lod").size()); // each level, LODs 0 and 8 m
    const Result exported =
        run("export", tree + " " + (m_dir / "all.gpkg").string() + " --level tract --progress json");
    ASSERT_EQ(exported.code, 0) << exported.err;
    EXPECT_EQ(exported.out.rfind("export: " + std::to_string(json_lines(exported, "export", "nodes")) + " nodes, ", 0),
              0U)
        << exported.out;
    const Result render = run("render", tree + " " + (m_dir / "render").string() + " --frames 2 --progress json");
    ASSERT_EQ(render.code, 0) << render.err;
    EXPECT_EQ(json_lines(render, "render", "frames"), 3U * 2U); // three modes, two frames each
    // On a pipe, by default, nothing; a mode that does not exist: exit 2.
    const Result quiet = run("color", in + " " + (m_dir / "c2").string() + " --tolerances 8");
    EXPECT_TRUE(quiet.err.empty()) << quiet.err;
    expect_failure(run("color", in + " " + out() + " --progress loud"), 2,
                   "option '--progress' must be auto, bar, json or none, not 'loud'");
}

TEST_F(Cli, SimplifyGivesTheSameStoresOnEglAndWithASmallFramebuffer)
{
    make_tiger();
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + (m_dir / "in").string()).code, 0);
    const std::string in = (m_dir / "in").string();
    const Result base =
        run("simplify", in + " " + (m_dir / "base").string() + " --tolerances 1,8 --shortcut-test voronoi");
    ASSERT_EQ(base.code, 0) << base.err;
    auto expect_same_stores = [&](const fs::path& dir) {
        size_t stores = 0;
        for (const auto& e : fs::recursive_directory_iterator(m_dir / "base")) {
            if (e.is_regular_file() && e.path().extension() == ".tlc") {
                const auto rel = fs::relative(e.path(), m_dir / "base");
                EXPECT_EQ(slurp(e.path()), slurp(dir / rel)) << dir.filename() << " " << rel;
                ++stores;
            }
        }
        EXPECT_GT(stores, 0U);
    };
    // Every tile in a framebuffer of 64 pixels when its box fits, else in the large one.
    const Result small = run("simplify", in + " " + (m_dir / "small").string() +
                                             " --tolerances 1,8 --shortcut-test voronoi --window-pixels 64");
    ASSERT_EQ(small.code, 0) << small.err;
    expect_same_stores(m_dir / "small");
    // The default, --gl auto: a GPU where the machine has a GPU's device
    // node, else OSMesa without opening EGL; the same stores as OSMesa named.
    const Result osmesa = run("simplify", in + " " + (m_dir / "osmesa").string() +
                                              " --tolerances 1,8 --shortcut-test voronoi --gl osmesa --verbose");
    ASSERT_EQ(osmesa.code, 0) << osmesa.err;
    EXPECT_NE(osmesa.out.find("(osmesa)"), std::string::npos) << osmesa.out;
    EXPECT_EQ(osmesa.err.find("--gl auto"), std::string::npos) << osmesa.err;
    expect_same_stores(m_dir / "osmesa");
    const bool gpu_node = tigerlod::gl::Context::gpu_device_node();
    const Result autod =
        run("simplify", in + " " + (m_dir / "auto").string() + " --tolerances 1,8 --shortcut-test voronoi --verbose");
    ASSERT_EQ(autod.code, 0) << autod.err;
    expect_same_stores(m_dir / "auto");
    if (!gpu_node) {
        EXPECT_NE(autod.out.find("(osmesa)"), std::string::npos) << autod.out;
        EXPECT_NE(autod.err.find("--gl auto: no GPU device node"), std::string::npos) << autod.err;
    } else {
        std::printf("[ info ] this machine has a GPU's device node: --gl auto chose %s\n",
                    autod.out.find("(egl)") != std::string::npos ? "EGL" : "OSMesa");
    }
    // The EGL backend: on a GPU's driver in production; here Mesa's
    // device or surfaceless platform, where one is installed.
    const Result egl =
        run("simplify", in + " " + (m_dir / "egl").string() + " --tolerances 1,8 --shortcut-test voronoi --gl egl");
    if (egl.code == 3) {
        GTEST_SKIP() << "no EGL context on this machine (exit 3): " << egl.err;
    }
    ASSERT_EQ(egl.code, 0) << egl.err;
    EXPECT_NE(egl.out.find("(egl)"), std::string::npos) << egl.out;
    expect_same_stores(m_dir / "egl");
}

TEST_F(Cli, ColorAndSimplifyRejectBadInput)
{
    make_tiger();
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + (m_dir / "in").string()).code, 0);
    const std::string in = (m_dir / "in").string() + " " + (m_dir / "res").string();
    for (const char* tool : {"color", "simplify"}) {
        expect_failure(run(tool, in + " --tolerances ''"), 2, "is empty: give at least one tolerance");
        expect_failure(run(tool, in + " --tolerances 4,2"), 2, "must increase: 2 follows");
        // One range for the command line and the config (the schema's), and
        // the store's rules (simplify::check_ladder) in both stages alike.
        for (const char* t : {"0,2", "-1", "1,1e308", "1e20", "1e-300", "2e6"}) {
            expect_failure(run(tool, in + " --tolerances " + t), 2,
                           "every tolerance must be in [0.0001, 1e+06] metres");
        }
        expect_failure(run(tool, in + " --tolerances 0.001,1"), 2,
                       ".tlc: tolerance 0.001000 m is below the store's grid step of 0.010000 m");
        expect_failure(run(tool, in + " --tolerances 1,600"), 2,
                       ".tlc: cut with a halo of 1000.000000 m, but tolerance 600.000000 m needs at least");
        expect_failure(run(tool, in + " --tolerances 1,x"), 2, "has 'x', not a number");
        expect_failure(run(tool, in + " --metric l3"), 2, "must be l2, l1 or linf");
        expect_failure(run(tool, in + " --class-scale S1400"), 2, "expected CLASS=FACTOR");
        expect_failure(run(tool, (m_dir / "nothing").string() + " " + (m_dir / "res").string()), 2, "not a folder");
        // Three chains meet at every junction: two classes cannot separate them.
        const Result over =
            run(tool, in + " --max-classes 2" + (std::string(tool) == "simplify" ? " --shortcut-test voronoi" : ""));
        expect_failure(over, 1, "needs more than 2 stencil classes");
        // The tile is placed on the map too: its centre in lon/lat, on the hand-made map.
        double lon = 0, lat = 0;
        const auto at = over.err.find("centred at lon/lat (");
        ASSERT_NE(at, std::string::npos) << over.err;
        ASSERT_EQ(std::sscanf(over.err.c_str() + at, "centred at lon/lat (%lf, %lf)", &lon, &lat), 2) << over.err;
        EXPECT_TRUE(lon > -96.0 && lon < -95.997 && lat > 40.0 && lat < 40.003) << over.err;
        EXPECT_FALSE(fs::exists(m_dir / "res"));
    }
    for (const char* tool : {"color", "simplify"}) {
        expect_failure(run(tool, in + " --pixel-fraction 0.9"), 2, "option '--pixel-fraction' must be in (0, 0.5]");
        expect_failure(run(tool, in + " --tile-pixels 10"), 2, "option '--tile-pixels' must be in 64..16384");
        expect_failure(run(tool, in + " --max-classes 300"), 2, "option '--max-classes' must be in 2..255");
        expect_failure(run(tool, in + " --threads 2000"), 2, "option '--threads' must be in 0..1024");
    }
    expect_failure(run("simplify", in + " --max-reach -1"), 2, "option '--max-reach' must be >= 0");
    // Colours: a folder without the store's file, and a corrupt file.
    const std::string colors = (m_dir / "colors").string();
    ASSERT_EQ(run("color", (m_dir / "in").string() + " " + colors + " --tolerances 8").code, 0);
    expect_failure(run("simplify", in + " --tolerances 8 --colors " + (m_dir / "nocolors").string()), 1,
                   "nocolors: no manifest.json: not a finished tigerlod-color output");
    fs::rename(m_dir / "colors" / "eps-8m" / "tract" / "51063.colors.json", m_dir / "keep.json");
    expect_failure(run("simplify", in + " --tolerances 8 --colors " + colors), 2, "cannot open the colours file");
    std::ofstream(m_dir / "colors" / "eps-8m" / "tract" / "51063.colors.json")
        << "{\"schema\": \"tigerlod.colors/1\", ";
    expect_failure(run("simplify", in + " --tolerances 8 --colors " + colors), 1,
                   "51063.colors.json: not a colours file");
    std::ofstream(m_dir / "colors" / "eps-8m" / "tract" / "51063.colors.json")
        << R"({"schema": "tigerlod.colors/1", "level": "tract", "partition": "51063", "eps_m": 8, "metric": "l2",)"
           R"( "pixel": 1, "splits": 0, "conflict_edges": 0, "tiles": []})";
    expect_failure(run("simplify", in + " --tolerances 8 --colors " + colors), 2, "made at eps");
    expect_failure(run("simplify", in + " --compliance occlusion"), 2, "must be ssbo or readback");
    expect_failure(run("simplify", in + " --lazy --exhaustive"), 2, "'--lazy' and '--exhaustive' exclude each other");
    expect_failure(run("simplify", in + " --gl glx"), 2, "must be auto, osmesa or egl");
    expect_failure(run("simplify", in + " --window-pixels 4"), 2, "option '--window-pixels' must be in 8..16384");
    expect_failure(run("simplify", in + " --tolerances 800"), 2, "needs at least 1600");
    std::ofstream(m_dir / "points.csv") << "name,lon,lat\na,-95.99,40.001\nb,-95.99,north\n";
    expect_failure(run("simplify", in + " --points " + (m_dir / "points.csv").string()), 1,
                   "points.csv: line 3: lon/lat are not numbers");
    std::ofstream(m_dir / "points.json")
        << R"({"type": "FeatureCollection", "features": [)"
        << R"({"type": "Feature", "geometry": {"type": "LineString", "coordinates": []}}]})";
    expect_failure(run("simplify", in + " --points " + (m_dir / "points.json").string()), 1,
                   "points.json: feature 0: geometry type LineString, expected Point or MultiPoint");
    EXPECT_FALSE(fs::exists(m_dir / "res"));

    // A store of another major version, and a corrupt one.
    const fs::path store = m_dir / "in" / "tract" / "51063.tlc";
    std::string bytes = slurp(store);
    std::string v2 = bytes;
    v2[8] = 2;
    std::ofstream(store, std::ios::binary) << v2;
    expect_failure(run("simplify", in), 1, "51063.tlc: unsupported major version 2 (reads 1)");
    std::string corrupt = bytes;
    corrupt[corrupt.size() / 2] ^= 0x10;
    std::ofstream(store, std::ios::binary) << corrupt;
    expect_failure(run("color", in), 1, "51063.tlc: checksum mismatch (corrupt file)");
    expect_failure(run("simplify", in), 1, "51063.tlc: checksum mismatch (corrupt file)");
    EXPECT_FALSE(fs::exists(m_dir / "res"));
    // A store that breaks the partition contract: a unit its chains bound has no point.
    tigerlod::chains::ChainStore s =
        tigerlod::chains::decode(std::as_bytes(std::span(bytes.data(), bytes.size())), store.string());
    ASSERT_FALSE(s.constraints.empty());
    const std::string unit = s.strings[s.constraints.front().unit];
    s.constraints.erase(s.constraints.begin());
    tigerlod::chains::write(store, s);
    expect_failure(run("simplify", in), 1, "bounds unit " + unit + ", but the store holds no internal point");
    EXPECT_FALSE(fs::exists(m_dir / "res"));
    std::ofstream(store, std::ios::binary) << bytes;
}

TEST_F(Cli, NoStageWritesOverItsInputs)
{
    // With --overwrite, an output that is an input, or a folder holding one,
    // would delete what the stage reads: usage error, the input untouched.
    make_tiger();
    const fs::path cfg = tiger_config();
    const std::string in = (m_dir / "in").string(), simp = (m_dir / "simp").string(),
                      colors = (m_dir / "colors").string(), tree = (m_dir / "t.gpkg").string();
    ASSERT_EQ(run("ingest", cfg.string() + " " + in).code, 0);
    ASSERT_EQ(run("color", in + " " + colors + " --tolerances 8").code, 0);
    ASSERT_EQ(run("simplify", in + " " + simp + " --tolerances 8").code, 0);
    ASSERT_EQ(run("pack", in + " " + simp + " " + tree).code, 0) << slurp(m_dir / "stderr");
    fs::create_symlink(m_dir / "in", m_dir / "link");
    auto refused = [&](const std::string& tool, const std::string& args, const std::string& fragment) {
        const Result r = run(tool, args + (tool == "pack" ? "" : " --overwrite")); // pack updates in place
        EXPECT_EQ(r.code, 2) << tool << " " << args << ": " << r.err;
        EXPECT_NE(r.err.find(fragment), std::string::npos) << tool << " " << args << ": " << r.err;
    };
    refused("ingest", cfg.string() + " " + m_dir.string(), "holds the input " + cfg.string());
    refused("color", in + " " + in + " --tolerances 8", "is the input " + in);
    refused("simplify", in + " " + in + " --tolerances 8", "is the input " + in);
    refused("simplify", in + " " + (m_dir / "link").string() + " --tolerances 8", "is the input " + in);
    refused("simplify", in + " " + m_dir.string() + " --tolerances 8", "holds the input " + in);
    refused("simplify", in + " " + colors + " --tolerances 8 --colors " + colors, "is the input " + colors);
    refused("pack", in + " " + simp + " " + simp, "is the input " + simp);
    refused("verify", tree + " " + in + " " + tree, "is the input " + tree);
    refused("verify", tree + " " + in + " " + in, "is the input " + in);
    refused("export", tree + " " + tree, "is the input " + tree);
    // An output inside an input folder would replace part of what it reads.
    std::string level;
    for (const auto& e : fs::directory_iterator(m_dir / "in")) {
        if (e.is_directory()) {
            level = e.path().string();
        }
    }
    ASSERT_FALSE(level.empty());
    refused("color", in + " " + level + " --tolerances 8", "lies inside the input " + in);
    refused("simplify", in + " " + colors + "/x --tolerances 8 --colors " + colors, "lies inside the input " + colors);
    refused("verify", tree + " " + in + " " + tree + "/tiles", "lies inside the input " + tree);
    refused("render", tree + " " + tree + "/tiles", "lies inside the input " + tree);
    // Everything is still there and still reads.
    EXPECT_TRUE(fs::exists(cfg));
    EXPECT_TRUE(fs::exists(m_dir / "in" / "manifest.json"));
    EXPECT_TRUE(fs::exists(m_dir / "colors" / "color-report.json"));
    EXPECT_TRUE(fs::exists(m_dir / "simp" / "simplify-report.json"));
    EXPECT_EQ(run("verify", tree + " " + in + " " + out()).code, 0) << slurp(m_dir / "stderr");
}

TEST_F(Cli, OverwriteReplacesOnlyAStagesOutputOrAnEmptyFolder)
{
    // --overwrite onto a folder of the user's (no tigerlod manifest): exit 2
    // naming a file found there, the folder untouched, for every stage that
    // writes a folder; onto an empty folder or a stage's output: done.
    make_tiger();
    const fs::path cfg = tiger_config();
    const std::string in = (m_dir / "in").string(), simp = (m_dir / "simp").string(), tree = (m_dir / "tree").string();
    ASSERT_EQ(run("ingest", cfg.string() + " " + in).code, 0);
    ASSERT_EQ(run("simplify", in + " " + simp + " --tolerances 8").code, 0);
    ASSERT_EQ(run("pack", in + " " + simp + " " + tree).code, 0) << slurp(m_dir / "stderr");
    const fs::path mine = m_dir / "thesis";
    fs::create_directories(mine / "chapters");
    std::ofstream(mine / "notes.txt") << "years of work";
    const std::vector<std::pair<std::string, std::string>> stages = {
        {"ingest", cfg.string() + " "},
        {"color", in + " --tolerances 8 "},
        {"simplify", in + " --tolerances 8 "},
        {"verify", tree + " " + in + " "},
        {"render", "--mode none --frames 2 --size 32x32 " + tree + " "},
        {"synth", "--states 1 --counties-per-state 2 "},
    };
    for (const auto& [tool, args] : stages) {
        const Result r = run(tool, args + mine.string() + " --overwrite");
        EXPECT_EQ(r.code, 2) << tool << ": " << r.err;
        EXPECT_NE(r.err.find(mine.string() + " is not a tigerlod stage's output (it holds chapters and 1 more"),
                  std::string::npos)
            << tool << ": " << r.err;
        EXPECT_EQ(slurp(mine / "notes.txt"), "years of work") << tool;
        EXPECT_TRUE(fs::is_directory(mine / "chapters")) << tool;
    }
    // An empty folder is replaced, and then (a stage's output) again.
    for (const auto& [tool, args] : stages) {
        const fs::path dest = m_dir / ("empty-" + tool);
        fs::create_directories(dest);
        for (int twice = 0; twice < 2; ++twice) {
            const Result r = run(tool, args + dest.string() + " --overwrite");
            EXPECT_EQ(r.code, 0) << tool << ": " << r.err;
        }
    }
}

TEST_F(Cli, UnitCodesAreCheckedNotMadeUp)
{
    // Squares 0.1 degree wide, each a feature with its code.
    auto write_map = [&](const std::vector<std::pair<double, std::string>>& squares,
                         const std::string& name = "map.geojson") {
        std::ofstream out(m_dir / name);
        out << R"({"type": "FeatureCollection", "features": [)";
        for (size_t i = 0; i < squares.size(); ++i) {
            const double x = squares[i].first;
            out << (i ? "," : "") << R"({"type": "Feature", "properties": {"code": ")" << squares[i].second
                << R"("}, "geometry": {"type": "Polygon", "coordinates": [[[)" << x << ",40],[" << x + 0.1 << ",40],["
                << x + 0.1 << ",40.1],[" << x << ",40.1],[" << x << ",40]]]}}";
        }
        out << "]}";
    };
    const std::string levels = "dataset: {kind: polygons, inputs: [map.geojson], code_field: code}\n"
                               "levels:\n  - {name: state, prefix: 2}\n  - {name: county, prefix: 5}\n";
    // One code on two features, apart or adjacent: stopped, both named.
    for (const double second : {-99.0, -99.9}) {
        write_map({{-100, "01001"}, {second, "01001"}});
        expect_failure(run("ingest", config(levels).string() + " " + out()), 1,
                       "map.geojson: 1 feature repeats the 'code' of another ('01001' on feature 0 and feature 1): "
                       "give each unit its own code, or set dataset.duplicate_code: merge");
    }
    // One code in two files, the same square (an input named twice) or
    // another one: stopped too, both places named.
    const std::string two_files = "dataset: {kind: polygons, inputs: [map.geojson, more.geojson], code_field: code}\n"
                                  "levels:\n  - {name: state, prefix: 2}\n  - {name: county, prefix: 5}\n";
    for (const double other : {-100.0, -99.0}) {
        write_map({{other, "01001"}}, "more.geojson");
        write_map({{-100, "01001"}, {-99.9, "01002"}});
        const Result r = run("ingest", config(two_files).string() + " " + out());
        EXPECT_EQ(r.code, 1) << r.err;
        EXPECT_NE(r.err.find("more.geojson:0: 'code' 01001 is also that of "), std::string::npos) << r.err;
        EXPECT_NE(r.err.find("map.geojson:0, in another file: give each unit its own code"), std::string::npos)
            << r.err;
        EXPECT_FALSE(fs::exists(out()));
    }
    // Merged on request: one county in two parts, and said so.
    std::ofstream(m_dir / "config.yaml") << "name: t\ndataset: {kind: polygons, inputs: [map.geojson], code_field: "
                                            "code, duplicate_code: merge}\nlevels:\n  - {name: state, prefix: 2}\n"
                                            "  - {name: county, prefix: 5}\n";
    write_map({{-100, "01001"}, {-99.0, "01001"}});
    const Result ok = run("ingest", (m_dir / "config.yaml").string() + " " + out());
    ASSERT_EQ(ok.code, 0) << ok.err;
    EXPECT_NE(ok.err.find("1 feature repeats the 'code' of another ('01001' on feature 0 and feature 1) merged"),
              std::string::npos)
        << ok.err;
    // The report's table: one unit at the county level.
    const size_t row = ok.out.find("  county ");
    ASSERT_NE(row, std::string::npos) << ok.out;
    std::istringstream cells(ok.out.substr(row));
    std::string level;
    uint64_t units = 0;
    cells >> level >> units;
    EXPECT_EQ(units, 1U) << ok.out;
    fs::remove_all(out());
    // A code shorter than a level's prefix would make up a unit.
    write_map({{-100, "01001"}, {-99.9, "0100"}});
    expect_failure(run("ingest", config(levels).string() + " " + out()), 1,
                   "map.geojson:1: code '0100' is shorter than level 'county' needs (its first 5 characters)");
    // Prefixes count characters: a two-byte letter is never cut.
    write_map({{-100, "\xc3\xa9"
                      "1001"},
               {-99.9, "\xc3\xa9"
                       "1002"}});
    const Result utf = run("ingest", config(levels).string() + " " + out());
    ASSERT_EQ(utf.code, 0) << utf.err;
    EXPECT_TRUE(fs::exists(m_dir / "out" / "county" / "%C3%A91.tlc")); // the state code is "\xc3\xa9" "1", whole
}

TEST_F(Cli, AnInputWithoutFeaturesIsRefused)
{
    // An empty layer (a cut-off download, the wrong layer) would map nothing
    // there with exit 0: exit 1 naming it, nothing written.
    std::ofstream(m_dir / "empty.geojson") << R"({"type": "FeatureCollection", "features": []})";
    expect_failure(run("ingest", config("dataset: {kind: lines, inputs: [empty.geojson]}\n").string() + " " + out()), 1,
                   "empty.geojson layer 'empty': no features: an empty layer");
}

TEST_F(Cli, DatasetWhereSelectsFeaturesAndMessagesNumberThemAsTheFileDoes)
{
    // Four squares 0.1 degree wide; the condition keeps the last three.
    {
        std::ofstream map(m_dir / "map.geojson");
        map << R"({"type": "FeatureCollection", "features": [)";
        const char* codes[] = {"01001", "01002", "02003", "02002"};
        for (int i = 0; i < 4; ++i) {
            const double x = -100 + 0.1 * i;
            map << (i ? "," : "") << R"({"type": "Feature", "properties": {"code": ")" << codes[i] << R"(", "keep": )"
                << (i > 0 ? 1 : 0) << R"(}, "geometry": {"type": "Polygon", "coordinates": [[[)" << x << ",40],["
                << x + 0.1 << ",40],[" << x + 0.1 << ",40.1],[" << x << ",40.1],[" << x << ",40]]]}}";
        }
        map << "]}";
    }
    const auto with_where = [&](const std::string& where) {
        return config("dataset: {kind: polygons, inputs: [map.geojson], code_field: code, where: \"" + where +
                      "\"}\nlevels:\n  - {name: state, prefix: 2}\n  - {name: county, prefix: 5}\n")
                   .string() +
               " " + out();
    };
    const Result kept = run("ingest", with_where("keep = 1"));
    ASSERT_EQ(kept.code, 0) << kept.err;
    std::istringstream cells(kept.out.substr(kept.out.find("  county ")));
    std::string level;
    uint64_t units = 0;
    cells >> level >> units;
    EXPECT_EQ(units, 3U) << kept.out;
    fs::remove_all(out());
    // A message names a feature by its place in the file, not among the
    // selected: the code too short for a level is feature 3's.
    {
        std::string text = slurp(m_dir / "map.geojson");
        text.replace(text.rfind("02002"), 5, "0200");
        std::ofstream(m_dir / "map.geojson") << text;
    }
    expect_failure(run("ingest", with_where("keep = 1")), 1, "map.geojson:3: code '0200' is shorter");
    // A condition that selects nothing, or that OGR cannot read: exit 1,
    // the condition named, nothing written.
    expect_failure(run("ingest", with_where("keep = 7")), 1, "dataset.where 'keep = 7' selects none of its 4 features");
    expect_failure(run("ingest", with_where("keep = = 1")), 1, "dataset.where 'keep = = 1': ");
    // TIGER's files stay whole.
    make_tiger();
    expect_failure(
        run("ingest", tiger_config("edges.zip", "faces.zip", "  where: \"STATEFP20 = '51'\"\n").string() + " " + out()),
        2, "'dataset.where' applies to polygons and lines");
}

TEST_F(Cli, EveryConfigKeyOfAStageIsOneOfItsOptions)
{
    // The schema says which stage takes a key as which option; each stage's
    // --help shows that option with the key it mirrors.
    size_t checked = 0;
    for (const auto& k : tigerlod::config::keys()) {
        std::istringstream stages(k.stages);
        for (std::string stage; stages >> stage;) {
            const Result r = run(stage, "--help");
            ASSERT_EQ(r.code, 0);
            EXPECT_NE(r.out.find("  --" + k.flag + (k.type == tigerlod::config::Type::boolean ? "\n" : " ")),
                      std::string::npos)
                << stage << " has no --" << k.flag;
            EXPECT_NE(r.out.find("config: " + k.name), std::string::npos) << stage << " " << k.name;
            ++checked;
        }
    }
    EXPECT_GE(checked, 25U);
}

TEST_F(Cli, StagesTakeTheirSectionFromTheConfigAndTheCommandLineWins)
{
    make_tiger();
    const std::string in = (m_dir / "in").string();
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + in).code, 0);
    const fs::path cfg = tiger_config("edges.zip", "faces.zip",
                                      "simplify:\n  tolerances_m: [8, 32]\n  tile_pixels: 2048\n"
                                      "pack:\n  tile_mb: 0.5\nverify:\n  max_items: 3\n");
    const std::string with = " --config " + cfg.string();
    ASSERT_EQ(run("color", in + " " + (m_dir / "c1").string() + with).code, 0);
    EXPECT_TRUE(fs::exists(m_dir / "c1" / "eps-8m") && fs::exists(m_dir / "c1" / "eps-32m"));
    EXPECT_NE(slurp(m_dir / "c1" / "manifest.json").find("\"tile_pixels\": 2048"), std::string::npos);
    // A flag on the command line wins over the config's key.
    ASSERT_EQ(run("color", in + " " + (m_dir / "c2").string() + with + " --tolerances 8").code, 0);
    EXPECT_TRUE(fs::exists(m_dir / "c2" / "eps-8m"));
    EXPECT_FALSE(fs::exists(m_dir / "c2" / "eps-32m"));
    // simplify with the same config takes color's output: the options agree.
    const std::string simp = (m_dir / "simp").string(), tree = (m_dir / "tree").string();
    const Result s = run("simplify", in + " " + simp + with + " --colors " + (m_dir / "c1").string());
    ASSERT_EQ(s.code, 0) << s.err;
    ASSERT_EQ(run("pack", in + " " + simp + " " + tree + with).code, 0);
    EXPECT_NE(slurp(m_dir / "tree" / "manifest.json").find("\"tile_mb\": 0.5"), std::string::npos);
    ASSERT_EQ(run("verify", tree + " " + in + " " + (m_dir / "v").string() + with).code, 0);
    EXPECT_NE(slurp(m_dir / "v" / "manifest.json").find("\"max_items\": 3"), std::string::npos);
    // A bad value in the config: the file, the line, the key; nothing written.
    const fs::path bad = tiger_config("edges.zip", "faces.zip", "simplify:\n  tile_pixels: 10\n");
    expect_failure(run("color", in + " " + out() + " --config " + bad.string()), 2,
                   bad.string() + ":7: 'simplify.tile_pixels' must be in 64..16384");
    expect_failure(run("pack", in + " " + simp + " " + out() + " --config " + (m_dir / "none.yaml").string()), 2,
                   "none.yaml: no such config file");
    // Stages without a section take no --config.
    expect_failure(run("export", tree + " " + (m_dir / "x.gpkg").string() + with), 2, "unknown option '--config'");
}

TEST_F(Cli, VerifyChecksATreeAgainstTheContractItsManifestsCarry)
{
    // Before manifests, verify took simplify's options again by hand: a
    // mismatch gave false violations or false passes, and a tree was checked
    // against whatever ingest output it was given.
    make_tiger();
    const std::string in = (m_dir / "in").string(), simp = (m_dir / "simp").string(), tree = (m_dir / "tree").string();
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + in).code, 0);
    std::ofstream(m_dir / "points.csv") << "lon,lat\n-95.99,40.001\n";
    const std::string points = (m_dir / "points.csv").string();
    ASSERT_EQ(run("simplify", in + " " + simp + " --tolerances 8,32 --class-scale S1400=0.5 --points " + points).code,
              0);
    ASSERT_EQ(run("pack", in + " " + simp + " " + tree).code, 0);
    for (const char* f : {"simp/manifest.json", "tree/manifest.json"}) {
        EXPECT_NE(slurp(m_dir / f).find("\"schema\": \"tigerlod.manifest/1\""), std::string::npos) << f;
    }
    // The tree's manifest carries simplify's options, the points themselves included.
    const std::string tree_manifest = slurp(m_dir / "tree" / "manifest.json");
    for (const char* part :
         {"\"stage\": \"pack\"", "\"S1400\": 0.5", "\"lonlat\": [", "-95.99", "\"point_constraints\": true"}) {
        EXPECT_NE(tree_manifest.find(part), std::string::npos) << part << "\n" << tree_manifest;
    }
    const Result v = run("verify", tree + " " + in + " " + (m_dir / "v1").string());
    ASSERT_EQ(v.code, 0) << v.err;
    const std::string report = slurp(m_dir / "v1" / "verify-report.json");
    EXPECT_NE(slurp(m_dir / "v1" / "manifest.json").find("\"stage\": \"verify\""), std::string::npos);
    EXPECT_NE(report.find("\"contract\": {\n    \"class_scale\": {\n      \"S1400\": 0.5\n    },\n    "
                          "\"projection_scale\": true,\n    \"point_constraints\": true,\n    \"user_points\": 1"),
              std::string::npos)
        << report;

    // Another ingest output than the one the tree and the simplified stores were made from.
    const std::string in2 = (m_dir / "in2").string();
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + in2 + " --halo-m 900").code, 0);
    expect_failure(run("verify", tree + " " + in2 + " " + (m_dir / "v2").string()), 1,
                   "tree was made by tigerlod-pack from another ingest output than " + in2);
    EXPECT_FALSE(fs::exists(m_dir / "v2"));
    expect_failure(run("pack", in2 + " " + simp + " " + (m_dir / "tree2").string()), 1,
                   "simp was made by tigerlod-simplify from another ingest output than " + in2);
    // The same ingest run again gives the same manifest: it is accepted.
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + in2 + " --overwrite").code, 0);
    EXPECT_EQ(slurp(m_dir / "in" / "manifest.json"), slurp(m_dir / "in2" / "manifest.json"));
    EXPECT_EQ(run("verify", tree + " " + in2 + " " + (m_dir / "v2").string()).code, 0);

    // Without point constraints simplify lets points change side; the tree's
    // contract says so, and verify does not count them.
    ASSERT_EQ(run("simplify", in + " " + (m_dir / "free").string() + " --tolerances 8 --no-point-constraints").code, 0);
    ASSERT_EQ(run("pack", in + " " + (m_dir / "free").string() + " " + (m_dir / "tree3").string()).code, 0);
    ASSERT_EQ(run("verify", (m_dir / "tree3").string() + " " + in + " " + (m_dir / "v3").string()).code, 0);
    const std::string free_report = slurp(m_dir / "v3" / "verify-report.json");
    EXPECT_NE(free_report.find("\"point_constraints\": false"), std::string::npos) << free_report;
    EXPECT_NE(free_report.find("\"points\": 0"), std::string::npos) << free_report;

    // A tree without a manifest (packed before manifests) is refused, naming it.
    fs::remove(m_dir / "tree" / "manifest.json");
    expect_failure(run("verify", tree + " " + in + " " + (m_dir / "v4").string()), 1,
                   "tree: no manifest.json: not a finished tigerlod-pack output");
    // Damaged manifests: the file, and what is wrong with it; nothing written.
    const std::string tree5 = (m_dir / "tree5").string();
    const fs::path simp_manifest = m_dir / "simp" / "manifest.json";
    const std::string kept = slurp(simp_manifest);
    std::ofstream(simp_manifest) << "{\"schema\": ";
    expect_failure(run("pack", in + " " + simp + " " + tree5), 1, "simp/manifest.json: not JSON");
    std::ofstream(simp_manifest) << R"({"schema": "tigerlod.colors/1"})";
    expect_failure(run("pack", in + " " + simp + " " + tree5), 1, "simp/manifest.json: not a tigerlod.manifest/1");
    std::ofstream(simp_manifest) << R"({"schema": "tigerlod.manifest/1", "stage": "simplify", "inputs": {}})";
    expect_failure(run("pack", in + " " + simp + " " + tree5), 1, "simp/manifest.json: no input 'ingest'");
    std::ofstream(simp_manifest) << kept;
    std::string no_contract = slurp(m_dir / "tree3" / "manifest.json");
    const std::string section = "\n  \"simplify\": {"; // the top level's, not the input's
    ASSERT_NE(no_contract.find(section), std::string::npos) << no_contract;
    no_contract.replace(no_contract.find(section), section.size(), "\n  \"other\": {");
    std::ofstream(m_dir / "tree3" / "manifest.json") << no_contract;
    expect_failure(run("verify", (m_dir / "tree3").string() + " " + in + " " + (m_dir / "v5").string()), 1,
                   "tree3/manifest.json: no 'simplify' section");
    EXPECT_FALSE(fs::exists(m_dir / "tree5"));
    EXPECT_FALSE(fs::exists(m_dir / "v5"));
}

TEST_F(Cli, PackRefusesALadderWithATolerancePartMissing)
{
    make_tiger();
    const std::string in = (m_dir / "in").string(), simp = (m_dir / "simp").string();
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + in).code, 0);
    ASSERT_EQ(run("simplify", in + " " + simp + " --tolerances 8,32").code, 0);
    // A tolerance folder lost after simplify: pack would build a tree with an LOD fewer.
    fs::copy(m_dir / "simp", m_dir / "part", fs::copy_options::recursive);
    fs::remove_all(m_dir / "part" / "eps-32m");
    expect_failure(run("pack", in + " " + (m_dir / "part").string() + " " + out()), 1,
                   "its manifest lists the tolerances 8, 32 m, but the eps-<E>m folders hold 8 m");
    // A folder without its manifest: not a finished simplify output.
    fs::remove(m_dir / "simp" / "manifest.json");
    expect_failure(run("pack", in + " " + simp + " " + out()), 1,
                   "simp: no manifest.json: not a finished tigerlod-simplify output");
}

TEST_F(Cli, ColorAndSimplifyReadOnlyTheStoresIngestWrote)
{
    // Foreign stores: before, color and simplify exited 0 and only pack noticed.
    make_tiger();
    const std::string in = (m_dir / "in").string();
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + in).code, 0);
    ASSERT_EQ(run("ingest", tiger_config("edges.zip", "faces.zip", "projection:\n  grid_m: 0.1\n").string() + " " +
                                (m_dir / "coarse").string())
                  .code,
              0);
    const fs::path tract = m_dir / "in" / "tract" / "51063.tlc";
    const fs::path block_group = fs::directory_iterator(m_dir / "in" / "block_group")->path();
    const fs::path keep = m_dir / "keep.tlc";
    fs::copy_file(tract, keep);
    auto both = [&](int code, const std::string& fragment) {
        for (const std::string tool : {"color", "simplify"}) {
            SCOPED_TRACE(tool);
            expect_failure(run(tool, in + " " + out() + " --tolerances 8"), code, fragment);
        }
    };
    // Another level's store under the tract's name.
    fs::copy_file(block_group, tract, fs::copy_options::overwrite_existing);
    both(1, "tract/51063.tlc: holds partition '" + block_group.stem().string() +
                "' of level 'block_group', not what its place names");
    // The same store on another grid.
    fs::copy_file(m_dir / "coarse" / "tract" / "51063.tlc", tract, fs::copy_options::overwrite_existing);
    both(1, "tract/51063.tlc: projection albers lon0=-96 lat0=23 stdlat=29.5,45.5 grid=0.1m, but tigerlod-ingest "
            "wrote the others in albers lon0=-96 lat0=23 stdlat=29.5,45.5 grid=0.01m");
    // A store more, a store fewer, a level ingest did not write.
    fs::copy_file(keep, tract, fs::copy_options::overwrite_existing);
    fs::copy_file(keep, m_dir / "in" / "tract" / "51999.tlc");
    both(1, "tract: 2 chain stores, but tigerlod-ingest wrote 1 (ingest-report.json)");
    fs::remove(m_dir / "in" / "tract" / "51999.tlc");
    fs::remove(tract);
    both(1, "tract: tigerlod-ingest wrote 1 chain stores of level 'tract' here, and none is left");
    fs::copy_file(keep, tract);
    fs::create_directories(m_dir / "in" / "zone");
    fs::copy_file(keep, m_dir / "in" / "zone" / "51063.tlc");
    both(1, "zone: a level tigerlod-ingest did not write");
    fs::remove_all(m_dir / "in" / "zone");
    // No report: not a finished ingest output.
    fs::rename(m_dir / "in" / "ingest-report.json", m_dir / "report.json");
    both(1, "no ingest-report.json: not a finished tigerlod-ingest output");
    fs::rename(m_dir / "report.json", m_dir / "in" / "ingest-report.json");
    // Put back as ingest wrote it: both run.
    EXPECT_EQ(run("color", in + " " + out() + " --tolerances 8").code, 0) << slurp(m_dir / "stderr");
}

TEST_F(Cli, PackDumpExportAndVerifyRejectBadInput)
{
    make_tiger();
    const std::string in = (m_dir / "in").string(), simp = (m_dir / "simp").string(), tree = (m_dir / "tree").string();
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + in).code, 0);
    ASSERT_EQ(run("simplify", in + " " + simp + " --tolerances 8").code, 0);
    ASSERT_EQ(run("pack", in + " " + simp + " " + tree).code, 0) << slurp(m_dir / "stderr");
    // pack
    const std::string pack_args = in + " " + simp + " " + out();
    expect_failure(run("pack", pack_args + " --tile-mb 0"), 2, "option '--tile-mb' must be in (0, 4096]");
    expect_failure(run("pack", pack_args + " --draco-speed 11"), 2, "option '--draco-speed' must be in 0..10");
    expect_failure(run("pack", pack_args + " --threads -1"), 2, "option '--threads' must be in 0..1024");
    expect_failure(run("pack", in + " " + (m_dir / "nosimp").string() + " " + out()), 1,
                   "nosimp: no manifest.json: not a finished tigerlod-simplify output");
    expect_failure(run("pack", in + " " + in + " " + out()), 1,
                   "in/manifest.json: written by tigerlod-ingest, not tigerlod-simplify");
    // dump
    expect_failure(run("dump", tree + " --lod 1"), 2, "'--lod' and '--geojson' need '--node'");
    expect_failure(run("dump", tree + " --node root --lod -1"), 2, "option '--lod' must be >= 0");
    expect_failure(run("dump", tree + " --node root --lod 5"), 2, "no LOD 5 (the tree has 2)");
    expect_failure(run("dump", in + "/tract/51063.tlc --node root"), 2, "'--node' needs a Data Tree");
    // export: nothing written under any name
    auto no_export = [&] {
        for (const auto& e : fs::directory_iterator(m_dir)) {
            EXPECT_NE(e.path().filename().string().rfind("x", 0), 0U) << e.path();
        }
    };
    const std::string gpkg = (m_dir / "x.gpkg").string();
    expect_failure(run("export", tree + " " + gpkg + " --node root --level tract"), 2,
                   "give '--node' or '--level', not both");
    expect_failure(run("export", tree + " " + (m_dir / "x.shp").string()), 2, "OUTPUT must end in .gpkg or .geojson");
    expect_failure(run("export", tree + " " + gpkg + " --layer roads"), 2,
                   "option '--layer' must be chains, units or unit_points");
    expect_failure(run("export", tree + " " + gpkg + " --lod 7"), 2, "no LOD 7 (the tree has 2)");
    expect_failure(run("export", tree + " " + gpkg + " --node nowhere"), 2, "no node 'nowhere'");
    expect_failure(run("export", tree + " " + gpkg + " --level nowhere"), 2, "no level 'nowhere' in the tree");
    no_export();
    // verify
    const std::string verify_args = tree + " " + in + " " + out();
    // Simplify's options come from the tree's manifest, never by hand.
    expect_failure(run("verify", verify_args + " --class-scale S1400=0.5"), 2, "unknown option '--class-scale'");
    expect_failure(run("verify", verify_args + " --points " + (m_dir / "points.csv").string()), 2,
                   "unknown option '--points'");
    expect_failure(run("verify", verify_args + " --compare " + (m_dir / "old.json").string()), 2, "no such file");
    std::ofstream(m_dir / "old.json") << R"({"schema": "tigerlod.color-report/1"})";
    expect_failure(run("verify", verify_args + " --compare " + (m_dir / "old.json").string()), 1,
                   "old.json: not a tigerlod.verify-report/1");
    std::ofstream(m_dir / "old.json") << "{\"schema\": ";
    expect_failure(run("verify", verify_args + " --compare " + (m_dir / "old.json").string()), 1, "old.json: ");
    expect_failure(run("verify", verify_args + " --max-items -1"), 2, "option '--max-items' must be >= 0");
    expect_failure(run("verify", tree + " " + (m_dir / "noingest").string() + " " + out()), 2, "not a folder");
    // A clean run for contrast: exit 0.
    EXPECT_EQ(run("verify", verify_args).code, 0) << slurp(m_dir / "stderr");
}

namespace {

/// Every file under `dir`, by path relative to it, with its bytes.
std::map<std::string, std::string> files_under(const fs::path& dir)
{
    std::map<std::string, std::string> out;
    for (const auto& e : fs::recursive_directory_iterator(dir)) {
        if (e.is_regular_file()) {
            out[fs::relative(e.path(), dir).string()] = slurp(e.path());
        }
    }
    return out;
}

} // namespace

TEST_F(Cli, PackResumesAKilledFirstRunAndRepairsDamagedTiles)
{
    make_tiger();
    const std::string in = (m_dir / "in").string(), simp = (m_dir / "simp").string(), tree = (m_dir / "tree").string();
    ASSERT_EQ(run("ingest", tiger_config().string() + " " + in).code, 0);
    ASSERT_EQ(run("simplify", in + " " + simp + " --tolerances 8,32").code, 0);
    const std::string pack_args = " --tile-mb 0.0001 " + in + " " + simp + " ";
    ASSERT_EQ(run("pack", pack_args + tree).code, 0) << slurp(m_dir / "stderr");
    auto want = files_under(m_dir / "tree");
    want.erase("pack-report.json"); // its seconds vary
    std::vector<fs::path> tiles;
    for (const auto& e : fs::directory_iterator(m_dir / "tree" / "tiles")) {
        tiles.push_back(e.path());
    }
    std::sort(tiles.begin(), tiles.end());
    ASSERT_GE(tiles.size(), 3U);
    const std::string dead = std::to_string(tigerlod::testing::dead_pid()), live = std::to_string(::getpid());

    // A first pack killed before its skeleton: some tiles, temporaries of a
    // dead run. Before, every rerun exited 2 ("not a Data Tree").
    fs::copy(m_dir / "tree", m_dir / "killed", fs::copy_options::recursive);
    const fs::path killed = m_dir / "killed";
    fs::rename(killed / "skeleton.tls", killed / ("skeleton.tls.tmp-" + dead));
    fs::remove(killed / "pack-report.json");
    fs::remove(killed / "tiles" / tiles[0].filename());
    std::ofstream(killed / "tiles" / (tiles[1].filename().string() + ".tmp-" + dead)) << "half a tile";
    // Another run's temporary that is alive, and one of another host: not ours to remove.
    std::ofstream(killed / "tiles" / ("zz.tlt.tmp-" + live)) << "x";
    std::ofstream(killed / "tiles" / ("zz.tlt.tmp-otherhost-" + dead)) << "x";
    Result r = run("pack", "--verbose" + pack_args + killed.string());
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("(1 written, " + std::to_string(tiles.size() - 1) + " kept, 0 repaired, 0 removed)"),
              std::string::npos)
        << r.out;
    EXPECT_NE(r.err.find("removed " + (killed / ("skeleton.tls.tmp-" + dead)).string() + ", left by a run that died"),
              std::string::npos)
        << r.err;
    auto got = files_under(killed);
    got.erase("pack-report.json");
    EXPECT_EQ(got.erase("tiles/zz.tlt.tmp-" + live), 1U);
    EXPECT_EQ(got.erase("tiles/zz.tlt.tmp-otherhost-" + dead), 1U);
    EXPECT_EQ(got, want);

    // A kept tile with a flipped byte (same name, same size) is rewritten;
    // before, it was kept and verify failed.
    {
        std::string bytes = slurp(tiles[2]);
        bytes[bytes.size() / 2] ^= 0x10;
        std::ofstream(tiles[2], std::ios::binary) << bytes;
    }
    r = run("pack", pack_args + tree);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("(0 written, " + std::to_string(tiles.size() - 1) + " kept, 1 repaired, 0 removed)"),
              std::string::npos)
        << r.out;
    got = files_under(m_dir / "tree");
    got.erase("pack-report.json");
    EXPECT_EQ(got, want);
    EXPECT_EQ(run("verify", tree + " " + in + " " + out()).code, 0) << slurp(m_dir / "stderr");
    fs::remove_all(m_dir / "out");

    // A folder without a skeleton that holds a file pack does not write is
    // still refused: it may be someone's data.
    fs::remove(killed / "skeleton.tls");
    std::ofstream(killed / "notes.txt") << "mine";
    r = run("pack", pack_args + killed.string());
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_NE(r.err.find("exists and is not a Data Tree"), std::string::npos) << r.err;
    EXPECT_EQ(slurp(killed / "notes.txt"), "mine");

    // A pack that fails after writing tiles (here: its skeleton cannot be
    // renamed into place) removes the tiles it created.
    fs::remove_all(killed);
    fs::create_directories(killed / "skeleton.tls" / "in-the-way");
    r = run("pack", pack_args + killed.string());
    EXPECT_EQ(r.code, 3) << r.err;
    EXPECT_NE(r.err.find("skeleton.tls: cannot rename into place"), std::string::npos) << r.err;
    EXPECT_TRUE(fs::is_empty(killed / "tiles"));
}

TEST_F(Cli, StagesRemoveWhatADeadRunLeftBesideTheirOutput)
{
    // Killed runs leave OUTPUT.tmp-<host>-<pid> (and .old- during the swap);
    // the next run of a stage on the same output removes them, and only them.
    make_tiger();
    const std::string dead = std::to_string(tigerlod::testing::dead_pid()), live = std::to_string(::getpid());
    fs::create_directories(m_dir / ("in.tmp-" + dead) / "tract");
    fs::create_directories(m_dir / ("in.old-" + dead));
    fs::create_directories(m_dir / ("in.tmp-" + live));
    fs::create_directories(m_dir / ("simp.tmp-" + dead));
    const std::string in = (m_dir / "in").string();
    const Result r = run("ingest", "--verbose " + tiger_config().string() + " " + in);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("removed " + (m_dir / ("in.old-" + dead)).string() + ", left by a run that died"),
              std::string::npos)
        << r.err;
    EXPECT_FALSE(fs::exists(m_dir / ("in.tmp-" + dead)));
    EXPECT_FALSE(fs::exists(m_dir / ("in.old-" + dead)));
    EXPECT_TRUE(fs::exists(m_dir / ("in.tmp-" + live)));   // a live process's
    EXPECT_TRUE(fs::exists(m_dir / ("simp.tmp-" + dead))); // another output's: its own stage's business
    ASSERT_EQ(run("simplify", in + " " + (m_dir / "simp").string() + " --tolerances 8").code, 0);
    EXPECT_FALSE(fs::exists(m_dir / ("simp.tmp-" + dead)));
    // export's temporary keeps the extension: x.tmp-<host>-<pid>.gpkg
    ASSERT_EQ(run("pack", in + " " + (m_dir / "simp").string() + " " + (m_dir / "tree").string()).code, 0);
    std::ofstream(m_dir / ("x.tmp-" + dead + ".gpkg")) << "half";
    ASSERT_EQ(run("export", (m_dir / "tree").string() + " " + (m_dir / "x.gpkg").string()).code, 0)
        << slurp(m_dir / "stderr");
    EXPECT_FALSE(fs::exists(m_dir / ("x.tmp-" + dead + ".gpkg")));
}

TEST_F(Cli, ExportWritesEachUnitOnceAsAValidPolygon)
{
    // Tract T of county 001: a square with two holes, tract W east of it.
    // Island I (tract 200) is all of county 002, an enclave: it is whole in
    // county 001's map too. Triangle H (tract 300, county 001) touches T's
    // outer ring at V (3, 0): T's boundary passes V twice, and V is inside
    // a chain of T's shell (the shell's chains end at W's corners). Before, export wrote I twice and T as one
    // self-touching ring, which GEOS reports invalid.
    auto p = [](double x, double y) {
        std::ostringstream o;
        o.precision(10);
        o << (-96.0 + 0.001 * x) << " " << (40.0 + 0.001 * y);
        return o.str();
    };
    auto line = [&](double x0, double y0, double x1, double y1) {
        return "LINESTRING (" + p(x0, y0) + "," + p(x1, y1) + ")";
    };
    const std::vector<std::vector<std::string>> edges = {
        {line(0, 0, 3, 0), "1", "101", "900", "F"},  {line(3, 0, 6, 0), "2", "101", "900", "F"},
        {line(6, 0, 6, 6), "3", "101", "104", "F"},  {line(6, 6, 0, 6), "4", "101", "900", "F"},
        {line(0, 6, 0, 0), "5", "101", "900", "F"},  {line(3, 0, 4, 1), "6", "103", "101", "F"},
        {line(4, 1, 2, 1), "7", "103", "101", "F"},  {line(2, 1, 3, 0), "8", "103", "101", "F"},
        {line(2, 2, 4, 2), "9", "102", "101", "F"},  {line(4, 2, 4, 4), "10", "102", "101", "F"},
        {line(4, 4, 2, 4), "11", "102", "101", "F"}, {line(2, 4, 2, 2), "12", "102", "101", "F"},
        {line(6, 0, 9, 0), "13", "104", "900", "F"}, {line(9, 0, 9, 6), "14", "104", "900", "F"},
        {line(9, 6, 6, 6), "15", "104", "900", "F"}};
    write_shp(m_dir / "edges.shp", wkbLineString, {"TLID", "TFIDL", "TFIDR", "MTFCC"}, edges);
    auto point = [](double x, double y) {
        char lat[32], lon[32];
        std::snprintf(lat, sizeof lat, "%+.7f", 40.0 + 0.001 * y);
        std::snprintf(lon, sizeof lon, "%+.7f", -96.0 + 0.001 * x);
        return std::pair<std::string, std::string>(lat, lon);
    };
    const auto [t_lat, t_lon] = point(1, 4);
    const auto [i_lat, i_lon] = point(3, 3);
    const auto [h_lat, h_lon] = point(3, 0.5);
    const auto [w_lat, w_lon] = point(7.5, 3);
    const std::string square =
        "POLYGON ((" + p(0, 0) + "," + p(6, 0) + "," + p(6, 6) + "," + p(0, 6) + "," + p(0, 0) + "))";
    const std::vector<std::vector<std::string>> faces = {
        {square, "101", "51", "001", "000100", "1", "1000", t_lat, t_lon, "5"},
        {square, "102", "51", "002", "000200", "1", "1000", i_lat, i_lon, "5"},
        {square, "103", "51", "001", "000300", "1", "1000", h_lat, h_lon, "5"},
        {square, "104", "51", "001", "000400", "1", "1000", w_lat, w_lon, "5"}};
    write_shp(m_dir / "faces.shp", wkbPolygon, m_face_fields, faces);
    zip(m_dir / "edges.zip", shp_files(m_dir / "edges.shp"));
    zip(m_dir / "faces.zip", shp_files(m_dir / "faces.shp"));
    const fs::path cfg = tiger_config("edges.zip", "faces.zip",
                                      "levels:\n  - {name: state, fields: [STATEFP20]}\n"
                                      "  - {name: county, fields: [STATEFP20, COUNTYFP20]}\n"
                                      "  - {name: tract, fields: [STATEFP20, COUNTYFP20, TRACTCE20]}\n");
    const std::string in = (m_dir / "in").string(), simp = (m_dir / "simp").string(), tree = (m_dir / "tree").string();
    ASSERT_EQ(run("ingest", cfg.string() + " " + in).code, 0) << slurp(m_dir / "stderr");
    ASSERT_EQ(run("simplify", in + " " + simp + " --tolerances 8").code, 0) << slurp(m_dir / "stderr");
    ASSERT_EQ(run("pack", in + " " + simp + " " + tree).code, 0) << slurp(m_dir / "stderr");
    ASSERT_EQ(run("verify", tree + " " + in + " " + out()).code, 0) << slurp(m_dir / "stderr");
    for (const int lod : {0, 1}) {
        SCOPED_TRACE(lod);
        const fs::path gpkg = m_dir / ("tracts" + std::to_string(lod) + ".gpkg");
        ASSERT_EQ(run("export", tree + " " + gpkg.string() + " --level tract --lod " + std::to_string(lod)).code, 0)
            << slurp(m_dir / "stderr");
        GDALDatasetH ds = GDALOpenEx(gpkg.c_str(), GDAL_OF_VECTOR, nullptr, nullptr, nullptr);
        ASSERT_NE(ds, nullptr);
        OGRLayerH units = GDALDatasetGetLayerByName(ds, "units");
        ASSERT_NE(units, nullptr);
        std::map<std::string, int> seen;
        OGRFeatureH f = nullptr;
        while ((f = OGR_L_GetNextFeature(units)) != nullptr) {
            const std::string unit = OGR_F_GetFieldAsString(f, 0);
            ++seen[unit];
            OGRGeometryH g = OGR_F_GetGeometryRef(f);
            EXPECT_TRUE(OGR_G_IsValid(g)) << unit;
            if (unit == "51001000100") {
                ASSERT_EQ(OGR_G_GetGeometryCount(g), 1);                          // one polygon
                EXPECT_EQ(OGR_G_GetGeometryCount(OGR_G_GetGeometryRef(g, 0)), 3); // its shell and two holes
            }
            OGR_F_Destroy(f);
        }
        GDALClose(ds);
        EXPECT_EQ(seen, (std::map<std::string, int>{
                            {"51001000100", 1}, {"51001000300", 1}, {"51001000400", 1}, {"51002000200", 1}}));
    }
}

TEST_F(Cli, MessagesSayWhatIsWrongAndWhatToDo)
{
    make_tiger();
    // A config path that is a folder: was "internal error".
    fs::create_directories(m_dir / "cfgdir");
    expect_failure(run("ingest", (m_dir / "cfgdir").string() + " " + out()), 2,
                   "cfgdir: is a folder, not a config file");
    // A shapefile without its .dbf: was "no field 'TLID'" alone.
    fs::remove(m_dir / "edges.dbf");
    expect_failure(run("ingest", tiger_config("edges.shp", "faces.zip").string() + " " + out()), 1,
                   "no field 'TLID' (TIGER EDGES edge id); the layer has no attributes at all: " +
                       (m_dir / "edges.dbf").string() + " (its attributes) is missing beside it");
    // A tiger dataset without FACES: says how to read EDGES alone.
    expect_failure(run("ingest", config("dataset:\n  kind: tiger\n  edges: [edges.zip]\n").string() + " " + out()), 2,
                   "a tiger dataset needs 'edges' and 'faces' (EDGES alone, as lines without units: kind: lines");
    // A projected layer: says how to reproject.
    ASSERT_EQ(std::system(("ogr2ogr -t_srs EPSG:5070 " + (m_dir / "albers.shp").string() + " " +
                           (m_dir / "faces.shp").string() + " 2>/dev/null")
                              .c_str()),
              0);
    expect_failure(
        run("ingest", config("dataset:\n  kind: polygons\n  inputs: [albers.shp]\n  code_field: TFID\nlevels:\n  - "
                             "{name: a, prefix: 1}\n")
                              .string() +
                          " " + out()),
        1,
        "layer has a projected CRS; tigerlod reads lon/lat (NAD83 or WGS84): reproject it first, e.g. ogr2ogr -t_srs "
        "EPSG:4269 OUT.shp " +
            (m_dir / "albers.shp").string());
    // Tolerances as the user wrote them: was "1 follows 4.000000".
    for (const std::string tool : {"color", "simplify"}) {
        expect_failure(run(tool, m_dir.string() + " " + out() + " --tolerances 4,1"), 2,
                       "option '--tolerances' must increase: 1 follows 4\n");
    }
    // dump: a folder that is not a tree exits 2 as a missing store does (was 1).
    expect_failure(run("dump", (m_dir / "cfgdir").string()), 2,
                   "cfgdir: a folder without skeleton.tls, not a Data Tree");
}
