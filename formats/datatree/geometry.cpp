// Geometry payloads: chain point counts and shared-endpoint references in a
// varint side table, the points themselves in a Draco point cloud (sequential
// encoding, lossless INT32, so Draco neither reorders nor moves a point).

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

/// Draco's integer encoder spends time and memory linear in the largest value
/// it is given (a 2^28 value takes seconds, measured here), and codes small
/// values well. So each payload picks an escape bound 2^b, b in
/// [min_escape_bits, max_escape_bits]: the smallest power of two above 99% of
/// its differences. Differences below it in magnitude go to Draco as they
/// are; for any other Draco gets the marker 2^b and the difference goes, as a
/// zigzag varint, to an escape stream beside it. The worst encode stays near
/// 6 ms a payload (2^20), measured here.
constexpr int min_escape_bits = 12;
constexpr int max_escape_bits = 20;

int escape_bits_for(std::vector<uint64_t> magnitudes)
{
    if (magnitudes.empty()) {
        return min_escape_bits;
    }
    const size_t at = magnitudes.size() - 1 - magnitudes.size() / 100;
    std::nth_element(magnitudes.begin(), magnitudes.begin() + static_cast<std::ptrdiff_t>(at), magnitudes.end());
    const int bits = static_cast<int>(std::bit_width(magnitudes[at])); // 2^bits > the 99th percentile
    return std::clamp(bits, min_escape_bits, max_escape_bits);
}

uint64_t zigzag(int64_t v) noexcept
{
    return (static_cast<uint64_t>(v) << 1) ^ static_cast<uint64_t>(v >> 63);
}

int64_t unzigzag(uint64_t u) noexcept
{
    return static_cast<int64_t>((u >> 1) ^ (~(u & 1) + 1));
}

/// Draco with the settings of the format, over `npoints` points of `values` (x y interleaved).
std::string draco_encode(const int32_t* values, uint32_t npoints, int speed)
{
    draco::PointCloudBuilder builder;
    builder.Start(npoints);
    const int att = builder.AddAttribute(draco::GeometryAttribute::POSITION, 2, draco::DT_INT32);
    builder.SetAttributeValuesForAllPoints(att, values, 2 * sizeof(int32_t));
    const auto pc = builder.Finalize(false); // never deduplicate: order and count are the format
    draco::Encoder encoder;
    encoder.SetEncodingMethod(draco::POINT_CLOUD_SEQUENTIAL_ENCODING);
    encoder.SetSpeedOptions(speed, speed);
    // The values are already differences along the chains: no second prediction.
    encoder.SetAttributePredictionScheme(draco::GeometryAttribute::POSITION, draco::PREDICTION_NONE);
    draco::EncoderBuffer buffer;
    const draco::Status st = encoder.EncodePointCloudToBuffer(*pc, &buffer);
    if (!st.ok()) {
        throw input_error(std::string("geometry payload: Draco encoding failed: ") + st.error_msg());
    }
    return {buffer.data(), buffer.size()};
}

/// The first bytes of every Draco buffer of ours: header (magic, version,
/// point cloud, sequential, no flags), the point count (bytes 11-14, which
/// differ), one attributes decoder with one 2 x INT32 position attribute,
/// integer coding, no prediction. Decoding checks them before Draco sees the
/// buffer: Draco allocates what a damaged count asks for (the fuzzer made it
/// take 2 GiB), so the count must be the one the side table gives.
constexpr size_t draco_prefix_size = 24;
constexpr size_t draco_count_at = 11;

