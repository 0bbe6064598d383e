// Hand-made maps with exact expectations for tigerlod-color and
// tigerlod-simplify, on OSMesa (a dependency installed by scripts/setup):
// the mechanisms (candidates, raster, colouring, statistics). Maps whose
// outcome alone is the point are data: tests/maps/ (test_maps.cpp).
#include "core/errors.hpp"
#include "core/segment_grid.hpp"
#include "gl/context.hpp"
#include "simplification/candidates.hpp"
#include "simplification/cell_cover.hpp"
#include "simplification/coloring.hpp"
#include "simplification/fewest_edges.hpp"
#include "simplification/hull_scan.hpp"
#include "simplification/near_parts.hpp"
#include "simplification/raster.hpp"
#include "simplification/simplifier.hpp"
#include "../../support/simplify_fixture.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>
#include <stdexcept>
#include <string_view>

using namespace tigerlod;
using namespace tigerlod::simplify;
using namespace tigerlod::simplify::testing;

namespace {

/// A chain of n points from the origin, each step drawn from [lo, hi] in x
/// and the same divided by y_div in y (mostly forward, turning back at times).
Pts random_walk(std::mt19937& rng, int n, int lo, int hi, int y_div)
{
    Pts pts;
    GridPoint p{0, 0};
    std::uniform_int_distribution<int> step(lo, hi);
    for (int i = 0; i < n; ++i) {
        pts.push_back(p);
        const int dx = step(rng);
        p = {p.x + dx, p.y + step(rng) / y_div};
    }
    return pts;
}

/// A square render tile: origin and pixel in grid units, side in pixels.
TileSpec square_tile(double x0, double y0, double pixel, uint32_t side)
{
    TileSpec t;
    t.x0 = x0;
    t.y0 = y0;
    t.pixel = pixel;
    t.width = t.height = side;
    return t;
}

bool dp_within(const Pts& pts, size_t a, size_t b, double eps)
{
    for (size_t i = a + 1; i < b; ++i) {
        if (!within(pts[i], pts[a], pts[b], Tolerance(eps, Metric::l2))) {
            return false;
        }
    }
    return true;
}

/// Plain per-chain Douglas-Peucker, for contrast.
Pts douglas_peucker(const Pts& pts, double eps)
{
    std::vector<bool> keep(pts.size(), false);
    keep.front() = keep.back() = true;
    std::vector<std::pair<size_t, size_t>> stack{{0, pts.size() - 1}};
    while (!stack.empty()) {
        auto [a, b] = stack.back();
        stack.pop_back();
        if (b <= a + 1 || dp_within(pts, a, b, eps)) {
            continue;
        }
        size_t far = a + 1;
        double best = -1;
        for (size_t i = a + 1; i < b; ++i) {
            const double d = distance(pts[i], pts[a], pts[b], Metric::l2);
            if (d > best) {
                best = d;
                far = i;
            }
        }
        keep[far] = true;
        stack.push_back({a, far});
        stack.push_back({far, b});
    }
    Pts out;
    for (size_t i = 0; i < pts.size(); ++i) {
        if (keep[i]) {
            out.push_back(pts[i]);
        }
    }
    return out;
}

/// Every proximate shortcut of `pts`, by testing each vertex between
/// (ends equal to the start left out; at most `reach` vertices ahead, 0: no cap).
std::vector<Shortcut> brute_force_shortcuts(const Pts& pts, const Tolerance& tol, uint32_t reach)
{
    std::vector<Shortcut> want;
    for (uint32_t j = 0; j < pts.size(); ++j) {
        for (uint32_t k = j + 2; k < pts.size() && (reach == 0 || k <= j + reach); ++k) {
            bool ok = pts[j] != pts[k];
            for (uint32_t i = j + 1; ok && i < k; ++i) {
                ok = within(pts[i], pts[j], pts[k], tol);
            }
            if (ok) {
                want.push_back({j, k});
            }
        }
    }
    return want;
}

} // namespace

TEST(Metric, WithinMatchesTheDistanceOnRandomPoints)
{
    std::mt19937 rng(7);
    std::uniform_int_distribution<int> c(-300, 300);
    for (Metric m : {Metric::l2, Metric::l1, Metric::linf}) {
        const Tolerance tol(100, m);
        for (int i = 0; i < 20000; ++i) {
            const GridPoint p{c(rng), c(rng)}, a{c(rng), c(rng)}, b{c(rng), c(rng)};
            const double d = distance(p, a, b, m);
            if (std::abs(d - 100) < 1e-6) {
                continue; // on the boundary: the double distance cannot decide
            }
            EXPECT_EQ(within(p, a, b, tol), d < 100) << metric_name(m) << " p " << p.x << "," << p.y;
        }
    }
}

TEST(Candidates, MatchBruteForceOnRandomChains)
{
    std::mt19937 rng(11);
    for (Metric m : {Metric::l2, Metric::l1, Metric::linf}) {
        for (int trial = 0; trial < 200; ++trial) {
            const Pts pts = random_walk(rng, 40, -60, 100, 2);
            const Tolerance tol(double(50 + trial % 7 * 20), m);
            const uint32_t reach = trial % 3 == 0 ? 5 : 0;
            const std::vector<Shortcut> want = brute_force_shortcuts(pts, tol, reach);
            const auto got = proximate_shortcuts(pts, tol, reach).list();
            ASSERT_EQ(got.size(), want.size()) << metric_name(m) << " trial " << trial;
            for (size_t i = 0; i < got.size(); ++i) {
                EXPECT_EQ(got[i].from, want[i].from);
                EXPECT_EQ(got[i].to, want[i].to);
            }
        }
    }
}

// Chains that go out and back within a strip narrower than eps, as a
// coastline at a coarse tolerance does: most ends lie short of the farthest
// vertex, where the scan's exact tests (the list of far vertices and the
// anchor of UnsureEnds) decide, in both kernels. Regression: the coarse
// ladder's candidate scan, O(n w^2) before 2026-11-24.
TEST(Candidates, ChainsGoingOutAndBackMatchBruteForce)
{
    std::mt19937 rng(5);
    std::uniform_int_distribution<int> noise(-40, 40);
    for (Metric m : {Metric::l2, Metric::l1, Metric::linf}) {
        for (int trial = 0; trial < 30; ++trial) {
            Pts pts;
            const double back = 150 + 20 * trial; // how far each meander turns back
            for (int k = 0; k < 120; ++k) {
                pts.push_back({static_cast<int32_t>(std::lround(100.0 * k + back * std::sin(0.9 * k))),
                               noise(rng) + (trial % 3 == 0 ? k * 7 : 0)});
            }
            const Tolerance tol(double(150 + trial % 5 * 150), m);
            const std::vector<Shortcut> want = brute_force_shortcuts(pts, tol, 0);
            for (const ScanKernel kernel :
                 {ScanKernel::fastest, ScanKernel::scalar, ScanKernel::lanes, ScanKernel::lanes4, ScanKernel::hulls}) {
                const auto got = proximate_shortcuts(pts, tol, 0, kernel).list();
                ASSERT_EQ(got, want) << metric_name(m) << " trial " << trial;
            }
        }
    }
}

// Step 4 reads a run of shortcuts one at a time, or through a tree of range
// minima where runs are long: the same path, edge for edge, whatever is
// banned (single shortcuts, a run's first or last, whole stretches), open
// chains and rings, short runs and long ones.
TEST(FewestEdges, TheTreeFindsThePathOneByOneReadingFinds)
{
    std::mt19937 rng(29);
    size_t compared = 0, long_runs = 0, banned_in_runs = 0;
    for (int trial = 0; trial < 300; ++trial) {
        Pts pts;
        const int n = 3 + static_cast<int>(rng() % 400);
        std::uniform_int_distribution<int> wiggle(-30, 30);
        for (int k = 0; k < n; ++k) {
            pts.push_back({100 * k + (trial % 3 == 0 ? 0 : wiggle(rng)), trial % 2 == 0 ? wiggle(rng) : (k % 7) * 40});
        }
        const bool ring = trial % 5 == 0;
        if (ring) {
            pts.push_back({pts.back().x, pts.back().y + 5000});
            pts.push_back(pts.front());
        }
        const Tolerance tol(double(20 + trial % 7 * 60), Metric::l2);
        const auto cand = proximate_shortcuts(pts, tol, 0);
        std::vector<uint8_t> state(cand.size(), 0);
        const int mode = trial % 4; // none banned, a few, a tenth, most
        std::uniform_int_distribution<int> pick(0, 99);
        for (auto& st : state) {
            const int p = pick(rng);
            const bool ban = mode == 1 ? p < 2 : mode == 2 ? p < 10 : mode == 3 ? p < 80 : false;
            st = ban ? static_cast<uint8_t>(first_banned_state + rng() % 3) : static_cast<uint8_t>(rng() % 2);
        }
        for (const auto& r : cand.runs()) {
            long_runs += r.hi - r.lo >= 48;
        }
        for (const uint8_t st : state) {
            banned_in_runs += st >= first_banned_state;
        }
        std::vector<uint32_t> path1, cand1, path2, cand2, path3, cand3;
        fewest_edges_path(cand, state, pts.size(), ring, path1, cand1, RunReading::one_by_one);
        fewest_edges_path(cand, state, pts.size(), ring, path2, cand2, RunReading::tree);
        fewest_edges_path(cand, state, pts.size(), ring, path3, cand3);
        ASSERT_EQ(path1, path2) << "trial " << trial;
        ASSERT_EQ(cand1, cand2) << "trial " << trial;
        ASSERT_EQ(path1, path3) << "trial " << trial;
        ASSERT_EQ(path1.front(), 0U);
        ASSERT_EQ(path1.back(), pts.size() - 1);
        if (ring) {
            EXPECT_GE(path1.size(), 4U) << "a ring keeps three vertices";
        }
        for (size_t e = 0; e < cand1.size(); ++e) {
            if (cand1[e] != UINT32_MAX) {
                EXPECT_LT(state[cand1[e]], first_banned_state) << "trial " << trial;
                EXPECT_EQ(cand.at(cand1[e]).from, path1[e]);
                EXPECT_EQ(cand.at(cand1[e]).to, path1[e + 1]);
            } else {
                EXPECT_EQ(path1[e + 1], path1[e] + 1);
            }
        }
        compared += path1.size();
    }
    // The cases above must have made what they are there for.
    EXPECT_GT(long_runs, 1000U);
    EXPECT_GT(banned_in_runs, 10000U);
    EXPECT_GT(compared, 3000U);
}

