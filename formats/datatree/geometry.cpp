// Geometry payloads: chain point counts and shared-endpoint references in a
// varint side table, one symbol per new point in a Draco point cloud
// (sequential encoding, lossless INT32, so Draco neither reorders nor moves a
// point), each difference's low bits in a packed bit stream beside it.

#include "formats/datatree/datatree.hpp"

#include "core/bytes.hpp"
#include "core/errors.hpp"

#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/point_cloud/point_cloud_builder.h>

#include <algorithm>
#include <bit>
#include <unordered_map>

namespace tigerlod::datatree {

namespace {

constexpr uint8_t kind_geometry = 2;

/// How a payload's differences are coded (see SPEC.md). Each new point's
/// difference (dx, dy) loses its `low` lowest bits to a packed bit stream;
/// what is left, zigzagged, is zx and zy; when both are below 2^joint the
/// point goes to Draco as one symbol 1 + (zx << joint | zy), else as the
/// symbol 0 with dx and dy in the escape stream.
///
/// Why: Draco's integer decoder spends most of its time reading, one bit at
/// a time, the raw bits below each value's leading one (perf: 70% of a
/// decode), plus a fixed cost per value. The lowest bits of a chain's
/// differences are close to uniform, so no entropy coder gains on them: a
/// bit stream that decodes a word at a time holds them for the same bytes.
/// Draco then codes one small symbol per point, which its table coder
/// decodes fast, and coding x and y jointly gains what they share.
struct Split {
    int low = 0;   ///< bits of each difference in the low-bit stream
    int joint = 1; ///< bits of zx and of zy in a joint symbol
};

/// Symbols stay at or below 2^(2 max_joint_bits), inside the 18 bits Draco
/// codes with its table coder.
constexpr int max_joint_bits = 8;
constexpr int max_low_bits = 30;
constexpr uint32_t escape_symbol = 0;

/// The low bits are chosen so that 99% of the points' zigzagged high parts
/// fit in `target_joint_bits` bits; `joint` is then the smallest width that
/// takes in 99% of the points (at most that). Measured on the Floyd and
/// 20-state tract trees (pack_bench, decode speed against bytes per vertex,
/// 3 .. 8): 6 decodes twice as fast as putting every bit in Draco, for 0.2%
/// more bytes; 7 decodes 1.4 times slower than 6, and 5 or less adds bytes.
constexpr int target_joint_bits = 6;

Split split_for(const std::vector<int64_t>& diffs)
{
    Split s;
    const size_t n = diffs.size() / 2;
    if (n == 0) {
        return s;
    }
    // Per point, the larger magnitude of its two differences.
    std::vector<uint64_t> m(n);
    for (size_t i = 0; i < n; ++i) {
        const int64_t dx = diffs[2 * i], dy = diffs[2 * i + 1];
        m[i] = static_cast<uint64_t>(std::max(dx < 0 ? -dx : dx, dy < 0 ? -dy : dy));
    }
    const size_t at = n - 1 - n / 100;
    std::nth_element(m.begin(), m.begin() + static_cast<std::ptrdiff_t>(at), m.end());
    // Zigzag adds one bit.
    s.low = std::clamp(static_cast<int>(std::bit_width(m[at])) + 1 - target_joint_bits, 0, max_low_bits);
    // Per point, the wider of its two zigzagged high parts.
    for (size_t i = 0; i < n; ++i) {
        m[i] = std::max(zigzag(diffs[2 * i] >> s.low), zigzag(diffs[2 * i + 1] >> s.low));
    }
    std::nth_element(m.begin(), m.begin() + static_cast<std::ptrdiff_t>(at), m.end());
    s.joint = std::clamp(static_cast<int>(std::bit_width(m[at])), 1, max_joint_bits);
    return s;
}

/// Draco with the settings of the format: one symbol per point.
std::string draco_encode(const int32_t* symbols, uint32_t npoints, int speed)
{
    draco::PointCloudBuilder builder;
    builder.Start(npoints);
    const int att = builder.AddAttribute(draco::GeometryAttribute::GENERIC, 1, draco::DT_INT32);
    builder.SetAttributeValuesForAllPoints(att, symbols, sizeof(int32_t));
    const auto pc = builder.Finalize(false); // never deduplicate: order and count are the format
    draco::Encoder encoder;
    encoder.SetEncodingMethod(draco::POINT_CLOUD_SEQUENTIAL_ENCODING);
    encoder.SetSpeedOptions(speed, speed);
    // The values are already differences along the chains: no second prediction.
    encoder.SetAttributePredictionScheme(draco::GeometryAttribute::GENERIC, draco::PREDICTION_NONE);
    draco::EncoderBuffer buffer;
    const draco::Status st = encoder.EncodePointCloudToBuffer(*pc, &buffer);
    if (!st.ok()) {
        throw input_error(std::string("geometry payload: Draco encoding failed: ") + st.error_msg());
    }
    return {buffer.data(), buffer.size()};
}

/// The first bytes of every Draco buffer of ours: header (magic, version,
/// point cloud, sequential, no flags), the point count (bytes 11-14, which
/// differ), one attributes decoder with one 1 x INT32 generic attribute,
/// integer coding, no prediction. Decoding checks them before Draco sees the
/// buffer: Draco allocates what a damaged count asks for (the fuzzer made it
/// take 2 GiB), so the count must be the one the side table gives.
constexpr size_t draco_prefix_size = 24;
constexpr size_t draco_count_at = 11;

const std::string& draco_prefix()
{
    static const std::string prefix = [] {
        const int32_t one[1] = {0};
        return draco_encode(one, 1, 0).substr(0, draco_prefix_size);
    }();
    return prefix;
}

/// Reads `bits`-bit values, least significant first, from a packed stream.
/// Past its end it reads zeros and remembers it.
class LowBits {
  public:
    LowBits(std::span<const std::byte> bytes, int bits) noexcept
        : m_p(reinterpret_cast<const uint8_t*>(bytes.data())), m_end(m_p + bytes.size()), m_bits(bits),
          m_mask((uint64_t{1} << bits) - 1)
    {
    }
    uint32_t next() noexcept
    {
        if (m_n < m_bits) [[unlikely]] {
            refill();
        }
        const auto v = static_cast<uint32_t>(m_acc & m_mask);
        m_acc >>= m_bits;
        m_n -= m_bits;
        return v;
    }
    /// True when every byte was read, none past the end, and the bits after
    /// the last value are zero padding of less than a byte.
    bool used_up() const noexcept { return !m_short && m_p == m_end && m_acc == 0 && m_n < 8; }

