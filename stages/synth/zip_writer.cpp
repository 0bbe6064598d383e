#include "stages/synth/zip_writer.hpp"

#include <libdeflate.h>

#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace tigerlod::synth {

namespace {

// 2020-12-18 00:00, in MS-DOS form, on every member.
constexpr uint16_t dos_date = ((2020 - 1980) << 9) | (12 << 5) | 18;
constexpr uint16_t dos_time = 0;

void put16(std::string& out, uint32_t v)
{
    out += char(v & 0xff);
    out += char((v >> 8) & 0xff);
}

void put32(std::string& out, uint32_t v)
{
    put16(out, v & 0xffff);
    put16(out, v >> 16);
}

uint32_t checked(size_t n, const std::string& what)
{
    if (n > std::numeric_limits<uint32_t>::max()) {
        throw std::runtime_error("zip: " + what + " passes 4 GiB, which needs Zip64");
    }
    return uint32_t(n);
}

/// This thread's compressor at one level, kept from member to member (its
/// tables are hundreds of KiB), and a buffer for its output.
struct Deflater {
    int level = -1;
    libdeflate_compressor* compressor = nullptr;
    std::vector<char> packed;
    Deflater() = default;
    Deflater(const Deflater&) = delete;
    Deflater& operator=(const Deflater&) = delete;
    ~Deflater() { libdeflate_free_compressor(compressor); }

    /// `data` deflated; valid until the next call on this thread.
    std::string_view deflate(int at_level, std::string_view data, const std::string& name)
    {
        if (compressor == nullptr || level != at_level) {
            libdeflate_free_compressor(compressor);
            compressor = libdeflate_alloc_compressor(at_level);
            level = at_level;
            if (compressor == nullptr) {
                throw std::runtime_error("zip: no deflate compressor at level " + std::to_string(at_level));
            }
        }
        const size_t bound = libdeflate_deflate_compress_bound(compressor, data.size());
        if (packed.size() < bound) {
            packed.resize(bound);
        }
        const size_t n =
            libdeflate_deflate_compress(compressor, data.data(), data.size(), packed.data(), packed.size());
        if (n == 0 && !data.empty()) {
            throw std::runtime_error("zip: deflate failed for " + name);
        }
        return {packed.data(), n};
    }
};

} // namespace

void ZipWriter::add(const std::string& name, std::string_view data)
{
    thread_local Deflater deflater;
    Member m;
    m.name = name;
    m.size = checked(data.size(), name);
    m.crc = libdeflate_crc32(0, data.data(), data.size());
    const std::string_view packed = deflater.deflate(m_level, data, name);
    m.compressed = checked(packed.size(), name);
    m.offset = checked(m_out.size(), "the archive");
    put32(m_out, 0x04034b50);
    put16(m_out, 20); // version needed: deflate
    put16(m_out, 0);  // flags
    put16(m_out, 8);  // deflate
    put16(m_out, dos_time);
    put16(m_out, dos_date);
    put32(m_out, m.crc);
    put32(m_out, m.compressed);
    put32(m_out, m.size);
    put16(m_out, uint32_t(name.size()));
    put16(m_out, 0);
    m_out += name;
    m_out += packed;
    m_members.push_back(std::move(m));
}

std::string ZipWriter::finish()
{
    const uint32_t directory = checked(m_out.size(), "the archive");
    for (const auto& m : m_members) {
        put32(m_out, 0x02014b50);
        put16(m_out, 20); // made by: MS-DOS, 2.0
        put16(m_out, 20);
        put16(m_out, 0);
        put16(m_out, 8);
        put16(m_out, dos_time);
        put16(m_out, dos_date);
        put32(m_out, m.crc);
        put32(m_out, m.compressed);
        put32(m_out, m.size);
        put16(m_out, uint32_t(m.name.size()));
        put16(m_out, 0); // extra
        put16(m_out, 0); // comment
        put16(m_out, 0); // disk
        put16(m_out, 0); // internal attributes
        put32(m_out, 0); // external attributes
        put32(m_out, m.offset);
        m_out += m.name;
    }
    const uint32_t size = checked(m_out.size() - directory, "the archive");
    put32(m_out, 0x06054b50);
    put16(m_out, 0);
    put16(m_out, 0);
    put16(m_out, uint32_t(m_members.size()));
    put16(m_out, uint32_t(m_members.size()));
    put32(m_out, size);
    put32(m_out, directory);
    put16(m_out, 0);
    return std::move(m_out);
}

} // namespace tigerlod::synth
