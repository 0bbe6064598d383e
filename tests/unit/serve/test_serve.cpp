// tigerlod-serve: what each request gets (serve::Site, called directly), and
// the binary over a real socket (ranges, 304s, the port it prints). The tree
// is a hand-made map from GeoJSON through ingest, simplify and pack.
#include "core/fs.hpp"
#include "stages/serve/site.hpp"
#include "../../support/run_tool.hpp"

#include <httplib.h>
#include <nlohmann/json.hpp>

#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>

namespace fs = std::filesystem;
using namespace tigerlod;
using nlohmann::json;

namespace {

class Serve : public ::testing::Test {
  protected:
    static inline fs::path dir;
    static inline std::shared_ptr<const reader::Tree> tree;

    static void SetUpTestSuite()
    {
        dir = fs::temp_directory_path() / ("tigerlod-serve-" + std::to_string(::getpid()));
        fs::remove_all(dir);
        fs::create_directories(dir / "viewer");
        std::ofstream(dir / "map.geojson") << R"({"type": "FeatureCollection", "features": [
{"type": "Feature", "properties": {"code": "01001", "name": "Alpha"}, "geometry": {"type": "Polygon", "coordinates": [[[-100,40],[-99.9,40],[-99.9,40.1],[-100,40.1],[-100,40]]]}},
{"type": "Feature", "properties": {"code": "01002", "name": "Beta"}, "geometry": {"type": "Polygon", "coordinates": [[[-99.9,40],[-99.8,40],[-99.8,40.1],[-99.9,40.1],[-99.9,40]]]}},
{"type": "Feature", "properties": {"code": "02001", "name": "Gamma"}, "geometry": {"type": "Polygon", "coordinates": [[[-90,40],[-89.9,40],[-89.9,40.1],[-90,40.1],[-90,40]]]}}]})";
        std::ofstream(dir / "config.yaml") << "name: t\ndataset: {kind: polygons, inputs: [map.geojson], code_field: "
                                              "code, name_field: name}\nlevels:\n  - {name: state, prefix: 2}\n"
                                              "  - {name: county, prefix: 5}\n";
        std::ofstream(dir / "viewer" / "index.html") << "<!doctype html><title>v</title>";
        std::ofstream(dir / "viewer" / "viewer.js") << "export const x = 1;\n";
        std::ofstream(dir / "viewer" / ".hidden") << "secret";
        std::ofstream(dir / "secret.txt") << "not to be served";
        std::ofstream(dir / "report.json") << R"({"clean": true})";
        const std::string d = dir.string() + "/";
        for (const auto& [tool, args] : std::vector<std::pair<std::string, std::string>>{
                 {"ingest", d + "config.yaml " + d + "orig"},
                 {"simplify", "--shortcut-test exact --tolerances 100,500 " + d + "orig " + d + "simp"},
                 {"pack", d + "orig " + d + "simp " + d + "tree"}}) {
            ASSERT_EQ(tigerlod::testing::run_tool(TIGERLOD_BIN_DIR, tool, args, dir / "log"), 0)
                << tigerlod::testing::slurp(dir / "log");
        }
        std::string error;
        tree = reader::Tree::open(dir / "tree", error);
        ASSERT_TRUE(tree) << error;
    }
    static void TearDownTestSuite()
    {
        tree.reset();
        fs::remove_all(dir);
    }

    serve::Site site(uint64_t cache_bytes = 1 << 20) const
    {
        serve::SiteOptions o;
        o.viewer = dir / "viewer";
        o.verify = dir / "report.json";
        o.cache_bytes = cache_bytes;
        return serve::Site(tree, o);
    }
    static serve::Response get(const serve::Site& s, const std::string& path,
                               std::map<std::string, std::string> query = {}, std::string if_none_match = "")
    {
        serve::Request r;
        r.path = path;
        r.query = std::move(query);
        r.if_none_match = std::move(if_none_match);
        return s.handle(r);
    }
    static std::string header(const serve::Response& r, const std::string& name)
    {
        for (const auto& [k, v] : r.headers) {
            if (k == name) {
                return v;
            }
        }
        return "";
    }
};

