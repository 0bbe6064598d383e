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

/// Incremental SHA-256. Blocks go through the CPU's SHA extensions where it
/// has them (x86-64 SHA-NI, checked at run time), else through portable C++;
/// both give the same digest.
class Sha256 {
  public:
    enum class Engine {
        automatic, ///< the SHA extensions if this CPU has them
        portable   ///< always the portable code (tests compare the two)
    };
    explicit Sha256(Engine engine = Engine::automatic) noexcept;
    void update(std::span<const std::byte> data) noexcept;
    /// Finish and return the digest as 64 lowercase hex digits.
    std::string hex_digest();
    /// Whether Engine::automatic uses the SHA extensions on this CPU.
    static bool hardware_accelerated() noexcept;

  private:
    using Blocks = void (*)(uint32_t* state, const uint8_t* p, size_t count) noexcept;
    Blocks m_blocks;
    std::array<uint32_t, 8> m_h{};
    std::array<uint8_t, 64> m_buf{};
    size_t m_buf_len = 0;
    uint64_t m_total = 0;
}; // class Sha256

/// SHA-256 of a whole file as hex. Throws environment_error if it cannot be read.
std::string sha256_file(const std::filesystem::path& path);

} // namespace tigerlod
