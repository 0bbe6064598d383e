// tigerlod-verify on hand-made trees: for every check, a tree that breaks it
// and the exact violations expected; the clean tree reports zero.
#include "formats/chains/chain_store.hpp"
#include "stages/pack/packer.hpp"
#include "stages/verify/cgal_check.hpp"
#include "stages/verify/verifier.hpp"
#include "stages/verify/verify_stage.hpp"

#include <gdal.h>
#include <ogr_api.h>

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <functional>
#include <map>

namespace fs = std::filesystem;
using namespace tigerlod;
using chains::ChainStore;
using Pts = std::vector<GridPoint>;

namespace {

ChainStore store(uint32_t level, uint32_t nlevels, const std::string& level_name, const std::string& partition)
{
    ChainStore s;
    s.level_index = level;
    s.level_count = nlevels;
    s.level_name = level_name;
    s.partition = partition;
    s.projection.grid_m = 1.0;
    s.halo_m = 1000;
    return s;
}

void chain(ChainStore& s, uint64_t id, const std::string& left, const std::string& right, const Pts& pts,
           bool halo = false)
{
    const uint32_t flags = (pts.front() == pts.back() ? chains::chain_closed : 0U) | (halo ? chains::chain_halo : 0U);
    s.add_chain({id, s.intern(left), s.intern(right), s.intern("X0000"), flags, 0, 0}, pts);
}

void point(ChainStore& s, const std::string& unit, GridPoint p)
{
    s.constraints.push_back({s.intern(unit), chains::constraint_internal, p});
}

/// A map: original stores, and their simplification at one eps with some chains replaced.
struct Map {
    std::vector<ChainStore> stores;
    double eps_m = 300;
    std::map<uint64_t, Pts> simplified; ///< chains that differ at LOD 1
};

/// Expected counts: every kind not named must be 0.
using Counts = std::map<std::string, uint64_t>;

class Verify : public ::testing::Test {
  protected:
    fs::path dir;
    void SetUp() override
    {
        dir = fs::temp_directory_path() /
              ("tigerlod-verify-" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "-" +
               std::to_string(::getpid()));
        fs::remove_all(dir);
    }
    void TearDown() override { fs::remove_all(dir); }

    /// Pack `m`, let `tamper` change payloads or the skeleton, write, verify.
    verify::Report
    run(const Map& m, const std::function<void(pack::PackedTree&, std::vector<std::vector<std::string>>&)>& tamper = {},
        verify::Options options = {})
    {
        for (auto s : m.stores) {
            s.canonicalize();
            fs::create_directories(dir / "orig" / s.level_name);
            chains::write(dir / "orig" / s.level_name / (s.partition + ".tlc"), s);
            ChainStore t = s;
            t.eps_m = m.eps_m;
            t.chains.clear();
            t.points.clear();
            for (const auto& c : s.chains) {
                const auto it = m.simplified.find(c.id);
                const auto pts = s.chain_points(c);
                t.add_chain(c, it == m.simplified.end() || (c.flags & chains::chain_halo) ? Pts(pts.begin(), pts.end())
                                                                                          : it->second);
            }
            t.canonicalize();
            char name[32];
            std::snprintf(name, sizeof name, "eps-%gm", m.eps_m);
            fs::create_directories(dir / "simp" / name / s.level_name);
            chains::write(dir / "simp" / name / s.level_name / (s.partition + ".tlc"), t);
        }
        pack::PackedTree tree = pack::build_tree(dir / "orig", dir / "simp", {});
        if (tamper) {
            auto& sk = tree.skeleton;
            std::vector<std::vector<std::string>> payloads(sk.nodes.size());
            for (size_t n = 0; n < sk.nodes.size(); ++n) {
                auto get = [&](const datatree::PayloadRef& r) {
                    return tree.tile_bytes[r.tile].substr(r.offset, r.size);
                };
                payloads[n].push_back(get(sk.nodes[n].table));
                for (const auto& l : sk.nodes[n].lods) {
                    payloads[n].push_back(get(l.payload));
                }
                // Its units payload, where it follows the last LOD's (Data Tree 2.2).
                const std::string& tile = tree.tile_bytes[sk.nodes[n].lods.back().payload.tile];
                const uint64_t at = datatree::units_at(sk.nodes[n]);
                const auto [size, crc] =
                    datatree::units_body(std::as_bytes(std::span(tile.data() + at, tile.size() - at)), "units");
                payloads[n].push_back(tile.substr(at, datatree::units_head_size + size));
            }
            tamper(tree, payloads);
            pack::layout_tiles(tree, std::move(payloads), 1ULL << 30);
        }
        pack::write_tree(dir / "tree", tree, "{}\n");
        std::string error;
        const auto t = reader::Tree::open(dir / "tree", error);
        EXPECT_TRUE(t) << error;
        options.tolerance.projection_scale = false; // eps in grid metres: exact expectations
        auto whole = verify::verify_tree(*t, dir / "orig", options);
        expect_same_by_stores(*t, options, whole);
        // The second checker, on CGAL, finds the same meetings in every case.
        const auto cgal = verify::cgal_check(*t, whole);
        for (const auto& d : cgal.disagreements) {
            ADD_FAILURE() << "CGAL check: " << d;
        }
        return whole;
    }

