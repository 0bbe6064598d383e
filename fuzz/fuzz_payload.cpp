// libFuzzer target: the payload decoders. Byte 0 picks the chain table (odd),
// a units payload's body (2 mod 4, bytes 5-12 its origin) or a geometry
// payload (0 mod 4); for geometry, bytes 1-4 give the chain and
// vertex counts the skeleton would expect and bytes 5-12 the origin. Any input
// either fails with format_error or decodes to something that encodes and
// decodes back to itself.
#include "core/errors.hpp"
#include "formats/datatree/datatree.hpp"

#include <cstddef>
#include <cstdint>
#include <cstring>

using namespace tigerlod;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    if (size < 13) {
        return 0;
    }
    const auto payload = std::as_bytes(std::span(data + 13, size - 13));
    try {
        if (data[0] & 1) {
            const auto t = datatree::decode_table(payload, "fuzz");
            const std::string back = datatree::encode_table(t);
            if (datatree::decode_table(std::as_bytes(std::span(back.data(), back.size())), "again") != t) {
                __builtin_trap();
            }
        } else if ((data[0] & 3) == 2) {
            GridPoint origin;
            std::memcpy(&origin.x, data + 5, 4);
            std::memcpy(&origin.y, data + 9, 4);
            const auto t = datatree::decode_units(payload, origin, "fuzz");
            const std::string back = datatree::encode_units(t, origin);
            const auto whole = std::as_bytes(std::span(back.data(), back.size()));
            const auto [body_size, crc] = datatree::units_body(whole, "again");
            if (body_size != back.size() - datatree::units_head_size ||
                datatree::decode_units(whole.subspan(datatree::units_head_size), origin, "again") != t) {
                __builtin_trap();
            }
            (void)crc;
        } else {
            const uint64_t chains = data[1] | (uint64_t{data[2]} << 8);
            const uint64_t vertices = data[3] | (uint64_t{data[4]} << 8);
            GridPoint origin;
            std::memcpy(&origin.x, data + 5, 4);
            std::memcpy(&origin.y, data + 9, 4);
            const auto g = datatree::decode_geometry(payload, origin, chains, vertices, "fuzz");
            // Decoded points may wrap around; re-encoding needs them above the origin.
            bool above = true;
            for (const auto& p : g.points) {
                above = above && p.x >= origin.x && p.y >= origin.y;
            }
            if (above) {
                const std::string back = datatree::encode_geometry(g, origin);
                if (datatree::decode_geometry(std::as_bytes(std::span(back.data(), back.size())), origin, chains,
                                              vertices, "again") != g) {
                    __builtin_trap();
                }
            }
        }
    } catch (const format_error&) {
    } catch (const input_error&) {
        // encode_geometry refuses points too far from the origin to store.
    }
    return 0;
}
