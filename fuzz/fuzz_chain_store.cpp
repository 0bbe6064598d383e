// libFuzzer target: the chain store reader (formats/chains/SPEC.md), past
// its checksum: the header's file size and the CRC trailer are set to what
// the input's bytes need before parsing. Any input either fails with
// format_error or decodes to a store whose encoding is a fixed point
// (encode, decode, encode gives the same bytes).
#include "core/errors.hpp"
#include "fuzz/fixed_checksum.hpp"
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
    const std::string bytes = tigerlod::fuzz::with_size_and_crc(data, size);
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