    /// The workflow's verify: a run per store (its node checked, the nodes
    /// of its halo's owners decoded beside it), the reports merged: the
    /// whole run's report, item for item.
    void expect_same_by_stores(const reader::Tree& t, const verify::Options& options, const verify::Report& whole)
    {
        const pack::PackPlan plan = pack::plan_parts(dir / "orig", 1);
        std::vector<verify::Report> shares;
        for (const auto& [store, near] : plan.near) {
            verify::Selection one;
            one.stores = {store};
            one.near[store] = near;
            shares.push_back(verify::verify_tree(t, dir / "orig", options, &one));
        }
        const auto merged = verify::merge_reports(std::move(shares), t.skeleton().level_names, options.max_items);
        EXPECT_EQ(merged.violations, whole.violations);
        EXPECT_EQ(merged.input_problems, whole.input_problems);
        EXPECT_EQ(std::tie(merged.nodes, merged.lods, merged.chains, merged.segments, merged.points),
                  std::tie(whole.nodes, whole.lods, whole.chains, whole.segments, whole.points));
        ASSERT_EQ(merged.by_level_lod.size(), whole.by_level_lod.size());
        for (size_t i = 0; i < whole.by_level_lod.size(); ++i) {
            const auto &a = merged.by_level_lod[i], &b = whole.by_level_lod[i];
            EXPECT_EQ(std::tie(a.level, a.lod, a.nodes, a.chains, a.segments, a.vertices, a.points, a.violations,
                               a.input_problems),
                      std::tie(b.level, b.lod, b.nodes, b.chains, b.segments, b.vertices, b.points, b.violations,
                               b.input_problems));
        }
        ASSERT_EQ(merged.items.size(), whole.items.size());
        for (size_t i = 0; i < whole.items.size(); ++i) {
            const auto &a = merged.items[i], &b = whole.items[i];
            EXPECT_EQ(std::tie(a.kind, a.level, a.lod, a.node, a.chains, a.x, a.y, a.lon, a.lat, a.detail),
                      std::tie(b.kind, b.level, b.lod, b.node, b.chains, b.x, b.y, b.lon, b.lat, b.detail));
        }
        EXPECT_EQ(merged.items_dropped, whole.items_dropped);
    }