TEST_F(Serve, TheSkeletonAndEveryTileAsTheirFilesWithETagsAnd304s)
{
    const auto s = site();
    const auto sk = get(s, "/tree/skeleton.tls");
    ASSERT_EQ(sk.status, 200);
    EXPECT_EQ(sk.body, read_file(dir / "tree" / "skeleton.tls"));
    const std::string etag = header(sk, "ETag");
    ASSERT_FALSE(etag.empty());
    EXPECT_EQ(get(s, "/tree/skeleton.tls", {}, etag).status, 304);
    EXPECT_EQ(get(s, "/tree/skeleton.tls", {}, etag).body, "");
    EXPECT_EQ(get(s, "/tree/skeleton.tls", {}, "\"other\"").status, 200);
    ASSERT_FALSE(tree->skeleton().tiles.empty());
    for (const auto& t : tree->skeleton().tiles) {
        const auto r = get(s, "/" + fs::path("tree").append(t.file).string());
        ASSERT_EQ(r.status, 200) << t.file;
        EXPECT_EQ(r.body, read_file(dir / "tree" / t.file));
        EXPECT_EQ(header(r, "Cache-Control"), "public, max-age=31536000, immutable");
        EXPECT_EQ(get(s, "/tree/" + t.file, {}, header(r, "ETag")).status, 304);
    }
}

TEST_F(Serve, NothingOutsideTheTreeAndTheViewerIsServed)
{
    const auto s = site();
    const std::string tile = fs::path(tree->skeleton().tiles.front().file).filename().string();
    for (const std::string& path : std::vector<std::string>{"/tree/tiles/../skeleton.tls",
                                                            "/tree/tiles/../../secret.txt",
                                                            "/tree/../secret.txt",
                                                            "/tree/secret.txt",
                                                            "/tree/tiles/" + tile + "/..",
                                                            "/tree/tiles/x.tlt",
                                                            "/tree/tiles/",
                                                            "/tree/tiles",
                                                            "/tree/manifest.json",
                                                            "/tree/pack-report.json",
                                                            "/viewer/../secret.txt",
                                                            "/viewer/.hidden",
                                                            "/viewer/",
                                                            "/viewer/nope.js",
                                                            "/viewer/../../etc/passwd",
                                                            "/etc/passwd",
                                                            "/secret.txt",
                                                            "//secret.txt",
                                                            "/api",
                                                            "/api/node",
                                                            "/api/node/0",
                                                            "/api/node/99/0",
                                                            "/api/node/0/99",
                                                            "/api/node/-1/0",
                                                            "/api/node/0x1/0",
                                                            "/api/node/4294967296/0",
                                                            "/api/units/9",
                                                            "/api/table/x",
                                                            "/api/front/x",
                                                            "/api/tree/x"}) {
        const auto r = get(s, path);
        EXPECT_EQ(r.status, 404) << path << ": " << r.body;
        EXPECT_EQ(r.body.find("not to be served"), std::string::npos) << path;
        EXPECT_EQ(r.body.find("secret"), std::string::npos) << path;
    }
    for (const std::string& path :
         std::vector<std::string>{"", "relative", std::string("/a\0b", 4), "/" + std::string(600, 'a')}) {
        EXPECT_EQ(get(s, path).status, 400) << path;
    }
    serve::Request post;
    post.method = "POST";
    post.path = "/api/tree";
    EXPECT_EQ(s.handle(post).status, 405);
    // The viewer's own files are served, by their exact names.
    EXPECT_EQ(get(s, "/").body, "<!doctype html><title>v</title>");
    const auto js = get(s, "/viewer/viewer.js");
    EXPECT_EQ(js.status, 200);
    EXPECT_EQ(js.content_type, "text/javascript; charset=utf-8");
    EXPECT_EQ(get(s, "/api/verify").body, R"({"clean": true})");
}

