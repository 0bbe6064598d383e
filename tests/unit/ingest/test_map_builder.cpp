// Hand-made maps through the map builder, with exact expectations.
#include "core/errors.hpp"
#include "stages/ingest/map_builder.hpp"
#include "stages/ingest/map_steps.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <mutex>
#include <random>
#include <set>
#include <tuple>
#include <sstream>

using namespace tigerlod;
using namespace tigerlod::ingest;

namespace {

// Map coordinates: unit steps of 1000 micro-degrees (about 100 m) from (-96, 40).
LonLatE6 ll(int x, int y)
{
    return {-96000000 + 1000 * x, 40000000 + 1000 * y};
}

const Projection& proj()
{
    static const Projection p{ProjectionParams{}};
    return p;
}
GridPoint gp(int x, int y)
{
    const LonLatE6 p = ll(x, y);
    return *proj().to_grid(p.lon * 1e-6, p.lat * 1e-6);
}

struct Built {
    BuildResult result;
    std::vector<chains::ChainStore> stores;
    const chains::ChainStore& store(const std::string& level, const std::string& part = "all") const
    {
        for (const auto& s : stores) {
            if (s.level_name == level && s.partition == part) {
                return s;
            }
        }
        throw std::runtime_error("no store " + level + "/" + part);
    }
};

/// Build, collecting the stores (the sink runs on several threads) in (level, partition) order.
Built build(RawMap raw, BuildOptions o, const Projection& projection = proj())
{
    Built b;
    std::mutex m;
    b.result = build_map(std::move(raw), projection, o, [&](const chains::ChainStore& s) {
        std::lock_guard lock(m);
        b.stores.push_back(s);
    });
    std::sort(b.stores.begin(), b.stores.end(), [](const auto& x, const auto& y) {
        return std::tie(x.level_index, x.partition) < std::tie(y.level_index, y.partition);
    });
    return b;
}

Built build(RawMap raw, double halo_m = 1000)
{
    BuildOptions o;
    o.halo_m = halo_m;
    o.threads = 2;
    return build(std::move(raw), o);
}

/// A chain's points as "x,y x,y ..." in map units from lo to hi ("?" for one off them).
std::string map_points(const chains::ChainStore& s, const chains::ChainInfo& c, int lo, int hi)
{
    std::ostringstream o;
    for (GridPoint p : s.chain_points(c)) {
        bool found = false;
        for (int x = lo; x <= hi && !found; ++x) {
            for (int y = lo; y <= hi && !found; ++y) {
                if (gp(x, y) == p) {
                    o << (o.tellp() > 0 ? " " : "") << x << "," << y;
                    found = true;
                }
            }
        }
        if (!found) {
            o << (o.tellp() > 0 ? " ?" : "?");
        }
    }
    return o.str();
}

/// A chain as "LEFT|RIGHT x,y x,y ..." in map units, for exact comparisons.
std::vector<std::string> describe(const chains::ChainStore& s, bool halo = false)
{
    std::vector<std::string> out;
    for (const auto& c : s.chains) {
        if (((c.flags & chains::chain_halo) != 0) != halo) {
            continue;
        }
        out.push_back(s.strings[c.left] + "|" + s.strings[c.right] + " " + map_points(s, c, -3, 6));
    }
    std::sort(out.begin(), out.end());
    return out;
}

bool inside(const chains::ChainStore& s, const chains::ConstraintPoint& cp)
{
    return chains::unit_location(s, cp.unit, cp.p) == PointLocation::inside;
}

void edge(RawMap& m, std::vector<LonLatE6> pts, uint32_t l, uint32_t r, uint64_t tlid)
{
    m.add_polyline(pts, l, r, 0, tlid, {0, static_cast<int64_t>(tlid)});
}

/// An empty line layer (level "lines"), to be filled with add_polyline.
RawMap line_map()
{
    RawMap m;
    m.kind = RawMap::Kind::lines;
    m.level_names = {"lines"};
    m.files = {"hand"};
    return m;
}

/// A one-level polygon map (level "l") of `units`, to be filled by ring().
RawMap polygon_map(std::vector<RawUnit> units)
{
    RawMap m;
    m.kind = RawMap::Kind::polygon_rings;
    m.level_names = {"l"};
    m.files = {"hand"};
    m.units = std::move(units);
    return m;
}

/// A ring of `unit`, on its left or right as walked.
void ring(RawMap& m, std::vector<LonLatE6> r, uint32_t unit, bool unit_left)
{
    m.add_polyline(r, unit_left ? unit : no_unit, unit_left ? no_unit : unit, 0, 0, {0, unit});
}

/// Two coarse units A, B; B splits into B1 (north) and B2 (south) at the fine level:
///
///  (0,2)------(1,2)------(2,2)
///    |    A     |    B1    |
///    |          +----------(2,1)
///    |          |    B2    |
///  (0,0)------(1,0)------(2,0)
RawMap t_junction_map()
{
    RawMap m;
    m.kind = RawMap::Kind::edges;
    m.level_names = {"coarse", "fine"};
    m.files = {"hand"};
    m.units = {{{"1", "1a"}, ll(0, 0), 1, {}}, {{"2", "2a"}, std::nullopt, 1, {}}, {{"2", "2b"}, std::nullopt, 1, {}}};
    const uint32_t A = 0, B1 = 1, B2 = 2;
    edge(m, {ll(0, 0), ll(1, 0)}, A, no_unit, 1);
    edge(m, {ll(1, 0), ll(2, 0)}, B2, no_unit, 2);
    edge(m, {ll(2, 0), ll(2, 1)}, B2, no_unit, 3);
    edge(m, {ll(2, 1), ll(2, 2)}, B1, no_unit, 4);
    edge(m, {ll(2, 2), ll(1, 2)}, B1, no_unit, 5);
    edge(m, {ll(1, 2), ll(0, 2)}, A, no_unit, 6);
    edge(m, {ll(0, 2), ll(0, 0)}, A, no_unit, 7);
    edge(m, {ll(1, 0), ll(1, 1)}, A, B2, 8);
    edge(m, {ll(1, 1), ll(1, 2)}, A, B1, 9);
    edge(m, {ll(1, 1), ll(2, 1)}, B1, B2, 10);
    return m;
}

} // namespace

