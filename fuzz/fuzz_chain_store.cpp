// libFuzzer target: the chain store reader (formats/chains/SPEC.md), past
// its checksum: the header's file size and the CRC trailer are set to what
// the input's bytes need before parsing. Any input either fails with
// format_error or decodes to a store whose encoding is a fixed point
// (encode, decode, encode gives the same bytes).
#include "core/digest.hpp"
#include "core/errors.hpp"
#include "formats/chains/chain_store.hpp"

#include <cstddef>
#include <cstdint>
#include <string>

using namespace tigerlod;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    if (size < 28) {
        return 0;
    }
    std::string bytes(reinterpret_cast<const char*>(data), size);
    const uint64_t file_size = size;
    for (int i = 0; i < 8; ++i) {
        bytes[16 + i] = static_cast<char>((file_size >> (8 * i)) & 0xFF);
    }
    const uint32_t crc = crc32(std::as_bytes(std::span(bytes.data(), size - 4)));
    for (int i = 0; i < 4; ++i) {
        bytes[size - 4 + i] = static_cast<char>((crc >> (8 * i)) & 0xFF);
    }
    try {
        const auto store = chains::decode(std::as_bytes(std::span(bytes.data(), size)), "fuzz");
        const std::string once = chains::encode(store);
        const auto again = chains::decode(std::as_bytes(std::span(once.data(), once.size())), "again");
        if (chains::encode(again) != once) {
            __builtin_trap();
        }
    } catch (const format_error&) {
    }
    return 0;
}
