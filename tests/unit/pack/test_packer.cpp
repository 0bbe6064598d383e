// tigerlod-pack on a hand-made map of three levels: the border level of each
// chain in each node's table (Data Tree 2.1).
#include "formats/chains/chain_store.hpp"
#include "reader/reader.hpp"
#include "stages/pack/packer.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <map>

namespace fs = std::filesystem;
using namespace tigerlod;
using chains::ChainStore;
using Pts = std::vector<GridPoint>;

namespace {

struct Store {
    ChainStore s;
    Store(uint32_t level, const std::string& level_name, const std::string& partition)
    {
        s.level_index = level;
        s.level_count = 3;
        s.level_name = level_name;
        s.partition = partition;
        s.projection.grid_m = 1.0;
        s.halo_m = 1000;
    }
    Store& chain(uint64_t id, const std::string& left, const std::string& right, const Pts& pts, bool halo = false)
    {
        const uint32_t flags =
            (pts.front() == pts.back() ? chains::chain_closed : 0U) | (halo ? chains::chain_halo : 0U);
        s.add_chain({id, s.intern(left), s.intern(right), s.intern(""), flags, 0, 0}, pts);
        return *this;
    }
    Store& unit(const std::string& code, GridPoint p, uint32_t kind = chains::constraint_internal)
    {
        s.constraints.push_back({s.intern(code), kind, p});
        return *this;
    }
};

/// Each store as an original (DIR/orig) and as its one simplification at
/// 10 m (DIR/simp/eps-10m), canonical, as ingest and simplify write them;
/// `level_count` 0 keeps each store's own.
void write_stores(const fs::path& dir, const std::vector<Store>& stores, uint32_t level_count = 0)
{
    for (const auto& st : stores) {
        ChainStore s = st.s;
        s.level_count = level_count > 0 ? level_count : s.level_count;
        s.canonicalize();
        fs::create_directories(dir / "orig" / s.level_name);
        chains::write(dir / "orig" / s.level_name / (s.partition + ".tlc"), s);
        s.eps_m = 10;
        fs::create_directories(dir / "simp" / "eps-10m" / s.level_name);
        chains::write(dir / "simp" / "eps-10m" / s.level_name / (s.partition + ".tlc"), s);
    }
}

} // namespace

