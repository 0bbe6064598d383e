#include "core/digest.hpp"

#include <gtest/gtest.h>

#include <string>

namespace {
std::span<const std::byte> bytes(const std::string& s)
{
    return std::as_bytes(std::span(s.data(), s.size()));
}
} // namespace

TEST(Digest, Crc32KnownValues)
{
    EXPECT_EQ(tigerlod::crc32(bytes("")), 0U);
    EXPECT_EQ(tigerlod::crc32(bytes("123456789")), 0xCBF43926U);
    // Incremental equals whole.
    EXPECT_EQ(tigerlod::crc32(bytes("6789"), tigerlod::crc32(bytes("12345"))), 0xCBF43926U);
}

TEST(Digest, Sha256KnownValues)
{
    tigerlod::Sha256 empty;
    EXPECT_EQ(empty.hex_digest(), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
    tigerlod::Sha256 abc;
    abc.update(bytes("abc"));
    EXPECT_EQ(abc.hex_digest(), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    // Two blocks, split at an awkward place.
    tigerlod::Sha256 two;
    const std::string s = "abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq";
    two.update(bytes(s.substr(0, 13)));
    two.update(bytes(s.substr(13)));
    EXPECT_EQ(two.hex_digest(), "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
}
