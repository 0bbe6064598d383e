#pragma once
/// @file adversarial_lines.hpp
/// A seeded generator of line maps built to stress a line layer cut into grid
/// tiles (formats/chains/SPEC.md, the partition contract): contour-like nests
/// of wiggly rings, a few metres apart, and bundles of near-parallel open
/// lines in the corridors between them, written as GeoJSON for tigerlod-ingest.
///
/// The map is a grid of cells. Each cell holds a "hill": K closed rings around
/// its centre, ring k at radius r0 + k s + w(theta) + e_k(theta) at N angles,
/// where w is a wiggle shared by every ring of the hill (sines of a few
/// frequencies, so the rings bend together as contours do) and e_k a noise of
/// its own under s / 3 (the wiggle keeps every radius positive: each ring is
/// star-shaped around the centre, so simple). At each angle the radii increase strictly with k, and
/// two rings sampled at the same angles cannot cross (in each sector between
/// two rays, the inner ring's chord joins points nearer the centre on both
/// rays). The outermost ring keeps inside the cell's inscribed circle minus a
/// corridor. Along each vertical corridor between two columns of cells run
/// 2 to 4 open lines, 3 to 9 m apart, each wiggling by the same offsets (so
/// they stay apart) from one end of the map to the other, with short dangling
/// lines of two vertices between them here and there. Along the horizontal
/// cell edges, out of every hill's reach, lie thin loops (a few metres wide,
/// up to 220 m long): cut by a tile's edge into two pieces owned by two
/// tiles, both pieces can take the same chord at a coarse tolerance, which
/// only the chord rule (of two chains between the same two ends, only the
/// smaller id may become the chord; simplification/README.md, step 7) refuses.
///
/// Every coordinate is on TIGER's 1e-6 degree lattice; rounding moves a point
/// by under 0.1 m, against gaps of 3 m or more, so the map stays planar (the
/// test asserts ingest finds no crossing).

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <numbers>
#include <random>
#include <string>
#include <vector>

namespace tigerlod::testing {

class AdversarialLines {
  public:
    explicit AdversarialLines(uint64_t seed) : m_rng(seed)
    {
        const int cells = 3;
        for (int cy = 0; cy < cells; ++cy) {
            for (int cx = 0; cx < cells; ++cx) {
                hill(cx * kCell + kCell / 2, cy * kCell + kCell / 2);
            }
        }
        for (int cx = 1; cx < cells; ++cx) {
            corridor(cx * kCell, cells * kCell);
        }
        for (int cy = 1; cy < cells; ++cy) {
            for (int cx = 0; cx < cells; ++cx) {
                for (int k = 0; k < 3; ++k) {
                    loop(cx * kCell + 200.0 + 250.0 * k, cy * kCell);
                }
            }
        }
    }

    size_t vertices() const
    {
        size_t n = 0;
        for (const auto& l : m_lines) {
            n += l.size();
        }
        return n;
    }

    /// The map as GeoJSON LineStrings (lon/lat, micro-degree lattice).
    std::string geojson() const
    {
        std::string out = "{\"type\":\"FeatureCollection\",\"features\":[\n";
        for (size_t i = 0; i < m_lines.size(); ++i) {
            out += i ? ",\n" : "";
            out += "{\"type\":\"Feature\",\"properties\":{\"ID\":" + std::to_string(i) +
                   "},\"geometry\":{\"type\":\"LineString\",\"coordinates\":[";
            for (size_t k = 0; k < m_lines[i].size(); ++k) {
                out += (k ? ",[" : "[") + e6(m_lines[i][k].first) + "," + e6(m_lines[i][k].second) + "]";
            }
            out += "]}}";
        }
        return out + "\n]}\n";
    }

  private:
    /// Micro-degrees as exact decimal degrees.
    static std::string e6(int64_t v)
    {
        char buf[32];
        const auto a = static_cast<long long>(v < 0 ? -v : v);
        std::snprintf(buf, sizeof buf, "%s%lld.%06lld", v < 0 ? "-" : "", a / 1000000, a % 1000000);
        return buf;
    }

    static constexpr double kCell = 900.0; ///< metres
    static constexpr double kLon0 = -96.0, kLat0 = 40.0;
    static constexpr double kMPerDegLat = 111'000.0;

