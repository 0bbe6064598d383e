// Floyd County (../shared/data, skipped with a reason when absent) simplified
// at 1, 4, 16 and 64 m and checked exactly: no crossings or self-intersections
// anywhere in each level (partitions together), every original vertex within
// eps of the simplified chain, every internal point strictly inside its unit;
// with the eps-Voronoi test and with the exact rules alone.
#include "core/segment_grid.hpp"
#include "gl/context.hpp"
#include "stages/ingest/config.hpp"
#include "stages/ingest/map_builder.hpp"
#include "stages/ingest/sources.hpp"
#include "simplification/simplifier.hpp"
#include "../../support/sanitizers.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>

namespace fs = std::filesystem;
using namespace tigerlod;
using namespace tigerlod::simplify;
using chains::ChainStore;

namespace {

const fs::path source_dir = TIGERLOD_SOURCE_DIR;
const fs::path shared_data = source_dir.parent_path() / "shared" / "data";

std::vector<ChainStore> ingest_floyd()
{
    const auto cfg = ingest::load_config(source_dir / "configs" / "floyd.yaml");
    Log log;
    auto raw = ingest::read_dataset(cfg, 2, log);
    ingest::BuildOptions o;
    o.halo_m = cfg.halo_m;
    o.threads = 2;
    std::vector<ChainStore> stores;
    std::mutex m;
    ingest::build_map(std::move(raw), Projection(cfg.projection), o, [&](const ChainStore& s) {
        std::lock_guard lock(m);
        stores.push_back(s);
    });
    std::sort(stores.begin(), stores.end(), [](const auto& a, const auto& b) {
        return std::tie(a.level_index, a.partition) < std::tie(b.level_index, b.partition);
    });
    return stores;
}

/// Every simplified chain against its original: a subsequence with the same
/// ends, each skipped vertex within eps of the segment that replaced it.
size_t eps_violations(const ChainStore& orig, const ChainStore& simp, const SimplifyOptions& opt, double eps_m)
{
    const auto eps = chain_tolerances(orig, eps_m, opt);
    std::map<uint64_t, size_t> index;
    for (size_t i = 0; i < orig.chains.size(); ++i) {
        index[orig.chains[i].id] = i;
    }
    size_t bad = 0;
    for (const auto& c : simp.chains) {
        const size_t oi = index.at(c.id);
        const auto o = orig.chain_points(orig.chains[oi]);
        const auto s = simp.chain_points(c);
        const Tolerance tol(eps[oi], opt.metric);
        size_t k = 0; // position in o of s[j]
        if (s.front() != o.front() || s.back() != o.back()) {
            ++bad;
            continue;
        }
        for (size_t j = 1; j < s.size(); ++j) {
            size_t next = k + 1;
            while (next < o.size() && o[next] != s[j]) {
                ++next;
            }
            if (next == o.size()) {
                ++bad; // not a subsequence
                break;
            }
            for (size_t i = k + 1; i < next; ++i) {
                bad += !within(o[i], s[j - 1], s[j], tol);
            }
            k = next;
        }
    }
    return bad;
}

} // namespace