TEST(MapBuilder, ChainsMergeThroughDegreeTwoAndStopAtJunctions)
{
    const Built b = build(t_junction_map());
    const auto& coarse = b.store("coarse");
    // Junctions of degree 3 at (1,0) and (1,2); (1,1) and (2,1) have degree 2 at this level.
    // Each chain starts at its smaller end (by lon, then lat); left and right are as walked:
    // walking west along the bottom, A lies on the right.
    EXPECT_EQ(describe(coarse),
              (std::vector<std::string>{"1|2 1,0 1,1 1,2", "2| 1,0 2,0 2,1 2,2 1,2", "|1 1,0 0,0 0,2 1,2"}));
    ASSERT_EQ(coarse.junctions.size(), 2U);
    EXPECT_EQ(coarse.junctions[0].degree, 3U);
    // Chain ids are the smallest TLID of their edges.
    std::vector<uint64_t> ids;
    for (const auto& c : coarse.chains) {
        ids.push_back(c.id);
    }
    EXPECT_EQ(ids, (std::vector<uint64_t>{1, 2, 8}));
    // The fine level, partitioned by the coarse unit: the chain between A and B is owned by "1".
    EXPECT_EQ(describe(b.store("fine", "1")),
              (std::vector<std::string>{"1a|2a 1,1 1,2", "1a|2b 1,0 1,1", "|1a 1,0 0,0 0,2 1,2"}));
    EXPECT_EQ(describe(b.store("fine", "2")),
              (std::vector<std::string>{"2a|2b 1,1 2,1", "2b| 1,0 2,0 2,1", "|2a 1,2 2,2 2,1"}));
    EXPECT_EQ(b.result.levels[0].junctions, 2U);
    EXPECT_EQ(b.result.levels[1].junctions, 4U);
    EXPECT_EQ(b.result.levels[1].units, 3U);
    EXPECT_EQ(b.result.problems.at("crossings"), 0U);
}

TEST(MapBuilder, HaloHoldsNeighbouringChainsReadOnly)
{
    const Built b = build(t_junction_map(), 50.0);
    // Partition "2" sees the chains of partition "1" that touch it, as halo.
    const auto halo = describe(b.store("fine", "2"), true);
    EXPECT_NE(std::find(halo.begin(), halo.end(), "1a|2b 1,0 1,1"), halo.end());
    EXPECT_NE(std::find(halo.begin(), halo.end(), "1a|2a 1,1 1,2"), halo.end());
}

TEST(MapBuilder, InternalPointsAreInsideTheirUnits)
{
    const Built b = build(t_junction_map());
    for (const auto& s : b.stores) {
        for (const auto& cp : s.constraints) {
            // Unit A's given point (0,0) is its corner, on the boundary: it must be replaced.
            EXPECT_TRUE(inside(s, cp)) << s.level_name << " " << s.strings[cp.unit];
        }
    }
    EXPECT_EQ(b.result.problems.at("internal_points_replaced"), 2U);
}

