#include "stages/synth/nation.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <optional>
#include <queue>
#include <unordered_map>
#include <stdexcept>

namespace tigerlod::synth {

namespace {

// The figures below shape the distributions README.md compares with Floyd
// County's; each is a probability or a fraction of a cell.
constexpr double thin_line_p = 0.03;     ///< a row or column a twentieth of the others' width
constexpr double thin_line_width = 0.06; ///< ... of the spacing
constexpr double jitter = 0.18;          ///< a node moves at most this much of its narrower neighbour line
constexpr int rugged_cells = 12;         ///< the ruggedness field's grain, in cells
constexpr double split_p = 0.45;         ///< a curved edge is two edges, split at a degree-2 node
constexpr double dangle_p = 0.12;        ///< per cell corner: a road into the cell, ending there
constexpr double lake_p = 0.05;          ///< per cell
constexpr double island_p = 0.3;         ///< per lake
constexpr int cells_per_tract = 600, cells_per_group = 250, cells_per_block = 4;
/// Vertices per cell the lattice is sized with (measured: README.md).
constexpr double vertices_per_cell = 39;

// The state FIPS codes, in order; a nation of more states than this is refused by the options.
constexpr const char* state_fips[] = {
    "01", "02", "04", "05", "06", "08", "09", "10", "11", "12", "13", "15", "16", "17", "18", "19", "20", "21", "22",
    "23", "24", "25", "26", "27", "28", "29", "30", "31", "32", "33", "34", "35", "36", "37", "38", "39", "40", "41",
    "42", "44", "45", "46", "47", "48", "49", "50", "51", "53", "54", "55", "56", "60", "66", "69", "72", "78"};

uint64_t mix(uint64_t z)
{
    z += 0x9e3779b97f4a7c15ULL;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}

/// A hash of the seed and up to four numbers: the generator's only source of chance.
uint64_t hash(uint64_t seed, uint64_t a, uint64_t b = 0, uint64_t c = 0, uint64_t d = 0)
{
    return mix(mix(mix(mix(mix(seed) ^ a) ^ b) ^ c) ^ d);
}

/// Uniform in [0, 1).
double unit(uint64_t h)
{
    return double(h >> 11) * 0x1.0p-53;
}

// What a hash is for, so that two uses never draw the same number.
enum Use : uint64_t {
    use_col = 1,
    use_row,
    use_jitter_x,
    use_jitter_y,
    use_rugged,
    use_edge,
    use_split,
    use_dangle,
    use_lake,
    use_seed_cell,
    use_cost,
};

int64_t round_div10(int64_t num)
{
    return num >= 0 ? (num + 5) / 10 : -((-num + 5) / 10);
}

/// The point 0.6 of the way from ab's middle to c: (2a + 2b + 6c) / 10, rounded the same for ab and ba.
Pt towards(Pt a, Pt b, Pt c)
{
    return {round_div10(2 * (a.x + b.x) + 6 * c.x), round_div10(2 * (a.y + b.y) + 6 * c.y)};
}

bool strictly_inside(Pt a, Pt b, Pt c, Pt p) ///< triangle abc counter-clockwise
{
    return orient(a, b, p) > 0 && orient(b, c, p) > 0 && orient(c, a, p) > 0;
}

double dist(Pt a, Pt b)
{
    const double dx = double(a.x - b.x), dy = double(a.y - b.y);
    return std::sqrt(dx * dx + dy * dy);
}

double seg_dist(Pt p, Pt a, Pt b)
{
    const double dx = double(b.x - a.x), dy = double(b.y - a.y);
    const double l2 = dx * dx + dy * dy;
    double t = l2 > 0 ? ((double(p.x - a.x)) * dx + (double(p.y - a.y)) * dy) / l2 : 0;
    t = std::clamp(t, 0.0, 1.0);
    const double ex = double(a.x) + t * dx - double(p.x), ey = double(a.y) + t * dy - double(p.y);
    return std::sqrt(ex * ex + ey * ey);
}

std::string digits(uint32_t value, int width)
{
    char buf[16];
    std::snprintf(buf, sizeof buf, "%0*u", width, value);
    return buf;
}

} // namespace

/// A cell's corners counter-clockwise from (i, j), its centre, and whether
/// it is convex (every corner turning left), which everything inside it needs.
struct Nation::CellShape {
    Pt corner[4];
    Pt centre;
    bool convex = false;
};

Nation::Nation(const SynthOptions& options) : m_opt(options)
{
    if (options.states < 1 || options.states > int(std::size(state_fips))) {
        throw std::invalid_argument("synth: states must be in 1.." + std::to_string(std::size(state_fips)));
    }
    const double cells = std::max(1.0, double(options.target_vertices) / vertices_per_cell);
    m_w = std::max(1, int(std::lround(std::sqrt(2 * cells))));
    m_h = std::max(1, int(std::lround(cells / m_w)));
    const double sx = options.cell_m / (111'320 * cos_turns(options.lat0 / 360)) * 1e6;
    const double sy = options.cell_m / 110'574 * 1e6;
    auto lines = [&](int n, double s, Use use, double centre) {
        std::vector<double> width(static_cast<size_t>(n));
        double total = 0;
        for (int k = 0; k < n; ++k) {
            const double u = unit(hash(m_opt.seed, use, uint64_t(k)));
            // Most lines 0.6 to 2 spacings apart, a few a twentieth.
            width[size_t(k)] = u < thin_line_p ? s * thin_line_width : s * (0.6 + 1.4 * u * u);
            total += width[size_t(k)];
        }
        std::vector<int64_t> at(size_t(n) + 1);
        double x = centre * 1e6 - total / 2;
        for (int k = 0; k <= n; ++k) {
            at[size_t(k)] = std::llround(x);
            x += k < n ? width[size_t(k)] : 0;
        }
        return at;
    };
    m_col_x = lines(m_w, sx, use_col, options.lon0);
    m_row_y = lines(m_h, sy, use_row, options.lat0);

    // The ruggedness: value noise on a coarse grid, smoothly interpolated.
    m_rugged.resize(size_t(m_w) * size_t(m_h));
    for (int j = 0; j < m_h; ++j) {
        for (int i = 0; i < m_w; ++i) {
            const int gi = i / rugged_cells, gj = j / rugged_cells;
            const double fx = double(i % rugged_cells) / rugged_cells, fy = double(j % rugged_cells) / rugged_cells;
            auto v = [&](int a, int b) { return unit(hash(m_opt.seed, use_rugged, uint64_t(a), uint64_t(b))); };
            const double sx_ = fx * fx * (3 - 2 * fx), sy_ = fy * fy * (3 - 2 * fy);
            const double top = v(gi, gj) * (1 - sx_) + v(gi + 1, gj) * sx_;
            const double bottom = v(gi, gj + 1) * (1 - sx_) + v(gi + 1, gj + 1) * sx_;
            m_rugged[size_t(j) * size_t(m_w) + size_t(i)] = float(top * (1 - sy_) + bottom * sy_);
        }
    }
    // States and counties on squares of about a fifth of a county's side.
    const double county_cells = double(m_w) * m_h / (double(options.states) * options.counties_per_state);
    const int grain = std::max(1, int(std::sqrt(county_cells) / 5));
    for (int l = 0; l < level_count; ++l) {
        grow(Level(l), l <= county ? grain : 1);
    }
    m_county_cells.resize(m_units[county].size());
    for (uint32_t c = 0; c < m_cell_unit[county].size(); ++c) {
        m_county_cells[m_cell_unit[county][c]].push_back(c);
    }
}

uint32_t Nation::unit_of(int i, int j, Level level) const
{
    return m_cell_unit[level][size_t(j) * size_t(m_w) + size_t(i)];
}

Pt Nation::node(int i, int j) const
{
    auto width = [](const std::vector<int64_t>& at, int k) {
        const int n = int(at.size()) - 1;
        int64_t w = std::numeric_limits<int64_t>::max();
        if (k > 0) {
            w = std::min(w, at[size_t(k)] - at[size_t(k) - 1]);
        }
        if (k < n) {
            w = std::min(w, at[size_t(k) + 1] - at[size_t(k)]);
        }
        return double(w);
    };
    const double jx = (2 * unit(hash(m_opt.seed, use_jitter_x, uint64_t(i), uint64_t(j))) - 1) * jitter;
    const double jy = (2 * unit(hash(m_opt.seed, use_jitter_y, uint64_t(i), uint64_t(j))) - 1) * jitter;
    return {m_col_x[size_t(i)] + std::llround(jx * width(m_col_x, i)),
            m_row_y[size_t(j)] + std::llround(jy * width(m_row_y, j))};
}

Nation::CellShape Nation::cell_shape(int i, int j) const
{
    CellShape s;
    s.corner[0] = node(i, j);
    s.corner[1] = node(i + 1, j);
    s.corner[2] = node(i + 1, j + 1);
    s.corner[3] = node(i, j + 1);
    int64_t sx = 0, sy = 0;
    for (const Pt p : s.corner) {
        sx += p.x;
        sy += p.y;
    }
    s.centre = {sx >= 0 ? (sx + 2) / 4 : -((-sx + 2) / 4), sy >= 0 ? (sy + 2) / 4 : -((-sy + 2) / 4)};
    s.convex = true;
    for (int k = 0; k < 4; ++k) {
        s.convex = s.convex && orient(s.corner[k], s.corner[(k + 1) % 4], s.corner[(k + 2) % 4]) > 0 &&
                   orient(s.corner[k], s.corner[(k + 1) % 4], s.centre) > 0;
    }
    return s;
}

void Nation::grow(Level level, int grain)
{
    // The race runs on a grid of grain x grain cells (states and counties:
    // borders kilometres long, not a staircase of single cells), then each
    // cell takes its grid square's unit.
    const int gw = (m_w + grain - 1) / grain, gh = (m_h + grain - 1) / grain;
    const size_t n = size_t(gw) * size_t(gh);
    std::vector<uint32_t> parent(n, 0);
    if (level != state) {
        for (int j = 0; j < gh; ++j) {
            for (int i = 0; i < gw; ++i) {
                parent[size_t(j) * size_t(gw) + size_t(i)] = unit_of(i * grain, j * grain, Level(level - 1));
            }
        }
    }
    const size_t parents = level == state ? 1 : m_units[level - 1].size();
    std::vector<std::vector<uint32_t>> cells_of(parents);
    for (uint32_t c = 0; c < n; ++c) {
        cells_of[parent[c]].push_back(c);
    }
    std::vector<uint32_t> owner(n, UINT32_MAX);
    auto& units = m_units[level];
    units.clear();
    std::vector<float> cost(n, std::numeric_limits<float>::infinity());
    using Item = std::pair<float, uint32_t>;
    std::priority_queue<Item, std::vector<Item>, std::greater<>> queue;
    for (uint32_t p = 0; p < parents; ++p) {
        auto& cells = cells_of[p];
        const double size = double(cells.size()) * grain * grain;
        size_t want = 1;
        switch (level) {
        case state:
            want = size_t(m_opt.states);
            break;
        case county:
            want = size_t(m_opt.counties_per_state);
            break;
        case tract:
            want = size_t(std::max(1L, std::lround(size / cells_per_tract)));
            break;
        case block_group:
            want = size_t(std::clamp(std::lround(size / cells_per_group), 1L, 9L));
            break;
        default:
            want = size_t(std::clamp(std::lround(size / cells_per_block), 1L, 999L));
            break;
        }
        want = std::min(want, cells.size());
        // The seeds: the cells of smallest hash, then in cell order.
        std::vector<std::pair<uint64_t, uint32_t>> keyed;
        keyed.reserve(cells.size());
        for (const uint32_t c : cells) {
            keyed.emplace_back(hash(m_opt.seed, use_seed_cell, uint64_t(level), c), c);
        }
        std::nth_element(keyed.begin(), keyed.begin() + std::ptrdiff_t(want - 1), keyed.end());
        std::vector<uint32_t> seeds;
        for (size_t k = 0; k < want; ++k) {
            seeds.push_back(keyed[k].second);
        }
        std::sort(seeds.begin(), seeds.end());
        for (size_t k = 0; k < seeds.size(); ++k) {
            Unit u;
            u.parent = p;
            switch (level) {
            case state:
                u.code = state_fips[k];
                break;
            case county:
                u.code = digits(uint32_t(2 * k + 1), 3);
                break;
            case tract:
                u.code = digits(uint32_t(k + 1) * 100, 6);
                break;
            case block_group:
                u.code = digits(uint32_t(k + 1), 1);
                break;
            default:
                u.code = m_units[block_group][p].code + digits(uint32_t(k + 1), 3);
                break;
            }
            owner[seeds[k]] = uint32_t(units.size());
            cost[seeds[k]] = 0;
            queue.emplace(0.0f, seeds[k]);
            units.push_back(std::move(u));
        }
    }
    // The race: each cell goes to the unit whose seed reaches it first at
    // random costs, within its parent; ties to the smaller cell, then unit.
    while (!queue.empty()) {
        const auto [d, c] = queue.top();
        queue.pop();
        if (d > cost[c]) {
            continue;
        }
        const int i = int(c % uint32_t(gw)), j = int(c / uint32_t(gw));
        const int ni[4] = {i - 1, i + 1, i, i};
        const int nj[4] = {j, j, j - 1, j + 1};
        for (int k = 0; k < 4; ++k) {
            if (ni[k] < 0 || nj[k] < 0 || ni[k] >= gw || nj[k] >= gh) {
                continue;
            }
            const uint32_t o = uint32_t(nj[k]) * uint32_t(gw) + uint32_t(ni[k]);
            if (parent[o] != parent[c]) {
                continue;
            }
            const float step = float(0.3 + 1.4 * unit(hash(m_opt.seed, use_cost, uint64_t(level), o)));
            const float nd = d + step;
            if (nd < cost[o] || (nd == cost[o] && owner[c] < owner[o])) {
                cost[o] = nd;
                owner[o] = owner[c];
                queue.emplace(nd, o);
            }
        }
    }
    auto& cell_unit = m_cell_unit[level];
    cell_unit.resize(size_t(m_w) * size_t(m_h));
    for (int j = 0; j < m_h; ++j) {
        for (int i = 0; i < m_w; ++i) {
            const uint32_t u = owner[size_t(j / grain) * size_t(gw) + size_t(i / grain)];
            cell_unit[size_t(j) * size_t(m_w) + size_t(i)] = u;
            ++units[u].cells;
        }
    }
}

double sin_turns(double x)
{
    x -= std::floor(x);
    const double y = x < 0.25 ? x : x < 0.75 ? 0.5 - x : x - 1; // sin(2 pi x) = sin(2 pi y), |y| <= 1/4
    const double t = 2 * std::numbers::pi * y, t2 = t * t;
    return t *
           (1 + t2 * (-1.0 / 6 + t2 * (1.0 / 120 + t2 * (-1.0 / 5040 + t2 * (1.0 / 362880 + t2 * (-1.0 / 39916800))))));
}

int64_t lattice_tlid(const Nation& n, bool vertical, int i, int j, int part)
{
    const int64_t index = vertical ? (int64_t(j) * (n.width() + 1) + i) * 2 + 1 : (int64_t(j) * n.width() + i) * 2;
    return 1 + 2 * index + part;
}

namespace {

struct Ids {
    int64_t w, h, nodes, edges;
    Ids(const Nation& n) : w(n.width()), h(n.height()), nodes((w + 1) * (h + 1)), edges(2 * (w + 1) * (h + 1)) {}
    int64_t cell(int i, int j) const { return int64_t(j) * w + i; }
    int64_t face(int i, int j, int k) const { return 1 + 3 * cell(i, j) + k; } ///< k: 0 land, 1 lake, 2 island
    int64_t node(int i, int j) const { return 1 + int64_t(j) * (w + 1) + i; }
    int64_t split_node(int64_t tlid) const { return nodes + 1 + tlid; }
    int64_t inner_node(int i, int j, int k) const { return nodes + 2 * edges + 2 + cell(i, j) * 8 + k; }
    int64_t inner_tlid(int i, int j, int k) const { return 1 + 2 * edges + cell(i, j) * 8 + k; }
};

} // namespace

Nation::EdgeSides Nation::edge_sides(bool vertical, int i, int j) const
{
    // Walking from node (i, j): a horizontal edge has cell (i, j) on its left
    // and (i, j - 1) on its right, a vertical one (i - 1, j) and (i, j).
    EdgeSides e;
    e.li = vertical ? i - 1 : i;
    e.lj = j;
    e.ri = i;
    e.rj = vertical ? j : j - 1;
    e.has_l = e.li >= 0 && e.lj < m_h && e.li < m_w;
    e.has_r = e.ri < m_w && e.rj >= 0 && e.rj < m_h;
    return e;
}

Nation::Polyline Nation::lattice_polyline(bool vertical, int i, int j) const
{
    const Pt a = node(i, j), b = vertical ? node(i, j + 1) : node(i + 1, j);
    const EdgeSides e_sides = edge_sides(vertical, i, j);
    std::optional<Pt> hl, hr;
    float rugged = 0;
    int sides = 0;
    uint32_t county_l = UINT32_MAX, county_r = UINT32_MAX;
    // A side cell's apex h (when the cell is convex and h strictly inside its
    // fan triangle: (p, q, centre) counter-clockwise), its ruggedness, its county.
    auto side = [&](int ci, int cj, Pt p, Pt q, std::optional<Pt>& h_out, uint32_t& county_out) {
        const auto s = cell_shape(ci, cj);
        const Pt h = towards(a, b, s.centre);
        if (s.convex && strictly_inside(p, q, s.centre, h)) {
            h_out = h;
        }
        rugged += m_rugged[size_t(cj) * size_t(m_w) + size_t(ci)];
        county_out = unit_of(ci, cj, county);
        ++sides;
    };
    if (e_sides.has_l) {
        side(e_sides.li, e_sides.lj, a, b, hl, county_l);
    }
    if (e_sides.has_r) {
        side(e_sides.ri, e_sides.rj, b, a, hr, county_r);
    }
    rugged /= float(std::max(sides, 1));
    std::vector<Pt> out{a};
    const bool both = hl && hr;
    if (both &&
        !(orient(a, *hr, b) > 0 && orient(*hr, b, *hl) > 0 && orient(b, *hl, a) > 0 && orient(*hl, a, *hr) > 0)) {
        out.push_back(b); // the quadrilateral is not convex: a straight edge
        return out;
    }
    if (!hl && !hr) {
        out.push_back(b);
        return out;
    }
    auto inside = [&](Pt p) {
        if (both) {
            return orient(a, *hr, p) > 0 && orient(*hr, b, p) > 0 && orient(b, *hl, p) > 0 && orient(*hl, a, p) > 0;
        }
        return hl ? strictly_inside(a, b, *hl, p) : strictly_inside(a, *hr, b, p);
    };

    // The kind of edge: a border (another county, or the coast) is wigglier.
    const uint64_t e = vertical ? 1 + 2 * (uint64_t(j) * uint64_t(m_w + 1) + uint64_t(i))
                                : 2 * (uint64_t(j) * uint64_t(m_w) + uint64_t(i));
    const bool border = county_l != county_r;
    const double p_straight = 0.35 * (1 - rugged) * (border ? 0.5 : 1);
    const double p_wiggly = 0.12 + 0.55 * rugged + (border ? 0.3 : 0);
    const double u = unit(hash(m_opt.seed, use_edge, e, 0));
    int k = 0;
    double amp = 0;
    if (u < p_straight) {
        k = 0;
    } else if (u < 1 - p_wiggly) {
        k = 2 + int(unit(hash(m_opt.seed, use_edge, e, 1)) * 12);
        amp = 0.15 + 0.35 * unit(hash(m_opt.seed, use_edge, e, 2));
    } else {
        const double v = unit(hash(m_opt.seed, use_edge, e, 1)); // a long tail, mean about 24
        k = 8 + int(10 * v / (1 - 0.95 * v));
        amp = 0.55 + 0.4 * unit(hash(m_opt.seed, use_edge, e, 2));
    }
    const double dx = double(b.x - a.x), dy = double(b.y - a.y);
    const double len2 = dx * dx + dy * dy;
    const double nx = -dy / std::sqrt(len2), ny = dx / std::sqrt(len2); // left normal, unit
    auto frame = [&](std::optional<Pt> h) {                             // (t, height) of a side's apex
        if (!h) {
            return std::pair{0.5, 0.0};
        }
        const double hx = double(h->x - a.x), hy = double(h->y - a.y);
        return std::pair{std::clamp((hx * dx + hy * dy) / len2, 0.05, 0.95), std::abs(hx * nx + hy * ny)};
    };
    const auto [tl, hl_h] = frame(hl);
    const auto [tr, hr_h] = frame(hr);
    // Meanders: a slow bend, and on long wiggly edges a faster one over it.
    const double f1 = (k > 8 ? 0.8 + 2.2 * unit(hash(m_opt.seed, use_edge, e, 3))
                             : 0.3 + 0.9 * unit(hash(m_opt.seed, use_edge, e, 3)));
    const double f2 = 2.5 + 3 * unit(hash(m_opt.seed, use_edge, e, 4));
    const double ph1 = unit(hash(m_opt.seed, use_edge, e, 5)), ph2 = unit(hash(m_opt.seed, use_edge, e, 6));
    const int64_t along_end = int64_t(dx) * int64_t(dx) + int64_t(dy) * int64_t(dy);
    int64_t along_last = 0;
    for (int q = 0; q < k; ++q) {
        const double t = (q + 1 + 0.6 * (unit(hash(m_opt.seed, use_edge, e, 7 + uint64_t(q))) - 0.5)) / (k + 1);
        double s = 0.75 * sin_turns(f1 * t + ph1) + (k > 8 ? 0.25 * sin_turns(f2 * t + ph2) : 0);
        if (!hl) {
            s = -std::abs(s);
        } else if (!hr) {
            s = std::abs(s);
        }
        const auto [th, hh] = s > 0 ? std::pair{tl, hl_h} : std::pair{tr, hr_h};
        const double half = hh * std::min(t / th, (1 - t) / (1 - th)) * 0.9;
        const double off = amp * s * half;
        const Pt p{std::llround(double(a.x) + t * dx + off * nx), std::llround(double(a.y) + t * dy + off * ny)};
        const int64_t along = (p.x - a.x) * (b.x - a.x) + (p.y - a.y) * (b.y - a.y);
        if (along <= along_last || along >= along_end || !inside(p)) {
            continue; // rounded out of its quadrilateral, or back along ab
        }
        along_last = along;
        out.push_back(p);
    }
    out.push_back(b);
    return out;
}

void Nation::lattice_edge(bool vertical, int i, int j, Polyline pts, std::vector<Edge>& out) const
{
    const Ids ids(*this);
    const auto [li, lj, ri, rj, has_l, has_r] = edge_sides(vertical, i, j);
    Edge edge;
    edge.tfidl = has_l ? ids.face(li, lj, 0) : 0;
    edge.tfidr = has_r ? ids.face(ri, rj, 0) : 0;
    const bool border = !has_l || !has_r || unit_of(li, lj, county) != unit_of(ri, rj, county);
    const size_t inner = pts.size() - 2;
    edge.mtfcc = !has_l || !has_r ? "L4150" // the coast
                 : inner == 0     ? (border ? "P0001" : "S1400")
                 : inner < 9      ? "S1400"
                                  : "H3010";
    edge.tnidf = ids.node(i, j);
    edge.tnidt = vertical ? ids.node(i, j + 1) : ids.node(i + 1, j);
    edge.tlid = lattice_tlid(*this, vertical, i, j, 0);
    const uint64_t e = uint64_t(edge.tlid);
    if (inner >= 6 && unit(hash(m_opt.seed, use_split, e)) < split_p) {
        // At any inner vertex: short edges by junctions, as TIGER has them.
        const size_t mid = 1 + size_t(unit(hash(m_opt.seed, use_split, e, 1)) * double(inner));
        Edge second = edge;
        second.tlid = edge.tlid + 1;
        second.tnidf = ids.split_node(edge.tlid);
        second.points.assign(pts.begin() + std::ptrdiff_t(mid), pts.end());
        edge.tnidt = second.tnidf;
        pts.resize(mid + 1);
        edge.points = std::move(pts);
        out.push_back(std::move(edge));
        out.push_back(std::move(second));
        return;
    }
    edge.points = std::move(pts);
    out.push_back(std::move(edge));
}

/// A cell's shape, and the apex h on its side of each of its edges (corner
/// k -> k + 1) with whether it lies strictly inside its fan triangle: what
/// the dangles, the lake and the internal point keep away from.
struct Nation::CellFrame {
    CellShape shape;
    Pt h[4];
    bool h_ok[4] = {false, false, false, false};
    uint64_t cell = 0;
};

Nation::CellFrame Nation::cell_frame(int i, int j) const
{
    CellFrame f;
    f.shape = cell_shape(i, j);
    f.cell = uint64_t(Ids(*this).cell(i, j));
    const auto& s = f.shape;
    for (int k = 0; k < 4; ++k) {
        f.h[k] = towards(s.corner[k], s.corner[(k + 1) % 4], s.centre);
        f.h_ok[k] = s.convex && strictly_inside(s.corner[k], s.corner[(k + 1) % 4], s.centre, f.h[k]);
    }
    return f;
}

std::vector<std::vector<Pt>> Nation::cell_dangles(int i, int j, const CellFrame& f, std::vector<Edge>& edges_out) const
{
    // A road from corner k toward the centre, strictly inside the wedge
    // between the apexes of the two edges at k and inside the cell's fan
    // triangles at k (README.md says why nothing else can meet it).
    const Ids ids(*this);
    const auto& s = f.shape;
    const Pt c = s.centre;
    const int64_t corner_node[4] = {ids.node(i, j), ids.node(i + 1, j), ids.node(i + 1, j + 1), ids.node(i, j + 1)};
    std::vector<std::vector<Pt>> dangles;
    for (int k = 0; k < 4 && s.convex; ++k) {
        const int prev = (k + 3) % 4;
        const Pt u = s.corner[k];
        if (!f.h_ok[k] || !f.h_ok[prev] || unit(hash(m_opt.seed, use_dangle, f.cell, uint64_t(k))) >= dangle_p ||
            dist(u, c) < 100) {
            continue;
        }
        const double t_end = 0.05 + 0.35 * unit(hash(m_opt.seed, use_dangle, f.cell, 4 + uint64_t(k)));
        const Pt p{std::llround(double(u.x) + t_end * double(c.x - u.x)),
                   std::llround(double(u.y) + t_end * double(c.y - u.y))};
        const Pt next = s.corner[(k + 1) % 4], before = s.corner[prev];
        auto fits = [&](Pt q) { // strictly inside the wedge, and in the fan triangles at u
            const int64_t on = orient(u, c, q);
            const int64_t along = (q.x - u.x) * (c.x - u.x) + (q.y - u.y) * (c.y - u.y);
            return orient(u, f.h[k], q) > 0 && orient(u, q, f.h[prev]) > 0 &&
                   (strictly_inside(u, next, c, q) || strictly_inside(before, u, c, q) ||
                    (on == 0 && along > 0 && along < (c.x - u.x) * (c.x - u.x) + (c.y - u.y) * (c.y - u.y)));
        };
        if (!fits(p)) {
            continue;
        }
        // Up to three vertices between, near the segment, each fitting and
        // each farther along: a road of 2 to 5 vertices.
        std::vector<Pt> road{u};
        const int between = int(unit(hash(m_opt.seed, use_dangle, f.cell, 8 + uint64_t(k))) * 4);
        int64_t last = 0;
        const int64_t end = (p.x - u.x) * (p.x - u.x) + (p.y - u.y) * (p.y - u.y);
        for (int m = 1; m <= between; ++m) {
            const double t = double(m) / (between + 1);
            const double wobble =
                0.08 * (unit(hash(m_opt.seed, use_dangle, f.cell, 16 + 4 * uint64_t(k) + uint64_t(m))) - 0.5);
            const Pt q{std::llround(double(u.x) + t * double(p.x - u.x) - wobble * double(p.y - u.y)),
                       std::llround(double(u.y) + t * double(p.y - u.y) + wobble * double(p.x - u.x))};
            const int64_t along = (q.x - u.x) * (p.x - u.x) + (q.y - u.y) * (p.y - u.y);
            if (along > last && along < end && fits(q)) {
                road.push_back(q);
                last = along;
            }
        }
        road.push_back(p);
        dangles.push_back(road);
        Edge d;
        d.tlid = ids.inner_tlid(i, j, k);
        d.tfidl = d.tfidr = ids.face(i, j, 0);
        d.tnidf = corner_node[k];
        d.tnidt = ids.inner_node(i, j, k);
        d.mtfcc = "S1400";
        d.points = std::move(road);
        edges_out.push_back(std::move(d));
    }
    return dangles;
}

Nation::Lake Nation::cell_lake(const CellFrame& f) const
{
    // A lake around the centre, an island inside it: star-shaped rings in
    // disjoint ranges of radius, inside a disc no edge's triangle reaches
    // and no dangle (which stops 0.6 of the way from the centre to its corner).
    const auto& s = f.shape;
    const Pt c = s.centre;
    Lake lake;
    double min_corner = std::numeric_limits<double>::infinity();
    for (const Pt p : s.corner) {
        min_corner = std::min(min_corner, dist(p, c));
    }
    double radius = 0.45 * min_corner;
    for (int k = 0; k < 4; ++k) {
        const Pt a = s.corner[k], b = s.corner[(k + 1) % 4];
        radius = std::min(radius, 0.8 * std::min({seg_dist(c, a, b), seg_dist(c, a, f.h[k]), seg_dist(c, f.h[k], b)}));
    }
    lake.radius = radius - 3;
    auto ring = [&](double r_min, double r_max, uint64_t which) {
        const int n = 12 + int(unit(hash(m_opt.seed, use_lake, f.cell, which, 1)) * 36);
        const double turn = unit(hash(m_opt.seed, use_lake, f.cell, which, 2));
        std::vector<Pt> pts;
        for (int q = 0; q < n; ++q) {
            const double ang =
                (q + 0.3 * (unit(hash(m_opt.seed, use_lake, f.cell, which, 3 + uint64_t(q))) - 0.5) + turn) /
                n; // in turns
            const double r =
                r_min +
                (r_max - r_min) * (0.5 + 0.5 * sin_turns(3 * ang + turn) *
                                             unit(hash(m_opt.seed, use_lake, f.cell, which, 1000 + uint64_t(q))));
            pts.push_back({c.x + std::llround(r * cos_turns(ang)), c.y + std::llround(r * sin_turns(ang))});
        }
        for (int q = 0; q < n; ++q) {
            if (orient(c, pts[size_t(q)], pts[size_t((q + 1) % n)]) <= 0) {
                return std::vector<Pt>{}; // rounding turned it: no ring
            }
        }
        pts.push_back(pts.front());
        return pts;
    };
    if (s.convex && lake.radius >= 40 && unit(hash(m_opt.seed, use_lake, f.cell, 0)) < lake_p) {
        lake.lake = ring(0.6 * lake.radius, 0.9 * lake.radius, 1);
        if (!lake.lake.empty() && unit(hash(m_opt.seed, use_lake, f.cell, 2)) < island_p) {
            lake.island = ring(0.12 * lake.radius, 0.38 * lake.radius, 3);
        }
    }
    return lake;
}

void Nation::cell_faces(int i, int j, const CellFrame& f, const Polyline* sides[4],
                        const std::vector<std::vector<Pt>>& dangles, const Lake& lake,
                        std::vector<Face>& faces_out) const
{
    const Ids ids(*this);
    const Pt c = f.shape.centre;
    const uint32_t blk = unit_of(i, j, block);
    auto face = [&](int k, bool water, Pt intpt, std::vector<std::vector<Pt>> rings) {
        Face out;
        out.tfid = ids.face(i, j, k);
        out.block = blk;
        out.water = water;
        out.intpt = intpt;
        out.rings = std::move(rings);
        faces_out.push_back(std::move(out));
    };
    // The land: the four lattice edges counter-clockwise, the lake a hole.
    std::vector<Pt> outer;
    auto append = [&](const Polyline& pts, bool reverse) {
        const size_t skip = outer.empty() ? 0 : 1; // the node the last side ended at
        if (reverse) {
            outer.insert(outer.end(), pts.rbegin() + std::ptrdiff_t(skip), pts.rend());
        } else {
            outer.insert(outer.end(), pts.begin() + std::ptrdiff_t(skip), pts.end());
        }
    };
    append(*sides[0], false);
    append(*sides[1], false);
    append(*sides[2], true);
    append(*sides[3], true);
    std::vector<std::vector<Pt>> rings{std::move(outer)};
    if (!lake.lake.empty()) {
        rings.push_back(lake.lake);
    }
    // Its internal point: 0.85 of the way from the centre to an edge's apex
    // (outside that edge's triangle and the lake's disc), on no dangle.
    Pt intpt = c;
    for (int k = 0; k < 4; ++k) {
        const Pt p{std::llround(double(c.x) + 0.85 * double(f.h[k].x - c.x)),
                   std::llround(double(c.y) + 0.85 * double(f.h[k].y - c.y))};
        bool on_dangle = false;
        for (const auto& road : dangles) {
            for (size_t m = 0; m + 1 < road.size(); ++m) {
                on_dangle = on_dangle || orient(road[m], road[m + 1], p) == 0;
            }
        }
        if (f.h_ok[k] && !on_dangle && p != c) {
            intpt = p;
            break;
        }
    }
    face(0, false, intpt, std::move(rings));
    if (lake.lake.empty()) {
        return;
    }
    if (lake.island.empty()) {
        face(1, true, c, {lake.lake});
        return;
    }
    // The lake's point lies between the island's largest radius and the lake's chords.
    const Pt v = lake.lake.front();
    const double r = dist(v, c);
    face(1, true,
         {c.x + std::llround(double(v.x - c.x) * 0.5 * lake.radius / r),
          c.y + std::llround(double(v.y - c.y) * 0.5 * lake.radius / r)},
         {lake.lake, lake.island});
    face(2, false, c, {lake.island});
}

void Nation::cell_inner(int i, int j, const Polyline* sides[4], std::vector<Edge>& edges_out,
                        std::vector<Face>& faces_out) const
{
    const Ids ids(*this);
    const CellFrame f = cell_frame(i, j);
    const auto dangles = cell_dangles(i, j, f, edges_out);
    const Lake lake = cell_lake(f);
    // A ring edge (its node at both ends), its left face inside.
    auto ring_edge = [&](int k, int64_t inside, int64_t outside, const std::vector<Pt>& pts) {
        Edge e;
        e.tlid = ids.inner_tlid(i, j, k);
        e.tfidl = inside;
        e.tfidr = outside;
        e.tnidf = e.tnidt = ids.inner_node(i, j, k);
        e.mtfcc = "H2030";
        e.points = pts;
        edges_out.push_back(std::move(e));
    };
    if (!lake.lake.empty()) {
        ring_edge(4, ids.face(i, j, 1), ids.face(i, j, 0), lake.lake);
        if (!lake.island.empty()) {
            ring_edge(5, ids.face(i, j, 2), ids.face(i, j, 1), lake.island);
        }
    }
    cell_faces(i, j, f, sides, dangles, lake, faces_out);
}

Nation::CountyParts Nation::county_parts(uint32_t county_index) const
{
    CountyParts out;
    // Each lattice polyline once: a cell's sides, shared with the next
    // cell of the county, and its edges in the file.
    std::unordered_map<uint64_t, Polyline> cache;
    auto side = [&](bool vertical, int i, int j) -> const Polyline& {
        const uint64_t key = (uint64_t(uint32_t(j)) << 33) | (uint64_t(uint32_t(i)) << 1) | (vertical ? 1 : 0);
        auto it = cache.find(key);
        if (it == cache.end()) {
            it = cache.emplace(key, lattice_polyline(vertical, i, j)).first;
        }
        return it->second;
    };
    for (const uint32_t cell : m_county_cells.at(county_index)) {
        const int i = int(cell % uint32_t(m_w)), j = int(cell / uint32_t(m_w));
        const Polyline* sides[4] = {&side(false, i, j), &side(true, i + 1, j), &side(false, i, j + 1),
                                    &side(true, i, j)};
        lattice_edge(false, i, j, *sides[0], out.edges); // bottom
        lattice_edge(true, i, j, *sides[3], out.edges);  // left
        if (j + 1 >= m_h || unit_of(i, j + 1, county) != county_index) {
            lattice_edge(false, i, j + 1, *sides[2], out.edges); // top, unless the cell above writes it as its bottom
        }
        if (i + 1 >= m_w || unit_of(i + 1, j, county) != county_index) {
            lattice_edge(true, i + 1, j, *sides[1], out.edges);
        }
        cell_inner(i, j, sides, out.edges, out.faces);
    }
    return out;
}

} // namespace tigerlod::synth
