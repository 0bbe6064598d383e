#pragma once
// For fuzz targets that go past a file's checksum: the input with its
// header's file size (u64 at offset 16, as both the chain store and the Data
// Tree skeleton have it) and its CRC-32 trailer set to what its bytes need.
#include "core/digest.hpp"

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

namespace tigerlod::fuzz {

/// `data` (at least 28 bytes) with size and CRC fixed.
inline std::string with_size_and_crc(const uint8_t* data, size_t size)
{
    std::string bytes(reinterpret_cast<const char*>(data), size);
    const uint64_t file_size = size;
    for (int i = 0; i < 8; ++i) {
        bytes[16 + i] = static_cast<char>((file_size >> (8 * i)) & 0xFF);
    }
    const uint32_t crc = crc32(std::as_bytes(std::span(bytes.data(), size - 4)));
    for (int i = 0; i < 4; ++i) {
        bytes[size - 4 + i] = static_cast<char>((crc >> (8 * i)) & 0xFF);
    }
    return bytes;
}

} // namespace tigerlod::fuzz