TEST(MapBuilder, ALargePolygonMapIsTheSameOnOneThreadAndOnSeveral)
{
    // 80 x 80 square units, each side in three segments: 76,800 segment
    // records, enough for the merge to scan them in two parts. Two units
    // repeat a ring, one at each end of the records: overlapping polygons.
    const int n = 80;
    std::vector<RawUnit> units;
    for (int k = 0; k < n * n + 2; ++k) {
        std::string code = std::to_string(k);
        code.insert(0, 1, 'u');
        units.push_back({{code}, std::nullopt, 1, {0, k}});
    }
    RawMap m = polygon_map(units);
    auto square = [&](int cx, int cy, uint32_t unit) {
        std::vector<LonLatE6> r;
        auto at = [&](int i, int j) { return LonLatE6{-96000000 + 100 * (3 * cx + i), 40000000 + 100 * (3 * cy + j)}; };
        for (int i = 0; i < 3; ++i) {
            r.push_back(at(i, 0));
        }
        for (int j = 0; j < 3; ++j) {
            r.push_back(at(3, j));
        }
        for (int i = 3; i > 0; --i) {
            r.push_back(at(i, 3));
        }
        for (int j = 3; j >= 0; --j) {
            r.push_back(at(0, j));
        }
        ring(m, r, unit, true);
    };
    for (int cy = 0; cy < n; ++cy) {
        for (int cx = 0; cx < n; ++cx) {
            square(cx, cy, static_cast<uint32_t>(cy * n + cx));
        }
    }
    square(0, 0, n * n);
    square(n - 1, n - 1, n * n + 1);
    auto run = [&](unsigned threads) {
        BuildOptions o;
        o.threads = threads;
        o.halo_m = 0;
        const Built b = build(m, o);
        std::string all;
        for (const auto& s : b.stores) {
            all += chains::encode(s);
        }
        for (const auto& p : b.result.samples) {
            all += p.kind + " " + p.where + "\n";
        }
        EXPECT_EQ(b.result.problems.at("overlapping_polygons"), 24U);
        EXPECT_EQ(b.result.levels.at(0).units, size_t{n * n + 2});
        return all;
    };
    EXPECT_EQ(run(1), run(2));
}

TEST(MapBuilder, SharedPolygonEdgesMergeAndRingsCloseOnTheirSmallestVertex)
{
    // Two squares A | B sharing an edge, and an island C inside B (a hole in B).
    //  (0,0)-(2,0)-(4,0); B has a hole (2.., as ring (3,1)(3,2)... scaled below.
    RawMap m = polygon_map({{{"A"}, std::nullopt, 4, {}}, {{"B"}, std::nullopt, 4, {}}, {{"C"}, std::nullopt, 1, {}}});
    ring(m, {ll(0, 0), ll(2, 0), ll(2, 4), ll(0, 4), ll(0, 0)}, 0, true);  // A, counter-clockwise
    ring(m, {ll(2, 0), ll(2, 4), ll(6, 4), ll(6, 0), ll(2, 0)}, 1, false); // B, clockwise
    ring(m, {ll(3, 1), ll(3, 3), ll(5, 3), ll(5, 1), ll(3, 1)}, 1, true);  // B's hole, clockwise
    ring(m, {ll(3, 1), ll(5, 1), ll(5, 3), ll(3, 3), ll(3, 1)}, 2, true);  // C
    const Built b = build(std::move(m));
    const auto& s = b.store("l");
    // The island's ring starts at its smallest vertex (3,1) and heads to the smaller neighbour (3,3).
    EXPECT_EQ(describe(s), (std::vector<std::string>{"A|B 2,0 2,4", "B| 2,0 6,0 6,4 2,4", "B|C 3,1 3,3 5,3 5,1 3,1",
                                                     "|A 2,0 0,0 0,4 2,4"}));
    EXPECT_EQ(b.result.levels[0].rings, 1U);
    EXPECT_EQ(b.result.problems.at("overlapping_polygons"), 0U);
    for (const auto& cp : s.constraints) {
        EXPECT_TRUE(inside(s, cp)) << s.strings[cp.unit];
    }
    EXPECT_EQ(b.result.levels[0].computed_internal_points, 3U);
    for (const auto& c : s.chains) {
        EXPECT_EQ((c.flags & chains::chain_closed) != 0, s.chain_points(c).front() == s.chain_points(c).back());
    }
}