TEST(SimplifyReal, FloydAtFourTolerancesIsExactlyValid)
{
    if (!fs::exists(shared_data / "tiger" / "tl_2020_51063_edges.zip")) {
        GTEST_SKIP() << "../shared/data/tiger is absent: Floyd County tests need it";
    }
    const auto stores = ingest_floyd();
    auto ctx = gl::Context::create(gl::Backend::osmesa);
    RasterOptions ro;
    Raster raster(*ctx, ro);
    SimplifyOptions opt;
    opt.threads = 2;
    // With the eps-Voronoi test, then with the exact rules alone (no raster):
    // the same guarantees, and no more vertices than the raster keeps.
    std::map<double, size_t> voronoi_vertices;
#if TIGERLOD_SANITIZED
    // Two of the four under the sanitizers (the four took 44 s under ASan):
    // the same code at a fine and a coarse tolerance; the dev pass runs all.
    const std::vector<double> ladder = {4.0, 64.0};
#else
    const std::vector<double> ladder = {1.0, 4.0, 16.0, 64.0};
#endif
    // Third, the exact rules with ends at a greedy fit within eps / 2 where
    // the hull scan takes a chain (simplify.end_sample 2, far sparser than
    // the default's 256): a subset of the shortcuts, the same guarantees.
    struct Pass {
        Raster* engine;
        uint32_t end_sample;
    };
    for (const Pass pass : {Pass{&raster, 0}, Pass{nullptr, 0}, Pass{nullptr, 2}}) {
        Raster* engine = pass.engine;
        opt.end_sample = pass.end_sample;
        SCOPED_TRACE(engine ? "eps-Voronoi test" : pass.end_sample ? "ends at a greedy fit" : "exact rules alone");
        // The greedy fit's ends bite where the hull scan takes chains: at
        // the coarse tolerances the store's halo allows.
        const std::vector<double> coarse = {250.0, 500.0};
        for (const double eps_m : pass.end_sample ? coarse : ladder) {
            std::map<uint32_t, ChainStore> level_maps; // all partitions of a level together
            size_t in_vertices = 0, out_vertices = 0, violations = 0, candidates = 0, all_candidates = 0;
            for (const auto& store : stores) {
                ToleranceStats st;
                const auto simp = simplify_store(store, eps_m, opt, engine, nullptr, st);
                candidates += st.candidates;
                if (pass.end_sample) {
                    SimplifyOptions every = opt;
                    every.end_sample = 0;
                    ToleranceStats all;
                    simplify_store(store, eps_m, every, nullptr, nullptr, all);
                    all_candidates += all.candidates;
                }
                in_vertices += st.input_vertices;
                out_vertices += st.output_vertices;
                violations += eps_violations(store, simp, opt, eps_m);
                EXPECT_EQ(st.input_conflicts, 0U) << store.level_name << "/" << store.partition;
                auto& m = level_maps[store.level_index];
                m.projection = store.projection;
                for (const auto& c : simp.chains) {
                    chains::ChainInfo info = c;
                    info.left = m.intern(simp.strings[c.left]);
                    info.right = m.intern(simp.strings[c.right]);
                    info.feature_class = m.intern(simp.strings[c.feature_class]);
                    m.add_chain(info, simp.chain_points(c));
                }
                for (const auto& p : store.constraints) {
                    m.constraints.push_back({m.intern(store.strings[p.unit]), p.kind, p.p});
                }
            }
            EXPECT_EQ(violations, 0U) << "eps " << eps_m;
            EXPECT_LT(out_vertices, in_vertices);
            for (const auto& [level, m] : level_maps) {
                std::vector<Segment> segs;
                for (const auto& c : m.chains) {
                    const auto p = m.chain_points(c);
                    for (size_t i = 0; i + 1 < p.size(); ++i) {
                        segs.push_back({p[i], p[i + 1], uint32_t(segs.size())});
                    }
                }
                EXPECT_EQ(find_intersections(segs, 2).size(), 0U) << "level " << level << " eps " << eps_m;
                size_t outside = 0;
                for (const auto& p : m.constraints) {
                    outside += unit_location(m, p.unit, p.p) != PointLocation::inside;
                }
                EXPECT_EQ(outside, 0U) << "level " << level << " eps " << eps_m << ": internal points not inside";
            }
            if (engine) {
                voronoi_vertices[eps_m] = out_vertices;
            } else if (pass.end_sample) {
                EXPECT_LT(candidates, all_candidates) << "eps " << eps_m << ": the fit's ends did not bite";
                std::printf("eps %g m: %zu vertices, %zu of %zu candidates with ends at a greedy fit within eps / %u\n",
                            eps_m, out_vertices, candidates, all_candidates, pass.end_sample);
            } else {
                EXPECT_LE(out_vertices, voronoi_vertices.at(eps_m)) << "eps " << eps_m;
                std::printf("eps %g m: %zu vertices with the eps-Voronoi test, %zu with the exact rules alone\n", eps_m,
                            voronoi_vertices.at(eps_m), out_vertices);
            }
        }
    }
}

