#pragma once
/// @file digest.hpp
/// Checksums: CRC-32 (IEEE 802.3, as zlib) for file sections, SHA-256
/// (FIPS 180-4) for the input digests recorded in manifests.

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>

namespace tigerlod {

/// CRC-32 of `data`, continuing from `crc` (0 to start).
uint32_t crc32(std::span<const std::byte> data, uint32_t crc = 0) noexcept;

/// Incremental SHA-256.
class Sha256 {
  public:
    Sha256() noexcept;
    void update(std::span<const std::byte> data) noexcept;
    /// Finish and return the digest as 64 lowercase hex digits.
    std::string hex_digest();

  private:
    void block(const uint8_t* p) noexcept;
    std::array<uint32_t, 8> m_h{};
    std::array<uint8_t, 64> m_buf{};
    size_t m_buf_len = 0;
    uint64_t m_total = 0;
}; // class Sha256

/// SHA-256 of a whole file as hex. Throws environment_error if it cannot be read.
std::string sha256_file(const std::filesystem::path& path);

} // namespace tigerlod
