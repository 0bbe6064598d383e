#include "core/digest.hpp"

#include <zlib.h>

namespace tigerlod {

uint32_t crc32(std::span<const std::byte> data, uint32_t crc) noexcept
{
    return static_cast<uint32_t>(::crc32_z(crc, reinterpret_cast<const Bytef*>(data.data()), data.size()));
}

} // namespace tigerlod