TEST_F(Serve, TheFrontIsTheReadersAndBadViewsAre400)
{
    const auto s = site();
    const auto& root = tree->skeleton().nodes.front().box;
    const double cx = (double(root.min_x) + root.max_x) / 2, cy = (double(root.min_y) + root.max_y) / 2;
    const double whole = (double(root.max_x) - root.min_x) / 800; // the root across the view
    size_t views_drawn = 0;
    for (const double upp : {1e6, 1e4, 100.0, 1.0, 2 * whole, whole / 4, whole / 16, whole / 64}) {
        const reader::View view{cx, cy, upp, 800, 600};
        const auto want = reader::select_front(tree->skeleton(), view);
        const auto r = get(s, "/api/front",
                           {{"cx", std::to_string(cx)},
                            {"cy", std::to_string(cy)},
                            {"upp", std::to_string(upp)},
                            {"w", "800"},
                            {"h", "600"}});
        ASSERT_EQ(r.status, 200) << r.body;
        const auto body = json::parse(r.body);
        const auto got = body.at("front");
        ASSERT_EQ(got.size(), want.size()) << upp;
        for (size_t i = 0; i < want.size(); ++i) {
            EXPECT_EQ(got[i][0].get<uint32_t>(), want[i].node);
            EXPECT_EQ(got[i][1].get<uint32_t>(), want[i].lod);
        }
        // What to draw: reader::draw_list of the whole front loaded, each
        // chain with its border level, in the front's order.
        std::vector<reader::Drawable> front;
        for (const auto& f : want) {
            datatree::ChainTable t;
            ASSERT_TRUE(tree->read_table(f.node, t).ok());
            front.push_back({f, f.lod, std::make_shared<const datatree::Geometry>(),
                             std::make_shared<const reader::NodeChains>(reader::node_chains(*tree, f.node, t))});
        }
        std::vector<std::vector<uint32_t>> draw(want.size());
        for (const auto& dc : reader::draw_list(tree->skeleton(), front)) {
            draw[dc.item].push_back(dc.chain);
            draw[dc.item].push_back(front[dc.item].chains->flags[dc.chain] >> datatree::border_level_shift & 0xFFU);
        }
        EXPECT_EQ(body.at("draw").get<std::vector<std::vector<uint32_t>>>(), draw) << upp;
        views_drawn += std::any_of(draw.begin(), draw.end(), [](const auto& d) { return !d.empty(); }) ? 1 : 0;
    }
    EXPECT_GE(views_drawn, 2U); // the whole tree; nearer in, the centre may fall between chains
    // Each border level's style, as tigerlod-render draws it.
    const auto styles = json::parse(get(s, "/api/tree", {}).body).at("styles");
    ASSERT_EQ(styles.size(), std::max<size_t>(1, tree->skeleton().level_names.size()));
    for (uint32_t l = 0; l < styles.size(); ++l) {
        const auto st = reader::line_style(l, uint32_t(tree->skeleton().level_names.size()));
        EXPECT_EQ(styles[l].at("width").get<float>(), st.width);
        EXPECT_EQ(styles[l].at("rgb"), json({st.r, st.g, st.b}));
    }
    const std::map<std::string, std::string> good{{"cx", "0"}, {"cy", "0"}, {"upp", "1"}, {"w", "8"}, {"h", "8"}};
    EXPECT_EQ(get(s, "/api/front", good).status, 200);
    for (const auto& [key, value] : std::vector<std::pair<std::string, std::string>>{{"cx", ""},
                                                                                     {"cx", "nan"},
                                                                                     {"cy", "inf"},
                                                                                     {"upp", "0"},
                                                                                     {"upp", "-1"},
                                                                                     {"w", "0"},
                                                                                     {"h", "16385"},
                                                                                     {"w", "1e9"},
                                                                                     {"upp", "1x"},
                                                                                     {"pixel_error", "0"},
                                                                                     {"node_fraction", "2"}}) {
        auto q = good;
        q[key] = value;
        EXPECT_EQ(get(s, "/api/front", q).status, 400) << key << "=" << value;
    }
    auto missing = good;
    missing.erase("upp");
    EXPECT_EQ(get(s, "/api/front", missing).status, 400);
}

