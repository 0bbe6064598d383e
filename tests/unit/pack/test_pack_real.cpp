// Floyd County (../shared/data, skipped with a reason when absent) through
// ingest, simplify at 4 and 64 m, and pack, then read back with the reader
// runtime: every LOD of every node decodes to exactly the chains of the stores
// (borders from the store that owns them), packing is deterministic, and
// repacking after one partition changed rewrites only its tile.
#include "../../support/run_tool.hpp"
#include "formats/chains/chain_store.hpp"
#include "reader/reader.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <map>
#include <set>

namespace fs = std::filesystem;
using namespace tigerlod;

namespace {

const fs::path source_dir = TIGERLOD_SOURCE_DIR;
const fs::path bin_dir = TIGERLOD_BIN_DIR;
const fs::path floyd_edges = source_dir.parent_path() / "shared" / "data" / "tiger" / "tl_2020_51063_edges.zip";

using tigerlod::testing::slurp;

int run(const std::string& tool, const std::string& args, const fs::path& log)
{
    return tigerlod::testing::run_tool(bin_dir, tool, args, log);
}

class PackReal : public ::testing::Test {
  protected:
    static inline fs::path dir;
    static inline bool ready = false;

    static void SetUpTestSuite()
    {
        if (!fs::exists(floyd_edges)) {
            return;
        }
        dir = fs::temp_directory_path() / ("tigerlod-pack-real-" + std::to_string(::getpid()));
        fs::remove_all(dir);
        fs::create_directories(dir);
        const std::string d = dir.string();
        ASSERT_EQ(run("ingest", (source_dir / "configs" / "floyd.yaml").string() + " " + d + "/ingest", dir / "log"), 0)
            << slurp(dir / "log");
        ASSERT_EQ(run("simplify", "--tolerances 4,64 --threads 2 " + d + "/ingest " + d + "/simp", dir / "log"), 0)
            << slurp(dir / "log");
        // Small tiles, so the tree has several.
        ASSERT_EQ(run("pack", "--tile-mb 0.05 --threads 2 " + d + "/ingest " + d + "/simp " + d + "/tree", dir / "log"),
                  0)
            << slurp(dir / "log");
        ready = true;
    }
    static void TearDownTestSuite()
    {
        if (!dir.empty()) {
            fs::remove_all(dir);
        }
    }
    void SetUp() override
    {
        if (!fs::exists(floyd_edges)) {
            GTEST_SKIP() << "needs ../shared/data/tiger (Floyd County TIGER/Line 2020): " << floyd_edges;
        }
        ASSERT_TRUE(ready);
    }
    static std::shared_ptr<reader::Tree> open(const fs::path& p)
    {
        std::string error;
        auto t = reader::Tree::open(p, error);
        EXPECT_TRUE(t) << error;
        return t;
    }
};

/// The stores of one level at one LOD folder, by partition.
std::map<std::string, chains::ChainStore> level_stores(const fs::path& lod_dir, const std::string& level)
{
    std::map<std::string, chains::ChainStore> out;
    for (const auto& f : fs::directory_iterator(lod_dir / level)) {
        auto s = chains::read(f.path());
        out.emplace(s.partition, std::move(s));
    }
    return out;
}

} // namespace

