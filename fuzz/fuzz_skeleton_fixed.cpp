// libFuzzer target: the skeleton parser past its checksum. The header's file
// size and the CRC trailer are set to what the input's bytes need before
// parsing, so mutations reach the body (counts, strings, nodes, tiles,
// payload references) instead of stopping at "checksum mismatch". Any input
// either fails with format_error or decodes to a skeleton that encodes back
// to the same bytes.
#include "core/errors.hpp"
#include "fuzz/fixed_checksum.hpp"
#include "formats/datatree/datatree.hpp"

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    if (size < 28) {
        return 0;
    }
    const std::string bytes = tigerlod::fuzz::with_size_and_crc(data, size);
    try {
        const auto s = tigerlod::datatree::decode_skeleton(std::as_bytes(std::span(bytes.data(), size)), "fuzz");
        // The format is canonical: a valid skeleton re-encodes exactly, but
        // for its minor version (bytes 10-11: readers accept any, writers
        // write theirs) and so its CRC.
        std::string back = tigerlod::datatree::encode_skeleton(s);
        if (back.size() != bytes.size() || back.compare(0, 10, bytes, 0, 10) != 0 ||
            back.compare(12, size - 16, bytes, 12, size - 16) != 0) {
            __builtin_trap();
        }
    } catch (const tigerlod::format_error&) {
    }
    return 0;
}
