// Writes seed corpora for the fuzzers from a synthetic Data Tree:
// make_seeds SKELETON_DIR PAYLOAD_DIR
#include "../tests/support/synthetic_tree.hpp"

#include <cstring>
#include <fstream>

using namespace tigerlod;

int main(int argc, char** argv)
{
    if (argc != 3) {
        return 2;
    }
    const std::filesystem::path skel = argv[1], pay = argv[2];
    std::filesystem::create_directories(skel);
    std::filesystem::create_directories(pay);
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
    return 0;
}
