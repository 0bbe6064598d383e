#include "core/digest.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
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

TEST(Digest, Sha256InPiecesEqualsWhole)
{
    // A megabyte and a bit, fed whole and in uneven pieces.
    std::string data((1 << 20) + 77, '\0');
    for (size_t i = 0; i < data.size(); ++i) {
        data[i] = static_cast<char>((i * 2654435761U) >> 13);
    }
    tigerlod::Sha256 whole;
    whole.update(bytes(data));
    const std::string want = whole.hex_digest();
    for (const size_t piece : {1U, 63U, 64U, 65U, 4093U}) {
        tigerlod::Sha256 h;
        for (size_t at = 0; at < data.size(); at += piece) {
            h.update(bytes(data.substr(at, std::min(piece, data.size() - at))));
        }
        EXPECT_EQ(h.hex_digest(), want) << piece;
    }
    // The FIPS 180-4 long example, in uneven pieces.
    const std::string million(1000000, 'a');
    for (const size_t piece : {size_t{1000000}, size_t{63}, size_t{4097}}) {
        tigerlod::Sha256 h;
        for (size_t at = 0; at < million.size(); at += piece) {
            h.update(bytes(million).subspan(at, std::min(piece, million.size() - at)));
        }
        EXPECT_EQ(h.hex_digest(), "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0") << piece;
    }
}
