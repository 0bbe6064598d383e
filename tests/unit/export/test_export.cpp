// tigerlod-export as a GIS reads it: a tree of long segments (a chain from
// California to Maine, one up Alaska), exported in the tree's CRS and in
// lon/lat, read back with GDAL and moved between CRSs with PROJ (through
// GDAL's OGRCoordinateTransformation), none of tigerlod's projection code:
// in the tree's CRS every vertex comes back as the tree's; in lon/lat
// every vertex is kept and the lines between the written points stay
// within the stated bow of the tree's segments.
#include "core/projection.hpp"
#include "formats/chains/chain_store.hpp"
#include "stages/export/lonlat_line.hpp"
#include "stages/pack/packer.hpp"
#include "../../support/ground_distance.hpp"
#include "../../support/run_tool.hpp"

#include <gdal.h>
#include <ogr_api.h>
#include <ogr_srs_api.h>

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>

namespace fs = std::filesystem;
using namespace tigerlod;
using chains::ChainStore;
using Pts = std::vector<GridPoint>;

namespace {

Pts long_chain(const Projection& proj, const std::vector<std::pair<double, double>>& lonlat)
{
    Pts pts;
    for (const auto& [lon, lat] : lonlat) {
        pts.push_back(*proj.to_grid(lon, lat));
    }
    return pts;
}

class Export : public ::testing::Test {
  protected:
    fs::path dir;
    Pts a, b; // the two chains
    Projection proj{ProjectionParams{}};
    void SetUp() override
    {
        dir = fs::temp_directory_path() /
              ("tigerlod-export-" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "-" +
               std::to_string(::getpid()));
        fs::remove_all(dir);
        a = long_chain(proj, {{-122.4, 37.8}, {-104.99, 39.74}, {-87.6, 41.9}, {-70.3, 43.7}});
        b = long_chain(proj, {{-149.9, 61.2}, {-147.7, 64.8}, {-156.8, 71.3}});
        ChainStore s;
        s.level_name = "lines";
        s.partition = "all";
        s.halo_m = 10000;
        s.add_chain({1, s.intern(""), s.intern(""), s.intern("coast"), 0, 0, 0}, a);
        s.add_chain({2, s.intern(""), s.intern(""), s.intern("coast"), 0, 0, 0}, b);
        s.canonicalize();
        fs::create_directories(dir / "orig" / "lines");
        fs::create_directories(dir / "simp" / "eps-1000m" / "lines");
        chains::write(dir / "orig" / "lines" / "all.tlc", s);
        ChainStore t = s;
        t.eps_m = 1000;
        chains::write(dir / "simp" / "eps-1000m" / "lines" / "all.tlc", t);
        pack::write_tree(dir / "tree", pack::build_tree(dir / "orig", dir / "simp", {}), "{}\n");
        GDALAllRegister();
    }
    void TearDown() override { fs::remove_all(dir); }

    int run(const std::string& args)
    {
        return tigerlod::testing::run_tool(TIGERLOD_BIN_DIR, "export", args, dir / "log");
    }