// A rule asked inside the search (LazyRule) gives the path found when it is
// asked about every shortcut first, with either reading of the runs: each
// shortcut asked once, only those still undecided, and fewer than all.
TEST(FewestEdges, ARuleAskedLazilyFindsThePathOfTheRuleAskedFirst)
{
    std::mt19937 rng(31);
    size_t asked_in_all = 0, undecided_in_all = 0, refused_in_all = 0;
    for (int trial = 0; trial < 200; ++trial) {
        Pts pts;
        const int n = 3 + static_cast<int>(rng() % 300);
        std::uniform_int_distribution<int> wiggle(-30, 30);
        for (int k = 0; k < n; ++k) {
            pts.push_back({100 * k + wiggle(rng), trial % 2 == 0 ? wiggle(rng) : (k % 5) * 40});
        }
        const bool ring = trial % 4 == 0;
        if (ring) {
            pts.push_back({pts.back().x, pts.back().y + 5000});
            pts.push_back(pts.front());
        }
        const auto cand = proximate_shortcuts(pts, Tolerance(double(40 + trial % 5 * 80), Metric::l2), 0);
        // The rule: a hash of the ends, refusing about 3 in 4 (as the region rule does at coarse tolerances).
        const uint32_t salt = static_cast<uint32_t>(rng());
        auto allows = [salt](uint32_t from, uint32_t to) {
            uint32_t h = (from * 2654435761U) ^ (to * 40503U) ^ salt;
            h ^= h >> 13;
            h *= 0x5bd1e995U;
            return (h >> 15) % 4 == 0;
        };
        std::vector<uint8_t> start(cand.size(), 0);
        for (auto& st : start) {
            st = rng() % 10 == 0 ? static_cast<uint8_t>(first_banned_state + 1) : uint8_t{0};
        }
        // Asked first: every undecided shortcut gets its answer.
        std::vector<uint8_t> decided = start;
        for (size_t r = 0; r < cand.runs().size(); ++r) {
            const auto& run = cand.runs()[r];
            for (uint32_t k = run.lo; k <= run.hi; ++k) {
                uint8_t& st = decided[cand.run_id(r) + (k - run.lo)];
                if (st == 0) {
                    st = allows(run.from, k) ? 1 : first_banned_state;
                    ++undecided_in_all;
                }
            }
        }
        std::vector<uint32_t> want, want_cand;
        fewest_edges_path(cand, decided, pts.size(), ring, want, want_cand);
        for (const RunReading reading : {RunReading::one_by_one, RunReading::tree}) {
            std::vector<uint8_t> lazy = start;
            std::map<std::pair<uint32_t, uint32_t>, int> asked;
            const LazyRule rule{[&](uint32_t from, uint32_t to) {
                                    ++asked[{from, to}];
                                    return allows(from, to);
                                },
                                1, first_banned_state};
            std::vector<uint32_t> got, got_cand;
            fewest_edges_path(cand, lazy, pts.size(), ring, got, got_cand, reading, &rule);
            ASSERT_EQ(got, want) << "trial " << trial;
            ASSERT_EQ(got_cand, want_cand) << "trial " << trial;
            for (const auto& [ends, times] : asked) {
                ASSERT_EQ(times, 1) << "asked twice: " << ends.first << " -> " << ends.second;
            }
            for (size_t id = 0; id < lazy.size(); ++id) {
                if (start[id] != 0) {
                    ASSERT_EQ(lazy[id], start[id]) << "a decided shortcut keeps its state";
                } else if (lazy[id] != 0) {
                    ASSERT_EQ(lazy[id], decided[id]) << "the answer recorded";
                    refused_in_all += lazy[id] >= first_banned_state;
                }
            }
            ASSERT_EQ(static_cast<size_t>(std::count_if(lazy.begin(), lazy.end(), [](uint8_t s) { return s != 0; })),
                      asked.size() + static_cast<size_t>(
                                         std::count_if(start.begin(), start.end(), [](uint8_t s) { return s != 0; })));
            asked_in_all += asked.size();
        }
    }
    EXPECT_GT(refused_in_all, 1000U);
    EXPECT_LT(asked_in_all, undecided_in_all) << "the search asks about fewer shortcuts than there are";
}

// A long chain's starts are scanned in pieces on threads of their own
// (simplify's find_candidates): the pieces, appended in order, must be the
// whole scan, whichever kernel, metric, reach cap and cut points (cuts off
// the groups of eight and four starts of the lanes kernels included).
TEST(Candidates, StartsScannedInPiecesAppendToTheWholeScan)
{
    std::mt19937 rng(11);
    std::uniform_int_distribution<int> noise(-60, 60);
    for (Metric m : {Metric::l2, Metric::l1, Metric::linf}) {
        for (int trial = 0; trial < 12; ++trial) {
            Pts pts;
            for (int k = 0; k < 400; ++k) {
                pts.push_back({static_cast<int32_t>(std::lround(90.0 * k + 300 * std::sin(0.05 * k * (trial + 1)))),
                               noise(rng) + (trial % 2 == 0 ? k * 5 : 0)});
            }
            const auto n = static_cast<uint32_t>(pts.size());
            const Tolerance tol(double(100 + trial * 60), m);
            const uint32_t reach = trial % 3 == 0 ? 37 : 0;
            for (const ScanKernel kernel :
                 {ScanKernel::fastest, ScanKernel::scalar, ScanKernel::lanes, ScanKernel::lanes4, ScanKernel::hulls}) {
                const auto whole = proximate_shortcuts(pts, tol, reach, kernel);
                std::vector<uint32_t> cuts{0, n};
                std::uniform_int_distribution<uint32_t> at(1, n - 1);
                for (int c = 0; c < 1 + trial % 5; ++c) {
                    cuts.push_back(at(rng));
                }
                std::sort(cuts.begin(), cuts.end());
                Candidates pieces;
                for (size_t c = 0; c + 1 < cuts.size(); ++c) {
                    pieces.append(proximate_shortcuts_from(pts, tol, reach, cuts[c], cuts[c + 1], kernel));
                }
                pieces.finish(n);
                ASSERT_GT(whole.size(), 0U);
                ASSERT_EQ(pieces.list(), whole.list()) << metric_name(m) << " trial " << trial;
                ASSERT_EQ(pieces.runs().size(), whole.runs().size());
                for (uint32_t v = 0; v + 1 < n; ++v) {
                    ASSERT_EQ(pieces.first_id(v), whole.first_id(v));
                }
            }
        }
    }
}

TEST(Candidates, AVertexWhoseConeIsNearlyAHalfPlaneStillCounts)
{
    // Vertex 1 lies just outside the metric's ball around vertex 0, so the
    // directions that pass within eps of it span nearly a half-plane, too
    // close to one for the wedge to hold it. Vertex 2 lies on the other
    // side, far beyond: shortcut 0 -> 2 passes farther than eps from vertex
    // 1 (its nearest point is vertex 0) and must not be taken for sure.
    // Against it, vertex 2 straight ahead through vertex 1 is a shortcut.
    const double t = 4e6;
    for (const Metric m : {Metric::l1, Metric::linf}) {
        const Tolerance tol(t, m);
        const GridPoint q = m == Metric::l1 ? GridPoint{2000001, 2000000} : GridPoint{4000001, 0};
        const Pts behind = {{0, 0}, q, {-q.x * 3, -q.y * 3}};
        ASSERT_FALSE(within(behind[1], behind[0], behind[2], tol)) << metric_name(m);
        EXPECT_TRUE(proximate_shortcuts(behind, tol, 0).empty()) << metric_name(m);
        const Pts ahead = {{0, 0}, q, {q.x * 3, q.y * 3}};
        const auto got = proximate_shortcuts(ahead, tol, 0).list();
        ASSERT_EQ(got.size(), 1U) << metric_name(m);
        EXPECT_EQ(got[0], (Shortcut{0, 2})) << metric_name(m);
    }
}

TEST(Candidates, TheFastestKernelFindsWhatTheScalarScanFinds)
{
    // Eight starts at once (AVX-512F; four where the processor has AVX2 only)
    // and four against one at a time, run for run: chains of every length
    // around the lane counts, long straight stretches (long runs),
    // sharp turns and repeated points (gaps in runs, ends equal to the
    // start), a ring, tolerances from tiny to wide, with and without a reach.
    if (std::string_view(fastest_scan_kernel()) == "scalar") {
        GTEST_SKIP() << "this processor has no AVX2 (or this is not x86-64): both kernels are the scalar scan";
    }
    std::printf("fastest scan kernel here: %s\n", fastest_scan_kernel());
    std::mt19937 rng(23);
    size_t compared = 0, with_gaps = 0;
    for (int trial = 0; trial < 600; ++trial) {
        Pts pts;
        const int n = trial < 40 ? trial % 10 + 1 : 10 + static_cast<int>(rng() % 300);
        std::uniform_int_distribution<int> step(-40, 100), turn(0, 9);
        GridPoint p{static_cast<int32_t>(rng() % 1000), static_cast<int32_t>(rng() % 1000)};
        for (int i = 0; i < n; ++i) {
            pts.push_back(p);
            switch (turn(rng)) {
            case 0:
                break; // a repeated point
            case 1:
                p = {p.x - 3 * step(rng), p.y + step(rng)}; // back
                break;
            default:
                p = {p.x + step(rng) + 60, p.y + step(rng) / 4};
            }
        }
        if (trial % 7 == 0 && n > 3) {
            pts.push_back(pts.front()); // a ring
        }
        const Tolerance tol(double(1 + trial % 9 * 15), Metric::l2);
        const uint32_t reach = trial % 4 == 0 ? static_cast<uint32_t>(2 + trial % 11) : 0;
        const auto slow = proximate_shortcuts(pts, tol, reach, ScanKernel::scalar);
        for (const ScanKernel kernel : {ScanKernel::lanes, ScanKernel::lanes4}) {
            const auto fast = proximate_shortcuts(pts, tol, reach, kernel);
            const char* name = kernel == ScanKernel::lanes ? "lanes" : "lanes4";
            ASSERT_EQ(fast.runs().size(), slow.runs().size()) << name << " trial " << trial;
            for (size_t r = 0; r < fast.runs().size(); ++r) {
                EXPECT_EQ(fast.runs()[r].from, slow.runs()[r].from) << name << " trial " << trial << " run " << r;
                EXPECT_EQ(fast.runs()[r].lo, slow.runs()[r].lo) << name << " trial " << trial << " run " << r;
                EXPECT_EQ(fast.runs()[r].hi, slow.runs()[r].hi) << name << " trial " << trial << " run " << r;
            }
            EXPECT_EQ(fast.list(), slow.list()) << name << " trial " << trial;
        }
        for (size_t r = 1; r < slow.runs().size(); ++r) {
            with_gaps += slow.runs()[r].from == slow.runs()[r - 1].from;
        }
        compared += slow.size();
    }
    // The cases above must have made what they are there for.
    EXPECT_GT(compared, 20000U);
    EXPECT_GT(with_gaps, 50U);
}

