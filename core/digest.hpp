#pragma once
/// @file digest.hpp
/// Checksums: CRC-32 (IEEE 802.3) for file sections, from zlib; SHA-256
/// (FIPS 180-4) for content names and the input digests recorded in
/// manifests, from OpenSSL (which uses the CPU's SHA extensions where it has
/// them).

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>

namespace tigerlod {

/// CRC-32 of `data`, continuing from `crc` (0 to start), as zlib's crc32.
uint32_t crc32(std::span<const std::byte> data, uint32_t crc = 0) noexcept;

/// Incremental SHA-256 (tigerlod_core; the reader's tigerlod_base has CRC-32
/// only).
class Sha256 {
  public:
    /// Throws environment_error if OpenSSL cannot make a digest context.
    Sha256();
    Sha256(const Sha256&) = delete;
    Sha256& operator=(const Sha256&) = delete;
    ~Sha256();
    void update(std::span<const std::byte> data);
    /// Finish and return the digest as 64 lowercase hex digits. Throws
    /// environment_error if OpenSSL failed on the way.
    std::string hex_digest();

  private:
    struct Context;
    Context* m_ctx;
    bool m_ok = true;
}; // class Sha256

/// SHA-256 of a whole file as hex. Throws environment_error if it cannot be read.
std::string sha256_file(const std::filesystem::path& path);

} // namespace tigerlod
