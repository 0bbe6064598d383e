// The Data Tree format: skeleton, chain table and geometry payloads round-trip
// exactly, and every kind of damage is refused with a message, never a crash.
#include "formats/datatree/datatree.hpp"

#include "core/digest.hpp"
#include "core/errors.hpp"
#include "../../support/synthetic_tree.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <random>

using namespace tigerlod;
using namespace tigerlod::datatree;

namespace {

std::span<const std::byte> as_span(const std::string& s)
{
    return std::as_bytes(std::span(s.data(), s.size()));
}

std::string error_of(auto&& f)
{
    try {
        f();
    } catch (const format_error& e) {
        return e.what();
    }
    return "";
}

} // namespace

TEST(Geometry, SharedEndpointsAndRingsRoundTripExactly)
{
    Geometry g;
    // A star of three chains meeting at (100, 100), a ring, and a chain whose
    // interior point equals another chain's endpoint.
    g.add_chain(std::vector<GridPoint>{{100, 100}, {150, 120}, {200, 100}});
    g.add_chain(std::vector<GridPoint>{{100, 100}, {100, 300}});
    g.add_chain(std::vector<GridPoint>{{0, 0}, {50, 80}, {100, 100}});
    g.add_chain(std::vector<GridPoint>{{300, 300}, {400, 300}, {400, 400}, {300, 300}});
    g.add_chain(std::vector<GridPoint>{{200, 100}, {100, 300}, {0, 0}});
    const GridPoint origin{0, 0};
    const std::string bytes = encode_geometry(g, origin);
    const Geometry back = decode_geometry(as_span(bytes), origin, 5, g.points.size(), "test");
    EXPECT_EQ(back, g);
    EXPECT_EQ(back.memory_bytes(), geometry_bytes(5, g.points.size()));
}

TEST(Geometry, RandomChainsRoundTripExactly)
{
    std::mt19937 rng(7);
    for (int round = 0; round < 200; ++round) {
        Geometry g;
        const GridPoint origin{static_cast<int32_t>(rng() % 1000) - 500, -2000000000};
        std::uniform_int_distribution<int32_t> coord(0, 1 << (1 + round % 30));
        const size_t nchains = rng() % 8;
        std::vector<GridPoint> ends;
        for (size_t c = 0; c < nchains; ++c) {
            std::vector<GridPoint> pts;
            const size_t n = 2 + rng() % 20;
            for (size_t k = 0; k < n; ++k) {
                pts.push_back({origin.x + coord(rng), origin.y + coord(rng)});
            }
            if (!ends.empty() && rng() % 2) {
                pts.front() = ends[rng() % ends.size()];
            }
            if (!ends.empty() && rng() % 2) {
                pts.back() = ends[rng() % ends.size()];
            }
            ends.push_back(pts.front());
            ends.push_back(pts.back());
            g.add_chain(pts);
        }
        const std::string bytes = encode_geometry(g, origin);
        ASSERT_EQ(decode_geometry(as_span(bytes), origin, nchains, g.points.size(), "test"), g) << "round " << round;
    }
}

// The paths of the coding (SPEC.md, geometry payload): no low bits (steps of
// 0 and 1), a few far jumps among short steps (escaped points: beyond the
// 99th percentile), and differences near the 32-bit limits.
TEST(Geometry, EscapesLowBitsAndExtremeDifferencesRoundTripExactly)
{
    std::mt19937 rng(11);
    const GridPoint origin{0, 0};
    auto round_trip = [&](const Geometry& g) {
        const std::string bytes = encode_geometry(g, origin);
        EXPECT_EQ(decode_geometry(as_span(bytes), origin, g.chain_count(), g.points.size(), "test"), g);
        return bytes.size();
    };
    auto walk = [&](int step, int jump_every, int32_t jump) {
        Geometry g;
        std::vector<GridPoint> pts{{1 << 20, 1 << 20}};
        for (int i = 1; i < 2000; ++i) {
            GridPoint p = pts.back();
            if (jump_every > 0 && i % jump_every == 0) {
                const int32_t d = i / jump_every % 2 ? jump : -jump; // there and back
                p.x += d;
                p.y += d;
            } else {
                p.x += static_cast<int32_t>(rng() % (2 * step + 1)) - step;
                p.y += static_cast<int32_t>(rng() % (2 * step + 1)) - step;
            }
            pts.push_back(p);
        }
        g.add_chain(pts);
        return g;
    };
    round_trip(walk(1, 0, 0));
    round_trip(walk(0, 0, 0));
    // 1 point in 200 jumps a million times farther than the others step:
    // escaped, so the payload grows by about their varints only.
    const size_t plain = round_trip(walk(3, 0, 0));
    const size_t jumps = round_trip(walk(3, 200, 1 << 30));
    EXPECT_LT(jumps, plain + 10 * 10 + 64);
    // Differences of 2^31 - 1 either way, the most the node box allows.
    constexpr int32_t top = 2147483647;
    Geometry g;
    g.add_chain(std::vector<GridPoint>{{0, 0}, {top, top}, {0, top}, {top, 0}, {0, 1}, {1, 1}, {top, top}});
    round_trip(g);
}

