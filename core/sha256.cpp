#include "core/digest.hpp"
#include "core/errors.hpp"

#include <openssl/evp.h>

#include <fstream>
#include <vector>

namespace tigerlod {

struct Sha256::Context {
    EVP_MD_CTX* ctx = nullptr;
};

Sha256::Sha256() : m_ctx(new Context)
{
    m_ctx->ctx = EVP_MD_CTX_new();
    if (m_ctx->ctx == nullptr || EVP_DigestInit_ex(m_ctx->ctx, EVP_sha256(), nullptr) != 1) {
        EVP_MD_CTX_free(m_ctx->ctx);
        delete m_ctx;
        throw environment_error("SHA-256: OpenSSL cannot make a digest context");
    }
}

Sha256::~Sha256()
{
    EVP_MD_CTX_free(m_ctx->ctx);
    delete m_ctx;
}

void Sha256::update(std::span<const std::byte> data)
{
    m_ok = m_ok && EVP_DigestUpdate(m_ctx->ctx, data.data(), data.size()) == 1;
}

std::string Sha256::hex_digest()
{
    unsigned char md[EVP_MAX_MD_SIZE];
    unsigned int n = 0;
    if (!m_ok || EVP_DigestFinal_ex(m_ctx->ctx, md, &n) != 1 || n != 32) {
        throw environment_error("SHA-256: OpenSSL failed");
    }
    static constexpr char hex[] = "0123456789abcdef";
    std::string out(64, '0');
    for (unsigned int i = 0; i < n; ++i) {
        out[2 * i] = hex[md[i] >> 4];
        out[2 * i + 1] = hex[md[i] & 15];
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
