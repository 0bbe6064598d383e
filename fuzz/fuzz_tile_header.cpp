// libFuzzer target: the tile header check. Bytes 0-7 are the file size the
// reader saw; the rest is the start of the file. Any input either fails with
// format_error or is a header of this major version for exactly that size.
#include "core/errors.hpp"
#include "formats/datatree/datatree.hpp"

#include <cstddef>
#include <cstdint>
#include <cstring>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    if (size < 8) {
        return 0;
    }
    uint64_t file_size = 0;
    std::memcpy(&file_size, data, 8);
    const auto bytes = std::as_bytes(std::span(data + 8, size - 8));
    try {
        tigerlod::datatree::check_tile_header(bytes, file_size, "fuzz");
        const std::string want = tigerlod::datatree::tile_header(file_size);
        // Accepted: the magic, major version, flags and size are those a
        // writer gives that size (the minor version may differ).
        // Layout: magic 0-7, major 8-9, minor 10-11, flags 12-15, size 16-23.
        if (bytes.size() < want.size() || std::memcmp(bytes.data(), want.data(), 10) != 0 ||
            std::memcmp(bytes.data() + 12, want.data() + 12, 12) != 0) {
            __builtin_trap();
        }
    } catch (const tigerlod::format_error&) {
    }
    return 0;
}