    static void expect(const verify::Report& r, const Counts& want)
    {
        for (const char* k : verify::kinds) {
            const auto it = want.find(k);
            EXPECT_EQ(r.violations.at(k), it == want.end() ? 0U : it->second) << "kind " << k;
        }
        if (::testing::Test::HasFailure()) {
            for (const auto& v : r.items) {
                std::printf("  %s %s lod %u node %s (%g, %g): %s\n", v.kind.c_str(), v.level.c_str(), v.lod,
                            v.node.c_str(), v.x, v.y, v.detail.c_str());
            }
        }
    }
};

/// Replace chain `id`'s geometry at `lod` of node `node` in the payloads (and
/// loosen the skeleton's error bound from that LOD on).
void set_chain(const pack::PackedTree& tree, std::vector<std::vector<std::string>>& payloads, uint32_t node,
               uint32_t lod, uint64_t id, const Pts& pts)
{
    const auto& n = tree.skeleton.nodes[node];
    const auto table =
        datatree::decode_table(std::as_bytes(std::span(payloads[node][0].data(), payloads[node][0].size())), "t");
    const auto& bytes = payloads[node][1 + lod];
    const auto g = datatree::decode_geometry(std::as_bytes(std::span(bytes.data(), bytes.size())),
                                             {n.box.min_x, n.box.min_y}, n.chains, n.lods[lod].vertices, "g");
    datatree::Geometry out;
    for (size_t c = 0; c < g.chain_count(); ++c) {
        if (table.chains[c].id == id) {
            out.add_chain(pts);
        } else {
            out.add_chain(g.chain(c));
        }
    }
    payloads[node][1 + lod] = datatree::encode_geometry(out, {n.box.min_x, n.box.min_y});
    auto& l = const_cast<pack::PackedTree&>(tree).skeleton.nodes[node].lods;
    l[lod].vertices = out.points.size();
    // A loose error bound, so that only the intended violations show.
    for (size_t k = lod; k < l.size(); ++k) {
        l[k].error_m = 1e9;
    }
}

/// County A (a square) split into tracts A1 (west, with a pocket reaching east
/// at 500..800 x 400..600) and A2 (east); optionally an island tract I in A1.
Map county_a(bool island, GridPoint a1_point)
{
    Map m;
    ChainStore l0 = store(0, 2, "county", "all");
    chain(l0, 1, "A", "", {{0, 0}, {1000, 0}, {1000, 1000}, {0, 1000}, {0, 0}});
    point(l0, "A", {500, 500});
    ChainStore l1 = store(1, 2, "tract", "A");
    chain(l1, 10, "A2", "", {{500, 0}, {1000, 0}, {1000, 1000}, {500, 1000}});
    chain(l1, 11, "A1", "", {{500, 1000}, {0, 1000}, {0, 0}, {500, 0}});
    chain(l1, 12, "A1", "A2", {{500, 0}, {500, 400}, {800, 400}, {800, 600}, {500, 600}, {500, 1000}});
    point(l1, "A1", a1_point);
    point(l1, "A2", {900, 500});
    if (island) {
        chain(l1, 13, "I", "A1", {{450, 450}, {550, 450}, {550, 550}, {450, 550}, {450, 450}});
        point(l1, "I", {500, 500});
    }
    m.stores = {l0, l1};
    return m;
}

/// One level of unrelated lines (no units): partition "all".
Map lines(const std::vector<std::pair<uint64_t, Pts>>& cs, double eps_m)
{
    Map m;
    m.eps_m = eps_m;
    ChainStore s = store(0, 1, "lines", "all");
    for (const auto& [id, pts] : cs) {
        chain(s, id, "", "", pts);
    }
    m.stores = {s};
    return m;
}

} // namespace

TEST_F(Verify, CleanTreeReportsZero)
{
    Map m = county_a(true, {300, 200});
    m.simplified[11] = {{500, 1000}, {0, 1000}, {0, 0}, {500, 0}}; // as it was
    const auto r = run(m);
    expect(r, {});
    EXPECT_EQ(r.nodes, 2U);
    EXPECT_EQ(r.lods, 2U);
    EXPECT_EQ(r.by_level_lod.size(), 4U);
    EXPECT_GT(r.segments, 0U);
    EXPECT_EQ(r.points, 2U * (1 + 3)); // per LOD: A; A1, A2, I
}

TEST_F(Verify, ShortcutAcrossAnIslandIsACrossing)
{
    Map m = county_a(true, {300, 200});
    // Within eps (the pocket's corners are exactly 300 from x = 500) and a
    // subsequence, but it cuts through island I.
    m.simplified[12] = {{500, 0}, {500, 400}, {500, 600}, {500, 1000}};
    const auto r = run(m);
    expect(r, {{"crossings", 1}});
    ASSERT_EQ(r.items.size(), 1U);
    const auto& v = r.items[0];
    EXPECT_EQ(v.kind, "crossings");
    EXPECT_EQ(v.level, "tract");
    EXPECT_EQ(v.lod, 1U);
    EXPECT_EQ(v.node, "A");
    EXPECT_EQ(v.chains, (std::vector<uint64_t>{12, 13}));
    EXPECT_EQ(v.x, 500.0);
    EXPECT_TRUE(v.y == 450.0 || v.y == 550.0) << v.y;
    EXPECT_NEAR(v.lon, -96.0, 0.1); // grid 1 m around the Albers origin
}