// The coding's two widths are checked against what follows them: one more
// low bit than written leaves the low-bit stream short; one joint bit fewer
// puts symbols above 2^(2J). Both are refused, naming the payload.
TEST(Geometry, WrongLowOrJointBitsAreRefused)
{
    Geometry g;
    std::vector<GridPoint> pts;
    for (int i = 0; i < 400; ++i) {
        pts.push_back({1000 + 37 * i + (i * i) % 23, 5000 + 11 * i + (i * 7) % 19});
    }
    g.add_chain(pts);
    const std::string good = encode_geometry(g, {0, 0});
    // The offset of the low-bits varint: kind, chain count, new points, and the
    // chain's three side-table varints (all written by the encoder above).
    size_t at = 1;
    auto skip_varint = [&] {
        while (static_cast<uint8_t>(good[at]) & 0x80) {
            ++at;
        }
        ++at;
    };
    for (int k = 0; k < 5; ++k) {
        skip_varint();
    }
    const int low = good[at], joint = good[at + 1];
    ASSERT_GT(low, 0);
    ASSERT_LT(low, 30);
    ASSERT_GT(joint, 1);
    auto fault = [&](const std::string& bytes) {
        return error_of([&] { decode_geometry(as_span(bytes), {0, 0}, 1, pts.size(), "n7 LOD 2"); });
    };
    EXPECT_EQ(fault(good), "");
    std::string bad = good;
    bad[at] = static_cast<char>(low + 1);
    EXPECT_NE(fault(bad).find("n7 LOD 2"), std::string::npos) << fault(bad);
    EXPECT_NE(fault(bad).find("low-bit stream"), std::string::npos) << fault(bad);
    bad = good;
    bad[at + 1] = static_cast<char>(joint - 1);
    EXPECT_NE(fault(bad).find("n7 LOD 2"), std::string::npos) << fault(bad);
    EXPECT_NE(fault(bad).find("symbol"), std::string::npos) << fault(bad);
}

TEST(Geometry, PointBelowTheOriginIsRefused)
{
    Geometry g;
    g.add_chain(std::vector<GridPoint>{{10, 10}, {5, 20}});
    EXPECT_THROW(encode_geometry(g, {6, 0}), input_error);
}

TEST(Geometry, CountsThatDisagreeWithTheSkeletonAreRefused)
{
    Geometry g;
    g.add_chain(std::vector<GridPoint>{{10, 10}, {20, 20}, {30, 10}});
    const std::string bytes = encode_geometry(g, {0, 0});
    EXPECT_NE(error_of([&] {
                  decode_geometry(as_span(bytes), {0, 0}, 2, 3, "n7");
              }).find("n7: has 1 chains, the skeleton says 2"),
              std::string::npos);
    EXPECT_NE(error_of([&] {
                  decode_geometry(as_span(bytes), {0, 0}, 1, 4, "n7");
              }).find("has 3 points, the skeleton says 4"),
              std::string::npos);
}

