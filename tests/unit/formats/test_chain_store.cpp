#include "core/digest.hpp"
#include "core/errors.hpp"
#include "formats/chains/chain_store.hpp"

#include "../../support/run_tool.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>

using namespace tigerlod;
using namespace tigerlod::chains;

namespace {

ChainStore sample()
{
    ChainStore s;
    s.level_index = 2;
    s.level_count = 5;
    s.level_name = "tract";
    s.partition = "51063";
    s.halo_m = 250;
    s.projection.kind = ProjectionParams::Kind::lcc;
    s.projection.lon0_deg = -80;
    const GridPoint open[] = {{0, 0}, {10, 5}, {20, 0}};
    const GridPoint ring[] = {{0, 0}, {5, 5}, {0, 10}, {0, 0}};
    s.add_chain({9, s.intern("A"), s.intern("B"), s.intern("G5020"), 0, 0, 0}, open);
    s.add_chain({3, s.intern("A"), 0, 0, chain_closed | chain_halo, 0, 0}, ring);
    s.add_chain({7, 0, s.intern("B"), 0, chain_problem, 0, 0}, open);
    s.junctions = {{42, {20, 0}, 3}, {41, {0, 0}, 1}};
    s.constraints = {{s.intern("B"), constraint_internal, {3, 3}}, {s.intern("A"), constraint_user, {1, 1}}};
    s.canonicalize();
    return s;
}

std::span<const std::byte> as_span(const std::string& b)
{
    return std::as_bytes(std::span(b.data(), b.size()));
}

void expect_format_error(const std::string& bytes, const std::string& fragment)
{
    try {
        decode(as_span(bytes), "x.tlc");
        FAIL() << "expected a format_error with '" << fragment << "'";
    } catch (const format_error& e) {
        EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
        EXPECT_EQ(std::string(e.what()).rfind("x.tlc", 0), 0U) << e.what();
    }
}

} // namespace

TEST(ChainStore, CanonicalOrder)
{
    const ChainStore s = sample();
    ASSERT_EQ(s.chains.size(), 3U);
    EXPECT_EQ(s.chains[0].id, 7U); // owned first, by id
    EXPECT_EQ(s.chains[1].id, 9U);
    EXPECT_EQ(s.chains[2].id, 3U); // then halo
    EXPECT_EQ(s.junctions[0].id, 41U);
    EXPECT_EQ(s.strings[s.constraints[0].unit], "A");
    EXPECT_EQ(s.chain_points(s.chains[2]).size(), 4U);
}

TEST(ChainStore, RoundTripIsExact)
{
    const ChainStore s = sample();
    const std::string bytes = encode(s);
    const ChainStore back = decode(as_span(bytes), "mem");
    EXPECT_EQ(encode(back), bytes);
    EXPECT_EQ(to_text(back), to_text(s));
    EXPECT_EQ(back.projection, s.projection);
    EXPECT_EQ(back.points, s.points);
    EXPECT_EQ(back.level_name, "tract");
    EXPECT_EQ(back.partition, "51063");
}

TEST(ChainStore, FileRoundTripAndNoTemporaryLeft)
{
    const auto dir =
        std::filesystem::temp_directory_path() / ("tigerlod-test-chain-store-" + std::to_string(::getpid()));
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    write(dir / "a.tlc", sample());
    EXPECT_EQ(to_text(read(dir / "a.tlc")), to_text(sample()));
    size_t files = 0;
    for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir)) {
        ++files;
    }
    EXPECT_EQ(files, 1U);
    std::filesystem::remove_all(dir);
}

TEST(ChainStore, TextIsSortedAndComplete)
{
    const std::string text = to_text(sample());
    EXPECT_NE(text.find("chain 7 left= right=B class= flags=--p n=3 : 0,0 10,5 20,0\n"), std::string::npos) << text;
    EXPECT_NE(text.find("chain 3 left=A right= class= flags=ch- n=4"), std::string::npos);
    EXPECT_LT(text.find("junction 41"), text.find("junction 42"));
    EXPECT_NE(text.find("point A user 1,1\n"), std::string::npos);
}

TEST(ChainStore, RejectsBadFiles)
{
    const std::string good = encode(sample());
    expect_format_error("NOTACHAINSTOREATALL.........", "not a chain store");
    std::string v = good;
    v[8] = 3; // major version
    expect_format_error(v, "unsupported major version 3 (reads 1)");
    expect_format_error(good.substr(0, good.size() - 10), "truncated");
    expect_format_error(good + "xx", "trailing bytes");
    std::string flipped = good;
    flipped[good.size() / 2] ^= 0x40;
    expect_format_error(flipped, "checksum mismatch");
}

TEST(ChainStore, RejectsInconsistentContentEvenWithAValidChecksum)
{
    ChainStore s = sample();
    s.chains[0].left = 99; // no such string
    expect_format_error(encode(s), "string index 99 out of range");
    ChainStore c = sample();
    c.chains[0].flags |= chain_closed; // but its ends differ
    expect_format_error(encode(c), "closed flag disagrees");
}