// A chain wider than the lanes' 2^26 grid units (a nation's outline) is
// scanned by the lanes in windows narrower than that, the starts whose scan
// reaches a window's end with the wedge open by the scalar scan: the same
// runs as the scalar scan of the whole chain, whether the scans stop inside
// the windows (wiggles), run through several (straight stretches), or meet
// a segment longer than a window, with and without a reach cap.
TEST(Candidates, ChainsWiderThanTheLanesFindWhatTheScalarScanFinds)
{
    if (std::string_view(fastest_scan_kernel()) == "scalar") {
        GTEST_SKIP() << "this processor has no AVX2 (or this is not x86-64): every kernel is the scalar scan";
    }
    std::mt19937 rng(31);
    size_t compared = 0, wide = 0;
    for (int trial = 0; trial < 120; ++trial) {
        Pts pts;
        const int n = 140 + static_cast<int>(rng() % 300);   // 140 steps of 2^20: wider than 2^27
        const int64_t step = int64_t{1} << (20 + trial % 4); // 2^20 to 2^23: 8 to 64 steps a window
        std::uniform_int_distribution<int64_t> wiggle(-(step >> 3), step >> 3);
        int64_t x = -(int64_t{1} << 30), y = 0;
        for (int k = 0; k < n; ++k) {
            pts.push_back({static_cast<int32_t>(x), static_cast<int32_t>(y)});
            const int kind = (k / 25 + trial) % 3; // stretches: straight, wiggling, turning
            x += step;
            y += kind == 0 ? 0 : kind == 1 ? wiggle(rng) : (k % 2 ? step : -step / 2);
            if (trial % 10 == 0 && k == n / 2) {
                x += int64_t{1} << 27; // one segment wider than a window
            }
            x = std::min<int64_t>(x, (int64_t{1} << 31) - 1);
        }
        GridBox box;
        for (const GridPoint p : pts) {
            box.extend(p);
        }
        wide += box.max_x - box.min_x >= int64_t{1} << 26;
        const Tolerance tol(double(step / 4 + trial * 997), Metric::l2);
        const uint32_t reach = trial % 4 == 1 ? static_cast<uint32_t>(3 + trial % 40) : 0;
        const auto slow = proximate_shortcuts(pts, tol, reach, ScanKernel::scalar);
        for (const ScanKernel kernel : {ScanKernel::lanes, ScanKernel::lanes4}) {
            const auto fast = proximate_shortcuts(pts, tol, reach, kernel);
            ASSERT_EQ(fast.list(), slow.list())
                << (kernel == ScanKernel::lanes ? "lanes" : "lanes4") << " trial " << trial;
            // And in pieces, as a long chain's starts are spread over threads.
            const auto cut = static_cast<uint32_t>(pts.size() / 3);
            Candidates pieces = proximate_shortcuts_from(pts, tol, reach, 0, cut, kernel);
            pieces.append(proximate_shortcuts_from(pts, tol, reach, cut, static_cast<uint32_t>(pts.size()), kernel));
            pieces.finish(static_cast<uint32_t>(pts.size()));
            ASSERT_EQ(pieces.list(), slow.list()) << "in pieces, trial " << trial;
        }
        compared += slow.size();
    }
    EXPECT_EQ(wide, 120U) << "every chain wider than the lanes";
    EXPECT_GT(compared, 20000U);
}

// The hull scan (hull_scan.hpp) decides blocks of ends at once by their
// convex hulls: every proof it makes must give exactly what testing each
// shortcut vertex by vertex gives. Chains dense for their tolerance (where
// blocks serve), with zigzags smaller and larger than eps, spikes and
// meanders that turn back past an end, repeated points, rings, collinear
// stretches, and reach caps; against brute force where small, against the
// scalar scan where long. The blocks must have decided most ends, and each
// of its three ways must have served.
TEST(Candidates, TheHullScanFindsWhatTestingEachShortcutFinds)
{
    std::mt19937 rng(31);
    detail::HullScanCounts counts;
    size_t compared = 0, restricted_compared = 0;
    for (int trial = 0; trial < 400; ++trial) {
        Pts pts;
        const int n = trial < 30 ? trial + 1 : 30 + static_cast<int>(rng() % (trial % 10 == 0 ? 1500 : 250));
        std::uniform_int_distribution<int> jitter(-12, 12), turn(0, 39);
        const int zig = 1 + trial % 7 * 9; // zigzag amplitude, against eps of 20-400
        GridPoint p{static_cast<int32_t>(rng() % 5000), static_cast<int32_t>(rng() % 5000)};
        double heading = 0;
        for (int i = 0; i < n; ++i) {
            pts.push_back(p);
            switch (turn(rng)) {
            case 0:
                break; // a repeated point
            case 1:
                p = {p.x - 40 * (1 + trial % 5), p.y + jitter(rng)}; // a spike back
                break;
            case 2:
                heading += 2.5; // a sharp turn
                [[fallthrough]];
            default: {
                heading += 0.02 * jitter(rng);
                const int side = (i % 2 == 0 ? zig : -zig);
                p = {p.x + static_cast<int32_t>(std::lround(10 * std::cos(heading) - side * std::sin(heading))),
                     p.y + static_cast<int32_t>(std::lround(10 * std::sin(heading) + side * std::cos(heading)))};
            }
            }
            if (trial % 9 == 4 && i % 50 < 25) {
                p = {p.x + 7, p.y}; // a straight, collinear stretch
            }
        }
        if (trial % 7 == 0 && n > 3) {
            pts.push_back(pts.front()); // a ring
        }
        // Some chains scaled past 2^26 across (a nation's outline on a 1 cm
        // grid), where the lanes cannot run and the hull scan's squared
        // lengths are inexact in doubles.
        const int scale = trial % 11 == 3 ? 1 << 14 : 1;
        for (GridPoint& q : pts) {
            q = {q.x * scale, q.y * scale};
        }
        const Tolerance tol(double(20 + trial % 8 * 55) * scale, Metric::l2);
        const uint32_t reach = trial % 5 == 0 ? static_cast<uint32_t>(3 + trial % 90) : 0;
        Candidates hulls;
        const detail::HullScanCounts c =
            detail::scan_hulls(pts, tol, reach, tol.threshold, 0, static_cast<uint32_t>(pts.size()), hulls);
        hulls.finish(static_cast<uint32_t>(pts.size()));
        counts.block_ends += c.block_ends;
        counts.outside_ends += c.outside_ends;
        counts.single_ends += c.single_ends;
        const auto scalar = proximate_shortcuts(pts, tol, reach, ScanKernel::scalar);
        ASSERT_EQ(hulls.list(), scalar.list()) << "trial " << trial;
        ASSERT_EQ(hulls.runs().size(), scalar.runs().size()) << "trial " << trial;
        EXPECT_EQ(proximate_shortcuts(pts, tol, reach, ScanKernel::hulls).list(), scalar.list()) << "trial " << trial;
        if (pts.size() <= 120) {
            ASSERT_EQ(hulls.list(), brute_force_shortcuts(pts, tol, reach)) << "trial " << trial;
        }
        compared += scalar.size();
        // Ends restricted to a set (random, or a greedy fit's): exactly the
        // unrestricted shortcuts between two of its vertices.
        std::vector<uint8_t> ends(pts.size());
        if (trial % 2 == 0) {
            ends = detail::greedy_fit_vertices(pts, std::sqrt(double(tol.threshold)) / double(1 + trial % 16));
        } else {
            for (auto& e : ends) {
                e = rng() % 3 == 0 ? 1 : 0;
            }
        }
        Candidates restricted;
        detail::scan_hulls(pts, tol, reach, tol.threshold, 0, static_cast<uint32_t>(pts.size()), restricted, ends);
        restricted.finish(static_cast<uint32_t>(pts.size()));
        std::vector<Shortcut> between;
        for (const Shortcut& sc : scalar.list()) {
            if (ends[sc.from] && ends[sc.to]) {
                between.push_back(sc);
            }
        }
        ASSERT_EQ(restricted.list(), between) << "trial " << trial;
        restricted_compared += between.size();
    }
    EXPECT_GT(compared, 1000000U);
    EXPECT_GT(restricted_compared, 10000U);
    EXPECT_GT(counts.block_ends, counts.single_ends);
    EXPECT_GT(counts.outside_ends, 10000U);
    EXPECT_GT(counts.single_ends, 10000U);
}

