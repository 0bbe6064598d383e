// Writes the synthetic Data Tree of synthetic_tree.hpp to a folder:
// make_test_tree DIR [DEPTH]
#include "synthetic_tree.hpp"

#include <cstdlib>

int main(int argc, char** argv)
{
    if (argc < 2) {
        return 2;
    }
    const uint32_t depth = argc > 2 ? static_cast<uint32_t>(std::atoi(argv[2])) : 2;
    tigerlod::testing::make_synthetic_tree(depth).write(argv[1]);
    return 0;
}