    /// The chains layer read back: per chain id, its points, in the file's CRS
    /// or moved into `to_epsg`'s; and the layer's CRS name.
    std::map<int64_t, std::vector<std::pair<double, double>>> read_back(const fs::path& file, int to_epsg,
                                                                        std::string& crs)
    {
        std::map<int64_t, std::vector<std::pair<double, double>>> out;
        GDALDatasetH ds = GDALOpenEx(file.c_str(), GDAL_OF_VECTOR, nullptr, nullptr, nullptr);
        EXPECT_TRUE(ds) << file;
        if (!ds) {
            return out;
        }
        OGRLayerH layer = GDALDatasetGetLayerByName(ds, "chains");
        if (!layer) {
            layer = GDALDatasetGetLayer(ds, 0);
        }
        OGRSpatialReferenceH srs = OGR_L_GetSpatialRef(layer);
        EXPECT_TRUE(srs);
        const char* name = srs ? OSRGetAttrValue(srs, "PROJCS", 0) : nullptr;
        if (!name && srs) {
            name = OSRGetAttrValue(srs, "GEOGCS", 0);
        }
        crs = name ? name : "";
        OGRCoordinateTransformationH ct = nullptr;
        if (to_epsg != 0 && srs) {
            OGRSpatialReferenceH target = OSRNewSpatialReference(nullptr);
            OSRImportFromEPSG(target, to_epsg);
            OSRSetAxisMappingStrategy(target, OAMS_TRADITIONAL_GIS_ORDER);
            OGRSpatialReferenceH source = OSRClone(srs);
            OSRSetAxisMappingStrategy(source, OAMS_TRADITIONAL_GIS_ORDER);
            ct = OCTNewCoordinateTransformation(source, target);
            OSRDestroySpatialReference(source);
            OSRDestroySpatialReference(target);
        }
        OGR_L_ResetReading(layer);
        while (OGRFeatureH f = OGR_L_GetNextFeature(layer)) {
            const int64_t id = OGR_F_GetFieldAsInteger64(f, OGR_F_GetFieldIndex(f, "chain_id"));
            OGRGeometryH g = OGR_F_GetGeometryRef(f);
            for (int i = 0; i < OGR_G_GetPointCount(g); ++i) {
                double x = OGR_G_GetX(g, i), y = OGR_G_GetY(g, i), z = 0;
                if (ct) {
                    EXPECT_TRUE(OCTTransform(ct, 1, &x, &y, &z));
                }
                out[id].emplace_back(x, y);
            }
            OGR_F_Destroy(f);
        }
        if (ct) {
            OCTDestroyCoordinateTransformation(ct);
        }
        GDALClose(ds);
        return out;
    }
};

} // namespace

TEST_F(Export, InTheTreesCrsEveryVertexIsTheTreesAndTheCrsIsNamed)
{
    for (const char* file : {"x.gpkg", "x.geojson"}) {
        SCOPED_TRACE(file);
        ASSERT_EQ(run("--lod 1 " + (dir / "tree").string() + " " + (dir / file).string()), 0)
            << tigerlod::testing::slurp(dir / "log");
        std::string crs;
        const auto chains = read_back(dir / file, 0, crs);
        EXPECT_EQ(crs, "NAD83 / Conus Albers"); // EPSG:5070
        ASSERT_EQ(chains.size(), 2U);
        for (const auto& [id, want] : {std::pair{int64_t{1}, a}, std::pair{int64_t{2}, b}}) {
            const auto& got = chains.at(id);
            ASSERT_EQ(got.size(), want.size());
            for (size_t i = 0; i < got.size(); ++i) {
                EXPECT_EQ(std::llround(got[i].first / 0.01), want[i].x);
                EXPECT_EQ(std::llround(got[i].second / 0.01), want[i].y);
                EXPECT_NEAR(got[i].first, want[i].x * 0.01, 1e-6);
            }
        }
    }
}

