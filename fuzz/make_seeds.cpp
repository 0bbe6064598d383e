// Writes seed corpora for the fuzzers from a synthetic Data Tree and small
// chain stores: make_seeds SKELETON_DIR PAYLOAD_DIR CHAINS_DIR TILE_DIR
#include "../tests/support/synthetic_tree.hpp"
#include "formats/chains/chain_store.hpp"

#include <cstring>
#include <fstream>

using namespace tigerlod;

int main(int argc, char** argv)
{
    if (argc != 5) {
        return 2;
    }
    const std::filesystem::path skel = argv[1], pay = argv[2], chain_dir = argv[3], tile_dir = argv[4];
    for (const auto& d : {skel, pay, chain_dir, tile_dir}) {
        std::filesystem::create_directories(d);
    }
    // Chain stores: two units sharing a border, a closed ring, a halo chain,
    // junctions and every kind of constraint point; then the same store cut
    // down to one chain.
    for (int variant = 0; variant < 2; ++variant) {
        chains::ChainStore st;
        st.level_index = 2;
        st.level_count = 4;
        st.level_name = "tract";
        st.partition = "51063";
        st.halo_m = 1000;
        st.eps_m = variant == 0 ? 0.0 : 16.0;
        const uint32_t a = st.intern("51063020100"), b = st.intern("51063020200"), c = st.intern("51067010100");
        const uint32_t cls = st.intern("S1400");
        const std::vector<GridPoint> border = {{0, 0}, {50, 10}, {100, 0}};
        const std::vector<GridPoint> outer = {{100, 0}, {100, 100}, {0, 100}, {0, 0}};
        const std::vector<GridPoint> ring = {{40, 40}, {60, 40}, {60, 60}, {40, 60}, {40, 40}};
        const std::vector<GridPoint> halo = {{100, 0}, {200, 0}, {200, 100}, {100, 100}};
        st.add_chain({11, a, b, cls, 0, 0, 0}, border);
        if (variant == 0) {
            st.add_chain({12, a, 0, 0, 0, 0, 0}, outer);
            st.add_chain({13, b, a, cls, chains::chain_closed, 0, 0}, ring);
            st.add_chain({14, c, 0, 0, chains::chain_halo, 0, 0}, halo);
            st.junctions.push_back({(uint64_t{180000000} << 32) | 90000000U, {0, 0}, 3});
            st.junctions.push_back({(uint64_t{180000001} << 32) | 90000000U, {100, 0}, 3});
            st.constraints.push_back({a, chains::constraint_internal, {20, 80}});
            st.constraints.push_back({b, chains::constraint_internal, {50, 50}});
            st.constraints.push_back({a, chains::constraint_user, {30, 70}});
            st.constraints.push_back({c, chains::constraint_neighbour, {150, 50}});
        }
        st.canonicalize();
        std::ofstream(chain_dir / ("store" + std::to_string(variant)), std::ios::binary) << chains::encode(st);
    }
    for (const uint64_t size : {uint64_t{24}, uint64_t{4096}, uint64_t{1} << 40}) {
        std::string seed(8, '\0');
        std::memcpy(seed.data(), &size, 8);
        std::ofstream(tile_dir / ("size" + std::to_string(size)), std::ios::binary)
            << seed << datatree::tile_header(size);
    }
    for (uint32_t depth = 0; depth < 3; ++depth) {
        const auto t = testing::make_synthetic_tree(depth, 1 << (12 + 4 * depth), depth + 1);
        std::ofstream(skel / ("depth" + std::to_string(depth)), std::ios::binary)
            << datatree::encode_skeleton(t.skeleton);
        for (size_t n = 0; n < std::min<size_t>(t.skeleton.nodes.size(), 5); ++n) {
            const auto& node = t.skeleton.nodes[n];
            for (size_t k = 0; k < t.payloads[n].size(); ++k) {
                std::string prefix(13, '\0');
                const uint64_t vertices = k == 0 ? 0 : node.lods[k - 1].vertices;
                prefix[0] = k == 0 ? 1 : 0;
                prefix[1] = static_cast<char>(node.chains & 0xFF);
                prefix[2] = static_cast<char>(node.chains >> 8);
                prefix[3] = static_cast<char>(vertices & 0xFF);
                prefix[4] = static_cast<char>(vertices >> 8);
                std::memcpy(prefix.data() + 5, &node.box.min_x, 4);
                std::memcpy(prefix.data() + 9, &node.box.min_y, 4);
                std::ofstream(pay / ("d" + std::to_string(depth) + "n" + std::to_string(n) + "p" + std::to_string(k)),
                              std::ios::binary)
                    << prefix << t.payloads[n][k];
            }
        }
    }
    // A units payload's body (prefix byte 2), with text, integer and real fields.
    datatree::UnitTable units;
    units.fields = {{"NAMELSAD", 0}, {"ALAND", 1}, {"SHARE", 2}};
    units.units = {{"51063", "Floyd", {120, -40}, {"Floyd County", "988", "0.25"}},
                   {"51067", "", {-7, 3}, {"", "", "1e-3"}}};
    const std::string bytes = datatree::encode_units(units, {0, 0});
    std::string prefix(13, '\0');
    prefix[0] = 2;
    std::ofstream(pay / "units", std::ios::binary) << prefix << bytes.substr(datatree::units_head_size);
    return 0;
}
