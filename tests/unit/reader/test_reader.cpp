// The reader runtime on a synthetic quadtree: exact payloads, the front of
// Algorithm 6.1, the byte budget under a long random camera walk,
// prefetching, and damaged trees that are reported, never crashed on.
// Also built under ThreadSanitizer (scripts/test).
#include "reader/reader.hpp"

#include "../../support/synthetic_tree.hpp"

#include <gtest/gtest.h>

#include <chrono>

#include <fstream>
#include <random>
#include <set>

namespace fs = std::filesystem;
using namespace tigerlod;
using namespace tigerlod::reader;

namespace {

constexpr int32_t side = 1 << 20;

struct TreeDir {
    fs::path dir;
    tigerlod::testing::SyntheticTree tree;
    explicit TreeDir(const std::string& name, uint32_t depth = 3)
        : dir(fs::temp_directory_path() / ("tigerlod_reader_" + name + "_" + std::to_string(::getpid()))),
          tree(tigerlod::testing::make_synthetic_tree(depth, side))
    {
        fs::remove_all(dir);
        tree.write(dir);
    }
    ~TreeDir() { fs::remove_all(dir); }
    std::shared_ptr<Tree> open() const
    {
        std::string error;
        auto t = Tree::open(dir, error);
        EXPECT_TRUE(t) << error;
        return t;
    }
};

/// A view of the whole root box at `px` pixels a side.
View whole(uint32_t px = 512)
{
    return {side / 2.0, side / 2.0, double(side) / px, px, px};
}

} // namespace

TEST(Tree, EveryPayloadDecodesExactly)
{
    TreeDir d("exact");
    const auto t = d.open();
    ASSERT_TRUE(t);
    EXPECT_EQ(t->skeleton(), d.tree.skeleton);
    for (uint32_t n = 0; n < t->skeleton().nodes.size(); ++n) {
        for (uint32_t k = 0; k < t->skeleton().lod_eps_m.size(); ++k) {
            datatree::Geometry g;
            ASSERT_TRUE(t->read_geometry(n, k, g).ok());
            EXPECT_EQ(g, d.tree.geometry[n][k]) << n << " " << k;
        }
        datatree::ChainTable table;
        ASSERT_TRUE(t->read_table(n, table).ok());
        EXPECT_EQ(table, d.tree.tables[n]);
    }
    EXPECT_LT(t->skeleton_bytes(), t->tree_bytes());
}

TEST(Front, Algorithm61)
{
    TreeDir d("front", 2);
    const auto tree = d.open();
    const auto& s = tree->skeleton();
    // The LOD errors of every node are 0, 20 and 80 m (grid 1 cm).
    // Whole tree in 512 px: 2048 grid units (20.48 m) a pixel. The root covers
    // the whole viewport and each child a quarter, not less than the default
    // fraction: the 16 grandchildren (leaves) are drawn, each at the coarsest
    // LOD under one pixel of error (LOD 1: 20 m < 20.48 m).
    const auto front = select_front(s, whole());
    ASSERT_EQ(front.size(), 16U);
    for (uint32_t i = 0; i < 16; ++i) {
        EXPECT_EQ(front[i].lod, 1U);
        EXPECT_EQ(s.nodes[front[i].node].child_count, 0U);
        EXPECT_EQ(s.nodes[s.nodes[front[i].node].parent].parent, 0U);
    }
    // A larger fraction draws the four children.
    FrontOptions quarter;
    quarter.node_fraction = 0.3;
    EXPECT_EQ(select_front(s, whole(), quarter), (std::vector<FrontItem>{{1, 1}, {2, 1}, {3, 1}, {4, 1}}));
    // With a threshold of 4 px, LOD 2 (80 m < 81.9 m) qualifies.
    FrontOptions coarse;
    coarse.pixel_error = 4.0;
    EXPECT_EQ(select_front(s, whole(), coarse)[0].lod, 2U);
    // Above 1, even the root is small enough.
    FrontOptions big;
    big.node_fraction = 1.5;
    EXPECT_EQ(select_front(s, whole(), big), (std::vector<FrontItem>{{0, 1}}));
    // A root without chains (a line layer in tiles) is never drawn itself: its children are.
    auto tiles_root = s;
    tiles_root.nodes[0].chains = 0;
    EXPECT_EQ(select_front(tiles_root, whole(), big), (std::vector<FrontItem>{{1, 1}, {2, 1}, {3, 1}, {4, 1}}));
    // Zoomed into the lower-left quadrant: only its subtree survives culling,
    // and at this scale its children (leaves) are drawn at LOD 0.
    View v{side / 4.0 - 100, side / 4.0 - 100, double(side) / 2 / 512 / 8, 512, 512};
    const auto zoomed = select_front(s, v);
    ASSERT_FALSE(zoomed.empty());
    for (const auto& f : zoomed) {
        EXPECT_EQ(s.nodes[f.node].parent, 1U);
        EXPECT_EQ(f.lod, 0U);
    }
    // Outside the tree: nothing.
    View away = whole();
    away.center_x = -10.0 * side;
    EXPECT_TRUE(select_front(s, away).empty());
}