TEST_F(Verify, ViolationsGpkgHoldsEachItemsChainsAsLinesWithTheirUnits)
{
    Map m = county_a(true, {300, 200});
    m.simplified[12] = {{500, 0}, {500, 400}, {500, 600}, {500, 1000}}; // through island I, as above
    const auto r = run(m);
    ASSERT_EQ(r.items.size(), 1U);
    std::string error;
    const auto t = reader::Tree::open(dir / "tree", error);
    ASSERT_TRUE(t) << error;
    const fs::path gpkg = dir / "violations.gpkg";
    verify::write_violations_gpkg(gpkg, r, &*t);
    GDALAllRegister();
    GDALDatasetH ds = GDALOpenEx(gpkg.c_str(), GDAL_OF_VECTOR, nullptr, nullptr, nullptr);
    ASSERT_NE(ds, nullptr);
    OGRLayerH points = GDALDatasetGetLayerByName(ds, "violations");
    OGRLayerH lines = GDALDatasetGetLayerByName(ds, "violation_chains");
    ASSERT_NE(points, nullptr);
    ASSERT_NE(lines, nullptr);
    EXPECT_EQ(OGR_L_GetFeatureCount(points, TRUE), 1);
    // Chain 12 as LOD 1 holds it (the shortcut), and island I's ring, each
    // with its units, the item's point fid, LOD and eps, in grid metres.
    std::map<int64_t, std::string> got;
    OGR_L_ResetReading(lines);
    while (OGRFeatureH f = OGR_L_GetNextFeature(lines)) {
        std::string text = std::to_string(OGR_F_GetFieldAsInteger64(f, 0)) + " " + OGR_F_GetFieldAsString(f, 1) + " " +
                           OGR_F_GetFieldAsString(f, 2) + " " + std::to_string(OGR_F_GetFieldAsInteger(f, 3)) + " " +
                           std::to_string(OGR_F_GetFieldAsDouble(f, 4)) + " " + OGR_F_GetFieldAsString(f, 5) + " " +
                           OGR_F_GetFieldAsString(f, 7) + "|" + OGR_F_GetFieldAsString(f, 8) + " ";
        OGRGeometryH g = OGR_F_GetGeometryRef(f);
        for (int i = 0; g != nullptr && i < OGR_G_GetPointCount(g); ++i) {
            text += std::to_string(int(OGR_G_GetX(g, i))) + "," + std::to_string(int(OGR_G_GetY(g, i))) + " ";
        }
        got[OGR_F_GetFieldAsInteger64(f, 6)] = text;
        OGR_F_Destroy(f);
    }
    GDALClose(ds);
    ASSERT_EQ(got.size(), 2U);
    EXPECT_EQ(got[12], "1 crossings tract 1 300.000000 A A1|A2 500,0 500,400 500,600 500,1000 ");
    EXPECT_EQ(got[13], "1 crossings tract 1 300.000000 A I|A1 450,450 550,450 550,550 450,550 450,450 ");
    // Without the tree (its skeleton unreadable): the points alone.
    verify::write_violations_gpkg(dir / "points.gpkg", r, nullptr);
    ds = GDALOpenEx((dir / "points.gpkg").c_str(), GDAL_OF_VECTOR, nullptr, nullptr, nullptr);
    ASSERT_NE(ds, nullptr);
    EXPECT_EQ(GDALDatasetGetLayerByName(ds, "violation_chains"), nullptr);
    GDALClose(ds);
}

TEST_F(Verify, TheCgalCheckFindsTheCrossingAndNamesAMissedOne)
{
    Map m = county_a(true, {300, 200});
    m.simplified[12] = {{500, 0}, {500, 400}, {500, 600}, {500, 1000}}; // through island I, as above
    auto r = run(m);                                                    // run() asks the CGAL check to agree
    std::string error;
    const auto t = reader::Tree::open(dir / "tree", error);
    ASSERT_TRUE(t) << error;
    auto c = verify::cgal_check(*t, r);
    EXPECT_EQ(c.within_pairs, 1U);
    EXPECT_EQ(c.across_pairs, 0U); // 13 is the same at both LODs: the meeting is LOD 1's, not one across LODs
    EXPECT_TRUE(c.disagreements.empty());
    // A report that missed the crossing: the check says which pair.
    r.items.clear();
    c = verify::cgal_check(*t, r);
    ASSERT_EQ(c.disagreements.size(), 1U);
    EXPECT_EQ(c.disagreements[0], "tract LOD 1: CGAL finds chains 12 and 13 meeting; verify does not");
}