// Kind 2 (a neighbour unit's internal point) is new in 1.2: it round-trips,
// a file that calls itself 1.1 may not hold it, and kind 3 is nobody's.
TEST(ChainStore, NeighbourPointsAreVersionOneTwo)
{
    ChainStore s = sample();
    s.constraints.push_back({s.intern("C"), constraint_neighbour, {20, 1}});
    s.canonicalize();
    const std::string good = encode(s);
    const ChainStore back = decode(as_span(good), "x.tlc");
    EXPECT_EQ(back.minor, minor_version);
    EXPECT_EQ(encode(back), good);
    EXPECT_NE(to_text(back).find("point C neighbour 20,1"), std::string::npos) << to_text(back);
    auto with_crc = [](std::string b) {
        const uint32_t crc = crc32(as_span(b.substr(0, b.size() - 4)));
        std::memcpy(b.data() + b.size() - 4, &crc, 4);
        return b;
    };
    std::string old = good;
    old[10] = 1; // minor version 1
    expect_format_error(with_crc(old), "unknown constraint kind 2");
    ChainStore bad = s;
    bad.constraints.back().kind = 3;
    expect_format_error(encode(bad), "unknown constraint kind 3");
}

TEST(ChainStore, MissingFileIsAnEnvironmentError)
{
    EXPECT_THROW(read("/nonexistent/x.tlc"), environment_error);
}

TEST(ChainStore, UnitLocationUsesChainsWithTheUnitOnOneSideOnly)
{
    // Unit A: the square (0,0)-(10,10) as two chains, one with B on its other
    // side; a chain with A on both sides (inside A) must not count.
    ChainStore s;
    const uint32_t A = s.intern("A"), B = s.intern("B");
    const GridPoint south_east[] = {{0, 0}, {10, 0}, {10, 10}};
    const GridPoint north_west[] = {{10, 10}, {0, 10}, {0, 0}};
    const GridPoint inner[] = {{2, 2}, {8, 8}};
    s.add_chain({1, A, 0, 0, 0, 0, 0}, south_east);
    s.add_chain({2, A, B, 0, 0, 0, 0}, north_west);
    s.add_chain({3, A, A, 0, 0, 0, 0}, inner);
    EXPECT_EQ(unit_location(s, A, {5, 5}), PointLocation::inside);
    EXPECT_EQ(unit_location(s, A, {5, 11}), PointLocation::outside);
    EXPECT_EQ(unit_location(s, A, {10, 5}), PointLocation::boundary);
    EXPECT_EQ(unit_location(s, B, {5, 5}), PointLocation::outside); // B's boundary here is one open chain
}

// Format goldens: chain store files checked in at each format version
// (tests/data/formats/chain-store-1.2, written by tigerlod-ingest and
// -simplify from the small-map golden; chain-store-1.3, by tigerlod-ingest
// from a hand-made map with unit attributes) still read, as the same text.
// A file of the current version re-encodes to its bytes; an older one
// re-encodes to a current file that reads back as the same text but for
// its version. When the format's version changes, these files stay: the
// test then says whether the new reader still reads them.

static void expect_golden_reads(const char* version, std::initializer_list<const char*> names, uint16_t minor)
{
    const std::filesystem::path dir =
        std::filesystem::path(TIGERLOD_SOURCE_DIR) / "tests/data/formats" / (std::string("chain-store-") + version);
    size_t files = 0;
    for (const char* name : names) {
        SCOPED_TRACE(name);
        const auto tlc = dir / (std::string(name) + ".tlc");
        const auto store = chains::read(tlc);
        EXPECT_EQ(store.minor, minor);
        const std::string text = tigerlod::testing::slurp(dir / (std::string(name) + ".txt"));
        EXPECT_EQ(chains::to_text(store), text);
        const std::string again = chains::encode(store);
        if (minor == minor_version) {
            EXPECT_EQ(again, tigerlod::testing::slurp(tlc));
        } else {
            const auto back = decode(as_span(again), "again");
            EXPECT_EQ(back.minor, minor_version);
            const std::string old_head = "chain-store 1." + std::to_string(minor) + "\n";
            ASSERT_EQ(text.substr(0, old_head.size()), old_head);
            EXPECT_EQ(chains::to_text(back),
                      "chain-store 1." + std::to_string(minor_version) + "\n" + text.substr(old_head.size()));
        }
        ++files;
    }
    EXPECT_EQ(files, names.size());
}

TEST(FormatGolden, ChainStore12ReadsAsItsTextAndReencodesAsTheCurrentVersion)
{
    expect_golden_reads("1.2", {"unit-1", "unit-1-eps-8m"}, 2);
}

TEST(FormatGolden, ChainStore13WithUnitAttributesReadsAsItsTextAndReencodesToItsBytes)
{
    expect_golden_reads("1.3", {"county-01"}, 3);
}