TEST(Streamer, BudgetNeverExceededOnARandomWalk)
{
    TreeDir d("walk", 3);
    const auto t = d.open();
    uint64_t all = 0;
    for (const auto& n : t->skeleton().nodes) {
        for (const auto& l : n.lods) {
            all += datatree::geometry_bytes(n.chains, l.vertices);
        }
    }
    StreamOptions o;
    o.budget_bytes = all / 6;
    Streamer st(t, o);
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> pos(0, side), zoom(-6, 1);
    size_t drawn = 0;
    double waited = 0;  // as the caller measures it
    double counted = 0; // as the streamer counted it after the last wait
    for (int step = 0; step < 600; ++step) {
        View v = whole();
        v.center_x = pos(rng);
        v.center_y = pos(rng);
        v.units_per_pixel *= std::exp2(zoom(rng));
        st.set_view(v);
        if (step % 3 == 0) {
            const auto t0 = std::chrono::steady_clock::now();
            st.wait_front(std::chrono::milliseconds(200));
            waited += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
            counted = st.stats().seconds_waiting;
        } else {
            EXPECT_EQ(st.stats().seconds_waiting, counted); // nothing counted outside wait_front
        }
        for (const auto& dr : st.resident_front()) {
            if (dr.geometry) {
                ++drawn;
                ASSERT_EQ(*dr.geometry, d.tree.geometry[dr.wanted.node][dr.lod]);
            }
        }
        size_t held = 0;
        for (const auto& r : st.resident()) {
            const size_t bytes = r.item.lod == table_lod ? r.chains->memory_bytes() : r.geometry->memory_bytes();
            EXPECT_EQ(r.bytes, bytes);
            held += bytes;
        }
        ASSERT_LE(held, o.budget_bytes) << "step " << step;
    }
    st.wait_idle();
    const Stats s = st.stats();
    EXPECT_LE(s.peak_bytes, o.budget_bytes);
    EXPECT_GT(s.evictions, 0U);
    EXPECT_GT(s.hits, 0U);
    EXPECT_GT(drawn, 0U);
    EXPECT_EQ(s.errors, 0U);
    // The time counted is the time callers spent in wait_front, within the
    // call's own overhead (200 calls).
    EXPECT_LE(s.seconds_waiting, waited);
    EXPECT_GE(s.seconds_waiting, waited - 0.05);
}

TEST(Streamer, PrefetchTurnsAPanIntoHits)
{
    TreeDir d("prefetch", 3);
    const auto t = d.open();
    View v = whole();
    v.units_per_pixel /= 4; // a quarter of the tree in view
    v.center_x = v.center_y = side * 0.3;
    View panned = v;
    panned.center_x += 0.3 * v.width * v.units_per_pixel;
    // Misses right after the pan, and front payloads (not prefetched ones) the
    // pan still had to load. The second does not depend on how fast the I/O
    // thread is: without prefetching, a miss may be loaded before
    // resident_front() asks.
    auto after_pan = [&](bool prefetch) {
        StreamOptions o;
        o.prefetch = prefetch;
        o.budget_bytes = 1ULL << 30;
        Streamer st(t, o);
        st.set_view(v);
        st.wait_idle();
        const Stats before = st.stats();
        st.set_view(panned);
        st.resident_front();
        st.wait_idle();
        const Stats now = st.stats();
        return std::pair{now.misses - before.misses, (now.loads - now.prefetches) - (before.loads - before.prefetches)};
    };
    EXPECT_EQ(after_pan(true), std::pair(uint64_t{0}, uint64_t{0}));
    EXPECT_GT(after_pan(false).second, 0U);
}