// The greedy fit keeps both ends and, between two kept vertices a and b, a
// ray from a within d of every vertex before b; on a straight line it keeps
// only the ends, on a zigzag wider than d every vertex.
TEST(Candidates, TheGreedyFitKeepsTheEndsAndFitsWithinItsDistance)
{
    Pts line, zig;
    for (int i = 0; i < 100; ++i) {
        line.push_back({i * 10, 0});
        zig.push_back({i * 10, (i % 2) * 50});
    }
    const auto l = detail::greedy_fit_vertices(line, 1.0);
    EXPECT_EQ(std::count(l.begin(), l.end(), 1), 2);
    EXPECT_TRUE(l.front() && l.back());
    const auto z = detail::greedy_fit_vertices(zig, 5.0);
    EXPECT_EQ(std::count(z.begin(), z.end(), 1), 100);
    EXPECT_TRUE(detail::greedy_fit_vertices(Pts{}, 1.0).empty());
    EXPECT_EQ(detail::greedy_fit_vertices(Pts{{3, 4}}, 1.0), std::vector<uint8_t>{1});
    // A square ring: its four corners and the closing vertex.
    Pts ring;
    for (int i = 0; i < 40; ++i) {
        const int k = i % 10 * 10;
        ring.push_back(i < 10   ? GridPoint{k, 0}
                       : i < 20 ? GridPoint{100, k}
                       : i < 30 ? GridPoint{100 - k, 100}
                                : GridPoint{0, 100 - k});
    }
    ring.push_back(ring.front());
    const auto r = detail::greedy_fit_vertices(ring, 1.0);
    std::vector<uint32_t> kept;
    for (uint32_t i = 0; i < r.size(); ++i) {
        if (r[i]) {
            kept.push_back(i);
        }
    }
    EXPECT_EQ(kept, (std::vector<uint32_t>{0, 10, 20, 30, 40}));
}

// A block whose every vertex is deep in the wedge but lies nearer the start
// than an earlier vertex by more than eps along the way: the earlier vertex
// projects past each end of the block and is farther than eps from it, so
// no end of the block is proximate, and a block must not prove otherwise.
// Beside it the same chain without the far vertex, whose ends all are.
TEST(Candidates, TheHullScanRefusesABlockThatAnEarlierVertexOvershoots)
{
    const Tolerance tol(100.0, Metric::l2);
    Pts straight;
    for (int i = 0; i < 64; ++i) {
        straight.push_back({i * 10, (i % 2) * 30}); // a zigzag of 30 along x, eps 100
    }
    Pts overshoot = straight;
    overshoot[31] = {31 * 10 + 400, 30}; // 400 past its neighbours, within eps of the line
    for (const Pts& pts : {straight, overshoot}) {
        Candidates got;
        const detail::HullScanCounts c =
            detail::scan_hulls(pts, tol, 0, tol.threshold, 0, static_cast<uint32_t>(pts.size()), got);
        got.finish(static_cast<uint32_t>(pts.size()));
        EXPECT_GT(c.block_ends, 0U);
        EXPECT_EQ(got.list(), proximate_shortcuts(pts, tol, 0, ScanKernel::scalar).list());
    }
    const auto from0 = [&](const Pts& pts) {
        Candidates got;
        detail::scan_hulls(pts, tol, 0, tol.threshold, 0, 1, got);
        got.finish(static_cast<uint32_t>(pts.size()));
        return got.list();
    };
    // From vertex 0 the straight zigzag reaches every end; past vertex 31 of
    // the other, only the ends within eps of it (x of 610 to 710: 61 to 63) are.
    EXPECT_EQ(from0(straight).size(), 62U);
    std::vector<Shortcut> want;
    for (uint32_t k = 2; k <= 31; ++k) {
        want.push_back({0, k});
    }
    for (uint32_t k = 61; k <= 63; ++k) {
        want.push_back({0, k});
    }
    EXPECT_EQ(from0(overshoot), want);
}

TEST(Candidates, RunsNumberTheShortcutsInOrder)
{
    // A straight stretch 0..4 then a right-angle turn: from 0 every end up
    // to 4 (one run of 3), none past the corner.
    const Pts pts{{0, 0}, {100, 0}, {200, 0}, {300, 0}, {400, 0}, {400, 300}, {400, 600}};
    const auto c = proximate_shortcuts(pts, Tolerance(10, Metric::l2), 0);
    const std::vector<Shortcut> want{{0, 2}, {0, 3}, {0, 4}, {1, 3}, {1, 4}, {2, 4}, {4, 6}};
    EXPECT_EQ(c.list(), want);
    ASSERT_EQ(c.runs().size(), 4U);
    EXPECT_EQ(c.size(), 7U);
    for (uint32_t id = 0; id < c.size(); ++id) {
        EXPECT_EQ(c.at(id), want[id]) << id;
    }
    const std::vector<uint32_t> first{0, 3, 5, 6, 6, 7, 7, 7};
    for (uint32_t v = 0; v <= pts.size(); ++v) {
        EXPECT_EQ(c.first_id(v), first[v]) << v;
    }
    EXPECT_TRUE(c.runs_from(3).empty());
    ASSERT_EQ(c.runs_from(4).size(), 1U);
    EXPECT_EQ(c.run_id(c.first_run(4)), 6U);
    // A chain with no shortcut at all.
    const auto none = proximate_shortcuts(Pts{{0, 0}, {100, 0}}, Tolerance(10, Metric::l2), 0);
    EXPECT_TRUE(none.empty());
    EXPECT_EQ(none.first_id(0), 0U);
}

TEST(Candidates, MoreShortcutsThanAnIdNumbersAreRefusedNotWrapped)
{
    // 65,535 starts reaching 65,536 ends each: 4,294,901,760 shortcuts, just
    // under 2^32; one start more passes it. Counted from the runs alone.
    Candidates fits, over;
    for (uint32_t v = 0; v < 65536; ++v) {
        if (v < 65535) {
            fits.add_run(v, v + 2, v + 65537);
        }
        over.add_run(v, v + 2, v + 65537);
    }
    EXPECT_EQ(fits.count(), uint64_t{65535} * 65536);
    EXPECT_EQ(over.count(), uint64_t{65536} * 65536);
    fits.finish(140000);
    EXPECT_EQ(fits.size(), uint32_t(uint64_t{65535} * 65536));
    EXPECT_EQ(fits.run_id(65534), uint32_t(uint64_t{65534} * 65536));
    EXPECT_THROW(over.finish(140000), std::length_error);
}

TEST(Simplify, AChainWithMoreShortcutsThanItMayHoldIsScannedWithItsReachCapped)
{
    // 200 collinear vertices 1 m apart at eps 1 m: every one of the 19,701
    // shortcuts is proximate and the whole chain is one segment. Allowed
    // 1,000, the chain's reach is capped at 1000 / 200 = 5 vertices: 4
    // shortcuts a start, and the fewest edges over 199 are ceil(199 / 5) = 40.
    Pts line;
    for (int i = 0; i < 200; ++i) {
        line.push_back({100 * i, 0});
    }
    MapBuilder m;
    m.chain(1, line);
    ToleranceStats whole, capped;
    const auto out = run_exact(m.s, 1.0, plain(), &whole);
    EXPECT_EQ(points_of(out, 1), (Pts{line.front(), line.back()}));
    EXPECT_EQ(whole.candidates, 19701U);
    EXPECT_EQ(whole.reach_capped_chains, 0U);

    SimplifyOptions o = plain();
    o.max_chain_shortcuts = 1000;
    for (const bool with_raster : {false, true}) {
        const auto cut = with_raster ? run(m.s, 1.0, o, &capped) : run_exact(m.s, 1.0, o, &capped);
        const Pts got = points_of(cut, 1);
        ASSERT_EQ(got.size(), 41U) << with_raster;
        EXPECT_EQ(got.front(), line.front());
        EXPECT_EQ(got.back(), line.back());
        for (size_t k = 0; k + 1 < got.size(); ++k) {
            EXPECT_GT(got[k + 1].x, got[k].x);
            EXPECT_LE(got[k + 1].x - got[k].x, 500) << "a shortcut past the capped reach";
        }
        EXPECT_EQ(capped.reach_capped_chains, 1U);
        EXPECT_EQ(capped.candidates, 195U * 4 + 3 + 2 + 1); // starts 0-194 reach 4 ends, then 3, 2, 1
    }
}

TEST(Candidates, PointCullingMatchesTheRegionTestOnRandomChains)
{
    std::mt19937 rng(5);
    size_t culled = 0, kept = 0;
    for (int trial = 0; trial < 100; ++trial) {
        const Pts pts = random_walk(rng, 30, -40, 100, 3);
        // Points near the chain, where the regions between shortcuts and subchains are.
        Pts points;
        std::uniform_int_distribution<size_t> at(0, pts.size() - 1);
        std::uniform_int_distribution<int> off(-50, 50);
        for (int i = 0; i < 20; ++i) {
            const GridPoint v = pts[at(rng)];
            points.push_back({v.x + off(rng), v.y + off(rng)});
        }
        // And vertices themselves (junctions): at a shortcut's end they do
        // not count, elsewhere on the subchain they do.
        for (int i = 0; i < 3; ++i) {
            points.push_back(pts[at(rng)]);
        }
        const auto cand = proximate_shortcuts(pts, Tolerance(double(60 + trial % 5 * 40), Metric::l2), 0);
        std::vector<uint32_t> want;
        const auto all = cand.list();
        for (uint32_t id = 0; id < all.size(); ++id) {
            for (const GridPoint q : points) {
                // The region between the shortcut and its subchain, closed by the shortcut.
                PointInPolygon pip(q);
                for (uint32_t k = all[id].from; k < all[id].to; ++k) {
                    pip.add_segment(pts[k], pts[k + 1]);
                }
                pip.add_segment(pts[all[id].to], pts[all[id].from]);
                if (pip.location() != PointLocation::outside && q != pts[all[id].from] && q != pts[all[id].to]) {
                    want.push_back(id);
                    break;
                }
            }
        }
        EXPECT_EQ(cull_by_points(pts, cand, points), want) << "trial " << trial;
        culled += want.size();
        kept += all.size() - want.size();
    }
    EXPECT_GT(culled, 100U) << "trials that cull nothing test nothing";
    EXPECT_GT(kept, 100U);
}

