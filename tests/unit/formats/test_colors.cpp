// The colours file (formats/colors/SPEC.md): its exact bytes, a round trip,
// and every refusal the SPEC lists.
#include "core/errors.hpp"
#include "formats/colors/colors.hpp"

#include <gtest/gtest.h>

using namespace tigerlod;

namespace {

colors::ColorFile sample()
{
    colors::ColorFile f;
    f.level = "tract";
    f.partition = "51063";
    f.eps_m = 16;
    f.metric = Metric::l1;
    f.pixel = 400;
    f.splits = 1;
    f.conflict_edges = 3;
    f.tiles.push_back({-1000.5, 2000, 4096, 2048, 1, {7, 11, 12}, {1, 2, 1}});
    f.tiles.push_back({3095.5, 2000, 4096, 2048, 1, {}, {}});
    return f;
}

std::string fault(const std::string& text)
{
    try {
        colors::decode(text, "c.json");
    } catch (const format_error& e) {
        return e.what();
    }
    return "";
}

} // namespace

TEST(Colors, BytesAsTheSpecSays)
{
    EXPECT_EQ(colors::encode(sample()),
              R"({"schema":"tigerlod.colors/1","level":"tract","partition":"51063","eps_m":16.0,"metric":"l1",)"
              R"("pixel":400.0,"splits":1,"conflict_edges":3,"tiles":[{"x0":-1000.5,"y0":2000.0,"width":4096,)"
              R"("height":2048,"depth":1,"chains":[7,11,12],"classes":[1,2,1]},{"x0":3095.5,"y0":2000.0,)"
              R"("width":4096,"height":2048,"depth":1,"chains":[],"classes":[]}]})"
              "\n");
}

TEST(Colors, RoundTrip)
{
    const std::string bytes = colors::encode(sample());
    const auto back = colors::decode(bytes, "c.json");
    EXPECT_EQ(colors::encode(back), bytes);
    EXPECT_EQ(back.metric, Metric::l1);
    ASSERT_EQ(back.tiles.size(), 2U);
    EXPECT_EQ(back.tiles[0].chains, (std::vector<uint64_t>{7, 11, 12}));
    EXPECT_EQ(back.tiles[0].classes, (std::vector<uint8_t>{1, 2, 1}));
}

TEST(Colors, EveryFaultIsNamed)
{
    const std::string good = colors::encode(sample());
    auto with = [&](const std::string& from, const std::string& to) {
        std::string s = good;
        const size_t at = s.find(from);
        EXPECT_NE(at, std::string::npos) << from;
        return s.replace(at, from.size(), to);
    };
    EXPECT_NE(fault("{").find("c.json: not a colours file"), std::string::npos);
    EXPECT_NE(fault(with("tigerlod.colors/1", "tigerlod.colors/2")).find("c.json: unknown schema"), std::string::npos);
    EXPECT_NE(fault(with(R"("metric":"l1")", R"("metric":"l3")")).find("unknown metric \"l3\""), std::string::npos);
    EXPECT_NE(fault(with(R"("splits":1,)", "")).find("not a colours file"), std::string::npos);
    EXPECT_NE(fault(with(R"("eps_m":16.0)", R"("eps_m":"16")")).find("not a colours file"), std::string::npos);
    EXPECT_NE(fault(with("[1,2,1]", "[1,256,1]")).find("class 256 outside 1..255"), std::string::npos);
    EXPECT_NE(fault(with("[1,2,1]", "[0,2,1]")).find("class 0 outside 1..255"), std::string::npos);
    EXPECT_NE(fault(with("[1,2,1]", "[1,2]")).find("a tile has 3 chains and 2 classes"), std::string::npos);
    EXPECT_NE(fault(with(R"("width":4096,"height":2048,"depth":1,"chains":[7)",
                         R"("width":0,"height":2048,"depth":1,"chains":[7)"))
                  .find("a tile has 3 chains and 3 classes"),
              std::string::npos);
    EXPECT_EQ(fault(good), "");
}