    /// Metres from the map's corner to the micro-degree lattice.
    std::pair<int64_t, int64_t> at(double x, double y) const
    {
        const double lat = kLat0 + y / kMPerDegLat;
        const double lon = kLon0 + x / (kMPerDegLat * std::cos(kLat0 * std::numbers::pi / 180.0));
        return {std::llround(lon * 1e6), std::llround(lat * 1e6)};
    }

    double uniform(double a, double b) { return std::uniform_real_distribution<double>(a, b)(m_rng); }
    int pick(int a, int b) { return std::uniform_int_distribution<int>(a, b)(m_rng); }

    void hill(double cx, double cy)
    {
        const int rings = pick(6, 12);
        const int n = pick(40, 120);
        const double s = uniform(4.0, 20.0); // ring spacing: under a pixel at coarse tolerances
        const double r0 = uniform(20.0, 60.0);
        // The shared wiggle: three sines, their sum under the room left
        // outside (to the corridors) and inside (to the centre).
        const double room = std::min(kCell / 2 - 60.0 - r0 - rings * s, r0 - 8.0);
        double amp[3], freq[3], phase[3];
        for (int k = 0; k < 3; ++k) {
            amp[k] = uniform(0.0, std::max(0.0, room) / 3.5);
            freq[k] = pick(2, 9);
            phase[k] = uniform(0.0, 2 * std::numbers::pi);
        }
        for (int k = 0; k < rings; ++k) {
            std::vector<std::pair<int64_t, int64_t>> ring;
            for (int i = 0; i < n; ++i) {
                const double t = 2 * std::numbers::pi * i / n;
                double r = r0 + k * s + uniform(-s / 3, s / 3);
                for (int f = 0; f < 3; ++f) {
                    r += amp[f] * std::sin(freq[f] * t + phase[f]);
                }
                ring.push_back(at(cx + r * std::cos(t), cy + r * std::sin(t)));
            }
            ring.push_back(ring.front());
            m_lines.push_back(std::move(ring));
        }
    }

    void corridor(double x, double height)
    {
        const int lines = pick(2, 4);
        const int n = pick(30, 90);
        std::vector<double> gap(static_cast<size_t>(lines));
        double off = 0;
        for (auto& g : gap) {
            g = off;
            off += uniform(3.0, 9.0);
        }
        std::vector<double> wiggle(static_cast<size_t>(n) + 1);
        for (auto& w : wiggle) {
            w = uniform(-12.0, 12.0);
        }
        for (int l = 0; l < lines; ++l) {
            std::vector<std::pair<int64_t, int64_t>> line;
            for (int i = 0; i <= n; ++i) {
                line.push_back(at(x - off / 2 + gap[size_t(l)] + wiggle[size_t(i)], height * i / n));
            }
            m_lines.push_back(std::move(line));
        }
        // Dangling two-vertex lines across the gap between the first two,
        // short of both: a straight chain with no middle vertex.
        for (int i = 2; i + 2 < n; i += pick(4, 12)) {
            const double y = height * (i + 0.5) / n;
            const double x0 = x - off / 2 + (wiggle[size_t(i)] + wiggle[size_t(i) + 1]) / 2;
            const double g = gap[1];
            if (g > 4.0) {
                m_lines.push_back({at(x0 + 1.2, y), at(x0 + g - 1.2, y + 0.5)});
            }
        }
    }

    /// A thin loop along a horizontal cell edge, where no hill reaches: an
    /// ellipse 2 x (40..110) m by 2 x (1.5..7) m. Cut into two pieces by a
    /// tile's edge, each piece can take the same chord at a coarse tolerance.
    void loop(double cx, double cy)
    {
        const double a = uniform(40.0, 110.0), b = uniform(1.5, 7.0);
        const int n = pick(12, 30);
        const double turn = uniform(0.0, 2 * std::numbers::pi);
        std::vector<std::pair<int64_t, int64_t>> ring;
        for (int i = 0; i < n; ++i) {
            const double t = turn + 2 * std::numbers::pi * i / n;
            ring.push_back(at(cx + a * std::cos(t), cy + b * std::sin(t)));
        }
        ring.push_back(ring.front());
        m_lines.push_back(std::move(ring));
    }

    std::mt19937_64 m_rng;
    std::vector<std::vector<std::pair<int64_t, int64_t>>> m_lines;
};

} // namespace tigerlod::testing
