#include "core/digest.hpp"

#include "core/errors.hpp"

#include <algorithm>
#include <bit>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <vector>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <cpuid.h>
#include <immintrin.h>
#define TIGERLOD_SHA_NI 1
#else
#define TIGERLOD_SHA_NI 0
#endif

namespace tigerlod {

namespace {

/// Tables for CRC-32 eight bytes at a time ("slicing-by-8"): table k maps a byte
/// to its contribution k bytes before the end of an 8-byte block.
constexpr std::array<std::array<uint32_t, 256>, 8> make_crc_tables() noexcept
{
    std::array<std::array<uint32_t, 256>, 8> t{};
    for (uint32_t i = 0; i < 256; ++i) {
        uint32_t c = i;
        for (int k = 0; k < 8; ++k) {
            c = (c & 1U) ? 0xEDB88320U ^ (c >> 1) : c >> 1;
        }
        t[0][i] = c;
    }
    for (uint32_t i = 0; i < 256; ++i) {
        for (size_t k = 1; k < 8; ++k) {
            t[k][i] = (t[k - 1][i] >> 8) ^ t[0][t[k - 1][i] & 0xFFU];
        }
    }
    return t;
}

constexpr auto crc_tables = make_crc_tables();

constexpr std::array<uint32_t, 64> sha_k = {
    0x428a2f98, 0x71374491, 0xb5c0fbcf, 0xe9b5dba5, 0x3956c25b, 0x59f111f1, 0x923f82a4, 0xab1c5ed5,
    0xd807aa98, 0x12835b01, 0x243185be, 0x550c7dc3, 0x72be5d74, 0x80deb1fe, 0x9bdc06a7, 0xc19bf174,
    0xe49b69c1, 0xefbe4786, 0x0fc19dc6, 0x240ca1cc, 0x2de92c6f, 0x4a7484aa, 0x5cb0a9dc, 0x76f988da,
    0x983e5152, 0xa831c66d, 0xb00327c8, 0xbf597fc7, 0xc6e00bf3, 0xd5a79147, 0x06ca6351, 0x14292967,
    0x27b70a85, 0x2e1b2138, 0x4d2c6dfc, 0x53380d13, 0x650a7354, 0x766a0abb, 0x81c2c92e, 0x92722c85,
    0xa2bfe8a1, 0xa81a664b, 0xc24b8b70, 0xc76c51a3, 0xd192e819, 0xd6990624, 0xf40e3585, 0x106aa070,
    0x19a4c116, 0x1e376c08, 0x2748774c, 0x34b0bcb5, 0x391c0cb3, 0x4ed8aa4a, 0x5b9cca4f, 0x682e6ff3,
    0x748f82ee, 0x78a5636f, 0x84c87814, 0x8cc70208, 0x90befffa, 0xa4506ceb, 0xbef9a3f7, 0xc67178f2};

} // namespace

uint32_t crc32(std::span<const std::byte> data, uint32_t crc) noexcept
{
    crc = ~crc;
    const auto* p = reinterpret_cast<const uint8_t*>(data.data());
    size_t n = data.size();
    const auto& t = crc_tables;
    while (n >= 8) {
        const uint32_t lo = crc ^ (uint32_t{p[0]} | uint32_t{p[1]} << 8 | uint32_t{p[2]} << 16 | uint32_t{p[3]} << 24);
        crc = t[7][lo & 0xFFU] ^ t[6][(lo >> 8) & 0xFFU] ^ t[5][(lo >> 16) & 0xFFU] ^ t[4][lo >> 24] ^ t[3][p[4]] ^
              t[2][p[5]] ^ t[1][p[6]] ^ t[0][p[7]];
        p += 8;
        n -= 8;
    }
    while (n-- > 0) {
        crc = t[0][(crc ^ *p++) & 0xFFU] ^ (crc >> 8);
    }
    return ~crc;
}

namespace {

/// SHA-256 compression of `count` 64-byte blocks, portable C++.
void blocks_portable(uint32_t* state, const uint8_t* p, size_t count) noexcept
{
    for (; count > 0; --count, p += 64) {
        std::array<uint32_t, 64> w;
        for (size_t i = 0; i < 16; ++i) {
            w[i] = (uint32_t{p[4 * i]} << 24) | (uint32_t{p[4 * i + 1]} << 16) | (uint32_t{p[4 * i + 2]} << 8) |
                   uint32_t{p[4 * i + 3]};
        }
        for (size_t i = 16; i < 64; ++i) {
            const uint32_t s0 = std::rotr(w[i - 15], 7) ^ std::rotr(w[i - 15], 18) ^ (w[i - 15] >> 3);
            const uint32_t s1 = std::rotr(w[i - 2], 17) ^ std::rotr(w[i - 2], 19) ^ (w[i - 2] >> 10);
            w[i] = w[i - 16] + s0 + w[i - 7] + s1;
        }
        uint32_t a = state[0], b = state[1], c = state[2], d = state[3];
        uint32_t e = state[4], f = state[5], g = state[6], h = state[7];
        for (size_t i = 0; i < 64; ++i) {
            const uint32_t s1 = std::rotr(e, 6) ^ std::rotr(e, 11) ^ std::rotr(e, 25);
            const uint32_t ch = (e & f) ^ (~e & g);
            const uint32_t t1 = h + s1 + ch + sha_k[i] + w[i];
            const uint32_t s0 = std::rotr(a, 2) ^ std::rotr(a, 13) ^ std::rotr(a, 22);
            const uint32_t maj = (a & b) ^ (a & c) ^ (b & c);
            const uint32_t t2 = s0 + maj;
            h = g;
            g = f;
            f = e;
            e = d + t1;
            d = c;
            c = b;
            b = a;
            a = t1 + t2;
        }
        state[0] += a;
        state[1] += b;
        state[2] += c;
        state[3] += d;
        state[4] += e;
        state[5] += f;
        state[6] += g;
        state[7] += h;
    }
}

#if TIGERLOD_SHA_NI
/// SHA-256 compression with the x86 SHA extensions. The instructions keep the
/// state as two vectors, "ABEF" and "CDGH" (A in the highest lane), and do two
/// rounds at a time; the message schedule is four words a step.
__attribute__((target("sha,sse4.1,ssse3"))) void blocks_sha_ni(uint32_t* state, const uint8_t* p, size_t count) noexcept
{
    const __m128i byte_swap = _mm_set_epi64x(0x0c0d0e0f08090a0bLL, 0x0405060700010203LL);
    auto* st = reinterpret_cast<__m128i*>(state);
    const __m128i dcba = _mm_shuffle_epi32(_mm_loadu_si128(st), 0xB1);     // lanes B A D C
    const __m128i hgfe = _mm_shuffle_epi32(_mm_loadu_si128(st + 1), 0x1B); // lanes H G F E
    __m128i abef = _mm_alignr_epi8(dcba, hgfe, 8);                         // lanes F E B A
    __m128i cdgh = _mm_blend_epi16(hgfe, dcba, 0xF0);                      // lanes H G D C
    for (; count > 0; --count, p += 64) {
        const __m128i abef0 = abef, cdgh0 = cdgh;
        __m128i w[4]; // NOLINT: words 4g..4g+3 of the schedule, at g mod 4
        for (size_t i = 0; i < 4; ++i) {
            w[i] = _mm_shuffle_epi8(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p + 16 * i)), byte_swap);
        }
        for (size_t g = 0; g < 16; ++g) {
            if (g >= 4) {
                const __m128i w4 = w[g & 3U], w3 = w[(g + 1) & 3U], w2 = w[(g + 2) & 3U], w1 = w[(g + 3) & 3U];
                w[g & 3U] =
                    _mm_sha256msg2_epu32(_mm_add_epi32(_mm_sha256msg1_epu32(w4, w3), _mm_alignr_epi8(w1, w2, 4)), w1);
            }
            __m128i wk = _mm_add_epi32(w[g & 3U], _mm_loadu_si128(reinterpret_cast<const __m128i*>(&sha_k[4 * g])));
            cdgh = _mm_sha256rnds2_epu32(cdgh, abef, wk); // two rounds: the new ABEF; the old is now CDGH
            wk = _mm_shuffle_epi32(wk, 0x0E);
            abef = _mm_sha256rnds2_epu32(abef, cdgh, wk);
        }
        abef = _mm_add_epi32(abef, abef0);
        cdgh = _mm_add_epi32(cdgh, cdgh0);
    }
    const __m128i abef_r = _mm_shuffle_epi32(abef, 0x1B); // lanes A B E F
    const __m128i cdgh_r = _mm_shuffle_epi32(cdgh, 0xB1); // lanes G H C D
    _mm_storeu_si128(st, _mm_blend_epi16(abef_r, cdgh_r, 0xF0));
    _mm_storeu_si128(st + 1, _mm_alignr_epi8(cdgh_r, abef_r, 8));
}