TEST(Cells, GridKeysKeepTheOrderOfCellsAndBucketsKeepTheOrderOfValues)
{
    const CellGrid grid(-250.0, -90.0, 310.0, 40.0, 100.0); // cells x -4..4, y -2..1 with the margin
    EXPECT_TRUE(grid.contains(-4, -2));
    EXPECT_TRUE(grid.contains(4, 1));
    EXPECT_FALSE(grid.contains(5, 0));
    EXPECT_FALSE(grid.contains(0, -3));
    std::vector<std::pair<int64_t, int64_t>> cells;
    for (int64_t x = -4; x <= 4; ++x) {
        for (int64_t y = -2; y <= 1; ++y) {
            cells.emplace_back(x, y);
        }
    }
    for (size_t i = 0; i < cells.size(); ++i) {
        EXPECT_EQ(grid.key(cells[i].first, cells[i].second), i) << "keys are dense and ordered by x, then y";
    }
    // Values come back per key in the order they were added, whatever the keys' order.
    std::vector<std::pair<uint64_t, uint32_t>> pairs;
    std::mt19937 rng(3);
    std::uniform_int_distribution<uint64_t> key(0, 40);
    std::map<uint64_t, std::vector<uint32_t>> want;
    for (uint32_t v = 0; v < 500; ++v) {
        const uint64_t k = key(rng) * 0x10000001ULL; // spread over many bits
        pairs.emplace_back(k, v);
        want[k].push_back(v);
    }
    const CellBuckets<uint32_t> buckets(pairs);
    size_t cells_seen = 0, values_seen = 0;
    buckets.for_each([&](std::span<const uint32_t> values) {
        ++cells_seen;
        values_seen += values.size();
    });
    EXPECT_EQ(cells_seen, want.size());
    EXPECT_EQ(values_seen, pairs.size());
    for (const auto& [k, values] : want) {
        const auto got = buckets.find(k);
        EXPECT_EQ(std::vector<uint32_t>(got.begin(), got.end()), values) << k;
    }
    EXPECT_TRUE(buckets.find(7).empty());
    EXPECT_TRUE(CellBuckets<uint32_t>({}).find(0).empty());
}

TEST(Candidates, Figure5NonProximateSegmentInsideTheBandIsNotACandidate)
{
    // v1 -> v6 runs along the x axis inside C + B_eps (the legs of the deep
    // notch are 20 apart), but v3 and v4 are 180 from it.
    const Pts pts{{0, 0}, {100, 0}, {100, 180}, {120, 180}, {120, 0}, {220, 0}};
    const auto got = proximate_shortcuts(pts, Tolerance(50, Metric::l2), 0).list();
    for (const auto& s : got) {
        EXPECT_FALSE(s.from <= 1 && s.to >= 4) << s.from << "->" << s.to << " skips the notch";
    }
    // ...and the simplified chain keeps the notch.
    MapBuilder m;
    m.chain(1, pts);
    const auto out = run(m.s, 0.5);
    int max_y = 0;
    for (const GridPoint q : points_of(out, 1)) {
        max_y = std::max(max_y, q.y);
    }
    EXPECT_EQ(max_y, 180) << "the notch was cut off";
}

TEST(Simplify, TwoCloseChainsThatDouglasPeuckerMakesCrossDoNot)
{
    const Pts a{{0, 0}, {500, 90}, {1000, 0}};
    const Pts b{{300, -50}, {500, 60}, {700, -50}};
    MapBuilder m;
    m.chain(1, a).chain(2, b);
    ASSERT_EQ(count_intersections({&m.s}), 0U);
    // Douglas-Peucker at 1 m (100 units) straightens a through b.
    MapBuilder dp;
    dp.chain(1, douglas_peucker(a, 100)).chain(2, douglas_peucker(b, 100));
    EXPECT_EQ(points_of(dp.s, 1).size(), 2U);
    EXPECT_GT(count_intersections({&dp.s}), 0U);

    ToleranceStats st;
    const auto out = run(m.s, 1.0, plain(), &st);
    EXPECT_EQ(points_of(out, 1), a);
    EXPECT_EQ(points_of(out, 2), b);
    EXPECT_EQ(count_intersections({&out}), 0U);
    EXPECT_EQ(st.banned_exact, 0U) << "the exact net must not be what saves it";
    EXPECT_GE(st.banned_raster + st.banned_points, 1U);
}

TEST(Simplify, TheRegionRuleKeepsAShortcutOffAnotherChainsOriginal)
{
    // b dips 1 unit under the line of a's shortcut (0,0)-(1000,0), near the
    // junction where a lies 1.8 units lower still: a sliver no pixel sees
    // (pixels of 4 eps here). At 1 m both straighten without meeting, but a's
    // shortcut crosses b's original, so a view showing a at 1 m beside b at
    // LOD 0 would cross. b's representative point (its middle vertex) is
    // away from a, so the point constraints do not see it either.
    const Pts a{{0, 0}, {500, -3}, {1000, 0}};
    const Pts b{{0, 0}, {300, -1}, {600, 50}, {900, 200}};
    MapBuilder m;
    m.chain(1, a).chain(2, b);
    ASSERT_EQ(count_intersections({&m.s}), 0U);
    auto o = plain();
    o.color.pixel_fraction = 4;
    ToleranceStats st;
    const auto out = run(m.s, 1.0, o, &st);
    EXPECT_EQ(points_of(out, 1), a) << "a's shortcut holds b's vertex (300,-1) in its region";
    EXPECT_EQ(points_of(out, 2).size(), 2U) << "b's own shortcut holds nothing of a";
    EXPECT_GE(st.banned_region, 1U);
    // Every LOD of each against the other's original.
    MapBuilder mixed;
    mixed.chain(1, points_of(out, 1)).chain(2, b);
    EXPECT_EQ(count_intersections({&mixed.s}), 0U);
    MapBuilder mixed2;
    mixed2.chain(1, a).chain(2, points_of(out, 2));
    EXPECT_EQ(count_intersections({&mixed2.s}), 0U);
}

TEST(Raster, ShortcutThroughANeighboursRegionFailsAndOriginalEdgesPass)
{
    const Pts a{{0, 0}, {500, 90}, {1000, 0}};
    const Pts b{{300, -50}, {500, 60}, {700, -50}};
    const TentChain tents[] = {{a, 100, 1}, {b, 100, 2}};
    const TileSpec tile = square_tile(-200, -300, 25, 64);
    const TestSegment segs[] = {{a[0], a[2], 1, 0}, // a's shortcut across b
                                {a[0], a[1], 1, 1}, // a's own edges
                                {a[1], a[2], 1, 2},
                                {b[1], b[2], 2, 3},  // b's own edge
                                {a[0], a[2], 2, 4}}; // a's shortcut drawn as if it were b's: fails in a's region
    for (Compliance mode : {Compliance::ssbo, Compliance::readback}) {
        std::vector<uint8_t> fails(5, 0);
        raster(mode).run_tile(tile, tents, segs, fails);
        EXPECT_EQ(fails, (std::vector<uint8_t>{1, 0, 0, 0, 1})) << (mode == Compliance::ssbo ? "ssbo" : "readback");
    }
}

TEST(Raster, ShortcutGrazingTheEdgeOfItsOwnBandPasses)
{
    // The shortcut a0-a2 passes 99.9 units from a's middle vertex, eps 100:
    // near x = 2000 the band reaches 0.1 units above it, and the pixel
    // centres a quarter pixel above are in no one's region. Not a failure:
    // only another class's region fails a shortcut.
    const Pts a{{0, 0}, {2000, -100}, {4000, 0}};
    const TentChain tents[] = {{a, 100, 1}};
    const TileSpec tile = square_tile(-500, -1000, 25, 256);
    const TestSegment segs[] = {{a[0], a[2], 1, 0},             // a's own
                                {a[0], a[2], 2, 1},             // the same as another class's: in a's region
                                {{0, 150}, {4000, 150}, 1, 2}}; // above a's band: no one's region
    for (Compliance mode : {Compliance::ssbo, Compliance::readback}) {
        std::vector<uint8_t> fails(3, 0);
        raster(mode).run_tile(tile, tents, segs, fails);
        EXPECT_EQ(fails, (std::vector<uint8_t>{0, 1, 0})) << (mode == Compliance::ssbo ? "ssbo" : "readback");
    }
}

TEST(Raster, OnlyTheGivenPartOfAShortcutIsTested)
{
    // b's region crosses the middle of a's shortcut: the whole shortcut
    // fails, its first and last quarters pass.
    const Pts a{{0, 0}, {2000, 50}, {4000, 0}};
    const Pts b{{2000, 400}, {2000, 30}};
    const TentChain tents[] = {{a, 100, 1}, {b, 100, 2}};
    const TileSpec tile = square_tile(-500, -1000, 25, 256);
    TestSegment whole{a[0], a[2], 1, 0}, first{a[0], a[2], 1, 1}, last{a[0], a[2], 1, 2}, middle{a[0], a[2], 1, 3};
    first.t1 = 0.25f;
    last.t0 = 0.75f;
    middle.t0 = 0.45f;
    middle.t1 = 0.55f;
    const TestSegment segs[] = {whole, first, last, middle};
    for (Compliance mode : {Compliance::ssbo, Compliance::readback}) {
        std::vector<uint8_t> fails(4, 0);
        raster(mode).run_tile(tile, tents, segs, fails);
        EXPECT_EQ(fails, (std::vector<uint8_t>{1, 0, 0, 1})) << (mode == Compliance::ssbo ? "ssbo" : "readback");
    }
}

TEST(NearParts, CapsuleIntervalsAreExact)
{
    using G = GridPoint;
    // A disk only: segment pq points away from ab.
    auto iv = capsule_interval(G{0, 0}, G{100, 0}, G{50, 10}, G{50, 20}, 15);
    ASSERT_TRUE(iv);
    EXPECT_NEAR(iv->first, 0.5 - std::sqrt(125.0) / 100, 1e-12);
    EXPECT_NEAR(iv->second, 0.5 + std::sqrt(125.0) / 100, 1e-12);
    // Parallel at distance 5, r 10: the rectangle and both disks.
    iv = capsule_interval(G{0, 0}, G{100, 0}, G{20, 5}, G{60, 5}, 10);
    ASSERT_TRUE(iv);
    EXPECT_NEAR(iv->first, 0.2 - std::sqrt(75.0) / 100, 1e-12);
    EXPECT_NEAR(iv->second, 0.6 + std::sqrt(75.0) / 100, 1e-12);
    // Crossing: the rectangle alone decides, clamped to the segment.
    iv = capsule_interval(G{0, 0}, G{100, 0}, G{90, -50}, G{90, 50}, 20);
    ASSERT_TRUE(iv);
    EXPECT_NEAR(iv->first, 0.7, 1e-12);
    EXPECT_EQ(iv->second, 1.0);
    // Too far.
    EXPECT_FALSE(capsule_interval(G{0, 0}, G{100, 0}, G{0, 30}, G{100, 30}, 29.9));
}

