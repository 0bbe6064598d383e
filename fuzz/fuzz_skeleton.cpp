// libFuzzer target: the skeleton parser. Any input either fails with
// format_error or decodes to a skeleton that encodes back to the same bytes.
#include "core/errors.hpp"
#include "formats/datatree/datatree.hpp"

#include <cstddef>
#include <cstdint>
#include <cstring>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    const auto bytes = std::as_bytes(std::span(data, size));
    try {
        const auto s = tigerlod::datatree::decode_skeleton(bytes, "fuzz");
        const std::string back = tigerlod::datatree::encode_skeleton(s);
        if (back.size() != size || std::memcmp(back.data(), data, size) != 0) {
            __builtin_trap(); // the format is canonical: a valid skeleton re-encodes exactly
        }
    } catch (const tigerlod::format_error&) {
    }
    return 0;
}