TEST_F(Verify, VertexFartherThanEps)
{
    Map m = county_a(false, {300, 200});
    m.simplified[11] = {{500, 1000}, {0, 0}, {500, 0}}; // (0, 1000) is 447 m from the shortcut
    const auto r = run(m);
    expect(r, {{"eps_exceeded", 1}});
    EXPECT_EQ(r.items.at(0).chains, (std::vector<uint64_t>{11}));
    EXPECT_EQ(r.items.at(0).x, 0.0);
    EXPECT_EQ(r.items.at(0).y, 1000.0);
}

TEST_F(Verify, MovedVertexIsNotASubsequence)
{
    const auto r = run(county_a(false, {300, 200}), [](pack::PackedTree& t, auto& p) {
        set_chain(t, p, 1, 1, 11, {{500, 1000}, {0, 1000}, {1, 0}, {500, 0}});
    });
    expect(r, {{"not_subsequence", 1}});
}

TEST_F(Verify, InternalPointLeftOnTheOtherSide)
{
    Map m = county_a(false, {650, 500});        // A1's point in its pocket
    m.simplified[12] = {{500, 0}, {500, 1000}}; // the pocket goes to A2
    const auto r = run(m);
    expect(r, {{"point_constraints", 1}});
    EXPECT_EQ(r.items.at(0).x, 650.0);
    EXPECT_NE(r.items.at(0).detail.find("internal point of A1"), std::string::npos);
}

TEST_F(Verify, IslandPassedToTheNeighbourKeepsItsPointButIsCaught)
{
    // An island tract in A1's pocket; the pocket goes to A2 and the island
    // with it. Every point stays inside its own unit (I's inside I), but
    // I's point is now inside A2 too: A1's hole lies outside its shell.
    Map m = county_a(false, {300, 200});
    chain(m.stores[1], 13, "I", "A1", {{600, 450}, {700, 450}, {700, 550}, {600, 550}, {600, 450}});
    point(m.stores[1], "I", {650, 500});
    m.simplified[12] = {{500, 0}, {500, 1000}};
    const auto r = run(m);
    expect(r, {{"point_constraints", 1}});
    EXPECT_NE(r.items.at(0).detail.find("internal point of I inside unit A2"), std::string::npos)
        << r.items.at(0).detail;
}

TEST_F(Verify, UserPointLeftOnTheOtherSide)
{
    Map m = county_a(false, {300, 200});
    m.simplified[12] = {{500, 0}, {500, 400}, {500, 600}, {500, 1000}}; // the pocket goes to A2
    verify::Options o;
    // A user point in the pocket, given in lon/lat.
    Projection proj(m.stores[0].projection);
    double lon = 0, lat = 0;
    proj.to_lonlat(700, 500, lon, lat);
    o.user_points.push_back({lon, lat});
    const auto r = run(m, {}, o);
    expect(r, {{"point_constraints", 1}});
    EXPECT_NE(r.items.at(0).detail.find("user point 0 left unit A1"), std::string::npos) << r.items.at(0).detail;
}

TEST_F(Verify, UnitWhoseAreaChangedSign)
{
    // The island's ring with its sides swapped in the tree: I's boundary
    // closes, but I now has a negative area (at both LODs).
    const auto r = run(county_a(true, {300, 200}), [](pack::PackedTree& t, auto& p) {
        auto table = datatree::decode_table(std::as_bytes(std::span(p[1][0].data(), p[1][0].size())), "t");
        for (auto& c : table.chains) {
            if (c.id == 13) {
                std::swap(c.left, c.right);
            }
        }
        p[1][0] = datatree::encode_table(table);
        (void)t;
    });
    expect(r, {{"invalid_polygons", 2}});
    EXPECT_NE(r.items.at(0).detail.find("unit I: area sign -1, originally 1"), std::string::npos)
        << r.items.at(0).detail;
}