TEST(MapBuilder, RingsThatMeetAlongTheMeridian180WithOtherVerticesEachSideShareTheirEdges)
{
    // On a cone centred on 100 E (cut at 80 W), the meridian 180 is inside
    // the map. Unit F in two parts cut there, each side with a vertex the
    // other lacks (13 N west, 16 N east); units G and H meeting there, 35 N
    // on H's side only. The reader writes -180 as 180 and gives the sides.
    ProjectionParams pp;
    pp.lon0_deg = 100;
    pp.lat0_deg = 0;
    pp.stdlat1_deg = 20;
    pp.stdlat2_deg = 50;
    pp.grid_m = 0.1;
    const Projection cone(pp);
    auto at = [](int lon, int lat) { return LonLatE6{lon * 1000000, lat * 1000000}; };
    for (const bool reversed : {false, true}) {
        SCOPED_TRACE(reversed ? "the east rings drawn clockwise, the unit on their right" : "all counter-clockwise");
        RawMap m =
            polygon_map({{{"F"}, std::nullopt, 2, {}}, {{"G"}, std::nullopt, 1, {}}, {{"H"}, std::nullopt, 1, {}}});
        auto east_ring = [&](std::vector<LonLatE6> r, uint32_t unit) {
            if (reversed) {
                std::reverse(r.begin(), r.end());
            }
            ring(m, r, unit, !reversed);
        };
        ring(m, {at(170, 10), at(180, 10), at(180, 13), at(180, 20), at(170, 20), at(170, 10)}, 0, true);
        east_ring({at(180, 10), at(-170, 10), at(-170, 20), at(180, 20), at(180, 16), at(180, 10)}, 0);
        ring(m, {at(170, 30), at(180, 30), at(180, 40), at(170, 40), at(170, 30)}, 1, true);
        east_ring({at(180, 30), at(-170, 30), at(-170, 40), at(180, 40), at(180, 35), at(180, 30)}, 2);
        BuildOptions o;
        o.halo_m = 20000;
        o.threads = 2;
        const Built b = build(std::move(m), o, cone);
        for (const char* kind : {"overlapping_polygons", "spikes", "crossings", "overlaps", "touches"}) {
            EXPECT_EQ(b.result.problems.at(kind), 0U) << kind;
        }
        // F: one ring without its seam (six corners); G | H: one edge along
        // the seam, through 35 N; G's and H's outer sides, between its ends.
        std::vector<std::string> chains;
        const auto& s = b.store("l");
        for (const auto& c : s.chains) {
            chains.push_back(s.strings[c.left] + "|" + s.strings[c.right] + " " +
                             std::to_string(s.chain_points(c).size()));
        }
        std::sort(chains.begin(), chains.end());
        EXPECT_EQ(chains, (std::vector<std::string>{"F| 7", "G|H 3", "H| 4", "|G 4"}));
        EXPECT_EQ(b.result.levels[0].rings, 1U);
    }
}

TEST(MapBuilder, PolygonSegmentsJoinIntoOneEdgePerRunBetweenJunctions)
{
    // A and B share a boundary of three segments, and each ring starts at a
    // different vertex; an island D lies inside B. After merging, the edges are
    // the runs: A|B, A's outer side, B's outer side, and the island's ring.
    //  (0,4)---(2,4)-----------(6,4)
    //    |  A    \      B        |
    //    |        (3,2)  (4,2)-(5,2)
    //    |       /         | D  |
    //    |  (2,1)        (4,1)-(5,1)
    //  (0,0)---(2,0)-----------(6,0)
    RawMap m = polygon_map({{{"A"}, std::nullopt, 4, {}}, {{"B"}, std::nullopt, 4, {}}, {{"D"}, std::nullopt, 1, {}}});
    ring(m, {ll(0, 4), ll(0, 0), ll(2, 0), ll(2, 1), ll(3, 2), ll(2, 4), ll(0, 4)}, 0, true); // A, ccw
    ring(m, {ll(3, 2), ll(2, 1), ll(2, 0), ll(6, 0), ll(6, 4), ll(2, 4), ll(3, 2)}, 1, true); // B, ccw
    ring(m, {ll(5, 2), ll(5, 1), ll(4, 1), ll(4, 2), ll(5, 2)}, 1, true);                     // B's hole, cw
    ring(m, {ll(4, 2), ll(5, 2), ll(5, 1), ll(4, 1), ll(4, 2)}, 2, false);                    // D, cw
    const Built b = build(std::move(m));
    EXPECT_EQ(b.result.edges, 4U);
    EXPECT_EQ(b.result.problems.at("overlapping_polygons"), 0U);
    EXPECT_EQ(describe(b.store("l")), (std::vector<std::string>{"A|B 2,0 2,1 3,2 2,4", "B| 2,0 6,0 6,4 2,4",
                                                                "B|D 4,1 4,2 5,2 5,1 4,1", "|A 2,0 0,0 0,4 2,4"}));
}

TEST(MapBuilder, SnapRoundsHalfAwayFromZeroExactlyAsLlround)
{
    // Random degrees, and values whose micro-degree product lands on or next
    // to a half (the ties decide which way a point snaps).
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> lon(-180.0, 180.0), lat(-90.0, 90.0);
    std::vector<std::pair<double, double>> points;
    for (int i = 0; i < 200000; ++i) {
        points.emplace_back(lon(rng), lat(rng));
    }
    for (int64_t k : {int64_t{0}, int64_t{1}, int64_t{-1}, int64_t{2}, int64_t{-3}, int64_t{89999999},
                      int64_t{-96123456}, int64_t{179999999}, int64_t{-179999999}}) {
        for (double half : {0.5, -0.5}) {
            const double x = (static_cast<double>(k) + half) / 1e6;
            for (double v : {x, std::nextafter(x, 0.0), std::nextafter(x, 1e9), std::nextafter(x, -1e9)}) {
                points.emplace_back(v, std::clamp(v, -90.0, 90.0));
            }
        }
    }
    points.emplace_back(2.5e-6, -2.5e-6);
    points.emplace_back(0.0, -0.0);
    for (const auto& [x, y] : points) {
        const LonLatE6 s = snap_e6(x, y);
        ASSERT_EQ(s.lon, std::llround(x * 1e6)) << std::hexfloat << x;
        ASSERT_EQ(s.lat, std::llround(y * 1e6)) << std::hexfloat << y;
    }
}