TEST_F(PackReal, EveryLodOfEveryNodeDecodesToItsStoresExactly)
{
    const auto tree = open(dir / "tree");
    ASSERT_TRUE(tree);
    const auto& sk = tree->skeleton();
    ASSERT_EQ(sk.lod_eps_m, (std::vector<double>{0.0, 4.0, 64.0}));
    ASSERT_EQ(sk.level_names.size(), 5U);
    // One node per unit with units below it: the root, 1 state, 1 county, 5 tracts, 12 block groups.
    EXPECT_EQ(sk.nodes.size(), 20U);
    EXPECT_GT(sk.tiles.size(), 2U);
    const std::vector<fs::path> lod_dirs{dir / "ingest", dir / "simp" / "eps-4m", dir / "simp" / "eps-64m"};
    size_t checked_chains = 0, borders = 0;
    for (uint32_t l = 0; l < sk.level_names.size(); ++l) {
        // The node's chains come from the original stores (simplified stores hold no halo).
        const auto originals = level_stores(lod_dirs[0], sk.level_names[l]);
        for (size_t k = 0; k < lod_dirs.size(); ++k) {
            const auto stores = level_stores(lod_dirs[k], sk.level_names[l]);
            // Owned chains of the level, by id.
            std::map<uint64_t, std::pair<const chains::ChainStore*, const chains::ChainInfo*>> owned;
            for (const auto& [p, s] : stores) {
                for (const auto& c : s.chains) {
                    if (!(c.flags & chains::chain_halo)) {
                        ASSERT_TRUE(owned.emplace(c.id, std::make_pair(&s, &c)).second);
                    }
                }
            }
            for (uint32_t n = 0; n < sk.nodes.size(); ++n) {
                const auto& node = sk.nodes[n];
                if (node.level != l) {
                    continue;
                }
                const std::string partition = n == 0 ? "all" : sk.strings[node.code];
                const auto& store = originals.at(partition);
                std::set<std::string> units;
                for (const auto& cp : store.constraints) {
                    if (cp.kind != chains::constraint_neighbour) { // the partition's own units
                        units.insert(store.strings[cp.unit]);
                    }
                }
                std::set<uint64_t> expect_ids;
                for (const auto& c : store.chains) {
                    const bool border = units.contains(store.strings[c.left]) || units.contains(store.strings[c.right]);
                    if (!(c.flags & chains::chain_halo) || border) {
                        expect_ids.insert(c.id);
                        borders += (c.flags & chains::chain_halo) != 0;
                    }
                }
                datatree::ChainTable table;
                ASSERT_TRUE(tree->read_table(n, table).ok());
                datatree::Geometry g;
                const auto st = tree->read_geometry(n, static_cast<uint32_t>(k), g);
                ASSERT_TRUE(st.ok()) << st.error;
                ASSERT_EQ(table.chains.size(), expect_ids.size()) << "node " << n;
                ASSERT_EQ(g.chain_count(), expect_ids.size());
                auto id = expect_ids.begin();
                for (size_t i = 0; i < table.chains.size(); ++i, ++id) {
                    const auto& e = table.chains[i];
                    ASSERT_EQ(e.id, *id);
                    const auto& [os, oc] = owned.at(e.id);
                    const auto pts = os->chain_points(*oc);
                    ASSERT_TRUE(std::equal(pts.begin(), pts.end(), g.chain(i).begin(), g.chain(i).end()))
                        << "node " << n << " LOD " << k << " chain " << e.id;
                    EXPECT_EQ(table.strings[e.left], os->strings[oc->left]);
                    EXPECT_EQ(table.strings[e.right], os->strings[oc->right]);
                    EXPECT_EQ(e.flags & chains::chain_closed, oc->flags & chains::chain_closed);
                    ++checked_chains;
                }
                EXPECT_EQ(node.lods[k].vertices, g.points.size());
                if (k > 0) {
                    EXPECT_GE(node.lods[k].error_m, node.lods[k - 1].error_m);
                    EXPECT_LE(node.lods[k].error_m, sk.lod_eps_m[k] * 1.01); // eps is ground metres; Albers scale ~1
                }
            }
        }
    }
    EXPECT_GT(checked_chains, 1000U);
    EXPECT_GT(borders, 0U); // borders owned by a neighbour do appear
    EXPECT_LT(double(tree->skeleton_bytes()), 0.01 * double(tree->tree_bytes()));
}