TEST_F(Export, AGeoPackageHasTheSameBytesWhenWrittenAgain)
{
    // GDAL stamps gpkg_contents.last_change with the time of writing unless
    // told a date: the export fixes it (the epoch, or SOURCE_DATE_EPOCH).
    ASSERT_EQ(run("--lod 1 " + (dir / "tree").string() + " " + (dir / "d.gpkg").string()), 0)
        << tigerlod::testing::slurp(dir / "log");
    GDALDatasetH ds = GDALOpenEx((dir / "d.gpkg").c_str(), GDAL_OF_VECTOR, nullptr, nullptr, nullptr);
    ASSERT_NE(ds, nullptr);
    const auto count = [&](const char* sql) {
        OGRLayerH rows = GDALDatasetExecuteSQL(ds, sql, nullptr, nullptr);
        EXPECT_NE(rows, nullptr) << sql;
        int64_t n = -1;
        if (OGRFeatureH f = rows ? OGR_L_GetNextFeature(rows) : nullptr) {
            n = OGR_F_GetFieldAsInteger64(f, 0);
            OGR_F_Destroy(f);
        }
        if (rows) {
            GDALDatasetReleaseResultSet(ds, rows);
        }
        return n;
    };
    EXPECT_GE(count("SELECT COUNT(*) FROM gpkg_contents"), 1);
    EXPECT_EQ(count("SELECT COUNT(*) FROM gpkg_contents WHERE last_change <> '1970-01-01T00:00:00.000Z'"), 0);
    GDALClose(ds);
    ASSERT_EQ(run("--lod 1 " + (dir / "tree").string() + " " + (dir / "e.gpkg").string()), 0);
    EXPECT_EQ(tigerlod::testing::slurp(dir / "d.gpkg"), tigerlod::testing::slurp(dir / "e.gpkg"));
}

TEST_F(Export, SourceDateEpochDatesTheFileOrIsRefused)
{
    // The reproducible-builds convention: the file carries that date; a
    // value that is no date is exit 2 naming it, with no file written.
    struct Env {
        explicit Env(const char* v) { ::setenv("SOURCE_DATE_EPOCH", v, 1); }
        ~Env() { ::unsetenv("SOURCE_DATE_EPOCH"); }
        Env(const Env&) = delete;
        Env& operator=(const Env&) = delete;
    };
    {
        const Env env("86400");
        ASSERT_EQ(run("--lod 1 " + (dir / "tree").string() + " " + (dir / "day.gpkg").string()), 0)
            << tigerlod::testing::slurp(dir / "log");
    }
    GDALDatasetH ds = GDALOpenEx((dir / "day.gpkg").c_str(), GDAL_OF_VECTOR, nullptr, nullptr, nullptr);
    ASSERT_NE(ds, nullptr);
    OGRLayerH rows = GDALDatasetExecuteSQL(
        ds, "SELECT COUNT(*) FROM gpkg_contents WHERE last_change = '1970-01-02T00:00:00.000Z'", nullptr, nullptr);
    ASSERT_NE(rows, nullptr);
    OGRFeatureH f = OGR_L_GetNextFeature(rows);
    ASSERT_NE(f, nullptr);
    EXPECT_GE(OGR_F_GetFieldAsInteger64(f, 0), 1);
    OGR_F_Destroy(f);
    GDALDatasetReleaseResultSet(ds, rows);
    GDALClose(ds);
    for (const char* bad : {"yesterday", "-1", "1e9", " 5", "253402300800", "99999999999999999999999"}) {
        SCOPED_TRACE(bad);
        const Env env(bad);
        EXPECT_EQ(run("--lod 1 " + (dir / "tree").string() + " " + (dir / "bad.geojson").string()), 2);
        const std::string log = tigerlod::testing::slurp(dir / "log");
        EXPECT_NE(log.find(std::string("SOURCE_DATE_EPOCH is '") + bad + "'"), std::string::npos) << log;
        EXPECT_FALSE(fs::exists(dir / "bad.geojson"));
    }
    bool leftover = false;
    for (const auto& e : fs::directory_iterator(dir)) {
        leftover = leftover || e.path().filename().string().rfind("bad", 0) == 0;
    }
    EXPECT_FALSE(leftover);
}