TEST_F(Verify, UnitWhoseBoundaryDoesNotClose)
{
    // Chain 10 with its sides swapped: A2's boundary no longer closes.
    const auto r = run(county_a(false, {300, 200}), [](pack::PackedTree&, auto& p) {
        auto table = datatree::decode_table(std::as_bytes(std::span(p[1][0].data(), p[1][0].size())), "t");
        for (auto& c : table.chains) {
            if (c.id == 10) {
                std::swap(c.left, c.right);
            }
        }
        p[1][0] = datatree::encode_table(table);
    });
    expect(r, {{"invalid_polygons", 2}});
    EXPECT_NE(r.items.at(0).detail.find("unit A2: boundary does not close"), std::string::npos) << r.items.at(0).detail;
}

/// Counties A (x < 1000) and B, one tract each (A1, B1), their border (1 at
/// the county level, 11 at the tract level, owned by A) with a vertex at
/// (1010, 500); each tract store holds the other's chain of the border area as halo.
Map two_counties()
{
    Map m;
    ChainStore l0 = store(0, 2, "county", "all");
    chain(l0, 1, "A", "B", {{1000, 0}, {1010, 500}, {1000, 1000}});
    chain(l0, 2, "A", "", {{1000, 1000}, {0, 1000}, {0, 0}, {1000, 0}});
    chain(l0, 3, "B", "", {{1000, 0}, {2000, 0}, {2000, 1000}, {1000, 1000}});
    point(l0, "A", {500, 500});
    point(l0, "B", {1500, 500});
    ChainStore a = store(1, 2, "tract", "A");
    chain(a, 11, "A1", "B1", {{1000, 0}, {1010, 500}, {1000, 1000}});
    chain(a, 12, "A1", "", {{1000, 1000}, {0, 1000}, {0, 0}, {1000, 0}});
    chain(a, 13, "B1", "", {{1000, 0}, {2000, 0}, {2000, 1000}, {1000, 1000}}, true);
    point(a, "A1", {500, 500});
    ChainStore b = store(1, 2, "tract", "B");
    chain(b, 13, "B1", "", {{1000, 0}, {2000, 0}, {2000, 1000}, {1000, 1000}});
    chain(b, 11, "A1", "B1", {{1000, 0}, {1010, 500}, {1000, 1000}}, true);
    point(b, "B1", {1500, 500});
    m.stores = {l0, a, b};
    return m;
}

TEST_F(Verify, BorderShownDifferentlyByTwoNodes)
{
    // The border's vertex is one that 300 m drops.
    Map m = two_counties();
    m.simplified[1] = {{1000, 0}, {1000, 1000}};
    m.simplified[11] = {{1000, 0}, {1000, 1000}};
    expect(run(m), {});
    // Node B (index 2) shows the border with the original vertex at LOD 1.
    const auto r = run(m, [](pack::PackedTree& t, auto& p) {
        ASSERT_EQ(t.skeleton.strings[t.skeleton.nodes[2].code], "B");
        set_chain(t, p, 2, 1, 11, {{1000, 0}, {1010, 500}, {1000, 1000}});
    });
    expect(r, {{"border_mismatch", 1}});
    EXPECT_EQ(r.items.at(0).node, "B");
    EXPECT_EQ(r.items.at(0).chains, (std::vector<uint64_t>{11}));
}

TEST_F(Verify, AMeetingAcrossPartitionsIsFiledOnceUnderItsOwner)
{
    // At LOD 1 tract B1's outline (13, owned by B) cuts west across the
    // border (11, owned by A). The run of A's node files the crossing (11
    // has the smaller home, and 13 is in A's halo), B's does not: merged
    // (run() compares), the whole run's one crossing.
    const Map m = two_counties();
    const auto r = run(m, [](pack::PackedTree& t, auto& p) {
        ASSERT_EQ(t.skeleton.strings[t.skeleton.nodes[2].code], "B");
        set_chain(t, p, 2, 1, 13, {{1000, 0}, {2000, 0}, {2000, 1000}, {1005, 500}, {1000, 1000}});
    });
    EXPECT_EQ(r.violations.at("crossings"), 1U);
    const auto it = std::find_if(r.items.begin(), r.items.end(), [](const auto& v) { return v.kind == "crossings"; });
    ASSERT_NE(it, r.items.end());
    EXPECT_EQ(it->node, "A");
    EXPECT_EQ(it->chains, (std::vector<uint64_t>{11, 13}));
}