TEST(MapBuilder, SnappingMergesNearPointsAndSpikesAreRepaired)
{
    RawMap m = line_map();
    // 0,0 then a point 0.3 micro-degrees away (snaps onto it), then a p-q-p spike at 2,0.
    LonLatE6 near = snap_e6(-96.0 + 0.3e-6, 40.0);
    m.add_polyline(std::vector<LonLatE6>{ll(0, 0), near, ll(1, 0), ll(2, 0), ll(2, 1), ll(2, 0), ll(3, 0)}, no_unit,
                   no_unit, 0, 0, {0, 0});
    const Built b = build(std::move(m));
    EXPECT_EQ(b.result.problems.at("duplicate_points"), 1U);
    EXPECT_EQ(b.result.problems.at("spikes"), 1U);
    EXPECT_EQ(describe(b.store("lines")), (std::vector<std::string>{"| 0,0 1,0 2,0 3,0"}));
}

TEST(MapBuilder, DistinctPointsThatRoundOntoOneGridPointBecomeOneVertexOnACoarseGrid)
{
    // Line b ends one micro-degree (11 cm) north of a vertex of line a.
    const LonLatE6 end{ll(1, 0).lon, ll(1, 0).lat + 1};
    auto map = [&] {
        RawMap m = line_map();
        m.add_polyline(std::vector<LonLatE6>{ll(0, 0), ll(1, 0), ll(2, 0)}, no_unit, no_unit, 0, 0, {0, 0});
        m.add_polyline(std::vector<LonLatE6>{ll(1, 1), end}, no_unit, no_unit, 0, 0, {0, 1});
        return m;
    };
    BuildOptions o;
    o.threads = 2;
    // On the 1 cm grid they stay apart: two chains, nothing merged.
    const Built fine = build(map(), o);
    EXPECT_EQ(fine.result.problems.at("merged_vertices"), 0U);
    EXPECT_EQ(fine.store("lines").chains.size(), 2U);
    // On a 1 m grid both round onto one grid point: b ends on a, which splits there.
    ProjectionParams coarse;
    coarse.grid_m = 1.0;
    const Projection metre(coarse);
    ASSERT_EQ(metre.to_grid(end.lon * 1e-6, end.lat * 1e-6), metre.to_grid(ll(1, 0).lon * 1e-6, ll(1, 0).lat * 1e-6));
    const Built merged = build(map(), o, metre);
    EXPECT_EQ(merged.result.problems.at("merged_vertices"), 1U);
    EXPECT_EQ(merged.store("lines").chains.size(), 3U);
}

TEST(MapBuilder, CrossingsTouchesAndOverlapsAreFoundAndMarked)
{
    RawMap m = line_map();
    auto line = [&](std::vector<LonLatE6> p, int64_t f) { m.add_polyline(p, no_unit, no_unit, 0, 0, {0, f}); };
    line({ll(0, 0), ll(2, 2)}, 0); // X with the next
    line({ll(0, 2), ll(2, 0)}, 1);
    // On the central meridian x is exactly 0, so these are exactly collinear after projection.
    line({ll(0, 10), ll(0, 12)}, 2); // T: the next ends on its interior
    line({ll(0, 11), ll(2, 11)}, 3);
    line({ll(0, 6), ll(0, 8)}, 4); // collinear overlap with the next
    line({ll(0, 7), ll(0, 9)}, 5);
    line({ll(0, -2), ll(5, -2)}, 6); // clean
    const Built b = build(std::move(m));
    EXPECT_EQ(b.result.problems.at("crossings"), 1U);
    EXPECT_EQ(b.result.problems.at("touches"), 1U);
    EXPECT_EQ(b.result.problems.at("overlaps"), 1U);
    size_t flagged = 0;
    for (const auto& c : b.store("lines").chains) {
        flagged += (c.flags & chains::chain_problem) != 0;
    }
    EXPECT_EQ(flagged, 6U); // every chain but the clean one
    ASSERT_FALSE(b.result.samples.empty());
    EXPECT_EQ(b.result.samples[0].kind, "crossings");
    EXPECT_NEAR(b.result.samples[0].lon_deg, -96.0 + 0.001, 1e-6);
    EXPECT_NEAR(b.result.samples[0].lat_deg, 40.0 + 0.001, 1e-5);
}