TEST_F(Export, InLonLatSegmentsAreDensifiedWithinTheStatedBow)
{
    // 1 % of the LOD's 1000 m: 10 m.
    ASSERT_EQ(run("--lod 1 --crs lonlat " + (dir / "tree").string() + " " + (dir / "ll.gpkg").string()), 0)
        << tigerlod::testing::slurp(dir / "log");
    std::string crs;
    const auto chains = read_back(dir / "ll.gpkg", 0, crs);
    EXPECT_EQ(crs, "NAD83");
    // PROJ moves the points into EPSG:5070: every vertex of the tree is there.
    std::string crs5070;
    const auto moved = read_back(dir / "ll.gpkg", 5070, crs5070);
    for (const auto& [id, want] : {std::pair{int64_t{1}, a}, std::pair{int64_t{2}, b}}) {
        SCOPED_TRACE("chain " + std::to_string(id));
        const auto& ll = chains.at(id);
        const auto& xy = moved.at(id);
        EXPECT_GT(ll.size(), 20 * want.size()); // thousands of km: densified
        size_t next = 0;
        for (const auto& [x, y] : xy) {
            if (next < want.size() && std::hypot(x - want[next].x * 0.01, y - want[next].y * 0.01) < 1e-3) {
                ++next;
            }
        }
        EXPECT_EQ(next, want.size()) << "the tree's vertices, in order, within 1 mm";
        // The straight lon/lat line between written points, sampled, stays
        // within 10 m on the ground of the tree's segment it follows.
        double worst = 0;
        size_t seg = 0;
        for (size_t i = 0; i + 1 < ll.size(); ++i) {
            // The tree's segment this piece lies on: the one whose end comes next.
            GridPoint p0 = want[seg], p1 = want[seg + 1];
            for (int j = 1; j < 8; ++j) {
                const double t = j / 8.0;
                const double lon = ll[i].first + t * (ll[i + 1].first - ll[i].first);
                const double lat = ll[i].second + t * (ll[i + 1].second - ll[i].second);
                worst = std::max(worst, tigerlod::testing::ground_to_segment_m(proj, lon, lat, p0, p1, 400));
            }
            double gx = 0, gy = 0;
            proj.forward(ll[i + 1].first, ll[i + 1].second, gx, gy);
            if (seg + 2 < want.size() && std::hypot(gx - p1.x, gy - p1.y) < 0.1) {
                ++seg;
            }
        }
        EXPECT_LE(worst, 10.0);
        EXPECT_GT(worst, 1.0); // the bound is used, not far too many points
    }
}

TEST_F(Export, BadCrsOrBowIsAUsageError)
{
    EXPECT_EQ(run("--crs mercator " + (dir / "tree").string() + " " + (dir / "x.gpkg").string()), 2);
    EXPECT_NE(tigerlod::testing::slurp(dir / "log").find("'--crs' must be tree or lonlat"), std::string::npos);
    EXPECT_EQ(run("--crs lonlat --max-bow 0 " + (dir / "tree").string() + " " + (dir / "x.gpkg").string()), 2);
    EXPECT_FALSE(fs::exists(dir / "x.gpkg"));
}

TEST(LonLatLine, AShortSegmentIsLeftAloneALongOneBisected)
{
    const Projection proj{ProjectionParams{}};
    const Pts short_segment{*proj.to_grid(-96, 40), *proj.to_grid(-95.999, 40.0005)};
    EXPECT_EQ(exporter::densify_lonlat(proj, short_segment, 1.0).size(), 2U);
    const Pts long_segment{*proj.to_grid(-124, 48), *proj.to_grid(-68, 45)};
    const auto pts = exporter::densify_lonlat(proj, long_segment, 1.0);
    EXPECT_GT(pts.size(), 100U);
    EXPECT_LT(pts.size(), 5000U);
    // A bow of kilometres undensified.
    EXPECT_GT(exporter::lonlat_bow_m(proj, long_segment[0].x, long_segment[0].y, long_segment[1].x, long_segment[1].y),
              1e4);
}