TEST(Geometry, EveryDamagedByteIsRefusedOrDecodedWithoutCrashing)
{
    const auto t = tigerlod::testing::make_synthetic_tree(1);
    const std::string good = t.payloads[1][1];
    const auto& node = t.skeleton.nodes[1];
    size_t refused = 0;
    for (size_t i = 0; i < good.size(); ++i) {
        for (uint8_t flip : {uint8_t{0x01}, uint8_t{0x80}, uint8_t{0xFF}}) {
            std::string bad = good;
            bad[i] = static_cast<char>(bad[i] ^ flip);
            try {
                decode_geometry(as_span(bad), {node.box.min_x, node.box.min_y}, node.chains, node.lods[0].vertices,
                                "x");
            } catch (const format_error&) {
                ++refused;
            }
        }
    }
    // Truncations are always refused.
    for (size_t n = 0; n < good.size(); ++n) {
        EXPECT_THROW(decode_geometry(as_span(good.substr(0, n)), {node.box.min_x, node.box.min_y}, node.chains,
                                     node.lods[0].vertices, "x"),
                     format_error)
            << n;
    }
    EXPECT_GT(refused, 0U);
}

TEST(ChainTable, RoundTripAndDamage)
{
    ChainTable t;
    t.strings = {"", "51063", "510630201001", "S1400"};
    t.chains = {{5, 1, 2, 3, 0}, {3, 0, 1, 0, 1}, {~0ULL, 2, 2, 0, 4}};
    const std::string bytes = encode_table(t);
    EXPECT_EQ(decode_table(as_span(bytes), "t"), t);
    for (size_t n = 0; n < bytes.size(); ++n) {
        EXPECT_THROW(decode_table(as_span(bytes.substr(0, n)), "t"), format_error);
    }
    std::string bad = bytes;
    bad[0] = 2; // a geometry payload's kind
    EXPECT_NE(error_of([&] { decode_table(as_span(bad), "t"); }).find("not a chain table"), std::string::npos);
}

TEST(Skeleton, RoundTrip)
{
    const auto t = tigerlod::testing::make_synthetic_tree(2);
    const std::string bytes = encode_skeleton(t.skeleton);
    EXPECT_EQ(decode_skeleton(as_span(bytes), "s"), t.skeleton);
    EXPECT_EQ(t.skeleton.nodes.size(), 21U);
}

TEST(Skeleton, DamageIsNamed)
{
    const auto t = tigerlod::testing::make_synthetic_tree(1);
    const std::string good = encode_skeleton(t.skeleton);
    auto fault = [&](const std::string& bytes) { return error_of([&] { decode_skeleton(as_span(bytes), "sk.tls"); }); };
    std::string bad = good;
    bad[0] = 'X';
    EXPECT_NE(fault(bad).find("sk.tls: not a Data Tree skeleton (wrong magic)"), std::string::npos);
    bad = good;
    bad[8] = 9;
    EXPECT_NE(fault(bad).find("unsupported major version 9"), std::string::npos);
    EXPECT_NE(fault(good.substr(0, good.size() - 10)).find("truncated"), std::string::npos);
    EXPECT_NE(fault(good + "xx").find("trailing bytes"), std::string::npos);
    bad = good;
    bad[200] = static_cast<char>(bad[200] ^ 1);
    EXPECT_NE(fault(bad).find("checksum mismatch"), std::string::npos);
    // Every single-byte change and every truncation is refused.
    for (size_t i = 0; i < good.size(); ++i) {
        bad = good;
        bad[i] = static_cast<char>(bad[i] ^ 0x40);
        EXPECT_FALSE(fault(bad).empty()) << i;
        EXPECT_FALSE(fault(good.substr(0, i)).empty()) << i;
    }
}