TEST_F(PackReal, DeterministicAcrossThreads)
{
    const std::string d = dir.string();
    ASSERT_EQ(run("pack", "--tile-mb 0.05 --threads 1 " + d + "/ingest " + d + "/simp " + d + "/tree1", dir / "log"), 0)
        << slurp(dir / "log");
    EXPECT_EQ(slurp(dir / "tree1" / "skeleton.tls"), slurp(dir / "tree" / "skeleton.tls"));
    for (const auto& f : fs::directory_iterator(dir / "tree" / "tiles")) {
        EXPECT_EQ(slurp(f.path()), slurp(dir / "tree1" / "tiles" / f.path().filename()));
    }
    fs::remove_all(dir / "tree1");
}

TEST_F(PackReal, RepackingAfterOnePartitionChangedRewritesOnlyTheTilesShowingIt)
{
    const std::string d = dir.string();
    fs::copy(dir / "simp", dir / "simp2", fs::copy_options::recursive);
    fs::copy(dir / "tree", dir / "tree2", fs::copy_options::recursive);
    // The region is re-simplified: one block group's blocks at 64 m get the
    // (also valid) 4 m chains.
    const auto before = open(dir / "tree2");
    const auto& sk = before->skeleton();
    uint32_t node = 0;
    for (uint32_t n = 0; n < sk.nodes.size(); ++n) {
        if (sk.nodes[n].child_count == 0 && sk.nodes[n].level == 4) {
            node = n;
            break;
        }
    }
    ASSERT_NE(node, 0U);
    const std::string code = sk.strings[sk.nodes[node].code];
    auto store = chains::read(dir / "simp2" / "eps-4m" / "block" / (code + ".tlc"));
    store.eps_m = 64.0;
    chains::write(dir / "simp2" / "eps-64m" / "block" / (code + ".tlc"), store);
    // The nodes that show a chain of that partition: its own node and the
    // neighbours across its borders. Their tiles, and only theirs, must change.
    std::set<uint64_t> changed_ids;
    for (const auto& c : store.chains) {
        if (!(c.flags & chains::chain_halo)) {
            changed_ids.insert(c.id);
        }
    }
    std::set<std::string> affected_tiles;
    size_t affected_nodes = 0;
    for (uint32_t n = 0; n < sk.nodes.size(); ++n) {
        if (sk.nodes[n].level != sk.nodes[node].level) {
            continue;
        }
        datatree::ChainTable t;
        ASSERT_TRUE(before->read_table(n, t).ok());
        if (std::any_of(t.chains.begin(), t.chains.end(), [&](const auto& e) { return changed_ids.contains(e.id); })) {
            affected_tiles.insert(fs::path(sk.tiles[sk.nodes[n].lods[2].payload.tile].file).filename().string());
            ++affected_nodes;
        }
    }
    EXPECT_GE(affected_nodes, 2U); // the block group and at least one neighbour
    std::map<std::string, fs::file_time_type> times;
    for (const auto& f : fs::directory_iterator(dir / "tree2" / "tiles")) {
        times[f.path().filename().string()] = fs::last_write_time(f.path());
    }
    ASSERT_EQ(run("pack", "--tile-mb 0.05 " + d + "/ingest " + d + "/simp2 " + d + "/tree2", dir / "log"), 0)
        << slurp(dir / "log");
    const size_t n_aff = affected_tiles.size();
    // Appended piece by piece: GCC 12's -Wrestrict misfires on "(" + std::string&& at -O3.
    std::string counts = "(";
    counts += std::to_string(n_aff);
    counts += " written, ";
    counts += std::to_string(sk.tiles.size() - n_aff);
    counts += " kept, 0 repaired, ";
    counts += std::to_string(n_aff);
    counts += " removed)";
    EXPECT_NE(slurp(dir / "log").find(counts), std::string::npos) << slurp(dir / "log");
    // The tiles that were not affected are the very same files, untouched.
    size_t untouched = 0;
    for (const auto& f : fs::directory_iterator(dir / "tree2" / "tiles")) {
        const auto name = f.path().filename().string();
        auto it = times.find(name);
        if (it != times.end()) {
            EXPECT_FALSE(affected_tiles.contains(name)) << name;
            untouched += it->second == fs::last_write_time(f.path());
        }
    }
    EXPECT_EQ(untouched, sk.tiles.size() - n_aff);
    const auto after = open(dir / "tree2");
    datatree::Geometry g2, g1;
    ASSERT_TRUE(after->read_geometry(node, 2, g2).ok());
    ASSERT_TRUE(after->read_geometry(node, 1, g1).ok());
    EXPECT_EQ(g2, g1); // the node now shows the 4 m chains at LOD 2
    EXPECT_EQ(after->skeleton().nodes[node].lods[2].vertices, after->skeleton().nodes[node].lods[1].vertices);
    fs::remove_all(dir / "tree2");
    fs::remove_all(dir / "simp2");
}