TEST_F(Verify, ChainsThatOverlap)
{
    const auto m = lines({{1, {{0, 0}, {300, 0}}}, {2, {{0, 100}, {100, 50}, {300, 100}}}}, 60);
    const auto r = run(m, [](pack::PackedTree& t, auto& p) {
        set_chain(t, p, 0, 1, 2, {{0, 100}, {100, 0}, {200, 0}, {300, 100}});
    });
    expect(r, {{"overlaps", 1}, {"not_subsequence", 1}});
}

TEST_F(Verify, ChainsThatMeetOnlyAcrossLods)
{
    // At LOD 1 both lines are straight and only share their end; but a's
    // shortcut crosses b's original, which a view drawing a at LOD 1 beside
    // b at LOD 0 would show. (b's unchanged segments at LOD 1 are not
    // reported twice: a meeting that is one of a single LOD is that LOD's.)
    Map m = lines({{1, {{0, 0}, {500, -3}, {1000, 0}}}, {2, {{0, 0}, {300, -1}, {600, 50}, {900, 200}}}}, 100);
    m.simplified[1] = {{0, 0}, {1000, 0}};
    m.simplified[2] = {{0, 0}, {900, 200}};
    const auto r = run(m);
    expect(r, {{"lod_crossings", 1}});
    ASSERT_EQ(r.items.size(), 1U);
    EXPECT_EQ(r.items[0].lod, 1U);
    EXPECT_EQ(r.items[0].chains, (std::vector<uint64_t>{1, 2}));
    EXPECT_NEAR(r.items[0].x, 306.0, 1.0);
    EXPECT_EQ(r.items[0].y, 0.0);
    // b kept as it was: a at LOD 1 meets b at LOD 1 as well, which the LOD's own check reports.
    m.simplified.erase(2);
    expect(run(m), {{"crossings", 1}});
}

TEST_F(Verify, ChainThatCrossesItself)
{
    // Dropping (920, 300), 67.6 m from the shortcut (800, 0)-(920, 700), is
    // within 70 m, but the shortcut cuts (900, 400)-(200, 0) at (865.2, 380.1).
    auto m = lines({{3, {{900, 400}, {200, 0}, {800, 0}, {920, 300}, {920, 700}, {200, 900}}}}, 70);
    m.simplified[3] = {{900, 400}, {200, 0}, {800, 0}, {920, 700}, {200, 900}};
    const auto r = run(m);
    expect(r, {{"self_intersections", 1}});
    EXPECT_EQ(r.items.at(0).chains, (std::vector<uint64_t>{3}));
}

TEST_F(Verify, RingCollapsed)
{
    // Chain stores refuse such a ring, so it is put in the tree directly.
    const auto m = lines({{4, {{0, 0}, {40, 0}, {40, 40}, {0, 40}, {0, 0}}}}, 60);
    const auto r = run(m, [](pack::PackedTree& t, auto& p) { set_chain(t, p, 0, 1, 4, {{0, 0}, {40, 0}, {0, 0}}); });
    expect(r, {{"ring_collapsed", 1}, {"self_intersections", 1}});
}

TEST_F(Verify, RingOrientationFlipped)
{
    // A counter-clockwise ring through the corners of a square in bow-tie
    // order, going round the outside; keeping only the corners flips its area.
    auto m = lines({{5, {{0, 0}, {100, 100}, {100, 0}, {100, -50}, {-50, -50}, {-50, 100}, {0, 100}, {0, 0}}}}, 60);
    const auto r = run(m, [](pack::PackedTree& t, auto& p) {
        set_chain(t, p, 0, 1, 5, {{0, 0}, {100, 100}, {100, 0}, {0, 100}, {0, 0}});
    });
    expect(r, {{"ring_orientation", 1}, {"self_intersections", 1}, {"eps_exceeded", 1}});
}

