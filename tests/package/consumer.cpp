// Opens a Data Tree through the installed reader runtime and walks a view:
// consumer TREE prints the front size and the number of drawable payloads.
#include <reader/reader.hpp>

#include <cstdio>

int main(int argc, char** argv)
{
    if (argc != 2) {
        return 2;
    }
    std::string error;
    const auto tree = tigerlod::reader::Tree::open(argv[1], error);
    if (!tree) {
        std::printf("error: %s\n", error.c_str());
        return 1;
    }
    const auto& root = tree->skeleton().nodes[0].box;
    tigerlod::reader::View view{(root.min_x + double(root.max_x)) / 2, (root.min_y + double(root.max_y)) / 2,
                                (root.max_x - double(root.min_x)) / 256, 512, 512};
    tigerlod::reader::Streamer streamer(tree, {});
    const auto front = streamer.set_view(view);
    streamer.wait_front(std::chrono::seconds(10));
    size_t drawn = 0;
    for (const auto& d : streamer.resident_front()) {
        drawn += d.geometry != nullptr;
    }
    std::printf("front %zu drawn %zu\n", front.size(), drawn);
    return drawn == front.size() && drawn > 0 ? 0 : 1;
}