TEST(MapBuilder, ACrossingNamesTheFeatureAtThePlaceNotTheFirstOfItsJoinedChain)
{
    // Three features end to end become one chain; a fourth crosses the
    // middle one: the problem names that one, whichever way the chain runs.
    for (const bool reversed : {false, true}) {
        SCOPED_TRACE(reversed ? "the middle feature drawn backwards" : "all one way");
        RawMap m = line_map();
        auto line = [&](std::vector<LonLatE6> p, int64_t f) { m.add_polyline(p, no_unit, no_unit, 0, 0, {0, f}); };
        line({ll(0, 0), ll(2, 0)}, 0);
        line(reversed ? std::vector{ll(4, 0), ll(2, 0)} : std::vector{ll(2, 0), ll(4, 0)}, 1);
        line({ll(4, 0), ll(6, 0)}, 2);
        line({ll(3, -1), ll(3, 1)}, 3); // crosses feature 1 inside both segments
        const Built b = build(std::move(m));
        EXPECT_EQ(describe(b.store("lines")).size(), 2U); // the three joined, and the crossing line
        ASSERT_EQ(b.result.problems.at("crossings"), 1U);
        ASSERT_EQ(b.result.samples.size(), 1U);
        EXPECT_EQ(b.result.samples[0].where, "hand:1 hand:3");
    }
}

TEST(MapBuilder, SourceRunsTurnAroundAndStayCanonical)
{
    namespace rd = tigerlod::ingest::detail;
    using rd::SourceRun;
    auto text = [](const std::vector<SourceRun>& runs) {
        std::string t;
        for (const auto& r : runs) {
            t += std::to_string(r.first) + ":" + std::to_string(r.src.feature) + " ";
        }
        return t;
    };
    const SourceRef a{0, 10}, b{0, 11}, c{0, 12};
    // Segments 0-1 from a, 2-4 from b: turned round, 0-2 from b, 3-4 from a.
    EXPECT_EQ(text(rd::reversed_runs(std::vector<SourceRun>{{0, a}, {2, b}}, 5)), "0:11 3:10 ");
    EXPECT_EQ(text(rd::reversed_runs(std::vector<SourceRun>{{0, a}}, 3)), "0:10 ");
    // The last of equal starts wins, equal neighbours merge, starts past the end go.
    EXPECT_EQ(text(rd::canonical_runs({{0, a}, {2, b}, {2, c}, {4, c}, {5, a}}, 5)), "0:10 2:12 ");
    EXPECT_EQ(text(rd::canonical_runs({{0, a}, {1, b}, {1, a}}, 3)), "0:10 ");
}

TEST(MapBuilder, OutputDoesNotDependOnThreads)
{
    auto run = [](unsigned threads) {
        BuildOptions o;
        o.threads = threads;
        std::string all;
        for (const auto& s : build(t_junction_map(), o).stores) {
            all += chains::encode(s);
        }
        return all;
    };
    EXPECT_EQ(run(1), run(4));
}

TEST(MapBuilder, CoordinateOutsideTheProjectionIsAnInputError)
{
    ProjectionParams p;
    p.kind = ProjectionParams::Kind::tm;
    p.lon0_deg = 0;
    const Projection tm(p);
    RawMap m = t_junction_map();
    EXPECT_THROW(build_map(std::move(m), tm, {}, [](const chains::ChainStore&) {}), input_error);
}

TEST(MapBuilder, SnapRepairDropsAPassThroughVertexWithinThePrecisionOnly)
{
    // A line on the central meridian (x = 0 exactly), and a second line with a
    // vertex V on it, its neighbours 1 micro-degree (8.5 cm) west:
    //        W2
    //   |   /
    //   |  V      V touches the first line; dropping V moves the second by 8.5 cm.
    //   |   \ .
    //        W1
    auto make = [] {
        RawMap m = line_map();
        const LonLatE6 v = ll(0, 2);
        m.add_polyline(std::vector<LonLatE6>{ll(0, 0), ll(0, 4)}, no_unit, no_unit, 0, 0, {0, 0});
        m.add_polyline(std::vector<LonLatE6>{{v.lon - 1, v.lat - 1000}, v, {v.lon - 1, v.lat + 1000}}, no_unit, no_unit,
                       0, 0, {0, 1});
        return m;
    };
    auto run = [&](double max_shift_m) {
        BuildOptions o;
        o.max_snap_shift_m = max_shift_m;
        return build(make(), o);
    };
    const Built repaired = run(0.12);
    EXPECT_EQ(repaired.result.problems.at("snap_repairs"), 1U);
    EXPECT_EQ(repaired.result.problems.at("touches"), 0U);
    ASSERT_EQ(repaired.stores.size(), 1U);
    for (const auto& c : repaired.stores[0].chains) {
        EXPECT_EQ(c.count, 2U); // V is gone from the second line
    }
    const Built kept = run(0.05);
    EXPECT_EQ(kept.result.problems.at("snap_repairs"), 0U);
    EXPECT_EQ(kept.result.problems.at("touches"), 2U); // counted per segment pair: both segments at V
}

