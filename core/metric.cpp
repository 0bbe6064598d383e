#include "core/metric.hpp"

#include <algorithm>
#include <cmath>

namespace tigerlod {

const char* metric_name(Metric m) noexcept
{
    switch (m) {
    case Metric::l1:
        return "l1";
    case Metric::linf:
        return "linf";
    default:
        return "l2";
    }
}

std::optional<Metric> parse_metric(const std::string& name) noexcept
{
    if (name == "l2") {
        return Metric::l2;
    }
    if (name == "l1") {
        return Metric::l1;
    }
    if (name == "linf") {
        return Metric::linf;
    }
    return std::nullopt;
}

double l2_reach(Metric m) noexcept
{
    return m == Metric::linf ? std::sqrt(2.0) : 1.0;
}

Tolerance::Tolerance(double eps_grid, Metric m) : eps(eps_grid), metric(m)
{
    if (m == Metric::l2) {
        // floor(eps^2), corrected for the rounding of the double square.
        auto t = static_cast<int128>(std::floor(eps_grid * eps_grid));
        while (static_cast<long double>(t + 1) <= static_cast<long double>(eps_grid) * eps_grid) {
            ++t;
        }
        while (t > 0 && static_cast<long double>(t) > static_cast<long double>(eps_grid) * eps_grid) {
            --t;
        }
        threshold = t;
    } else {
        threshold = static_cast<int128>(std::floor(eps_grid));
    }
}

namespace {

__extension__ typedef unsigned __int128 uint128;

/// a * b as a 256-bit number (hi, lo).
void mul_wide(uint128 a, uint128 b, uint128& hi, uint128& lo) noexcept
{
    const uint128 mask = (uint128{1} << 64) - 1;
    const uint128 a0 = a & mask, a1 = a >> 64, b0 = b & mask, b1 = b >> 64;
    const uint128 p00 = a0 * b0, p01 = a0 * b1, p10 = a1 * b0, p11 = a1 * b1;
    const uint128 mid = (p00 >> 64) + (p01 & mask) + (p10 & mask);
    lo = (p00 & mask) | (mid << 64);
    hi = p11 + (p01 >> 64) + (p10 >> 64) + (mid >> 64);
}

/// a * b <= c * d for non-negative a, b, c, d.
bool product_le(uint128 a, uint128 b, uint128 c, uint128 d) noexcept
{
    uint128 h1 = 0, l1 = 0, h2 = 0, l2 = 0;
    mul_wide(a, b, h1, l1);
    mul_wide(c, d, h2, l2);
    return h1 < h2 || (h1 == h2 && l1 <= l2);
}

uint128 abs128(int128 v) noexcept
{
    return v < 0 ? static_cast<uint128>(-v) : static_cast<uint128>(v);
}

int128 l1_norm(int128 x, int128 y) noexcept
{
    return (x < 0 ? -x : x) + (y < 0 ? -y : y);
}

} // namespace

bool within(GridPoint p, GridPoint a, GridPoint b, const Tolerance& tol) noexcept
{
    const int128 ux = int64_t{p.x} - a.x, uy = int64_t{p.y} - a.y;
    const int128 dx = int64_t{b.x} - a.x, dy = int64_t{b.y} - a.y;
    const int128 e = tol.threshold;
    switch (tol.metric) {
    case Metric::l2: {
        const int128 dot = ux * dx + uy * dy;
        const int128 len2 = dx * dx + dy * dy;
        if (dot <= 0 || len2 == 0) {
            return ux * ux + uy * uy <= e;
        }
        if (dot >= len2) {
            const int128 vx = int64_t{p.x} - b.x, vy = int64_t{p.y} - b.y;
            return vx * vx + vy * vy <= e;
        }
        const int128 cross = ux * dy - uy * dx;
        return product_le(abs128(cross), abs128(cross), static_cast<uint128>(e), static_cast<uint128>(len2));
    }
    case Metric::l1: {
        // |ux - t dx| + |uy - t dy| is convex and piecewise linear in t: its
        // minimum over [0, 1] is at t = 0, t = 1 or where one term vanishes.
        if (l1_norm(ux, uy) <= e || l1_norm(ux - dx, uy - dy) <= e) {
            return true;
        }
        const int128 cross = ux * dy - uy * dx;
        const uint128 ac = abs128(cross);
        // t = ux / dx in (0, 1): value |cross| / |dx|.
        if (dx != 0) {
            const bool in = (dx > 0) ? (ux > 0 && ux < dx) : (ux < 0 && ux > dx);
            if (in && product_le(ac, 1, static_cast<uint128>(e), abs128(dx))) {
                return true;
            }
        }
        if (dy != 0) {
            const bool in = (dy > 0) ? (uy > 0 && uy < dy) : (uy < 0 && uy > dy);
            if (in && product_le(ac, 1, static_cast<uint128>(e), abs128(dy))) {
                return true;
            }
        }
        return false;
    }
    case Metric::linf: {
        // Exists t in [0, 1] with |ux - t dx| <= e and |uy - t dy| <= e:
        // intersect the t-intervals as fractions num/den with den > 0.
        struct Frac {
            int128 num, den;
        };
        Frac lo{0, 1}, hi{1, 1};
        auto less = [](Frac x, Frac y) { return x.num * y.den < y.num * x.den; };
        auto clip = [&](int128 u, int128 d) {
            if (d == 0) {
                return (u < 0 ? -u : u) <= e;
            }
            // (u - e) / d <= t <= (u + e) / d, flipped when d < 0.
            Frac f1{u - e, d}, f2{u + e, d};
            if (d < 0) {
                f1 = {-(u + e), -d};
                f2 = {-(u - e), -d};
            }
            if (less(lo, f1)) {
                lo = f1;
            }
            if (less(f2, hi)) {
                hi = f2;
            }
            return true;
        };
        if (!clip(ux, dx) || !clip(uy, dy)) {
            return false;
        }
        return !less(hi, lo);
    }
    }
    return false;
}

double distance(GridPoint p, GridPoint a, GridPoint b, Metric m) noexcept
{
    const double ux = double(p.x) - a.x, uy = double(p.y) - a.y;
    const double dx = double(b.x) - a.x, dy = double(b.y) - a.y;
    const double len2 = dx * dx + dy * dy;
    auto at = [&](double t) {
        const double x = ux - t * dx, y = uy - t * dy;
        switch (m) {
        case Metric::l1:
            return std::abs(x) + std::abs(y);
        case Metric::linf:
            return std::max(std::abs(x), std::abs(y));
        default:
            return std::sqrt(x * x + y * y);
        }
    };
    if (len2 == 0) {
        return at(0);
    }
    double best = std::min(at(0), at(1));
    const double ts[] = {(ux * dx + uy * dy) / len2, dx != 0 ? ux / dx : 0.0, dy != 0 ? uy / dy : 0.0,
                         (dx - dy) != 0 ? (ux - uy) / (dx - dy) : 0.0, (dx + dy) != 0 ? (ux + uy) / (dx + dy) : 0.0};
    for (double t : ts) {
        best = std::min(best, at(std::clamp(t, 0.0, 1.0)));
    }
    return best;
}

} // namespace tigerlod