TEST(NearParts, OnlyBlockedSegmentsGiveParts)
{
    // A straight chain of 5 vertices; segments 0 and 3 blocked.
    const Pts pts{{0, 0}, {100, 0}, {200, 0}, {300, 0}, {400, 0}};
    const std::vector<NearSegment> blocked{{0, 0, 1}, {3, 0, 1}};
    const auto parts = near_parts(pts, 0, 4, blocked, 10, 4);
    ASSERT_EQ(parts.size(), 2U);
    EXPECT_EQ(parts[0].first, 0.0);
    EXPECT_NEAR(parts[0].second, (110 + 4) / 400.0, 1e-8);
    EXPECT_NEAR(parts[1].first, (290 - 4) / 400.0, 1e-8);
    EXPECT_EQ(parts[1].second, 1.0);
    EXPECT_TRUE(near_parts(pts, 1, 3, blocked, 10, 4).empty()) << "segments 1 and 2 are clear";
    const auto one = near_parts(pts, 2, 4, blocked, 10, 4);
    ASSERT_EQ(one.size(), 1U);
    EXPECT_NEAR(one[0].first, (90 - 4) / 200.0, 1e-8);
    // Only the first quarter of segment 3 near another chain: the part ends
    // within r of x = 325, not at the end.
    const std::vector<NearSegment> quarter{{3, 0, 0.25}};
    const auto q = near_parts(pts, 0, 4, quarter, 10, 4);
    ASSERT_EQ(q.size(), 1U);
    EXPECT_NEAR(q[0].first, (290 - 4) / 400.0, 1e-8);
    EXPECT_NEAR(q[0].second, (335 + 4) / 400.0, 1e-8);
}

TEST(Simplify, HaloChainConstrainsWhereItComesNearAndOnlyThere)
{
    // An owned chain dipping 800 below the line between its ends, and a
    // neighbour's (halo) chain coming down from 9 km away to 300 below that
    // line: the owned chain's shortcut along the line would cross it.
    const Pts owned{{0, 0}, {5000, -800}, {10000, 0}};
    const Pts halo{{900000, 900000}, {5000, 100000}, {5000, -300}};
    MapBuilder m;
    m.chain(1, owned).chain(2, halo, "N", "M", "", chains::chain_halo);

    // Only the halo's last segment is within reach of the owned chain.
    const auto keep = segments_in_reach(m.s, 2000);
    ASSERT_EQ(keep.size(), m.s.points.size());
    const auto& c1 = m.s.chains[0];
    const auto& c2 = m.s.chains[1];
    ASSERT_FALSE(c1.flags & chains::chain_halo);
    EXPECT_EQ(keep[c1.first], 1);
    EXPECT_EQ(keep[c1.first + 1], 1);
    EXPECT_EQ(keep[c2.first], 0);
    EXPECT_EQ(keep[c2.first + 1], 1);
    EXPECT_TRUE(segments_in_reach(MapBuilder().chain(1, owned).s, 2000).empty()) << "no halo: everything takes part";

    // At 10 m (1000 units) the dip is within eps of the line, but the halo
    // keeps the owned chain from taking the shortcut; without it, it does.
    const auto out = run(m.s, 10.0);
    EXPECT_EQ(points_of(out, 1), owned);
    ASSERT_EQ(out.chains.size(), 1U) << "the halo is not written";
    const auto alone = run(MapBuilder().chain(1, owned).s, 10.0);
    EXPECT_EQ(points_of(alone, 1), (Pts{{0, 0}, {10000, 0}}));
}

TEST(Simplify, PointConstraintKeepsItsSideAndIsLostWithoutConstraints)
{
    const Pts a{{0, 0}, {500, 80}, {1000, 0}};
    MapBuilder m;
    m.chain(1, a, "north", "south").point("south", {500, 40});
    ToleranceStats st;
    const auto kept = run(m.s, 1.0, plain(), &st);
    EXPECT_EQ(points_of(kept, 1), a);
    EXPECT_EQ(st.banned_points, 1U);
    SimplifyOptions off = plain();
    off.point_constraints = false;
    const auto lost = run(m.s, 1.0, off);
    EXPECT_EQ(points_of(lost, 1), (Pts{{0, 0}, {1000, 0}}));
}

TEST(Simplify, UserPointsConstrainLikeInternalPoints)
{
    const Pts a{{0, 0}, {500, 80}, {1000, 0}};
    MapBuilder m;
    m.chain(1, a);
    // The store's projection is CONUS Albers; put a user point at grid (500, 40).
    const Projection proj(m.s.projection);
    LonLat ll;
    proj.to_lonlat(500, 40, ll.lon, ll.lat);
    SimplifyOptions o = plain();
    o.user_points = {ll};
    ASSERT_EQ(proj.to_grid(ll.lon, ll.lat), (GridPoint{500, 40}));
    EXPECT_EQ(points_of(run(m.s, 1.0, o), 1), a);
    EXPECT_EQ(points_of(run(m.s, 1.0), 1).size(), 2U);
}

TEST(Simplify, ShortestPathThatSelfIntersectsIsRepaired)
{
    // The only proximate shortcut at 2 m, 2 -> 4, crosses the chain's first edge.
    const Pts c{{900, 400}, {200, 0}, {800, 0}, {900, 300}, {900, 700}, {200, 900}};
    MapBuilder m;
    m.chain(1, c);
    const auto cand = proximate_shortcuts(c, Tolerance(200, Metric::l2), 0).list();
    ASSERT_EQ(cand.size(), 1U);
    EXPECT_EQ(cand[0].from, 2U);
    EXPECT_EQ(cand[0].to, 4U);
    ToleranceStats st;
    const auto out = run(m.s, 2.0, plain(), &st);
    EXPECT_EQ(points_of(out, 1), c);
    EXPECT_EQ(st.self_intersection_repairs, 1U);
    EXPECT_EQ(st.banned_exact, 1U);
}

namespace {

/// A small dense map: a grid of wiggly chains.
ChainStore wiggly_map()
{
    MapBuilder m;
    uint64_t id = 1;
    for (int row = 0; row < 6; ++row) {
        Pts p;
        for (int i = 0; i <= 40; ++i) {
            p.push_back({i * 50, row * 120 + ((i * 37 + row * 11) % 7) * 9 - (i % 3) * 7});
        }
        m.chain(id++, p);
    }
    return m.s;
}

} // namespace

TEST(Simplify, ReadbackAndStorageBufferAgree)
{
    const auto map = wiggly_map();
    for (double eps : {0.3, 0.6, 1.2}) {
        ToleranceStats a, b;
        const auto ssbo = run(map, eps, plain(), &a, Compliance::ssbo);
        const auto readback = run(map, eps, plain(), &b, Compliance::readback);
        EXPECT_EQ(chains::to_text(ssbo), chains::to_text(readback)) << "eps " << eps;
        EXPECT_EQ(a.banned_raster, b.banned_raster) << "eps " << eps;
        EXPECT_EQ(count_intersections({&ssbo}), 0U);
    }
}

/// Simplifies `map` at `eps` with options a and b, expects the same stores,
/// and returns both runs' statistics.
std::pair<ToleranceStats, ToleranceStats> expect_same_stores(const ChainStore& map, double eps,
                                                             const SimplifyOptions& a, const SimplifyOptions& b)
{
    ToleranceStats sa, sb;
    const auto out_a = run(map, eps, a, &sa);
    const auto out_b = run(map, eps, b, &sb);
    EXPECT_EQ(chains::to_text(out_a), chains::to_text(out_b)) << "eps " << eps;
    EXPECT_EQ(sa.output_vertices, sb.output_vertices) << "eps " << eps;
    return {sa, sb};
}

TEST(Simplify, LazyEqualsExhaustive)
{
    const auto map = wiggly_map();
    for (double eps : {0.3, 0.6, 1.2}) {
        SimplifyOptions exhaustive = plain(), lazy = plain();
        exhaustive.lazy = false;
        lazy.lazy = true;
        const auto [all, some] = expect_same_stores(map, eps, exhaustive, lazy);
        EXPECT_LE(some.drawn_segments, all.drawn_segments) << "eps " << eps;
    }
}

/// Three wiggly arms of 60 vertices, 3000 units long, from a junction at the
/// origin: close to each other only near it.
ChainStore star_map()
{
    MapBuilder m;
    for (int arm = 0; arm < 3; ++arm) {
        const double angle = arm * 2.0943951023931953;
        Pts p{{0, 0}};
        for (int i = 1; i <= 60; ++i) {
            const double along = i * 50.0, across = ((i * 37 + arm * 5) % 7) * 6.0 - 18;
            p.push_back({int32_t(std::lround(along * std::cos(angle) - across * std::sin(angle))),
                         int32_t(std::lround(along * std::sin(angle) + across * std::cos(angle)))});
        }
        m.chain(uint64_t(arm + 1), p);
    }
    return m.s;
}

TEST(Simplify, DrawingOnlyTheNearPartsChangesNothing)
{
    const auto map = star_map();
    for (double eps : {0.3, 0.6, 1.2}) {
        SimplifyOptions whole = plain();
        whole.clip_tests = false;
        const auto [clipped, full] = expect_same_stores(map, eps, plain(), whole);
        EXPECT_EQ(clipped.drawn_segments, full.drawn_segments) << "eps " << eps;
        EXPECT_LT(clipped.drawn_pixels, full.drawn_pixels) << "eps " << eps;
    }
}