TEST(MapBuilder, IdenticalLineworkInALineLayerBecomesOneChain)
{
    // A river stored twice (features 0 and 1), and a tributary joining at (2,0):
    //   0,0 --- 1,0 --- 2,0 --- 3,0      (twice)
    //                    |
    //                   2,-2
    RawMap m = line_map();
    m.add_polyline(std::vector<LonLatE6>{ll(0, 0), ll(1, 0), ll(2, 0), ll(3, 0)}, no_unit, no_unit, 0, 0, {0, 0});
    m.add_polyline(std::vector<LonLatE6>{ll(3, 0), ll(2, 0), ll(1, 0), ll(0, 0)}, no_unit, no_unit, 0, 0, {0, 1});
    m.add_polyline(std::vector<LonLatE6>{ll(2, -2), ll(2, 0)}, no_unit, no_unit, 0, 0, {0, 2});
    const Built b = build(std::move(m));
    EXPECT_EQ(b.result.problems.at("duplicate_segments"), 3U);
    EXPECT_EQ(b.result.problems.at("overlaps"), 0U);
    EXPECT_EQ(describe(b.store("lines")), (std::vector<std::string>{"| 0,0 1,0 2,0", "| 2,-2 2,0", "| 2,0 3,0"}));
}

namespace {

/// Every store's chains: "partition: [halo ]points", sorted.
std::vector<std::string> tiled(const Built& b)
{
    std::vector<std::string> out;
    for (const auto& s : b.stores) {
        for (const auto& c : s.chains) {
            out.push_back(s.partition + ": " + ((c.flags & chains::chain_halo) ? "halo " : "") +
                          map_points(s, c, -6, 9));
        }
    }
    std::sort(out.begin(), out.end());
    return out;
}

} // namespace

TEST(MapBuilder, ALineLayerIsCutIntoGridTilesWhereItsChainsStrayOut)
{
    // Tiles of 1 km: the central meridian (-96, map x = 0) is the edge between
    // columns -1 and 0, and a chain may stray 125 m (an eighth) out of its
    // tile before it is cut; a map unit is about 85 m east, 111 m north.
    //
    //   y=8..9  a ring from x=-1 that strays east once (at 2,8) and comes
    //           back within the margin: one cut, so it stays whole
    //   y=5..7  a line zigzagging across the edge within the margin: whole
    //   y=4..5  a ring inside column 0
    //   y=3     a line from x=-3 to 6: cut at 2,3, where it strays
    //   y=1..2  a ring across the edge: cut twice, two pieces
    auto make = [] {
        RawMap m = line_map();
        auto line = [&](std::vector<std::pair<int, int>> pts, uint64_t id) {
            std::vector<LonLatE6> v;
            for (auto [x, y] : pts) {
                v.push_back(ll(x, y));
            }
            m.add_polyline(v, no_unit, no_unit, 0, 0, {0, static_cast<int64_t>(id)});
        };
        line({{-3, 3}, {-2, 3}, {-1, 3}, {0, 3}, {1, 3}, {2, 3}, {3, 3}, {4, 3}, {5, 3}, {6, 3}}, 0);
        line({{-1, 5}, {1, 5}, {1, 6}, {-1, 6}, {-1, 7}, {1, 7}}, 1);
        line({{-3, 1}, {4, 1}, {4, 2}, {-3, 2}, {-3, 1}}, 2);
        line({{5, 4}, {6, 4}, {6, 5}, {5, 5}, {5, 4}}, 3);
        line({{-1, 8}, {2, 8}, {1, 9}, {-1, 9}, {-1, 8}}, 4);
        return m;
    };
    BuildOptions o;
    o.halo_m = 100;
    o.threads = 2;
    o.line_tile_m = 1000;
    const Built b = build(make(), o);
    // Every point lies in one row of tiles (the test's premise).
    const int64_t side = std::llround(1000 / proj().params().grid_m);
    auto row = [&](int y) { return gp(0, y).y >= 0 ? gp(0, y).y / side : -((-gp(0, y).y + side - 1) / side); };
    ASSERT_EQ(row(1), row(9));
    const std::string west = "x-1y" + std::to_string(row(1)), east = "x0y" + std::to_string(row(1));
    // The line is cut at 2,3; the ring at 1..2 walks -3,1 -3,2 4,2 (strays:
    // cut) 4,1 and back to -3,1, which strays from the east tile: cut too.
    // The ring at 8..9 strays once, at 2,8, and its first vertex -1,8 lies
    // within the east tile's margin: whole, in the tile of its first vertex.
    EXPECT_EQ(tiled(b), (std::vector<std::string>{
                            west + ": -1,5 1,5 1,6 -1,6 -1,7 1,7",
                            west + ": -1,8 -1,9 1,9 2,8 -1,8",
                            west + ": -3,1 -3,2 4,2",
                            west + ": -3,3 -2,3 -1,3 0,3 1,3 2,3",
                            west + ": halo 2,3 3,3 4,3 5,3 6,3",
                            west + ": halo 4,2 4,1 -3,1",
                            east + ": 2,3 3,3 4,3 5,3 6,3",
                            east + ": 4,2 4,1 -3,1",
                            east + ": 5,4 5,5 6,5 6,4 5,4",
                            east + ": halo -3,1 -3,2 4,2",
                            east + ": halo -3,3 -2,3 -1,3 0,3 1,3 2,3",
                        }));
    ASSERT_EQ(b.result.levels.size(), 1U);
    EXPECT_EQ(b.result.levels[0].partitions, 2U);
    EXPECT_EQ(b.result.levels[0].chains, 7U);
    EXPECT_EQ(b.result.levels[0].tile_cuts, 3U);
    // Ids unique over the level; the cut vertices are junctions of degree 2.
    std::set<uint64_t> ids;
    size_t own = 0;
    for (const auto& s : b.stores) {
        for (const auto& c : s.chains) {
            if ((c.flags & chains::chain_halo) == 0) {
                ids.insert(c.id);
                ++own;
            }
        }
    }
    EXPECT_EQ(ids.size(), own);
    size_t degree_two = 0;
    for (const auto& s : b.stores) {
        for (const auto& j : s.junctions) {
            degree_two += j.degree == 2;
        }
    }
    EXPECT_EQ(degree_two, 6U) << "each of the 3 cut vertices ends an own chain in both tiles";
    // The same map without tiles: one partition, `all`, of the five chains whole.
    o.line_tile_m = 0;
    const Built whole = build(make(), o);
    ASSERT_EQ(whole.stores.size(), 1U);
    EXPECT_EQ(whole.stores[0].partition, "all");
    EXPECT_EQ(whole.stores[0].chains.size(), 5U);
    EXPECT_EQ(whole.result.levels[0].tile_cuts, 0U);
}