// Under a budget that binds (the front and a little more), along a smooth
// zoom into a corner and back out with a pan: prefetching never evicts what
// the front or its own list wants, so it loads at most 1.5x what the
// streamer without prefetching loads, and misses no more. Each view's I/O
// finishes before the next (wait_idle), so the counts do not depend on the
// I/O thread's speed (the lookahead past 4 views, which follows the disk's
// pace, is held off: it is timed). Before the list was cut to the budget and
// prefetches were kept from evicting wanted payloads, this path thrashed.
TEST(Streamer, UnderABindingBudgetPrefetchingDoesNotThrash)
{
    TreeDir d("binding", 3);
    const auto t = d.open();
    const auto& s = t->skeleton();
    std::vector<View> path;
    for (int i = 0; i <= 60; ++i) { // in: 2^-6 of the whole, towards (0.3, 0.2)
        View v = whole();
        const double f = i / 60.0;
        v.center_x = side * (0.5 - 0.2 * f);
        v.center_y = side * (0.5 - 0.3 * f);
        v.units_per_pixel *= std::exp2(-6 * f);
        path.push_back(v);
    }
    for (int i = 0; i <= 30; ++i) { // a pan across the lower left
        View v = path.back();
        v.center_x += side * 0.2 * i / 30.0;
        path.push_back(v);
    }
    for (int i = 60; i >= 0; --i) { // and back out
        View v = path[size_t(i)];
        v.center_x += side * 0.2;
        path.push_back(v);
    }
    // The budget: the largest front's payloads and tables, and a third more.
    uint64_t largest = 0;
    for (const auto& v : path) {
        uint64_t bytes = 0;
        std::set<uint32_t> nodes;
        for (const auto& f : select_front(s, v)) {
            bytes += datatree::geometry_bytes(s.nodes[f.node].chains, s.nodes[f.node].lods[f.lod].vertices);
            if (nodes.insert(f.node).second) {
                bytes += NodeChains::bytes(s.nodes[f.node].chains);
            }
        }
        largest = std::max(largest, bytes);
    }
    struct Run {
        Stats stats;
        uint64_t misses = 0; // front payloads not resident when the view was set
    };
    auto run = [&](bool prefetch) -> Run {
        StreamOptions o;
        o.prefetch = prefetch;
        o.budget_bytes = largest * 4 / 3;
        o.max_lookahead_views = 4;
        Streamer st(t, o);
        Run r;
        for (const auto& v : path) {
            std::set<FrontItem> resident;
            for (const auto& x : st.resident()) {
                resident.insert(x.item);
            }
            for (const auto& f : select_front(s, v)) {
                r.misses += resident.contains(f) ? 0 : 1;
            }
            st.set_view(v);
            st.wait_idle();
            EXPECT_EQ(st.missing(), 0U); // the front always fits
            for (const auto& dr : st.resident_front()) {
                EXPECT_TRUE(dr.geometry);
                EXPECT_EQ(dr.lod, dr.wanted.lod);
            }
        }
        r.stats = st.stats();
        EXPECT_LE(r.stats.peak_bytes, o.budget_bytes);
        return r;
    };
    const Run plain = run(false);
    const Run ahead = run(true);
    std::printf("binding budget, %zu views: without prefetching %llu loads, %llu misses; with it %llu loads (%llu "
                "prefetched), %llu misses, %llu views' lists cut\n",
                path.size(), (unsigned long long)plain.stats.loads, (unsigned long long)plain.misses,
                (unsigned long long)ahead.stats.loads, (unsigned long long)ahead.stats.prefetches,
                (unsigned long long)ahead.misses, (unsigned long long)ahead.stats.prefetch_cuts);
    EXPECT_GT(plain.stats.evictions, 0U); // the budget binds
    EXPECT_GT(ahead.stats.prefetch_cuts, 0U);
    EXPECT_GT(ahead.stats.prefetches, 0U);
    EXPECT_LE(double(ahead.stats.loads), 1.5 * double(plain.stats.loads))
        << ahead.stats.loads << " loads with prefetching, " << plain.stats.loads << " without";
    EXPECT_LT(ahead.misses, plain.misses);
}