TEST(SimplifyReal, FloydIsByteIdenticalAcrossThreadCountsAndModes)
{
    if (!fs::exists(shared_data / "tiger" / "tl_2020_51063_edges.zip")) {
        GTEST_SKIP() << "../shared/data/tiger is absent: Floyd County tests need it";
    }
    const auto stores = ingest_floyd();
    auto ctx = gl::Context::create(gl::Backend::osmesa);
    Raster raster(*ctx, RasterOptions{});
    RasterOptions one_framebuffer, tiny;
    one_framebuffer.window_pixels = one_framebuffer.max_tile_pixels;
    tiny.window_pixels = 64;
    Raster raster_one(*ctx, one_framebuffer), raster_tiny(*ctx, tiny);
    auto all = [&](unsigned threads, bool lazy, bool clip = true, Raster* engine = nullptr) {
        SimplifyOptions opt;
        opt.threads = threads;
        opt.lazy = lazy;
        opt.clip_tests = clip;
        std::string bytes;
        for (const auto& s : stores) {
            if (s.level_name != "tract" && s.level_name != "block_group") {
                continue;
            }
            ToleranceStats st;
            bytes += chains::encode(simplify_store(s, 16.0, opt, engine ? engine : &raster, nullptr, st));
        }
        return bytes;
    };
    const std::string one = all(1, false);
    EXPECT_EQ(one, all(2, false));
    EXPECT_EQ(one, all(2, true));
    EXPECT_EQ(one, all(2, false, false)) << "drawing whole shortcuts, not their near parts";
    EXPECT_EQ(one, all(2, true, true, &raster_one)) << "every tile in one framebuffer of the tile's size";
    EXPECT_EQ(one, all(2, true, true, &raster_tiny)) << "a framebuffer of 64 pixels: most tiles in pieces";
    EXPECT_GT(raster.stats().one_piece_boxes, 0U);
    EXPECT_GT(raster_tiny.stats().one_piece_boxes, 0U);
    EXPECT_LT(raster_tiny.stats().one_piece_boxes, raster_tiny.stats().tiles);
    EXPECT_EQ(raster_one.stats().one_piece_boxes, raster_one.stats().tiles);
}

// The ladder (simplify_ladder: one grid for tolerances whose grids are alike,
// the segments in reach cut once) gives each tolerance byte for byte what
// simplify_store gives it alone, with the same counts, whether tolerances
// share a grid or not.
namespace {

/// Floyd's stores simplified at `ladder` in one go (simplify_ladder) and at
/// each tolerance alone: the same bytes and counts. One test per ladder and
/// engine (and level, for the coarse ladder), so that each has its own time
/// under the sanitizers (all in one test passed 900 s under ASan on a loaded
/// machine; the coarse ladder alone took 671 s idle).
void expect_floyd_ladder_alone(const std::vector<double>& ladder, bool with_raster, const std::string& level = "")
{
    if (!fs::exists(shared_data / "tiger" / "tl_2020_51063_edges.zip")) {
        GTEST_SKIP() << "../shared/data/tiger is absent: Floyd County tests need it";
    }
    const auto stores = ingest_floyd();
    std::unique_ptr<gl::Context> ctx;
    std::optional<Raster> raster;
    if (with_raster) {
        ctx = gl::Context::create(gl::Backend::osmesa);
        raster.emplace(*ctx, RasterOptions{});
    }
    Raster* engine = raster ? &*raster : nullptr;
    SimplifyOptions opt;
    opt.threads = 2;
    auto same_counts = [](const ToleranceStats& a, const ToleranceStats& b) {
        return std::tie(a.chains, a.input_vertices, a.output_vertices, a.candidates, a.drawn_segments, a.proved_far,
                        a.proved_short, a.banned_raster, a.banned_exact, a.banned_region, a.banned_points,
                        a.self_intersection_repairs, a.orientation_repairs, a.input_conflicts, a.rounds) ==
               std::tie(b.chains, b.input_vertices, b.output_vertices, b.candidates, b.drawn_segments, b.proved_far,
                        b.proved_short, b.banned_raster, b.banned_exact, b.banned_region, b.banned_points,
                        b.self_intersection_repairs, b.orientation_repairs, b.input_conflicts, b.rounds);
    };
    for (const auto& store : stores) {
        if (!level.empty() && store.level_name != level) {
            continue;
        }
        SCOPED_TRACE(store.level_name + "/" + store.partition + " at " + std::to_string(ladder.front()) + " m up, " +
                     (engine ? "eps-Voronoi test" : "exact rules alone"));
        std::vector<ToleranceStats> stats;
        std::vector<std::string> bytes(ladder.size());
        simplify_ladder(
            store, ladder, opt, engine, [](size_t) { return nullptr; }, stats,
            [&](size_t t, const ChainStore& result) { bytes[t] = chains::encode(result); });
        ASSERT_EQ(stats.size(), ladder.size());
        for (size_t t = 0; t < ladder.size(); ++t) {
            ToleranceStats alone;
            EXPECT_EQ(bytes[t], chains::encode(simplify_store(store, ladder[t], opt, engine, nullptr, alone)))
                << "eps " << ladder[t];
            EXPECT_TRUE(same_counts(stats[t], alone)) << "eps " << ladder[t];
            EXPECT_EQ(stats[t].eps_m, ladder[t]);
        }
    }
}

} // namespace