TEST(Simplify, TheFarRuleAndTheNearPartsChangeNothingInEveryMetric)
{
    // Without the far rule every candidate is drawn whole. Beside the
    // star and the wiggly rows, rows far apart whose shortcuts away from
    // their ends meet no other chain's reach.
    MapBuilder apart;
    for (int row = 0; row < 3; ++row) {
        Pts p;
        for (int i = 0; i <= 40; ++i) {
            p.push_back({i * 50, row * 2000 + ((i * 37 + row * 11) % 7) * 9 - (i % 3) * 7});
        }
        apart.chain(uint64_t(row + 1), p);
    }
    for (const Metric m : {Metric::l2, Metric::l1, Metric::linf}) {
        size_t proved_far = 0;
        double pixels_fast = 0, pixels_slow = 0;
        for (const auto& map : {star_map(), wiggly_map(), apart.s}) {
            for (double eps : {0.3, 0.6, 1.2}) {
                SimplifyOptions all = plain(m);
                all.far_rule = false;
                all.clip_tests = false;
                const auto [fast, slow] = expect_same_stores(map, eps, plain(m), all);
                EXPECT_EQ(slow.proved_far, 0U);
                EXPECT_EQ(fast.banned_raster, slow.banned_raster) << metric_name(m) << " eps " << eps;
                proved_far += fast.proved_far;
                pixels_fast += fast.drawn_pixels;
                pixels_slow += slow.drawn_pixels;
            }
        }
        EXPECT_GT(proved_far, 0U) << metric_name(m);
        EXPECT_LT(pixels_fast, pixels_slow) << metric_name(m);
    }
}

TEST(Simplify, DrawingInPiecesChangesNothing)
{
    // Tiles of 1024 pixels; with a framebuffer of 64, a tile whose tested
    // parts fit in 64 x 64 pixels is drawn in one piece, shifted (the
    // star's), the others in pieces of 64 (the wiggly grid's, where the
    // raster bans shortcuts), each with only the tents and tests that reach it.
    RasterOptions one, two, three;
    one.max_tile_pixels = two.max_tile_pixels = three.max_tile_pixels = 1024;
    one.window_pixels = 1024;
    two.window_pixels = three.window_pixels = 64;
    three.compliance = Compliance::readback; // Algorithm 5.1 piece by piece
    Raster large(context(), one), small(context(), two), small_readback(context(), three);
    size_t banned = 0;
    for (const auto& map : {star_map(), wiggly_map()}) {
        for (double eps : {0.3, 0.6, 1.2}) {
            ToleranceStats sa, sb, sc;
            const auto a = simplify_store(map, eps, plain(), &large, nullptr, sa);
            const auto b = simplify_store(map, eps, plain(), &small, nullptr, sb);
            const auto c = simplify_store(map, eps, plain(), &small_readback, nullptr, sc);
            EXPECT_EQ(chains::to_text(a), chains::to_text(b)) << "eps " << eps;
            EXPECT_EQ(chains::to_text(a), chains::to_text(c)) << "read back, eps " << eps;
            EXPECT_EQ(sa.banned_raster, sb.banned_raster) << "eps " << eps;
            EXPECT_EQ(sa.banned_raster, sc.banned_raster) << "read back, eps " << eps;
            banned += sa.banned_raster;
        }
    }
    EXPECT_GT(banned, 0U) << "the raster must have had something to find";
    EXPECT_EQ(large.stats().one_piece_boxes, large.stats().tiles);
    EXPECT_GT(small.stats().one_piece_boxes, 0U) << "no tile was drawn in one piece";
    EXPECT_LT(small.stats().one_piece_boxes, small.stats().tiles) << "every tile fit: no tile went in pieces";
    EXPECT_LT(small_readback.stats().one_piece_boxes, small_readback.stats().tiles);
}

TEST(Color, DsaturColoursAnOddCycleWithThreeAndFailsWithTwo)
{
    const std::vector<std::vector<uint32_t>> c5{{1, 4}, {0, 2}, {1, 3}, {2, 4}, {0, 3}};
    std::vector<uint8_t> colors;
    ASSERT_TRUE(dsatur(c5, 3, colors));
    for (uint32_t v = 0; v < 5; ++v) {
        for (uint32_t u : c5[v]) {
            EXPECT_NE(colors[v], colors[u]);
        }
        EXPECT_GE(colors[v], 1);
        EXPECT_LE(colors[v], 3);
    }
    EXPECT_FALSE(dsatur(c5, 2, colors));
}

TEST(Color, ConflictingChainsGetDifferentClassesAndTilesSplitBeforeFailing)
{
    // Three chains meeting at one junction conflict pairwise.
    const Pts a{{0, 0}, {1000, 0}}, b{{0, 0}, {0, 1000}}, c{{0, 0}, {-1000, -1000}};
    const Pts far{{50000, 50000}, {51000, 50000}};
    std::vector<ChainGeom> g{{a, 100, true}, {b, 100, true}, {c, 100, true}, {far, 100, true}};
    ColorOptions o;
    o.tile_pixels = 256;
    const auto r = color_tiles(g, o, 1);
    EXPECT_EQ(r.conflict_edges, 3U);
    for (const auto& t : r.tiles) {
        std::map<uint32_t, uint8_t> cls;
        for (size_t i = 0; i < t.chains.size(); ++i) {
            cls[t.chains[i]] = t.classes[i];
        }
        if (cls.count(0) && cls.count(1)) {
            EXPECT_NE(cls[0], cls[1]);
        }
        if (cls.count(1) && cls.count(2)) {
            EXPECT_NE(cls[1], cls[2]);
        }
    }
    // Two classes cannot separate them near the junction: tiles split down to
    // the smallest size, then a clear error naming the place.
    o.max_classes = 2;
    try {
        color_tiles(g, o, 1);
        ADD_FAILURE() << "expected input_error";
    } catch (const input_error& e) {
        EXPECT_NE(std::string(e.what()).find("needs more than 2 stencil classes"), std::string::npos) << e.what();
    }
}

// Only owned chains' shortcuts are tested in the stencil, so two halo chains
// need no edge however close they are; a halo chain near an owned one does.
TEST(Color, TwoHaloChainsAreNeverJoinedAHaloChainAndAnOwnedOneAre)
{
    const Pts a{{0, 0}, {1000, 0}};
    const Pts near_a{{0, 250}, {1000, 250}};                            // closer than 2 x (100 + 2 pixels of 25)
    const Pts h1{{0, 5000}, {1000, 5000}}, h2{{0, 5100}, {1000, 5100}}; // close to each other only
    std::vector<ChainGeom> g{{a, 100, true}, {near_a, 100, false}, {h1, 100, false}, {h2, 100, false}};
    ColorOptions o;
    const auto adj = conflict_graph(g, tile_pixel(std::vector<double>{100}, o), o);
    ASSERT_EQ(adj.size(), 4U);
    EXPECT_EQ(adj[0], std::vector<uint32_t>{1});
    EXPECT_EQ(adj[1], std::vector<uint32_t>{0});
    EXPECT_TRUE(adj[2].empty());
    EXPECT_TRUE(adj[3].empty());
    g[2].owned = true; // now h1's shortcuts are tested: h2 must differ from it
    const auto adj2 = conflict_graph(g, tile_pixel(std::vector<double>{100}, o), o);
    EXPECT_EQ(adj2[2], std::vector<uint32_t>{3});
    const auto r = color_tiles(g, o, 1);
    EXPECT_EQ(r.conflict_edges, 2U);
}

// An owned chain whose every shortcut is too short for the raster to test a
// pixel (testable_chain: pixel 25, about 65 units) is coloured as a halo
// chain: two such chains need no edge however close; a testable owned chain
// near them still does, and a chain one unit over the length is testable.
TEST(Color, OwnedChainsTooShortToBeTestedAreColouredAsHalo)
{
    ColorOptions o;
    const double pixel = tile_pixel(std::vector<double>{100}, o);
    ASSERT_EQ(pixel, 25.0);
    const int128 limit2 = untested_length2(pixel);
    const auto side = static_cast<int32_t>(std::sqrt(double(limit2) / 2)); // a square's diagonal at the limit
    ASSERT_LE(int128{2} * side * side, limit2);
    ASSERT_GT(int128{2} * (side + 1) * (side + 1), limit2);
    const Pts s1{{0, 0}, {side, side}}, s2{{0, 40}, {side, 40 + side}};
    const Pts s3{{0, 80}, {side + 1, 80 + side + 1}}; // one unit over: testable
    const Pts far{{5000, 0}, {6000, 0}};
    std::vector<ChainGeom> g{{s1, 100, true}, {s2, 100, true}, {far, 100, true}};
    EXPECT_FALSE(testable_chain(s1, pixel));
    EXPECT_TRUE(testable_chain(s3, pixel));
    auto adj = conflict_graph(g, pixel, o);
    EXPECT_TRUE(adj[0].empty());
    EXPECT_TRUE(adj[1].empty());
    auto r = color_tiles(g, o, 1);
    EXPECT_EQ(r.conflict_edges, 0U);
    g.push_back({s3, 100, true});
    adj = conflict_graph(g, pixel, o);
    EXPECT_EQ(adj[0], std::vector<uint32_t>{3});
    EXPECT_EQ(adj[1], std::vector<uint32_t>{3});
    EXPECT_EQ(adj[3], (std::vector<uint32_t>{0, 1}));
    r = color_tiles(g, o, 1);
    EXPECT_EQ(r.conflict_edges, 2U);
    // No testable chain at all: nothing to tile.
    g = {{s1, 100, true}, {s2, 100, true}};
    EXPECT_TRUE(color_tiles(g, o, 1).tiles.empty());
}