TEST(Streamer, FallsBackToAResidentLodOfTheSameNode)
{
    TreeDir d("fallback", 1);
    // Every LOD 0 payload is damaged, so a view that wants LOD 0 can only be
    // drawn from the coarser LODs already resident.
    for (const auto& n : d.tree.skeleton.nodes) {
        const auto& ref = n.lods[0].payload;
        std::fstream f(d.dir / d.tree.skeleton.tiles[ref.tile].file, std::ios::in | std::ios::out | std::ios::binary);
        f.seekp(static_cast<std::streamoff>(ref.offset + 1));
        f.put('\x33');
    }
    const auto t = d.open();
    StreamOptions o;
    o.prefetch = false;
    Streamer st(t, o);
    View v = whole();
    v.units_per_pixel *= 8; // coarse: LOD 2 for every node
    const auto coarse = st.set_view(v);
    ASSERT_TRUE(st.wait_front(std::chrono::seconds(10)));
    View fine = v;
    fine.units_per_pixel /= 1024; // LOD 0 wanted, the same nodes in view
    fine.width = fine.height = 512 * 1024;
    const auto front = st.set_view(fine);
    ASSERT_EQ(front.size(), coarse.size());
    st.wait_idle();
    for (const auto& dr : st.resident_front()) {
        EXPECT_EQ(dr.wanted.lod, 0U);
        ASSERT_TRUE(dr.geometry);
        EXPECT_EQ(dr.lod, 2U);
        EXPECT_EQ(*dr.geometry, d.tree.geometry[dr.wanted.node][2]);
    }
    EXPECT_EQ(st.stats().errors, front.size());
}

TEST(Damage, CorruptTruncatedAndMissingTilesAreReportedAndTheRestStillDraws)
{
    TreeDir d("damage", 1);
    const auto& sk = d.tree.skeleton;
    // Corrupt a payload byte of node 1 (tile 1); truncate tile 2; remove tile 3.
    {
        const auto& ref = sk.nodes[1].lods[0].payload;
        std::fstream f(d.dir / sk.tiles[ref.tile].file, std::ios::in | std::ios::out | std::ios::binary);
        f.seekp(static_cast<std::streamoff>(ref.offset + ref.size / 2));
        f.put('\x5A');
    }
    fs::resize_file(d.dir / sk.tiles[2].file, sk.tiles[2].size - 10);
    fs::remove(d.dir / sk.tiles[3].file);
    const auto t = d.open();
    datatree::Geometry g;
    Status s1 = t->read_geometry(1, 0, g);
    EXPECT_NE(s1.error.find("t1.tlt: node 1 (a) LOD 0: checksum mismatch"), std::string::npos) << s1.error;
    Status s2 = t->read_geometry(2, 0, g);
    EXPECT_NE(s2.error.find("t2.tlt: truncated"), std::string::npos) << s2.error;
    EXPECT_NE(s2.error.find("node 2 (b)"), std::string::npos) << s2.error;
    Status s3 = t->read_geometry(3, 0, g);
    EXPECT_NE(s3.error.find("t3.tlt: node 3 (c) LOD 0: cannot open"), std::string::npos) << s3.error;
    EXPECT_TRUE(t->read_geometry(4, 0, g).ok());

    StreamOptions o;
    Streamer st(t, o);
    View v = whole();
    v.units_per_pixel /= 64; // LOD 0 everywhere
    st.set_view(v);
    EXPECT_FALSE(st.wait_front(std::chrono::seconds(10)));
    st.wait_idle();
    size_t drawn = 0;
    for (const auto& dr : st.resident_front()) {
        drawn += dr.geometry != nullptr;
    }
    EXPECT_GE(drawn, 1U); // node 4 at least
    EXPECT_GE(st.stats().errors, 3U);
    EXPECT_EQ(st.errors().size(), st.stats().errors);
}