TEST(Skeleton, ShapeErrorsAreCaughtEvenWithAValidChecksum)
{
    auto t = tigerlod::testing::make_synthetic_tree(1);
    auto fault = [&](const Skeleton& s) {
        return error_of([&] { decode_skeleton(as_span(encode_skeleton(s)), "sk"); });
    };
    Skeleton s = t.skeleton;
    s.nodes[2].parent = 3;
    EXPECT_NE(fault(s).find("node 2: parent 3 is not an earlier node"), std::string::npos);
    s = t.skeleton;
    s.nodes[1].lods[2].error_m = 0.0;
    EXPECT_NE(fault(s).find("node 1: LOD errors must be finite and grow"), std::string::npos);
    s = t.skeleton;
    s.nodes[3].lods[1].payload.offset = s.tiles[s.nodes[3].lods[1].payload.tile].size;
    EXPECT_NE(fault(s).find("node 3: payload outside its tile"), std::string::npos);
    s = t.skeleton;
    s.tiles[0].file = "../../etc/passwd";
    EXPECT_NE(fault(s).find("must be relative and stay inside the tree"), std::string::npos);
    s = t.skeleton;
    s.nodes[0].child_count = 3;
    EXPECT_NE(fault(s).find("not reachable from the root"), std::string::npos);
    // The reserved byte after the metric, checksum fixed: refused, so that a
    // valid skeleton re-encodes to its own bytes (found by fuzz_skeleton_fixed).
    std::string bytes = encode_skeleton(t.skeleton);
    bytes[27] = 0x40;
    const uint32_t crc = tigerlod::crc32(as_span(bytes).first(bytes.size() - 4));
    std::memcpy(bytes.data() + bytes.size() - 4, &crc, 4);
    EXPECT_NE(error_of([&] { decode_skeleton(as_span(bytes), "sk"); }).find("reserved byte not 0"), std::string::npos);
}

TEST(Tile, HeaderChecked)
{
    const std::string h = tile_header(100);
    EXPECT_NO_THROW(check_tile_header(as_span(h), 100, "t"));
    EXPECT_NE(error_of([&] { check_tile_header(as_span(h), 90, "t.tlt"); }).find("t.tlt: truncated"),
              std::string::npos);
    EXPECT_NE(error_of([&] { check_tile_header(as_span(h.substr(0, 10)), 100, "t.tlt"); }).find("truncated in header"),
              std::string::npos);
}

TEST(UnitTable, RoundTripsExactlyAndDamageIsRefused)
{
    datatree::UnitTable t;
    t.fields = {{"ALAND", 1}, {"NOTE", 0}};
    t.units = {{"51063", "Floyd", {-5, 7}, {"987654321", ""}},
               {"51067", "", {INT32_MAX, INT32_MIN}, {"", "é"}},
               {"51071", "Giles", {0, 0}, {"-3", "x"}}};
    const GridPoint origin{-100, 100};
    const std::string bytes = datatree::encode_units(t, origin);
    const auto all = std::as_bytes(std::span(bytes.data(), bytes.size()));
    const auto [size, crc] = datatree::units_body(all, "t");
    ASSERT_EQ(size, bytes.size() - datatree::units_head_size);
    const auto body = all.subspan(datatree::units_head_size);
    EXPECT_EQ(crc, crc32(body));
    EXPECT_EQ(datatree::decode_units(body, origin, "t"), t);
    // Not a units payload: another kind, or reserved bytes set.
    for (const size_t at : {size_t{0}, size_t{1}, size_t{3}}) {
        std::string bad = bytes;
        bad[at] = static_cast<char>(bad[at] ^ 0x40);
        EXPECT_THROW(datatree::units_body(std::as_bytes(std::span(bad.data(), bad.size())), "t"), format_error);
    }
    // A body cut short, with a byte more, or an unknown field type.
    EXPECT_THROW(datatree::decode_units(body.first(body.size() - 1), origin, "t"), format_error);
    std::string more(reinterpret_cast<const char*>(body.data()), body.size());
    more += '\0';
    EXPECT_THROW(datatree::decode_units(std::as_bytes(std::span(more.data(), more.size())), origin, "t"), format_error);
    std::string typed(reinterpret_cast<const char*>(body.data()), body.size());
    typed[1 + 1 + 5] = 3; // the first field's type, after its count and its name "ALAND"
    EXPECT_THROW(datatree::decode_units(std::as_bytes(std::span(typed.data(), typed.size())), origin, "t"),
                 format_error);
    // Every damaged byte of the body: refused, or decoded to a table that round-trips.
    for (size_t i = 0; i < body.size(); ++i) {
        std::string d(reinterpret_cast<const char*>(body.data()), body.size());
        d[i] = static_cast<char>(d[i] ^ 0x5A);
        try {
            const auto u = datatree::decode_units(std::as_bytes(std::span(d.data(), d.size())), origin, "t");
            const std::string back = datatree::encode_units(u, origin);
            EXPECT_EQ(datatree::decode_units(as_span(back).subspan(datatree::units_head_size), origin, "t"), u) << i;
        } catch (const format_error&) {
        }
    }
}