TEST_F(Verify, SkeletonInconsistencies)
{
    Map m = lines({{1, {{0, 0}, {100, 30}, {200, 0}}}}, 60);
    m.simplified[1] = {{0, 0}, {200, 0}};
    // The LOD 1 error claims 0 m while the chain moved 30 m.
    auto r = run(m, [](pack::PackedTree& t, auto&) { t.skeleton.nodes[0].lods[1].error_m = 0; });
    expect(r, {{"skeleton", 1}});
    EXPECT_NE(r.items.at(0).detail.find("below the measured 30"), std::string::npos)
        << "[" << r.items.at(0).detail << "]";
    // A box that does not hold the chain: both LODs.
    fs::remove_all(dir);
    r = run(m, [](pack::PackedTree& t, auto&) { t.skeleton.nodes[0].box.max_x -= 1; });
    expect(r, {{"skeleton", 2}});
    // A payload that does not decode: reported, the rest checked.
    fs::remove_all(dir);
    r = run(m, [](pack::PackedTree&, auto& p) { p[0][2][5] = static_cast<char>(p[0][2][5] ^ 0x55); });
    expect(r, {{"skeleton", 1}});
    EXPECT_EQ(r.items.at(0).lod, 1U);
}

TEST_F(Verify, CrossingsAlreadyInTheInputAreInputProblemsNotViolations)
{
    // Two lines that cross in the original map (ingest reports and flags such
    // chains); the tree keeps them crossing at both LODs.
    const auto m = lines({{1, {{0, 0}, {100, 100}}}, {2, {{0, 100}, {100, 0}}}}, 60);
    const auto r = run(m);
    expect(r, {});
    EXPECT_EQ(r.input_problems, 2U);
    ASSERT_EQ(r.items.size(), 2U);
    EXPECT_EQ(r.items[0].kind, "input_problem");
    EXPECT_EQ(r.items[0].x, 50.0);
}

TEST_F(Verify, MeetingsAreTheSameFoundWindowByWindow)
{
    // The meeting checks cut a level into windows so that their memory
    // follows a window (Options::window_segments): windows of one segment
    // (each chain in several) report what one window over the level does,
    // within a LOD, across LODs, in the input, and a chain meeting itself.
    Map across = lines({{1, {{0, 0}, {500, -3}, {1000, 0}}}, {2, {{0, 0}, {300, -1}, {600, 50}, {900, 200}}}}, 100);
    across.simplified[1] = {{0, 0}, {1000, 0}};
    across.simplified[2] = {{0, 0}, {900, 200}};
    Map within = across;
    within.simplified.erase(2);
    auto self = lines({{3, {{900, 400}, {200, 0}, {800, 0}, {920, 300}, {920, 700}, {200, 900}}}}, 70);
    self.simplified[3] = {{900, 400}, {200, 0}, {800, 0}, {920, 700}, {200, 900}};
    const auto input = lines({{1, {{0, 0}, {100, 100}}}, {2, {{0, 100}, {100, 0}}}}, 60);
    // Two chains whose boxes start in different windows and meet far from both corners.
    const auto apart = lines({{1, {{0, 500}, {400, 510}, {1000, 500}}}, {2, {{800, 0}, {810, 400}, {800, 1000}}}}, 60);
    for (const Map* m : std::initializer_list<const Map*>{&across, &within, &self, &input, &apart}) {
        fs::remove_all(dir); // another map's stores
        const auto whole = run(*m);
        verify::Options small;
        small.window_segments = 1;
        const auto windows = run(*m, {}, small);
        EXPECT_GT(whole.items.size(), 0U);
        EXPECT_EQ(windows.violations, whole.violations);
        EXPECT_EQ(windows.input_problems, whole.input_problems);
        EXPECT_EQ(windows.segments, whole.segments);
        ASSERT_EQ(windows.items.size(), whole.items.size());
        for (size_t i = 0; i < whole.items.size(); ++i) {
            EXPECT_EQ(windows.items[i].kind, whole.items[i].kind);
            EXPECT_EQ(windows.items[i].lod, whole.items[i].lod);
            EXPECT_EQ(windows.items[i].chains, whole.items[i].chains);
            EXPECT_EQ(windows.items[i].x, whole.items[i].x);
            EXPECT_EQ(windows.items[i].y, whole.items[i].y);
            EXPECT_EQ(windows.items[i].detail, whole.items[i].detail);
        }
    }
}