TEST(Damage, BadSkeletonIsAnErrorNotACrash)
{
    TreeDir d("badskel", 1);
    {
        std::fstream f(d.dir / "skeleton.tls", std::ios::in | std::ios::out | std::ios::binary);
        f.seekp(0);
        f.put('Q');
    }
    std::string error;
    EXPECT_FALSE(Tree::open(d.dir, error));
    EXPECT_NE(error.find("skeleton.tls: not a Data Tree skeleton"), std::string::npos) << error;
    EXPECT_FALSE(Tree::open(d.dir / "nowhere", error));
    EXPECT_NE(error.find("cannot open"), std::string::npos);
}

// The draw list on a hand-made front: root > A, B > A1, A2 (under A), B1
// (under B). A's map shows A1|A2 (chain 10) and its outline toward B
// (chain 50, whose other side is unit B1, a node); B's map shows chain 60 and
// the same chain 50 (other side A1). B1's map, one level finer, shows 70
// and its outline 80 along the same border (tract-level units: no nodes).
TEST(DrawList, EachChainOnceSharedBordersAtTheFinerLodAndLevel)
{
    datatree::Skeleton s;
    const uint32_t none = datatree::no_node;
    auto node = [&](uint32_t parent, uint32_t level) {
        datatree::Node n;
        n.parent = parent;
        n.level = level;
        s.nodes.push_back(n);
    };
    node(none, 0); // 0 root
    node(0, 1);    // 1 A
    node(0, 1);    // 2 B
    node(1, 2);    // 3 A1
    node(1, 2);    // 4 A2
    node(2, 2);    // 5 B1
    auto chains = [](std::vector<uint64_t> ids, std::vector<uint32_t> across) {
        auto c = std::make_shared<NodeChains>();
        c->ids = std::move(ids);
        c->flags.assign(c->ids.size(), 0);
        c->across = std::move(across);
        return std::shared_ptr<const NodeChains>(c);
    };
    const auto geometry = std::make_shared<const datatree::Geometry>();
    const auto a = chains({10, 50}, {none, 5}), b = chains({50, 60}, {3, none}), b1 = chains({70, 80}, {none, none});
    auto item = [&](uint32_t n, uint32_t lod, std::shared_ptr<const NodeChains> c, bool ready = true) {
        return Drawable{{n, lod}, lod, ready ? geometry : nullptr, std::move(c)};
    };
    // One level: 50 once, by B, drawn at the finer LOD (1).
    EXPECT_EQ(draw_list(s, {item(1, 2, a), item(2, 1, b)}), (std::vector<DrawChain>{{0, 0}, {1, 0}, {1, 1}}));
    // The same LOD: by the earlier item.
    EXPECT_EQ(draw_list(s, {item(1, 1, a), item(2, 1, b)}), (std::vector<DrawChain>{{0, 0}, {0, 1}, {1, 1}}));
    // B opened into B1: the border is B1's (its chain 80, finer); A leaves its 50 to it.
    EXPECT_EQ(draw_list(s, {item(1, 1, a), item(5, 0, b1)}), (std::vector<DrawChain>{{0, 0}, {1, 0}, {1, 1}}));
    // Until B1 is resident, A draws 50, so that the border never goes missing.
    EXPECT_EQ(draw_list(s, {item(1, 1, a), item(5, 0, b1, false)}), (std::vector<DrawChain>{{0, 0}, {0, 1}}));
    // A node without its table draws nothing.
    EXPECT_EQ(draw_list(s, {item(1, 1, nullptr), item(2, 3, b)}), (std::vector<DrawChain>{{1, 0}, {1, 1}}));
}