// fine and coarse: one grid for the four on most stores; wide: 1 and 16 m
// share one, 2000 m (cells more than 8x wider) gets its own.
TEST(SimplifyReal, FloydFineLadderWithTheRasterIsByteIdenticalToEachToleranceAlone)
{
#if TIGERLOD_SANITIZED
    // 58 s under ASan on every level; the block groups alone run the same
    // code (the raster's shared grid for four tolerances); the dev pass
    // checks all.
    expect_floyd_ladder_alone({1, 4, 16, 64}, true, "block_group");
#else
    expect_floyd_ladder_alone({1, 4, 16, 64}, true);
#endif
}

TEST(SimplifyReal, FloydFineLadderWithTheExactRulesIsByteIdenticalToEachToleranceAlone)
{
    expect_floyd_ladder_alone({1, 4, 16, 64}, false);
}

TEST(SimplifyReal, FloydCoarseLadderIsByteIdenticalToEachToleranceAloneAtStateLevel)
{
    expect_floyd_ladder_alone({250, 500, 1000, 2000}, false, "state");
}

TEST(SimplifyReal, FloydCoarseLadderIsByteIdenticalToEachToleranceAloneAtCountyLevel)
{
    expect_floyd_ladder_alone({250, 500, 1000, 2000}, false, "county");
}

TEST(SimplifyReal, FloydCoarseLadderIsByteIdenticalToEachToleranceAloneAtTractLevel)
{
    expect_floyd_ladder_alone({250, 500, 1000, 2000}, false, "tract");
}

TEST(SimplifyReal, FloydCoarseLadderIsByteIdenticalToEachToleranceAloneAtBlockGroupLevel)
{
    expect_floyd_ladder_alone({250, 500, 1000, 2000}, false, "block_group");
}

TEST(SimplifyReal, FloydCoarseLadderIsByteIdenticalToEachToleranceAloneAtBlockLevel)
{
#if TIGERLOD_SANITIZED
    // Floyd's blocks at the coarse ladder took 650 s of the 900 under ASan,
    // and 104 s at its two smallest tolerances: the four levels above run
    // the same ladder code under the sanitizers; the dev pass checks the
    // blocks at all four.
    GTEST_SKIP() << "under the sanitizers the state to block-group levels run this ladder's code; the dev pass runs "
                    "the blocks";
#else
    expect_floyd_ladder_alone({250, 500, 1000, 2000}, false, "block");
#endif
}

TEST(SimplifyReal, FloydWideLadderIsByteIdenticalToEachToleranceAlone)
{
#if TIGERLOD_SANITIZED
    // 200 s under ASan on every level; the block groups alone run the same
    // code (two grids, one tolerance on its own); the dev pass checks all.
    expect_floyd_ladder_alone({1, 16, 2000}, false, "block_group");
#else
    expect_floyd_ladder_alone({1, 16, 2000}, false);
#endif
}