TEST_F(PackReal, BadInputIsNamed)
{
    const std::string d = dir.string();
    // A simplified folder missing a store.
    fs::copy(dir / "simp", dir / "simp3", fs::copy_options::recursive);
    fs::remove(dir / "simp3" / "eps-4m" / "county" / "51.tlc");
    EXPECT_EQ(run("pack", d + "/ingest " + d + "/simp3 " + d + "/tree3", dir / "log"), 1);
    EXPECT_NE(slurp(dir / "log").find("simp3/eps-4m: its chain stores are not those of"), std::string::npos)
        << slurp(dir / "log");
    EXPECT_NE(slurp(dir / "log").find("): it lacks county/51.tlc; re-run tigerlod-simplify"), std::string::npos)
        << slurp(dir / "log");
    EXPECT_FALSE(fs::exists(dir / "tree3")); // the tree it began is removed
    // A store that is not a subsequence of its original.
    fs::copy(dir / "simp" / "eps-4m" / "county" / "51.tlc", dir / "simp3" / "eps-4m" / "county" / "51.tlc");
    auto s = chains::read(dir / "simp3" / "eps-64m" / "county" / "51.tlc");
    for (const auto& c : s.chains) {
        if (!(c.flags & chains::chain_halo) && c.count > 2) {
            s.points[c.first + 1].x += 1;
            break;
        }
    }
    chains::write(dir / "simp3" / "eps-64m" / "county" / "51.tlc", s);
    EXPECT_EQ(run("pack", d + "/ingest " + d + "/simp3 " + d + "/tree3", dir / "log"), 1);
    EXPECT_NE(slurp(dir / "log").find("eps-64m/county/51.tlc: chain"), std::string::npos) << slurp(dir / "log");
    EXPECT_NE(slurp(dir / "log").find("is not a subsequence of its original"), std::string::npos);
    // Two stores whose files were swapped: each holds the other's partition.
    fs::copy(dir / "ingest", dir / "ingest3", fs::copy_options::recursive);
    std::vector<fs::path> groups;
    for (const auto& e : fs::directory_iterator(dir / "ingest3" / "block_group")) {
        groups.push_back(e.path());
    }
    std::sort(groups.begin(), groups.end());
    ASSERT_GE(groups.size(), 2U);
    fs::rename(groups[0], dir / "swap.tlc");
    fs::rename(groups[1], groups[0]);
    fs::rename(dir / "swap.tlc", groups[1]);
    EXPECT_EQ(run("pack", d + "/ingest3 " + d + "/simp " + d + "/tree3", dir / "log"), 1);
    EXPECT_NE(slurp(dir / "log")
                  .find(groups[0].filename().string() + ": holds partition " + groups[1].stem().string() +
                        ", not the one its name says"),
              std::string::npos)
        << slurp(dir / "log");
    EXPECT_FALSE(fs::exists(dir / "tree3" / "skeleton.tls"));
    fs::remove_all(dir / "ingest3");
    // Simplified stores swapped, within a tolerance and across two: the
    // message names a swapped store, never an intact one beside it.
    const auto swap = [&](const fs::path& a, const fs::path& b) {
        fs::rename(a, dir / "swap.tlc");
        fs::rename(b, a);
        fs::rename(dir / "swap.tlc", b);
    };
    fs::remove_all(dir / "simp3");
    fs::copy(dir / "simp", dir / "simp3", fs::copy_options::recursive);
    std::vector<fs::path> simplified;
    for (const auto& e : fs::directory_iterator(dir / "simp3" / "eps-4m" / "block_group")) {
        simplified.push_back(e.path());
    }
    std::sort(simplified.begin(), simplified.end());
    ASSERT_GE(simplified.size(), 2U);
    swap(simplified[0], simplified[1]);
    EXPECT_EQ(run("pack", d + "/ingest " + d + "/simp3 " + d + "/tree3", dir / "log"), 1);
    EXPECT_NE(slurp(dir / "log")
                  .find(simplified[0].filename().string() + ": holds partition " + simplified[1].stem().string() +
                        ", not the one its name says"),
              std::string::npos)
        << slurp(dir / "log");
    swap(simplified[0], simplified[1]);
    // Across tolerances, the first store of each folder (pack once took a
    // folder's tolerance from its first store, and then blamed the intact
    // stores beside it).
    std::vector<fs::path> rel;
    for (const auto& e : fs::recursive_directory_iterator(dir / "simp3" / "eps-4m")) {
        if (e.path().extension() == ".tlc") {
            rel.push_back(fs::relative(e.path(), dir / "simp3" / "eps-4m"));
        }
    }
    std::sort(rel.begin(), rel.end());
    ASSERT_FALSE(rel.empty());
    const fs::path in4 = dir / "simp3" / "eps-4m" / rel.front();
    const fs::path in64 = dir / "simp3" / "eps-64m" / rel.front();
    swap(in4, in64);
    EXPECT_EQ(run("pack", d + "/ingest " + d + "/simp3 " + d + "/tree3", dir / "log"), 1);
    const std::string log = slurp(dir / "log");
    EXPECT_TRUE(
        log.find(in4.string() + ": simplified at 64m, not at the 4m its folder's name says") != std::string::npos ||
        log.find(in64.string() + ": simplified at 4m, not at the 64m its folder's name says") != std::string::npos)
        << log;
    EXPECT_FALSE(fs::exists(dir / "tree3" / "skeleton.tls"));
    // OUTPUT that is something else.
    fs::create_directories(dir / "other");
    std::ofstream(dir / "other" / "x") << "x";
    EXPECT_EQ(run("pack", d + "/ingest " + d + "/simp " + d + "/other", dir / "log"), 2);
    EXPECT_NE(slurp(dir / "log").find("exists and is not a Data Tree"), std::string::npos);
    fs::remove_all(dir / "simp3");
    fs::remove_all(dir / "tree3");
    fs::remove_all(dir / "other");
}