TEST_F(Serve, PayloadsAreTheReadersDecodedAndTheCacheStaysInItsBudget)
{
    const auto& sk = tree->skeleton();
    const auto s = site(600); // smaller than the tiles: some are never kept
    for (uint32_t n = 0; n < sk.nodes.size(); ++n) {
        for (uint32_t k = 0; k < sk.lod_eps_m.size(); ++k) {
            datatree::Geometry g;
            ASSERT_TRUE(tree->read_geometry(n, k, g).ok());
            const auto r = get(s, "/api/node/" + std::to_string(n) + "/" + std::to_string(k));
            ASSERT_EQ(r.status, 200);
            EXPECT_EQ(r.body, serve::geometry_bytes(g));
            EXPECT_LE(s.cached_bytes(), 600U);
        }
        datatree::UnitTable u;
        ASSERT_TRUE(tree->read_units(n, u).ok());
        const auto ur = get(s, "/api/units/" + std::to_string(n));
        ASSERT_EQ(ur.status, 200) << ur.body;
        const auto units = json::parse(ur.body).at("units");
        ASSERT_EQ(units.size(), u.units.size());
        for (size_t i = 0; i < u.units.size(); ++i) {
            EXPECT_EQ(units[i].at("code"), u.units[i].code);
            EXPECT_EQ(units[i].at("name"), u.units[i].name);
            EXPECT_EQ(units[i].at("point")[0].get<int32_t>(), u.units[i].point.x);
        }
        const auto table = json::parse(get(s, "/api/table/" + std::to_string(n)).body);
        EXPECT_EQ(table.at("ids").size(), sk.nodes[n].chains);
    }
    for (const auto& t : sk.tiles) {
        get(s, "/tree/" + t.file);
        EXPECT_LE(s.cached_bytes(), 600U);
    }
    // The county node's units carry the names from the source.
    const auto names = json::parse(get(s, "/api/units/" + std::to_string(tree->unit_node(0, "01"))).body);
    EXPECT_EQ(names.at("units")[1].at("name"), "Beta");
}

// The binary: it prints the port it took, and the transport gives ranges.
TEST_F(Serve, OverASocketRangesAnd304sAndBadRangesAre416)
{
    const std::string cmd = std::string(TIGERLOD_BIN_DIR) + "/tigerlod-serve --port 0 --viewer " +
                            (dir / "viewer").string() + " " + (dir / "tree").string() + " > " +
                            (dir / "serve.out").string() + " 2>&1 & echo $!";
    FILE* p = ::popen(cmd.c_str(), "r");
    ASSERT_TRUE(p);
    int pid = 0;
    ASSERT_EQ(std::fscanf(p, "%d", &pid), 1);
    ::pclose(p);
    int port = 0;
    for (int i = 0; i < 200 && port == 0; ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(25));
        const std::string out = tigerlod::testing::slurp(dir / "serve.out");
        if (const auto at = out.find("serving http://127.0.0.1:"); at != std::string::npos) {
            port = std::atoi(out.c_str() + at + 25);
        }
    }
    ASSERT_GT(port, 0) << tigerlod::testing::slurp(dir / "serve.out");
    httplib::Client c("127.0.0.1", port);
    const std::string tile = "/tree/" + tree->skeleton().tiles.front().file;
    const std::string bytes = read_file(dir / "tree" / tree->skeleton().tiles.front().file);
    auto whole = c.Get(tile);
    ASSERT_TRUE(whole);
    EXPECT_EQ(whole->status, 200);
    EXPECT_EQ(whole->body, bytes);
    auto part = c.Get(tile, {{"Range", "bytes=24-99"}});
    ASSERT_TRUE(part);
    EXPECT_EQ(part->status, 206);
    EXPECT_EQ(part->body, bytes.substr(24, 76));
    EXPECT_EQ(part->get_header_value("Content-Range"), "bytes 24-99/" + std::to_string(bytes.size()));
    for (const std::string& range : std::vector<std::string>{
             "bytes=" + std::to_string(bytes.size()) + "-", "bytes=0-99999999999999999999", "pages=1-2", "bytes=9-2"}) {
        auto bad = c.Get(tile, {{"Range", range}});
        ASSERT_TRUE(bad);
        EXPECT_EQ(bad->status, 416) << range;
        EXPECT_TRUE(bad->body.empty() || bad->body.find(bytes.substr(0, 8)) == std::string::npos);
    }
    auto again = c.Get(tile, {{"If-None-Match", whole->get_header_value("ETag")}});
    ASSERT_TRUE(again);
    EXPECT_EQ(again->status, 304);
    auto traversal = c.Get("/tree/tiles/..%2F..%2Fsecret.txt");
    ASSERT_TRUE(traversal);
    EXPECT_EQ(traversal->status, 404);
    EXPECT_EQ(traversal->body.find("not to be served"), std::string::npos);
    auto page = c.Get("/");
    ASSERT_TRUE(page);
    EXPECT_EQ(page->body, "<!doctype html><title>v</title>");
    ::kill(pid, SIGTERM);
}

} // namespace
