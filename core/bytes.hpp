#pragma once
/// @file bytes.hpp
/// Little-endian byte writing and bounds-checked reading for the binary
/// formats (chain stores, the Data Tree). Fixed-width values and LEB128
/// varints; every read checks the bytes left and fails with a message that
/// names the file, the field and the byte offset.

#include "core/errors.hpp"
#include "core/geometry.hpp"

#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

namespace tigerlod {

/// Signed to unsigned, small magnitudes to small values: 0, -1, 1, -2 ... ->
/// 0, 1, 2, 3 ...
constexpr uint64_t zigzag(int64_t v) noexcept
{
    return (static_cast<uint64_t>(v) << 1) ^ static_cast<uint64_t>(v >> 63);
}
constexpr int64_t unzigzag(uint64_t u) noexcept
{
    return static_cast<int64_t>((u >> 1) ^ (~(u & 1) + 1));
}

static_assert(std::endian::native == std::endian::little, "the formats are little-endian, as every target of ours");

/// Appends values to a byte string.
class ByteWriter {
  public:
    template <class T> void put(T v)
    {
        static_assert(std::is_trivially_copyable_v<T>);
        char b[sizeof(T)];
        std::memcpy(b, &v, sizeof(T));
        m_out.append(b, sizeof(T));
    }
    /// Points as consecutive little-endian (i32 x, i32 y): GridPoint's own layout.
    void put_points(std::span<const GridPoint> pts)
    {
        static_assert(sizeof(GridPoint) == 8);
        m_out.append(reinterpret_cast<const char*>(pts.data()), pts.size_bytes());
    }
    /// A u32 byte length, then the bytes.
    void put_str(std::string_view s)
    {
        put(static_cast<uint32_t>(s.size()));
        m_out.append(s);
    }
    /// Unsigned LEB128.
    void put_varint(uint64_t v)
    {
        while (v >= 0x80) {
            m_out.push_back(static_cast<char>((v & 0x7F) | 0x80));
            v >>= 7;
        }
        m_out.push_back(static_cast<char>(v));
    }
    /// Signed values as zigzag LEB128.
    void put_svarint(int64_t v) { put_varint(zigzag(v)); }
    /// A varint byte length, then the bytes.
    void put_vstr(std::string_view s)
    {
        put_varint(s.size());
        m_out.append(s);
    }
    void put_bytes(std::string_view s) { m_out.append(s); }
    void reserve(size_t n) { m_out.reserve(n); }
    size_t size() const noexcept { return m_out.size(); }
    std::string& bytes() noexcept { return m_out; }

  private:
    std::string m_out;
}; // class ByteWriter

/// Reads values from a byte span; throws format_error naming `name` on any fault.
class ByteReader {
  public:
    ByteReader(std::span<const std::byte> bytes, const std::string& name) : m_bytes(bytes), m_name(name) {}
    [[noreturn]] void fail(const std::string& what) const
    {
        throw format_error(m_name + ": " + what + " (at byte " + std::to_string(m_pos) + ")");
    }
    size_t left() const noexcept { return m_bytes.size() - m_pos; }
    size_t pos() const noexcept { return m_pos; }
    void need(size_t n, const char* what) const
    {
        if (left() < n) {
            fail(std::string("truncated in ") + what);
        }
    }
    template <class T> T get(const char* what)
    {
        need(sizeof(T), what);
        T v;
        std::memcpy(&v, m_bytes.data() + m_pos, sizeof(T));
        m_pos += sizeof(T);
        return v;
    }
    std::string get_str(const char* what)
    {
        const auto n = get<uint32_t>(what);
        return take_string(n, what);
    }
    uint64_t get_varint(const char* what)
    {
        uint64_t v = 0;
        for (int shift = 0; shift < 64; shift += 7) {
            const auto b = static_cast<uint8_t>(get<uint8_t>(what));
            v |= static_cast<uint64_t>(b & 0x7F) << shift;
            if ((b & 0x80) == 0) {
                if (shift == 63 && b > 1) {
                    break;
                }
                return v;
            }
        }
        fail(std::string("varint overflow in ") + what);
    }
    /// A varint that must not exceed `max`.
    uint64_t get_varint(const char* what, uint64_t max)
    {
        const uint64_t v = get_varint(what);
        if (v > max) {
            fail(std::string(what) + " " + std::to_string(v) + " exceeds " + std::to_string(max));
        }
        return v;
    }
    int64_t get_svarint(const char* what) { return unzigzag(get_varint(what)); }
    std::string get_vstr(const char* what)
    {
        const uint64_t n = get_varint(what);
        need(n, what);
        return take_string(static_cast<size_t>(n), what);
    }
    /// The next `n` bytes, without copying.
    std::span<const std::byte> get_bytes(size_t n, const char* what)
    {
        need(n, what);
        auto s = m_bytes.subspan(m_pos, n);
        m_pos += n;
        return s;
    }
    /// A u32 count of records of at least `record_size` bytes each, checked against the bytes left.
    uint32_t get_count(size_t record_size, const char* what)
    {
        const auto n = get<uint32_t>(what);
        check_count(n, record_size, what);
        return n;
    }
    /// Fails unless `n` records of at least `record_size` bytes fit in the bytes left.
    void check_count(uint64_t n, size_t record_size, const char* what) const
    {
        if (record_size != 0 && n > left() / record_size) {
            fail(std::string("count ") + std::to_string(n) + " of " + what + " exceeds the data");
        }
    }
    /// Append `n` points (little-endian i32 pairs, GridPoint's layout).
    void get_points(uint32_t n, std::vector<GridPoint>& out)
    {
        need(static_cast<size_t>(n) * sizeof(GridPoint), "chain points");
        const size_t old = out.size();
        out.resize(old + n);
        std::memcpy(out.data() + old, m_bytes.data() + m_pos, static_cast<size_t>(n) * sizeof(GridPoint));
        m_pos += static_cast<size_t>(n) * sizeof(GridPoint);
    }

  private:
    std::string take_string(size_t n, const char* what)
    {
        need(n, what);
        std::string s(reinterpret_cast<const char*>(m_bytes.data() + m_pos), n);
        m_pos += n;
        return s;
    }
    std::span<const std::byte> m_bytes;
    const std::string& m_name;
    size_t m_pos = 0;
}; // class ByteReader

} // namespace tigerlod
