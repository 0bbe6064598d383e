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

namespace {
std::string sha(tigerlod::Sha256::Engine engine, std::span<const std::byte> data, size_t piece)
{
    tigerlod::Sha256 h(engine);
    for (size_t at = 0; at < data.size(); at += piece) {
        h.update(data.subspan(at, std::min(piece, data.size() - at)));
    }
    return h.hex_digest();
}
} // namespace

TEST(Digest, Sha256EnginesAgree)
{
    using Engine = tigerlod::Sha256::Engine;
    if (!tigerlod::Sha256::hardware_accelerated()) {
        std::printf("note: this CPU has no SHA extensions; both engines are the portable code\n");
    }
    // The FIPS 180-4 long example through both engines, in uneven pieces.
    const std::string million(1000000, 'a');
    for (Engine e : {Engine::automatic, Engine::portable}) {
        for (size_t piece : {size_t{1000000}, size_t{64}, size_t{63}, size_t{4097}}) {
            EXPECT_EQ(sha(e, bytes(million), piece),
                      "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
        }
    }
    // Every length around the block and padding boundaries, on varied bytes.
    std::string data(300, '\0');
    uint32_t x = 12345;
    for (char& c : data) {
        x = x * 1103515245U + 12345U;
        c = static_cast<char>(x >> 24);
    }
    for (size_t n = 0; n <= data.size(); ++n) {
        const auto view = bytes(data).first(n);
        const std::string expect = sha(Engine::portable, view, n == 0 ? 1 : n);
        EXPECT_EQ(sha(Engine::automatic, view, n == 0 ? 1 : n), expect) << n;
        EXPECT_EQ(sha(Engine::automatic, view, 7), expect) << n;
    }
}