namespace {

/// A square feature of a GeoJSON polygon layer: its code and its properties' JSON.
struct Square {
    double lon, lat, side;
    std::string props;
};
void write_squares(const fs::path& file, const std::vector<Square>& squares)
{
    std::ofstream out(file);
    out << R"({"type": "FeatureCollection", "features": [)";
    for (size_t i = 0; i < squares.size(); ++i) {
        const auto& [x, y, d, props] = squares[i];
        out << (i ? "," : "") << R"({"type": "Feature", "properties": {)" << props
            << R"(}, "geometry": {"type": "Polygon", "coordinates": [[[)" << x << "," << y << "],[" << x + d << "," << y
            << "],[" << x + d << "," << y + d << "],[" << x << "," << y + d << "],[" << x << "," << y << "]]]}}";
    }
    out << "]}";
}

/// One feature of a layer read back: its fields as text ("<null>" for
/// null), its geometry kept.
struct ReadFeature {
    std::map<std::string, std::string> fields;
    OGRGeometryH geometry = nullptr;
};

} // namespace

// From the source through ingest, simplify, pack and the reader to the
// export: the units' names and the attributes the config names, typed as
// every input file's field holds them, with each unit's internal point, in
// both CRSs; the point lies inside its unit's polygon at every LOD.
TEST(ExportUnits, NamesAttributesAndInternalPointsComeFromTheSourceThroughTheTree)
{
    const fs::path dir = fs::temp_directory_path() / ("tigerlod-export-units-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    // 01001 in two parts (merged), the larger first; 01002 beside it with
    // nulls; 02001 in another file, where ALAND is real and SHARE an integer.
    write_squares(
        dir / "a.geojson",
        {{-99.0, 40.0, 0.02, R"("code": "01001", "name": "Alpha small", "ALAND": 7, "SHARE": 9.25, "NOTE": "s")"},
         {-100.0, 40.0, 0.1, R"("code": "01001", "name": "Alpha", "ALAND": 100, "SHARE": 0.5, "NOTE": "x")"},
         {-99.9, 40.0, 0.1, R"("code": "01002", "name": "Beta", "ALAND": null, "SHARE": 2, "NOTE": null)"}});
    write_squares(dir / "b.geojson",
                  {{-90.0, 40.0, 0.1, R"("code": "02001", "name": "Gamma", "ALAND": 3.5, "SHARE": 1, "NOTE": "z")"}});
    std::ofstream(dir / "config.yaml")
        << "name: t\ndataset: {kind: polygons, inputs: [a.geojson, b.geojson], code_field: code, name_field: name,\n"
           "  attributes: [ALAND, SHARE, NOTE], duplicate_code: merge}\n"
           "levels:\n  - {name: state, prefix: 2}\n  - {name: county, prefix: 5}\n";
    auto tool = [&](const std::string& name, const std::string& args) {
        const int rc = tigerlod::testing::run_tool(TIGERLOD_BIN_DIR, name, args, dir / "log");
        EXPECT_EQ(rc, 0) << name << " " << args << ": " << tigerlod::testing::slurp(dir / "log");
        return rc == 0;
    };
    const std::string d = dir.string() + "/";
    ASSERT_TRUE(tool("ingest", d + "config.yaml " + d + "orig"));
    ASSERT_TRUE(tool("simplify", "--shortcut-test exact --tolerances 100,500 " + d + "orig " + d + "simp"));
    ASSERT_TRUE(tool("pack", d + "orig " + d + "simp " + d + "tree"));
    GDALAllRegister();
    auto read_layer = [&](const fs::path& file, const char* name, std::map<std::string, OGRFieldType>& types) {
        std::map<std::string, ReadFeature> out;
        GDALDatasetH ds = GDALOpenEx(file.c_str(), GDAL_OF_VECTOR, nullptr, nullptr, nullptr);
        EXPECT_TRUE(ds) << file;
        OGRLayerH layer = ds ? GDALDatasetGetLayerByName(ds, name) : nullptr;
        EXPECT_TRUE(layer) << file << " " << name;
        if (layer) {
            OGRFeatureDefnH defn = OGR_L_GetLayerDefn(layer);
            for (int i = 0; i < OGR_FD_GetFieldCount(defn); ++i) {
                OGRFieldDefnH fd = OGR_FD_GetFieldDefn(defn, i);
                types[OGR_Fld_GetNameRef(fd)] = OGR_Fld_GetType(fd);
            }
            while (OGRFeatureH f = OGR_L_GetNextFeature(layer)) {
                ReadFeature rf;
                for (int i = 0; i < OGR_FD_GetFieldCount(defn); ++i) {
                    rf.fields[OGR_Fld_GetNameRef(OGR_FD_GetFieldDefn(defn, i))] =
                        OGR_F_IsFieldSetAndNotNull(f, i) ? OGR_F_GetFieldAsString(f, i) : "<null>";
                }
                rf.geometry = OGR_G_Clone(OGR_F_GetGeometryRef(f));
                out[rf.fields["unit"]] = rf;
                OGR_F_Destroy(f);
            }
        }
        if (ds) {
            GDALClose(ds);
        }
        return out;
    };
    for (const int lod : {0, 1, 2}) {
        for (const std::string crs : {"tree", "lonlat"}) {
            const fs::path gpkg = dir / ("u" + std::to_string(lod) + crs + ".gpkg");
            ASSERT_TRUE(tool("export", d + "tree " + gpkg.string() + " --level county --lod " + std::to_string(lod) +
                                           " --crs " + crs));
            std::map<std::string, OGRFieldType> ptypes, utypes;
            auto points = read_layer(gpkg, "unit_points", ptypes);
            auto units = read_layer(gpkg, "units", utypes);
            ASSERT_EQ(points.size(), 3U);
            ASSERT_EQ(units.size(), 3U);
            // Integer in one file and real in the other: real; text stays text.
            for (auto* types : {&ptypes, &utypes}) {
                EXPECT_EQ((*types)["name"], OFTString);
                EXPECT_EQ((*types)["ALAND"], OFTReal);
                EXPECT_EQ((*types)["SHARE"], OFTReal);
                EXPECT_EQ((*types)["NOTE"], OFTString);
            }
            const std::map<std::string, std::vector<std::string>> want{{"01001", {"Alpha", "100", "0.5", "x"}},
                                                                       {"01002", {"Beta", "<null>", "2", "<null>"}},
                                                                       {"02001", {"Gamma", "3.5", "1", "z"}}};
            for (auto* layer : {&points, &units}) {
                for (const auto& [code, values] : want) {
                    const auto& f = (*layer)[code].fields;
                    EXPECT_EQ(std::vector<std::string>({f.at("name"), f.at("ALAND"), f.at("SHARE"), f.at("NOTE")}),
                              values)
                        << code << " LOD " << lod << " " << crs;
                }
            }
            for (auto& [code, p] : points) {
                ASSERT_TRUE(units[code].geometry) << code;
                EXPECT_TRUE(OGR_G_Within(p.geometry, units[code].geometry)) << code << " LOD " << lod << " " << crs;
                if (crs == "lonlat") {
                    // 01002's square: lon -99.9..-99.8, lat 40..40.1.
                    const double lon = OGR_G_GetX(p.geometry, 0), lat = OGR_G_GetY(p.geometry, 0);
                    if (code == "01002") {
                        EXPECT_TRUE(lon > -99.9 && lon < -99.8 && lat > 40 && lat < 40.1) << lon << " " << lat;
                    }
                }
            }
            for (auto* layer : {&points, &units}) {
                for (auto& [code, f] : *layer) {
                    OGR_G_DestroyGeometry(f.geometry);
                }
            }
        }
    }
    // GeoJSON: one layer, the points.
    ASSERT_TRUE(tool("export", d + "tree " + d + "p.geojson --level county --layer unit_points"));
    std::map<std::string, OGRFieldType> types;
    auto gj = read_layer(dir / "p.geojson", "unit_points", types);
    EXPECT_EQ(gj.size(), 3U);
    EXPECT_EQ(gj["02001"].fields["name"], "Gamma");
    for (auto& [code, f] : gj) {
        OGR_G_DestroyGeometry(f.geometry);
    }
    fs::remove_all(dir);
}