TEST_F(PackReal, DumpAndExport)
{
    const std::string d = dir.string();
    ASSERT_EQ(run("dump", d + "/tree", dir / "out"), 0);
    const std::string skel = slurp(dir / "out");
    // The format version the tree was written in (was a fixed "1.0").
    EXPECT_EQ(skel.rfind("data-tree " + std::to_string(datatree::major_version) + "." +
                             std::to_string(datatree::minor_version) + "\n",
                         0),
              0U);
    EXPECT_NE(skel.find("levels state county tract block_group block\nlods 0 4 64\n"), std::string::npos);
    ASSERT_EQ(run("dump", "--node 51063 --lod 2 " + d + "/tree", dir / "out"), 0);
    EXPECT_EQ(slurp(dir / "out").rfind("node 2 code=51063 lod 2 eps=64 chains=", 0), 0U) << slurp(dir / "out");
    const std::string text = slurp(dir / "out");
    const size_t at = text.find("chains=") + 7;
    const size_t chains = std::stoul(text.substr(at, text.find_first_of(" \n", at) - at));
    // GeoJSON through GDAL's driver: one LineString feature per chain.
    ASSERT_EQ(run("dump", "--node 51063 --geojson " + d + "/tree", dir / "out"), 0);
    const std::string geojson = slurp(dir / "out");
    EXPECT_NE(geojson.find("\"type\": \"FeatureCollection\""), std::string::npos) << geojson.substr(0, 200);
    size_t features = 0;
    for (size_t p = geojson.find("{ \"type\": \"Feature\","); p != std::string::npos;
         p = geojson.find("{ \"type\": \"Feature\",", p + 1)) {
        ++features;
    }
    EXPECT_EQ(features, chains);
    EXPECT_EQ(run("dump", "--node 99999 " + d + "/tree", dir / "out"), 2);
    EXPECT_NE(slurp(dir / "out").find("no node '99999'"), std::string::npos);
    // Every block of Floyd County comes back as a valid polygon at the 64 m LOD.
    ASSERT_EQ(run("export", "--level block --lod 2 " + d + "/tree " + d + "/blocks.gpkg", dir / "out"), 0)
        << slurp(dir / "out");
    EXPECT_NE(slurp(dir / "out").find("709 unit polygons"), std::string::npos) << slurp(dir / "out");
    ASSERT_EQ(std::system(("ogrinfo -q -sql \"SELECT COUNT(*) AS bad FROM units WHERE NOT ST_IsValid(geom)\" " + d +
                           "/blocks.gpkg > " + d + "/ogr.txt 2>&1")
                              .c_str()),
              0);
    EXPECT_NE(slurp(dir / "ogr.txt").find("bad (Integer) = 0"), std::string::npos) << slurp(dir / "ogr.txt");
    EXPECT_EQ(run("export", "--level block " + d + "/tree " + d + "/blocks.gpkg", dir / "out"), 2); // exists
    EXPECT_EQ(run("export", "--level nowhere " + d + "/tree " + d + "/x.gpkg", dir / "out"), 2);
    // A damaged tree: the dump names the file, the node and the fault.
    fs::copy(dir / "tree", dir / "bad", fs::copy_options::recursive);
    const auto t = open(dir / "bad");
    const auto& ref = t->skeleton().nodes[2].lods[1].payload;
    {
        std::fstream f(dir / "bad" / t->skeleton().tiles[ref.tile].file,
                       std::ios::in | std::ios::out | std::ios::binary);
        f.seekp(static_cast<std::streamoff>(ref.offset + 3));
        f.put('\x7F');
    }
    EXPECT_EQ(run("dump", "--node 51063 --lod 1 " + d + "/bad", dir / "out"), 1);
    EXPECT_NE(slurp(dir / "out").find("node 2 (51063) LOD 1: checksum mismatch"), std::string::npos)
        << slurp(dir / "out");
    fs::remove_all(dir / "bad");
}