  private:
    void refill() noexcept
    {
        // Whole bytes while they fit in the 64-bit accumulator.
        while (m_n <= 56 && m_p < m_end) {
            m_acc |= uint64_t{*m_p++} << m_n;
            m_n += 8;
        }
        if (m_n < m_bits) {
            m_short = true;
            m_n = m_bits; // zeros
        }
    }
    const uint8_t* m_p;
    const uint8_t* m_end;
    int m_bits;
    uint64_t m_mask;
    uint64_t m_acc = 0;
    int m_n = 0;
    bool m_short = false;
};

struct PointHash {
    size_t operator()(GridPoint p) const noexcept
    {
        return std::hash<uint64_t>{}((static_cast<uint64_t>(static_cast<uint32_t>(p.x)) << 32) ^
                                     static_cast<uint32_t>(p.y));
    }
};

} // namespace

std::string encode_geometry(const Geometry& g, GridPoint origin, const GeometryOptions& options)
{
    // The side table: per chain its count and, for each end, 0 (a new point)
    // or the distance back to the earlier output point it repeats.
    ByteWriter side;
    // New points, x y interleaved, each as its difference from the point
    // output before it (the origin for the first), so a chain whose start is
    // a reference still continues from that start.
    std::vector<int64_t> diffs;
    diffs.reserve(g.points.size() * 2);
    std::unordered_map<GridPoint, uint32_t, PointHash> ends;
    GridPoint prev = origin;
    auto add = [&](GridPoint p) {
        const int64_t dx = int64_t{p.x} - prev.x, dy = int64_t{p.y} - prev.y;
        if (int64_t{p.x} < origin.x || int64_t{p.y} < origin.y || dx < INT32_MIN || dx > INT32_MAX || dy < INT32_MIN ||
            dy > INT32_MAX) {
            throw input_error("geometry payload: point outside the node box");
        }
        diffs.push_back(dx);
        diffs.push_back(dy);
    };
    auto endpoint = [&](GridPoint p, uint32_t at) {
        const auto [it, inserted] = ends.try_emplace(p, at);
        if (inserted) {
            side.put_varint(0);
            add(p);
        } else {
            side.put_varint(at - it->second);
        }
        prev = p;
    };
    for (size_t i = 0; i < g.chain_count(); ++i) {
        const auto c = g.chain(i);
        if (c.size() < 2) {
            throw input_error("geometry payload: chain with fewer than 2 points");
        }
        side.put_varint(c.size());
        const auto first = g.offsets[i];
        endpoint(c.front(), first);
        for (size_t k = 1; k + 1 < c.size(); ++k) {
            add(c[k]);
            prev = c[k];
        }
        endpoint(c.back(), static_cast<uint32_t>(first + c.size() - 1));
    }
    const Split split = split_for(diffs);
    const uint64_t joint_limit = uint64_t{1} << split.joint;
    const uint32_t low_mask = (uint32_t{1} << split.low) - 1;
    const auto npoints = static_cast<uint32_t>(diffs.size() / 2);
    std::vector<int32_t> symbols;
    symbols.reserve(npoints);
    ByteWriter escapes;
    std::string lows;
    lows.reserve((diffs.size() * static_cast<size_t>(split.low) + 7) / 8);
    uint64_t acc = 0; // bits not yet written, the oldest lowest
    int nacc = 0;
    auto put_low = [&](int64_t d) {
        acc |= uint64_t{static_cast<uint32_t>(d) & low_mask} << nacc;
        for (nacc += split.low; nacc >= 8; nacc -= 8) {
            lows.push_back(static_cast<char>(acc & 0xFF));
            acc >>= 8;
        }
    };
    for (uint32_t i = 0; i < npoints; ++i) {
        const int64_t dx = diffs[2 * i], dy = diffs[2 * i + 1];
        const uint64_t zx = zigzag(dx >> split.low), zy = zigzag(dy >> split.low); // arithmetic shift: floor
        uint64_t symbol = escape_symbol;
        if (zx < joint_limit && zy < joint_limit) {
            symbol = 1 + (zx << split.joint | zy);
            put_low(dx);
            put_low(dy);
        } else {
            escapes.put_svarint(dx);
            escapes.put_svarint(dy);
        }
        // Draco zigzags what it is given: give it the value it maps to `symbol`.
        symbols.push_back(static_cast<int32_t>(unzigzag(symbol)));
    }
    if (nacc > 0) {
        lows.push_back(static_cast<char>(acc & 0xFF));
    }
    std::string draco_bytes;
    if (npoints > 0) {
        draco_bytes = draco_encode(symbols.data(), npoints, options.draco_speed);
    }
    ByteWriter w;
    w.put(kind_geometry);
    w.put_varint(g.chain_count());
    w.put_varint(npoints);
    w.put_bytes(side.bytes());
    w.put_varint(static_cast<uint64_t>(split.low));
    w.put_varint(static_cast<uint64_t>(split.joint));
    w.put_varint(escapes.size());
    w.put_bytes(escapes.bytes());
    w.put_varint(lows.size());
    w.put_bytes(lows);
    w.put_varint(draco_bytes.size());
    w.put_bytes(draco_bytes);
    return std::move(w.bytes());
}

Geometry decode_geometry(std::span<const std::byte> bytes, GridPoint origin, uint64_t expect_chains,
                         uint64_t expect_vertices, const std::string& name)
{
    ByteReader r(bytes, name);
    const std::string& r_name = name;
    if (r.get<uint8_t>("payload kind") != kind_geometry) {
        r.fail("not a geometry payload");
    }
    const uint64_t nchains = r.get_varint("chain count");
    if (nchains != expect_chains) {
        r.fail("has " + std::to_string(nchains) + " chains, the skeleton says " + std::to_string(expect_chains));
    }
    const uint64_t nfresh = r.get_varint("point count", expect_vertices);
    r.check_count(nchains, 3, "chains");
    // The side table, checked in full before any allocation sized by it.
    struct ChainRefs {
        uint32_t count, start, end;
    };
    std::vector<ChainRefs> refs(static_cast<size_t>(nchains));
    uint64_t total = 0, needed = 0;
    for (auto& c : refs) {
        c.count = static_cast<uint32_t>(r.get_varint("chain point count", expect_vertices));
        if (c.count < 2) {
            r.fail("chain with fewer than 2 points");
        }
        c.start = static_cast<uint32_t>(r.get_varint("endpoint reference", UINT32_MAX));
        c.end = static_cast<uint32_t>(r.get_varint("endpoint reference", UINT32_MAX));
        // A reference points back into what is already decoded.
        if (c.start > total || c.end > total + c.count - 1) {
            r.fail("endpoint reference before the first point");
        }
        needed += c.count - 2 + (c.start == 0) + (c.end == 0);
        total += c.count;
    }
    if (total != expect_vertices) {
        r.fail("has " + std::to_string(total) + " points, the skeleton says " + std::to_string(expect_vertices));
    }
    if (needed != nfresh) {
        r.fail("side table needs " + std::to_string(needed) + " new points, the payload has " + std::to_string(nfresh));
    }
    const auto low_bits = static_cast<int>(r.get_varint("low bits", max_low_bits));
    const auto joint_bits = static_cast<int>(r.get_varint("joint bits", max_joint_bits));
    if (joint_bits < 1) {
        r.fail("joint bits 0");
    }
    const uint64_t escape_size = r.get_varint("escape stream size");
    const auto escape_bytes =
        r.get_bytes(static_cast<size_t>(std::min<uint64_t>(escape_size, r.left() + 1)), "escape stream");
    const uint64_t low_size = r.get_varint("low-bit stream size");
    const auto low_bytes =
        r.get_bytes(static_cast<size_t>(std::min<uint64_t>(low_size, r.left() + 1)), "low-bit stream");
    const uint64_t draco_size = r.get_varint("Draco size");
    const auto draco_bytes =
        r.get_bytes(static_cast<size_t>(std::min<uint64_t>(draco_size, r.left() + 1)), "Draco data");
    if (r.left() != 0) {
        r.fail("trailing bytes after the Draco data");
    }
    // The points' symbols, as Draco's bytes.
    std::unique_ptr<draco::PointCloud> pc;
    std::vector<int32_t> copied;
    const std::byte* symbol_bytes = nullptr;
    if (nfresh > 0) {
        const std::string& prefix = draco_prefix();
        const auto* db = reinterpret_cast<const char*>(draco_bytes.data());
        uint32_t count = 0;
        if (draco_bytes.size() > draco_prefix_size) {
            std::memcpy(&count, db + draco_count_at, sizeof count);
        }
        if (draco_bytes.size() <= draco_prefix_size || std::memcmp(db, prefix.data(), draco_count_at) != 0 ||
            std::memcmp(db + draco_count_at + 4, prefix.data() + draco_count_at + 4,
                        draco_prefix_size - draco_count_at - 4) != 0) {
            r.fail("Draco data does not start as this format's does");
        }
        if (count != nfresh) {
            r.fail("Draco data has " + std::to_string(count) + " points, the side table " + std::to_string(nfresh));
        }
        draco::DecoderBuffer buffer;
        buffer.Init(reinterpret_cast<const char*>(draco_bytes.data()), draco_bytes.size());
        draco::Decoder decoder;
        auto decoded = decoder.DecodePointCloudFromBuffer(&buffer);
        if (!decoded.ok()) {
            r.fail(std::string("Draco decoding failed: ") + decoded.status().error_msg());
        }
        pc = std::move(decoded).value();
        if (pc->num_points() != nfresh || pc->num_attributes() != 1) {
            r.fail("Draco point cloud has " + std::to_string(pc->num_points()) + " points and " +
                   std::to_string(pc->num_attributes()) + " attributes, expected " + std::to_string(nfresh) + " and 1");
        }
        const draco::PointAttribute* att = pc->attribute(0);
        if (att->data_type() != draco::DT_INT32 || att->num_components() != 1 || att->byte_stride() != 4) {
            r.fail("Draco attribute is not 1 x INT32");
        }
        if (att->is_mapping_identity() && att->size() == nfresh) {
            symbol_bytes = reinterpret_cast<const std::byte*>(att->GetAddress(draco::AttributeValueIndex(0)));
        } else {
            copied.resize(static_cast<size_t>(nfresh));
            for (uint32_t p = 0; p < nfresh; ++p) {
                const auto v = att->mapped_index(draco::PointIndex(p));
                if (v.value() >= att->size()) {
                    r.fail("Draco attribute index out of range");
                }
                att->GetValue(v, copied.data() + p);
            }
            symbol_bytes = reinterpret_cast<const std::byte*>(copied.data());
        }
    } else if (draco_size != 0) {
        r.fail("Draco data without points");
    }
    // One pass: each point's difference from its symbol and low bits, or
    // from the escape stream; then the point from the one before it.
    ByteReader er(escape_bytes, r_name);
    LowBits lows(low_bytes, low_bits);
    const std::byte* next_symbol = symbol_bytes;
    const uint32_t joint_mask = (uint32_t{1} << joint_bits) - 1;
    const uint64_t symbol_limit = uint64_t{1} << (2 * joint_bits); // symbol - 1 is below it
    // The escape symbol or a damaged one: off the hot path.
    auto escaped = [&](uint32_t symbol) __attribute__((noinline))
    {
        if (symbol != escape_symbol) {
            r.fail("symbol " + std::to_string(symbol) + " above 2^" + std::to_string(2 * joint_bits));
        }
        // Modular, as the points: a corrupt payload gives wrong points, never undefined behaviour.
        const auto dx = static_cast<uint32_t>(static_cast<uint64_t>(er.get_svarint("escape stream")));
        const auto dy = static_cast<uint32_t>(static_cast<uint64_t>(er.get_svarint("escape stream")));
        return std::pair{dx, dy};
    };
    auto high = [&](uint32_t z) {
        return static_cast<uint32_t>(unzigzag(z)) << low_bits; // times 2^low, modular
    };
    Geometry g;
    g.offsets.reserve(static_cast<size_t>(nchains) + 1);
    g.points.resize(static_cast<size_t>(total));
    GridPoint* const out = g.points.data();
    GridPoint prev = origin;
    auto take = [&]() {
        int32_t v;
        std::memcpy(&v, next_symbol, sizeof v);
        next_symbol += sizeof v;
        const auto symbol = static_cast<uint32_t>(zigzag(v)); // as Draco maps signed values
        uint32_t dx, dy;
        if (uint64_t{symbol - 1U} < symbol_limit) [[likely]] {
            const uint32_t s = symbol - 1;
            dx = high(s >> joint_bits);
            dx += lows.next();
            dy = high(s & joint_mask);
            dy += lows.next();
        } else {
            std::tie(dx, dy) = escaped(symbol);
        }
        return GridPoint{static_cast<int32_t>(static_cast<uint32_t>(prev.x) + dx),
                         static_cast<int32_t>(static_cast<uint32_t>(prev.y) + dy)};
    };
    size_t at = 0;
    for (const auto& c : refs) {
        prev = out[at] = c.start == 0 ? take() : out[at - c.start];
        ++at;
        for (uint32_t k = 1; k + 1 < c.count; ++k) {
            prev = out[at++] = take();
        }
        prev = out[at] = c.end == 0 ? take() : out[at - c.end];
        ++at;
        g.offsets.push_back(static_cast<uint32_t>(at));
    }
    if (er.left() != 0) {
        r.fail("escape stream longer than its markers");
    }
    if (!lows.used_up()) {
        r.fail("low-bit stream of " + std::to_string(low_bytes.size()) + " bytes does not match its points");
    }
    return g;
}

} // namespace tigerlod::datatree