// The graph coarsens chains within an eighth of their reach and tests the
// segments of a pair only where the coarse distance is near the threshold:
// it must find exactly the pairs a test of every pair of segments finds. Wiggly
// chains with steps far below and above the coarsening radius, gaps in the
// halo's parts, single points, mixed tolerances, and pairs placed at the
// threshold exactly (1200 is not closer than 1200) and one unit inside it.
TEST(Color, ConflictGraphIsExactlyTheTestOfEveryPairOfSegments)
{
    std::mt19937 rng(29);
    std::uniform_int_distribution<int> coin(0, 9), place(0, 12000), tiny(-40, 40), jump(-1500, 1500);
    const std::vector<double> eps_choices{400, 800, 1600};
    ColorOptions o;
    size_t edges_seen = 0, short_owned = 0;
    for (int trial = 0; trial < 12; ++trial) {
        std::vector<Pts> pts;
        std::vector<double> eps;
        std::vector<std::vector<uint8_t>> keep;
        std::vector<bool> owned;
        // An owned chain at eps 400 and its halo partner.
        auto add_pair = [&](const Pts& own, const Pts& partner) {
            for (const Pts* chain : {&own, &partner}) {
                pts.push_back(*chain);
                eps.push_back(400);
                owned.push_back(chain == &own);
                keep.emplace_back();
            }
        };
        // Odd trials leave the random walks out: the rest, finely sampled,
        // is coarsened, and the pairs near the threshold take the segments'
        // own test (ChainDistance's unsure pairs); with the walks most
        // segments stay as they are and are tested directly.
        for (int c = 0; c < (trial % 2 == 0 ? 40 : 0); ++c) {
            Pts p;
            GridPoint at{place(rng), place(rng)};
            const int n = coin(rng) == 0 ? 1 : 2 + coin(rng) * 30;
            for (int i = 0; i < n; ++i) {
                p.push_back(at);
                at = coin(rng) < 8 ? GridPoint{at.x + tiny(rng), at.y + tiny(rng)}
                                   : GridPoint{at.x + jump(rng), at.y + jump(rng)};
            }
            pts.push_back(p);
            eps.push_back(eps_choices[size_t(coin(rng)) % 3]);
            owned.push_back(coin(rng) < 4);
            std::vector<uint8_t> k;
            if (!owned.back() && coin(rng) < 5 && p.size() > 1) { // a halo chain with parts left out
                for (size_t i = 0; i + 1 < p.size(); ++i) {
                    k.push_back(coin(rng) < 7 ? 1 : 0);
                }
            }
            keep.push_back(k);
        }
        // Wiggly chains and their copies moved by about the threshold (eps
        // 400: reach 600, 1200 for the pair), so that many pairs are decided
        // near it, where the coarse distance alone cannot tell.
        std::uniform_int_distribution<int> offset(1100, 1300);
        for (int c = 0; c < 10; ++c) {
            Pts p;
            GridPoint at{100000 + c * 6000, 100000};
            for (int i = 0; i < 60; ++i) {
                p.push_back(at);
                at = {at.x + 1 + coin(rng) * 5, at.y + tiny(rng)};
            }
            const int dy = offset(rng), dx = tiny(rng);
            Pts q;
            for (const GridPoint v : p) {
                q.push_back({v.x + dx, v.y + dy});
            }
            add_pair(p, q);
        }
        // A straight chain with one spike toward a straight partner 1250
        // above: the spike (inside a coarse segment along the line) is the
        // only part within 1200, or is not, by its height.
        for (const int spike : {40, 60}) {
            const int x0 = 300000 + trial * 5000, y0 = 300000 + (spike - 40) * 1000;
            Pts line, other{{x0, y0 + 1250}, {x0 + 2000, y0 + 1250}};
            for (int x = 0; x <= 2000; x += 5) {
                line.push_back({x0 + x, y0 + (x == 1000 + trial * 5 ? spike : 0)});
            }
            add_pair(line, other);
        }
        // Straight pairs at eps 400 (pixel 100, reach 600): 1200 apart and
        // 1199 apart, the first owned.
        for (const int d : {1200, 1199}) {
            const int x = 200000, y = 200000 + (d - 1199) * 20000; // far from the walks and each other
            add_pair({{x, y}, {x + 2000, y}}, {{x + 500, y + d}, {x + 2500, y + d}});
        }
        std::vector<ChainGeom> g;
        for (size_t c = 0; c < pts.size(); ++c) {
            g.push_back({pts[c], eps[c], owned[c], keep[c]});
        }
        const double pixel = tile_pixel(eps, o);
        ASSERT_EQ(pixel, 100.0);
        const auto adj = conflict_graph(g, pixel, o);
        for (uint32_t i = 0; i < g.size(); ++i) {
            for (uint32_t j = i + 1; j < g.size(); ++j) {
                bool close = false;
                const double limit = reach_radius(eps[i], pixel, o) + reach_radius(eps[j], pixel, o);
                // Owned and long enough for a shortcut to be tested (coloring.hpp).
                const bool tested_i = owned[i] && testable_chain(pts[i], pixel);
                const bool tested_j = owned[j] && testable_chain(pts[j], pixel);
                if (tested_i || tested_j) {
                    auto segs_of = [&](uint32_t c) {
                        std::vector<std::pair<GridPoint, GridPoint>> s;
                        for (size_t k = 0; k + 1 < pts[c].size(); ++k) {
                            if (takes_part(keep[c], k)) {
                                s.emplace_back(pts[c][k], pts[c][k + 1]);
                            }
                        }
                        if (pts[c].size() == 1) {
                            s.emplace_back(pts[c][0], pts[c][0]);
                        }
                        return s;
                    };
                    for (const auto& [a, b] : segs_of(i)) {
                        for (const auto& [c, d] : segs_of(j)) {
                            close = close || segment_distance(a, b, c, d) < limit;
                        }
                    }
                }
                const bool edge = std::binary_search(adj[i].begin(), adj[i].end(), j);
                EXPECT_EQ(edge, close) << "trial " << trial << ", chains " << i << " and " << j;
                EXPECT_EQ(edge, std::binary_search(adj[j].begin(), adj[j].end(), i));
                edges_seen += edge;
            }
        }
        const size_t n = g.size();
        for (size_t c = 0; c < g.size(); ++c) {
            short_owned += owned[c] && !testable_chain(pts[c], pixel) ? 1 : 0;
        }
        EXPECT_TRUE(adj[n - 4].empty()) << "1200 apart is not closer than 1200";
        EXPECT_EQ(adj[n - 2], std::vector<uint32_t>{uint32_t(n - 1)});
    }
    EXPECT_GT(edges_seen, 500U) << "the maps must have had pairs to find";
    EXPECT_GT(short_owned, 10U) << "the maps must have had owned chains too short to be tested";
}

// The partition contract's points (formats/chains/SPEC.md): every unit an
// owned chain bounds, whoever owns it, has its internal point in the store.
TEST(Simplify, AStoreMustHoldThePointOfEveryUnitItsOwnChainsBound)
{
    MapBuilder m;
    m.chain(1, {{0, 0}, {100, 50}, {200, 0}}, "A", "B");
    m.chain(2, {{0, 0}, {100, -50}, {200, 0}}, "B", "X", "", chains::chain_halo); // X: bounded by the halo only
    m.point("A", {100, 100});
    auto fault = partition_contract_fault(m.s);
    ASSERT_TRUE(fault.has_value());
    EXPECT_NE(fault->find("chain 1 bounds unit B"), std::string::npos) << *fault;
    EXPECT_NE(fault->find("missing_internal_points"), std::string::npos) << *fault;
    m.s.minor = 1; // a store from an ingest before the contract
    EXPECT_NE(partition_contract_fault(m.s)->find("chain store 1.1, written before the contract"), std::string::npos);
    m.s.constraints.push_back({m.s.intern("B"), chains::constraint_neighbour, {100, 0}});
    EXPECT_FALSE(partition_contract_fault(m.s).has_value());
    // A user point is no unit's internal point.
    m.s.constraints = {{m.s.intern("A"), chains::constraint_internal, {100, 100}},
                       {m.s.intern("B"), chains::constraint_user, {100, 0}}};
    EXPECT_TRUE(partition_contract_fault(m.s).has_value());
}

// The chord rule. A lake on a border between two partitions, its shores two
// chains from J to K (10 m apart, 2.5 pixels at 16 m: the raster tests no
// pixel of J K, all within 1.5 pixels of an end). Each partition sees the
// other's shore as halo, and both shores may become J K, each one's region
// empty of the other: simplified apart, or at two tolerances, they would
// overlap. Chain 20 gives way to chain 10 (the smaller id).
//
//            10 (north shore)
//          .-----.
//       J <       > K      1 m = 100 grid units
//          '-----'
//            20 (south shore)
TEST(Simplify, TwoShoresBetweenTheSameJunctionsNeverBothBecomeTheChord)
{
    // Both shores' chords are the segment J K, each one's region empty of
    // the other: only the chain with the smaller id (10) may become it, in
    // its own partition or beside 20 in one store, at any tolerance.
    const Pts north{{0, 0}, {333, 300}, {666, 300}, {1000, 0}};
    const Pts south{{0, 0}, {333, -300}, {666, -300}, {1000, 0}};
    MapBuilder a, b;
    a.chain(20, south, "S", "").chain(10, north, "", "N", "", chains::chain_halo);
    b.chain(10, north, "", "N").chain(20, south, "S", "", "", chains::chain_halo);
    for (const double eps : {16.0, 64.0}) {
        ToleranceStats sa, sb;
        const ChainStore out_a = run(a.s, eps, plain(), &sa);
        const ChainStore out_b = run(b.s, eps, plain(), &sb);
        ASSERT_EQ(out_a.chains.size(), 1U);
        ASSERT_EQ(out_b.chains.size(), 1U);
        EXPECT_EQ(out_b.chains[0].count, 2U); // 10 becomes J K
        EXPECT_EQ(out_a.chains[0].count, 3U); // 20 keeps one vertex
        EXPECT_EQ(sb.banned_region, 0U);
        EXPECT_EQ(sa.banned_region, 1U); // 20's J K
        const auto pa = out_a.chain_points(out_a.chains[0]), pb = out_b.chain_points(out_b.chains[0]);
        for (size_t i = 0; i + 1 < pa.size(); ++i) {
            for (size_t j = 0; j + 1 < pb.size(); ++j) {
                const auto rel = segment_relation(pa[i], pa[i + 1], pb[j], pb[j + 1]);
                EXPECT_TRUE(rel == SegmentRelation::disjoint || rel == SegmentRelation::shared_endpoint)
                    << "segment " << i << " of 20 and " << j << " of 10";
            }
        }
        // Within one store the same.
        MapBuilder whole;
        whole.chain(10, north, "", "N").chain(20, south, "S", "");
        ToleranceStats sw;
        const ChainStore out_w = run(whole.s, eps, plain(), &sw);
        EXPECT_EQ(points_of(out_w, 10).size(), 2U);
        EXPECT_EQ(points_of(out_w, 20).size(), 3U);
        EXPECT_EQ(sw.banned_exact, 0U);
    }
}