bool cpu_has_sha_ni() noexcept
{
    unsigned a = 0, b = 0, c = 0, d = 0;
    if (__get_cpuid(1, &a, &b, &c, &d) == 0 || (c & bit_SSE4_1) == 0 || (c & bit_SSSE3) == 0) {
        return false;
    }
    if (__get_cpuid_count(7, 0, &a, &b, &c, &d) == 0) {
        return false;
    }
    return (b & (1U << 29)) != 0; // SHA
}
#endif

} // namespace

bool Sha256::hardware_accelerated() noexcept
{
#if TIGERLOD_SHA_NI
    static const bool has = cpu_has_sha_ni();
    return has;
#else
    return false;
#endif
}

Sha256::Sha256(Engine engine) noexcept
    : m_blocks(blocks_portable), m_h{0x6a09e667, 0xbb67ae85, 0x3c6ef372, 0xa54ff53a,
                                     0x510e527f, 0x9b05688c, 0x1f83d9ab, 0x5be0cd19}
{
#if TIGERLOD_SHA_NI
    if (engine == Engine::automatic && hardware_accelerated()) {
        m_blocks = blocks_sha_ni;
    }
#else
    (void)engine;
#endif
}

void Sha256::update(std::span<const std::byte> data) noexcept
{
    m_total += data.size();
    const auto* p = reinterpret_cast<const uint8_t*>(data.data());
    size_t n = data.size();
    if (m_buf_len > 0) {
        const size_t take = std::min(n, m_buf.size() - m_buf_len);
        std::memcpy(m_buf.data() + m_buf_len, p, take);
        m_buf_len += take;
        p += take;
        n -= take;
        if (m_buf_len < m_buf.size()) {
            return;
        }
        m_blocks(m_h.data(), m_buf.data(), 1);
        m_buf_len = 0;
    }
    if (n >= 64) {
        m_blocks(m_h.data(), p, n / 64);
        p += n / 64 * 64;
        n %= 64;
    }
    if (n > 0) {
        std::memcpy(m_buf.data(), p, n);
        m_buf_len = n;
    }
}

std::string Sha256::hex_digest()
{
    const uint64_t bits = m_total * 8;
    const std::byte pad{0x80};
    update(std::span(&pad, 1));
    const std::byte zero{0};
    while (m_buf_len != 56) {
        update(std::span(&zero, 1));
    }
    for (int i = 7; i >= 0; --i) {
        m_buf[m_buf_len++] = static_cast<uint8_t>(bits >> (8 * i));
    }
    m_blocks(m_h.data(), m_buf.data(), 1);
    m_buf_len = 0;
    std::string out;
    char hex[9];
    for (uint32_t v : m_h) {
        std::snprintf(hex, sizeof hex, "%08x", v);
        out += hex;
    }
    return out;
}

std::string sha256_file(const std::filesystem::path& path)
{
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        throw environment_error(path.string() + ": cannot open for reading");
    }
    Sha256 sha;
    std::vector<char> buf(1 << 20);
    while (in) {
        in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
        const auto n = static_cast<size_t>(in.gcount());
        sha.update(std::as_bytes(std::span(buf.data(), n)));
    }
    if (in.bad()) {
        throw environment_error(path.string() + ": read failed");
    }
    return sha.hex_digest();
}

} // namespace tigerlod