TEST_F(PackReal, VerifyIsCleanOnRealDataAndCatchesDamage)
{
    const std::string d = dir.string();
    ASSERT_EQ(run("verify", "--cgal " + d + "/tree " + d + "/ingest " + d + "/v1", dir / "out"), 0)
        << slurp(dir / "out");
    EXPECT_NE(slurp(dir / "out").find("CLEAN: no violations"), std::string::npos) << slurp(dir / "out");
    EXPECT_NE(slurp(dir / "out").find("CGAL check: agrees"), std::string::npos) << slurp(dir / "out");
    EXPECT_NE(slurp(dir / "out").find("on the ellipsoid: skipped vertices at most"), std::string::npos)
        << slurp(dir / "out");
    const std::string report = slurp(dir / "v1" / "verify-report.json");
    EXPECT_NE(report.find("\"schema\": \"tigerlod.verify-report/1\""), std::string::npos);
    EXPECT_NE(report.find("\"clean\": true"), std::string::npos);
    EXPECT_TRUE(fs::exists(dir / "v1" / "violations.gpkg"));
    // The summary for a person, beside the JSON: the verdict, the ground
    // and CGAL checks, a row per level and LOD; no timings, so a second run
    // gives its bytes again.
    const std::string summary = slurp(dir / "v1" / "verify-summary.md");
    EXPECT_EQ(summary.rfind("# Verification of `" + d + "/tree`\n", 0), 0U) << summary;
    EXPECT_NE(summary.find("\n**CLEAN: no violations.**\n"), std::string::npos) << summary;
    EXPECT_NE(summary.find("\n- On the ellipsoid: skipped vertices at most 0."), std::string::npos) << summary;
    EXPECT_NE(summary.find("\n- CGAL check: agrees ("), std::string::npos) << summary;
    EXPECT_EQ(summary.find("## Violations by kind"), std::string::npos) << summary;
    EXPECT_NE(summary.find("\n| block | 0 | 0 | "), std::string::npos) << summary;
    EXPECT_NE(summary.find("\n| tract | 2 | 64 | "), std::string::npos) << summary;
    ASSERT_EQ(run("verify", "--cgal " + d + "/tree " + d + "/ingest " + d + "/v5", dir / "out"), 0)
        << slurp(dir / "out");
    EXPECT_EQ(slurp(dir / "v5" / "verify-summary.md"), summary);
    // A tree with a damaged payload: reported as such, exit 1, and --compare names it as new.
    fs::copy(dir / "tree", dir / "bad", fs::copy_options::recursive);
    const auto t = open(dir / "bad");
    const auto& ref = t->skeleton().nodes[3].lods[2].payload;
    {
        std::fstream f(dir / "bad" / t->skeleton().tiles[ref.tile].file,
                       std::ios::in | std::ios::out | std::ios::binary);
        f.seekp(static_cast<std::streamoff>(ref.offset + ref.size / 2));
        f.put('\x11');
    }
    EXPECT_EQ(run("verify", "--compare " + d + "/v1/verify-report.json " + d + "/bad " + d + "/ingest " + d + "/v2",
                  dir / "out"),
              1)
        << slurp(dir / "out");
    EXPECT_NE(slurp(dir / "out").find("skeleton"), std::string::npos) << slurp(dir / "out");
    EXPECT_NE(slurp(dir / "out").find(": 1 new, 0 fixed violations"), std::string::npos) << slurp(dir / "out");
    EXPECT_NE(slurp(dir / "v2" / "verify-report.json").find("checksum mismatch"), std::string::npos);
    const std::string damaged = slurp(dir / "v2" / "verify-summary.md");
    EXPECT_NE(damaged.find("\n**1 VIOLATION.**\n"), std::string::npos) << damaged;
    EXPECT_NE(damaged.find("\n- CGAL check: not run"), std::string::npos) << damaged;
    EXPECT_NE(damaged.find(": 1 new, 0 fixed violations.\n"), std::string::npos) << damaged;
    EXPECT_NE(damaged.find("\n## Violations by kind\n"), std::string::npos) << damaged;
    EXPECT_NE(damaged.find("\n## The first 1 of 1 items\n"), std::string::npos) << damaged;
    EXPECT_NE(damaged.find("checksum mismatch"), std::string::npos) << damaged;
    // An unreadable skeleton: one skeleton violation naming the file, exit 1.
    {
        std::fstream f(dir / "bad" / "skeleton.tls", std::ios::in | std::ios::out | std::ios::binary);
        f.seekp(40);
        f.put('\x7E');
    }
    EXPECT_EQ(run("verify", d + "/bad " + d + "/ingest " + d + "/v4", dir / "out"), 1) << slurp(dir / "out");
    const std::string broken = slurp(dir / "v4" / "verify-report.json");
    EXPECT_NE(broken.find("\"skeleton\": 1"), std::string::npos) << broken;
    EXPECT_NE(broken.find("skeleton.tls: checksum mismatch"), std::string::npos) << broken;
    // Usage errors.
    EXPECT_EQ(run("verify", d + "/tree " + d + "/nowhere " + d + "/v3", dir / "out"), 2);
    EXPECT_EQ(run("verify", d + "/tree " + d + "/ingest " + d + "/v1", dir / "out"), 2); // exists
    fs::remove_all(dir / "bad");
}