const std::string& draco_prefix()
{
    static const std::string prefix = [] {
        const int32_t one[2] = {0, 0};
        return draco_encode(one, 1, 0).substr(0, draco_prefix_size);
    }();
    return prefix;
}

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
    std::vector<uint64_t> magnitudes(diffs.size());
    for (size_t i = 0; i < diffs.size(); ++i) {
        magnitudes[i] = static_cast<uint64_t>(diffs[i] < 0 ? -diffs[i] : diffs[i]);
    }
    const int escape_bits = escape_bits_for(std::move(magnitudes));
    const int32_t escape = int32_t{1} << escape_bits;
    std::vector<int32_t> fresh;
    fresh.reserve(diffs.size());
    ByteWriter escapes;
    for (const int64_t d : diffs) {
        if (d > -escape && d < escape) {
            fresh.push_back(static_cast<int32_t>(d));
        } else {
            fresh.push_back(escape);
            escapes.put_varint(zigzag(d));
        }
    }
    const auto npoints = static_cast<uint32_t>(fresh.size() / 2);
    std::string draco_bytes;
    if (npoints > 0) {
        draco_bytes = draco_encode(fresh.data(), npoints, options.draco_speed);
    }
    ByteWriter w;
    w.put(kind_geometry);
    w.put_varint(g.chain_count());
    w.put_varint(npoints);
    w.put_bytes(side.bytes());
    w.put_varint(static_cast<uint64_t>(escape_bits));
    w.put_varint(escapes.size());
    w.put_bytes(escapes.bytes());
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
    const auto escape_bits = static_cast<int>(r.get_varint("escape bits", max_escape_bits));
    if (escape_bits < min_escape_bits) {
        r.fail("escape bits " + std::to_string(escape_bits) + " below " + std::to_string(min_escape_bits));
    }
    const int32_t escape = int32_t{1} << escape_bits;
    const uint64_t escape_size = r.get_varint("escape stream size");
    const auto escape_bytes =
        r.get_bytes(static_cast<size_t>(std::min<uint64_t>(escape_size, r.left() + 1)), "escape stream");
    const uint64_t draco_size = r.get_varint("Draco size");
    const auto draco_bytes =
        r.get_bytes(static_cast<size_t>(std::min<uint64_t>(draco_size, r.left() + 1)), "Draco data");
    if (r.left() != 0) {
        r.fail("trailing bytes after the Draco data");
    }
    std::vector<int32_t> fresh;
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
        const std::unique_ptr<draco::PointCloud> pc = std::move(decoded).value();
        if (pc->num_points() != nfresh || pc->num_attributes() != 1) {
            r.fail("Draco point cloud has " + std::to_string(pc->num_points()) + " points and " +
                   std::to_string(pc->num_attributes()) + " attributes, expected " + std::to_string(nfresh) + " and 1");
        }
        const draco::PointAttribute* att = pc->attribute(0);
        if (att->data_type() != draco::DT_INT32 || att->num_components() != 2 || att->byte_stride() != 8) {
            r.fail("Draco attribute is not 2 x INT32");
        }
        fresh.resize(static_cast<size_t>(nfresh) * 2);
        if (att->is_mapping_identity() && att->size() == nfresh) {
            std::memcpy(fresh.data(), att->GetAddress(draco::AttributeValueIndex(0)), fresh.size() * sizeof(int32_t));
        } else {
            for (uint32_t p = 0; p < nfresh; ++p) {
                const auto v = att->mapped_index(draco::PointIndex(p));
                if (v.value() >= att->size()) {
                    r.fail("Draco attribute index out of range");
                }
                att->GetValue(v, fresh.data() + 2 * p);
            }
        }
        // Put the escaped differences back.
        ByteReader er(escape_bytes, r_name);
        for (auto& v : fresh) {
            if (v == escape) {
                // Modular, as the points: a corrupt payload gives wrong points, never undefined behaviour.
                v = static_cast<int32_t>(
                    static_cast<uint32_t>(static_cast<uint64_t>(unzigzag(er.get_varint("escape stream")))));
            } else if (v <= -escape || v > escape) {
                r.fail("difference " + std::to_string(v) + " should have been escaped");
            }
        }
        if (er.left() != 0) {
            r.fail("escape stream longer than its markers");
        }
    } else if (draco_size != 0) {
        r.fail("Draco data without points");
    }
    Geometry g;
    g.offsets.reserve(static_cast<size_t>(nchains) + 1);
    g.points.reserve(static_cast<size_t>(total));
    size_t next = 0;
    GridPoint prev = origin;
    auto take = [&]() {
        // Modular arithmetic: a corrupt payload gives wrong points, never undefined behaviour.
        const GridPoint p{static_cast<int32_t>(static_cast<uint32_t>(prev.x) + static_cast<uint32_t>(fresh[next])),
                          static_cast<int32_t>(static_cast<uint32_t>(prev.y) + static_cast<uint32_t>(fresh[next + 1]))};
        next += 2;
        return p;
    };
    for (const auto& c : refs) {
        const size_t at = g.points.size();
        g.points.push_back(c.start == 0 ? take() : g.points[at - c.start]);
        prev = g.points.back();
        for (uint32_t k = 1; k + 1 < c.count; ++k) {
            g.points.push_back(take());
            prev = g.points.back();
        }
        const size_t end_at = at + c.count - 1;
        g.points.push_back(c.end == 0 ? take() : g.points[end_at - c.end]);
        prev = g.points.back();
        g.offsets.push_back(static_cast<uint32_t>(g.points.size()));
    }
    return g;
}

} // namespace tigerlod::datatree