// Two states side by side (S1 west of x = 200, S2 east), S1 of counties
// 11 (x < 100) and 12, S2 one county 21; county 11 of tracts 11a (y < 50)
// and 11b, county 12 one tract 12a, county 21 one tract 21a. In county 11's
// tract map, the 11a|11b border is a tract border (level 2), its outline
// toward 12 a county border (1); in county 12's, its outline toward 21 a
// state border (0), as is every chain on the map's outer edge.
TEST(Pack, EachChainCarriesItsBorderLevel)
{
    const fs::path dir = fs::temp_directory_path() / ("tigerlod-packer-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    std::vector<Store> stores;
    stores.emplace_back(0, "state", "all");
    stores.back()
        .chain(1, "S1", "", {{200, 0}, {0, 0}, {0, 100}, {200, 100}})
        .chain(2, "", "S2", {{200, 0}, {400, 0}, {400, 100}, {200, 100}})
        .chain(3, "S2", "S1", {{200, 0}, {200, 100}})
        .unit("S1", {100, 50})
        .unit("S2", {300, 50});
    stores.emplace_back(1, "county", "S1");
    stores.back()
        .chain(10, "11", "", {{100, 0}, {0, 0}, {0, 100}, {100, 100}})
        .chain(11, "12", "", {{100, 100}, {200, 100}})
        .chain(12, "", "12", {{100, 0}, {200, 0}})
        .chain(13, "12", "11", {{100, 0}, {100, 100}})
        .chain(14, "21", "12", {{200, 0}, {200, 100}})
        .chain(20, "", "21", {{200, 0}, {400, 0}, {400, 100}, {200, 100}}, true)
        .unit("11", {50, 50})
        .unit("12", {150, 50})
        .unit("21", {300, 50}, chains::constraint_neighbour);
    stores.emplace_back(1, "county", "S2");
    stores.back()
        .chain(20, "", "21", {{200, 0}, {400, 0}, {400, 100}, {200, 100}})
        .chain(14, "21", "12", {{200, 0}, {200, 100}}, true)
        .unit("21", {300, 50})
        .unit("12", {150, 50}, chains::constraint_neighbour);
    stores.emplace_back(2, "tract", "11");
    stores.back()
        .chain(100, "11a", "", {{100, 0}, {0, 0}, {0, 50}})
        .chain(101, "", "11b", {{100, 100}, {0, 100}, {0, 50}})
        .chain(102, "11b", "11a", {{0, 50}, {100, 50}})
        .chain(103, "12a", "11a", {{100, 0}, {100, 50}})
        .chain(104, "12a", "11b", {{100, 50}, {100, 100}})
        .unit("11a", {50, 25})
        .unit("11b", {50, 75})
        .unit("12a", {150, 50}, chains::constraint_neighbour);
    stores.emplace_back(2, "tract", "12");
    stores.back()
        .chain(110, "12a", "", {{100, 100}, {200, 100}})
        .chain(111, "", "12a", {{100, 0}, {200, 0}})
        .chain(112, "21a", "12a", {{200, 0}, {200, 100}})
        .chain(103, "12a", "11a", {{100, 0}, {100, 50}}, true)
        .chain(104, "12a", "11b", {{100, 50}, {100, 100}}, true)
        .unit("12a", {150, 50})
        .unit("11a", {50, 25}, chains::constraint_neighbour)
        .unit("11b", {50, 75}, chains::constraint_neighbour)
        .unit("21a", {300, 50}, chains::constraint_neighbour);
    stores.emplace_back(2, "tract", "21");
    stores.back()
        .chain(120, "", "21a", {{200, 0}, {400, 0}, {400, 100}, {200, 100}})
        .chain(112, "21a", "12a", {{200, 0}, {200, 100}}, true)
        .unit("21a", {300, 50})
        .unit("12a", {150, 50}, chains::constraint_neighbour);
    write_stores(dir, stores);
    const pack::PackedTree tree = pack::build_tree(dir / "orig", dir / "simp", {});
    fs::remove_all(dir);
    const auto& sk = tree.skeleton;
    // Node code -> (chain id -> border level).
    std::map<std::string, std::map<uint64_t, uint32_t>> levels;
    for (const auto& n : sk.nodes) {
        const auto& ref = n.table;
        const std::string& bytes = tree.tile_bytes[ref.tile];
        const auto table =
            datatree::decode_table(std::as_bytes(std::span(bytes.data() + ref.offset, ref.size)), "table");
        for (const auto& c : table.chains) {
            levels[sk.strings[n.code]][c.id] = c.border_level();
            EXPECT_EQ(c.flags & ~datatree::border_level_mask, 0U) << "chain " << c.id << ": open, no problem";
        }
    }
    using M = std::map<uint64_t, uint32_t>;
    EXPECT_EQ(levels[""], (M{{1, 0}, {2, 0}, {3, 0}}));                             // the root: states
    EXPECT_EQ(levels["S1"], (M{{10, 0}, {11, 0}, {12, 0}, {13, 1}, {14, 0}}));      // S1's counties
    EXPECT_EQ(levels["S2"], (M{{14, 0}, {20, 0}}));                                 // S2's county
    EXPECT_EQ(levels["11"], (M{{100, 0}, {101, 0}, {102, 2}, {103, 1}, {104, 1}})); // 11's tracts
    EXPECT_EQ(levels["12"], (M{{103, 1}, {104, 1}, {110, 0}, {111, 0}, {112, 0}}));
    EXPECT_EQ(levels["21"], (M{{112, 0}, {120, 0}}));
}

// reader::main_extent frames where most of the map is: 100 units in a
// 1000-unit square and one far out (a territory), each a node with a map of
// one unit inside it. The boxes of the nodes whose centres lie in the
// central 95 % of the finest units' points frame it: the far one is left
// out. With 10 units in the square there are too few to tell: the root's box.
TEST(Pack, TheMainExtentLeavesAFarUnitOut)
{
    const fs::path dir = fs::temp_directory_path() / ("tigerlod-extent-" + std::to_string(::getpid()));
    for (const size_t units : {size_t{100}, size_t{10}}) {
        fs::remove_all(dir);
        std::vector<Store> stores;
        stores.emplace_back(0, "region", "all");
        auto square = [](GridPoint c) {
            return Pts{{c.x - 40, c.y - 40},
                       {c.x + 40, c.y - 40},
                       {c.x + 40, c.y + 40},
                       {c.x - 40, c.y + 40},
                       {c.x - 40, c.y - 40}};
        };
        for (size_t i = 0; i <= units; ++i) {
            const std::string code = i == units ? "far" : "u" + std::to_string(i);
            const GridPoint c = i == units ? GridPoint{100000, 50000}
                                           : GridPoint{int32_t(100 + 100 * (i % 10)), int32_t(100 + 100 * (i / 10))};
            stores.front().chain(1 + i, code, "", square(c)).unit(code, c);
            stores.emplace_back(1, "place", code);
            stores.back().chain(1000 + i, code + "a", "", square(c)).unit(code + "a", c);
        }
        write_stores(dir, stores, 2);
        pack::write_tree(dir / "tree", pack::build_tree(dir / "orig", dir / "simp", {}), "{}\n");
        std::string error;
        const auto tree = reader::Tree::open(dir / "tree", error);
        ASSERT_TRUE(tree) << error;
        const datatree::Box root = tree->skeleton().nodes.front().box;
        const datatree::Box e = reader::main_extent(*tree);
        if (units == 100) {
            EXPECT_EQ(e, (datatree::Box{60, 60, 1040, 1040})); // the 100 squares, whole
            EXPECT_EQ(root, (datatree::Box{60, 60, 100040, 50040}));
        } else {
            EXPECT_EQ(e, root);
        }
    }
    fs::remove_all(dir);
}