TEST(MapBuilder, ALineLayersTilesKeepJunctionsAsEndsAndOneTileIsAll)
{
    // A loop closed at a junction J = 1,4 (a tail 1,4 - 3,4 ends there too)
    // that strays west and comes back: cut where it strays, and J stays the
    // end of its first and last pieces, never inside one.
    //   -4,6 ------------------ 4,6
    //    |                       |
    //    |                      4,5
    //   -4,4 ---------- J=1,4 --/--- 3,4
    auto make = [](bool west) {
        RawMap m = line_map();
        auto line = [&](std::vector<std::pair<int, int>> pts, int64_t id) {
            std::vector<LonLatE6> v;
            for (auto [x, y] : pts) {
                v.push_back(ll(x, y));
            }
            m.add_polyline(v, no_unit, no_unit, 0, 0, {0, id});
        };
        line({{1, 4}, {3, 4}}, 0);
        if (west) {
            line({{1, 4}, {-4, 4}, {-4, 6}, {4, 6}, {4, 5}, {1, 4}}, 1);
        } else {
            line({{1, 4}, {4, 4}, {4, 6}, {2, 6}, {2, 5}, {1, 4}}, 1);
        }
        return m;
    };
    BuildOptions o;
    o.halo_m = 100;
    o.threads = 2;
    o.line_tile_m = 1000;
    const int64_t side = std::llround(1000 / proj().params().grid_m);
    auto row = [&](int y) { return gp(0, y).y >= 0 ? gp(0, y).y / side : -((-gp(0, y).y + side - 1) / side); };
    ASSERT_EQ(row(4), row(6));
    const std::string west = "x-1y" + std::to_string(row(4)), east = "x0y" + std::to_string(row(4));
    std::vector<std::string> own;
    for (const auto& line : tiled(build(make(true), o))) {
        if (line.find("halo") == std::string::npos) {
            own.push_back(line);
        }
    }
    EXPECT_EQ(own, (std::vector<std::string>{
                       west + ": -4,4 -4,6 4,6",
                       east + ": 1,4 -4,4",
                       east + ": 1,4 3,4",
                       east + ": 4,6 4,5 1,4",
                   }));
    // Everything in the east tile: one partition, `all`, as without tiles.
    const Built one = build(make(false), o);
    ASSERT_EQ(one.stores.size(), 1U);
    EXPECT_EQ(one.stores[0].partition, "all");
    EXPECT_EQ(one.stores[0].chains.size(), 2U);
}
