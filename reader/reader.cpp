#include "reader/reader.hpp"

#include "core/digest.hpp"
#include "core/errors.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fcntl.h>
#include <functional>
#include <limits>
#include <optional>
#include <set>
#include <sys/stat.h>
#include <thread>
#include <unordered_map>
#include <unistd.h>

namespace tigerlod::reader {

namespace {

/// A file descriptor closed on scope exit.
struct Fd {
    int fd = -1;
    explicit Fd(int f) : fd(f) {}
    ~Fd()
    {
        if (fd >= 0) {
            ::close(fd);
        }
    }
    Fd(const Fd&) = delete;
    Fd& operator=(const Fd&) = delete;
};

/// Read exactly `n` bytes at `offset`; false on a short read or an error.
bool read_at(int fd, char* out, size_t n, uint64_t offset)
{
    while (n > 0) {
        const ssize_t got = ::pread(fd, out, n, static_cast<off_t>(offset));
        if (got < 0 && errno == EINTR) {
            continue;
        }
        if (got <= 0) {
            return false;
        }
        out += got;
        n -= static_cast<size_t>(got);
        offset += static_cast<uint64_t>(got);
    }
    return true;
}

std::string node_name(const datatree::Skeleton& s, uint32_t node)
{
    const auto& code = s.strings[s.nodes[node].code];
    return "node " + std::to_string(node) + (code.empty() ? std::string(" (root)") : " (" + code + ")");
}

} // namespace

std::shared_ptr<Tree> Tree::open(const std::filesystem::path& dir, std::string& error)
{
    const auto path = dir / "skeleton.tls";
    Fd f(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
    struct stat st {};
    if (f.fd < 0 || ::fstat(f.fd, &st) != 0) {
        error = path.string() + ": cannot open: " + std::strerror(errno);
        return nullptr;
    }
    std::string bytes(static_cast<size_t>(st.st_size), '\0');
    if (!read_at(f.fd, bytes.data(), bytes.size(), 0)) {
        error = path.string() + ": cannot read";
        return nullptr;
    }
    std::shared_ptr<Tree> t(new Tree);
    try {
        t->m_skeleton = datatree::decode_skeleton(std::as_bytes(std::span(bytes.data(), bytes.size())), path.string());
    } catch (const std::exception& e) {
        error = e.what();
        return nullptr;
    }
    t->m_dir = dir;
    t->m_skeleton_bytes = bytes.size();
    const auto& nodes = t->m_skeleton.nodes;
    for (uint32_t n = 1; n < nodes.size(); ++n) {
        // A unit's node shows the level below the map that has the unit (a
        // line layer's tiles are of their root's level, and units of none).
        if (nodes[n].level > nodes[nodes[n].parent].level) {
            t->m_unit_node.emplace(std::pair{nodes[n].level - 1, t->m_skeleton.strings[nodes[n].code]}, n);
        }
    }
    return t;
}

uint32_t Tree::unit_node(uint32_t map_level, const std::string& code) const
{
    const auto it = m_unit_node.find({map_level, code});
    return it == m_unit_node.end() ? datatree::no_node : it->second;
}

uint64_t Tree::skeleton_memory() const noexcept
{
    const auto& s = m_skeleton;
    auto string_heap = [](const std::string& str) { return str.capacity() > 15 ? str.capacity() + 1 : 0; };
    uint64_t n = sizeof(Tree) + s.nodes.capacity() * sizeof(datatree::Node) +
                 s.tiles.capacity() * sizeof(datatree::Tile) + s.strings.capacity() * sizeof(std::string) +
                 s.level_names.capacity() * sizeof(std::string) + s.lod_eps_m.capacity() * sizeof(double);
    for (const auto& node : s.nodes) {
        n += node.lods.capacity() * sizeof(datatree::LodInfo);
    }
    for (const auto& str : s.strings) {
        n += string_heap(str);
    }
    for (const auto& str : s.level_names) {
        n += string_heap(str);
    }
    for (const auto& t : s.tiles) {
        n += string_heap(t.file);
    }
    // A std::map node: three pointers and a colour, then the key and value.
    for (const auto& [key, node] : m_unit_node) {
        n += 4 * sizeof(void*) + sizeof(key) + sizeof(node) + string_heap(key.second);
    }
    return n;
}

void Tree::simulate_disk(std::chrono::microseconds latency, double bytes_per_second)
{
    m_latency = latency;
    m_bytes_per_second = bytes_per_second;
}

uint64_t Tree::tree_bytes() const noexcept
{
    uint64_t n = m_skeleton_bytes;
    for (const auto& t : m_skeleton.tiles) {
        n += t.size;
    }
    return n;
}

GridPoint Tree::origin(uint32_t node) const noexcept
{
    const auto& b = m_skeleton.nodes[node].box;
    return {b.min_x, b.min_y};
}

Status Tree::read_payload(uint32_t node, int lod, std::string& bytes) const
{
    const auto& s = m_skeleton;
    if (node >= s.nodes.size() || lod < -1 || lod >= static_cast<int>(s.lod_eps_m.size())) {
        return {"no node " + std::to_string(node) + " LOD " + std::to_string(lod) + " in " + m_dir.string()};
    }
    const auto& ref = lod < 0 ? s.nodes[node].table : s.nodes[node].lods[static_cast<size_t>(lod)].payload;
    const auto& tile = s.tiles[ref.tile];
    const auto path = m_dir / tile.file;
    const std::string where = path.string() + ": " + node_name(s, node) +
                              (lod < 0 ? std::string(" chain table") : " LOD " + std::to_string(lod)) + ": ";
    Fd f(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
    struct stat st {};
    if (f.fd < 0 || ::fstat(f.fd, &st) != 0) {
        return {where + "cannot open: " + std::strerror(errno)};
    }
    char header[datatree::tile_header_size];
    if (!read_at(f.fd, header, sizeof header, 0)) {
        return {where + "truncated tile: no header"};
    }
    try {
        datatree::check_tile_header(std::as_bytes(std::span(header)), static_cast<uint64_t>(st.st_size), path.string());
    } catch (const std::exception& e) {
        return {where + e.what()};
    }
    if (static_cast<uint64_t>(st.st_size) != tile.size) {
        return {where + "tile has " + std::to_string(st.st_size) + " bytes, the skeleton says " +
                std::to_string(tile.size)};
    }
    bytes.resize(ref.size);
    if (!read_at(f.fd, bytes.data(), ref.size, ref.offset)) {
        return {where + "payload past the end of the tile"};
    }
    if (crc32(std::as_bytes(std::span(bytes.data(), bytes.size()))) != ref.crc) {
        return {where + "checksum mismatch"};
    }
    if (m_latency.count() > 0 || m_bytes_per_second > 0) {
        const double transfer = m_bytes_per_second > 0 ? double(ref.size) / m_bytes_per_second : 0.0;
        std::this_thread::sleep_for(
            m_latency + std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::duration<double>(transfer)));
    }
    return {};
}

Status Tree::read_units(uint32_t node, datatree::UnitTable& out) const
{
    const auto& s = m_skeleton;
    out = {};
    if (node >= s.nodes.size()) {
        return {"no node " + std::to_string(node) + " in " + m_dir.string()};
    }
    if (s.minor < 2) {
        return {};
    }
    const auto& n = s.nodes[node];
    const auto& tile = s.tiles[n.lods.empty() ? n.table.tile : n.lods.back().payload.tile];
    const auto path = m_dir / tile.file;
    const std::string name = path.string() + ": " + node_name(s, node) + " units";
    const std::string where = name + ": ";
    Fd f(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
    struct stat st {};
    if (f.fd < 0 || ::fstat(f.fd, &st) != 0) {
        return {where + "cannot open: " + std::strerror(errno)};
    }
    if (static_cast<uint64_t>(st.st_size) != tile.size) {
        return {where + "tile has " + std::to_string(st.st_size) + " bytes, the skeleton says " +
                std::to_string(tile.size)};
    }
    const uint64_t at = datatree::units_at(n);
    char head[datatree::units_head_size];
    if (at > tile.size || tile.size - at < sizeof head || !read_at(f.fd, head, sizeof head, at)) {
        return {where + "no units payload after the last LOD's (past the end of the tile)"};
    }
    try {
        const auto [size, crc] = datatree::units_body(std::as_bytes(std::span(head)), name);
        if (size > tile.size - at - sizeof head) {
            return {where + "units payload past the end of the tile"};
        }
        std::string body(size, '\0');
        if (!read_at(f.fd, body.data(), size, at + sizeof head)) {
            return {where + "units payload past the end of the tile"};
        }
        const auto bytes = std::as_bytes(std::span(body.data(), body.size()));
        if (crc32(bytes) != crc) {
            return {where + "checksum mismatch"};
        }
        out = datatree::decode_units(bytes, origin(node), name);
    } catch (const std::exception& e) {
        out = {};
        return {e.what()};
    }
    return {};
}

Status Tree::read_geometry(uint32_t node, uint32_t lod, datatree::Geometry& out) const
{
    std::string bytes;
    if (Status st = read_payload(node, static_cast<int>(lod), bytes); !st.ok()) {
        return st;
    }
    const auto& n = m_skeleton.nodes[node];
    try {
        out = datatree::decode_geometry(std::as_bytes(std::span(bytes.data(), bytes.size())), origin(node), n.chains,
                                        n.lods[lod].vertices,
                                        (m_dir / m_skeleton.tiles[n.lods[lod].payload.tile].file).string() + ": " +
                                            node_name(m_skeleton, node) + " LOD " + std::to_string(lod));
    } catch (const std::exception& e) {
        return {e.what()};
    }
    return {};
}

Status Tree::read_table(uint32_t node, datatree::ChainTable& out) const
{
    std::string bytes;
    if (Status st = read_payload(node, -1, bytes); !st.ok()) {
        return st;
    }
    const auto& n = m_skeleton.nodes[node];
    try {
        out = datatree::decode_table(std::as_bytes(std::span(bytes.data(), bytes.size())),
                                     (m_dir / m_skeleton.tiles[n.table.tile].file).string() + ": " +
                                         node_name(m_skeleton, node) + " chain table");
    } catch (const std::exception& e) {
        return {e.what()};
    }
    if (out.chains.size() != n.chains) {
        return {m_dir.string() + ": " + node_name(m_skeleton, node) + ": chain table has " +
                std::to_string(out.chains.size()) + " chains, the skeleton says " + std::to_string(n.chains)};
    }
    return {};
}

// --- front selection -----------------------------------------------------------------------------

namespace {

struct Rect {
    double min_x, min_y, max_x, max_y;
};

Rect view_rect(const View& v, double margin)
{
    const double hw = 0.5 * v.width * v.units_per_pixel * (1.0 + 2.0 * margin);
    const double hh = 0.5 * v.height * v.units_per_pixel * (1.0 + 2.0 * margin);
    return {v.center_x - hw, v.center_y - hh, v.center_x + hw, v.center_y + hh};
}

bool visible(const datatree::Box& b, const Rect& r)
{
    return b.min_x <= r.max_x && r.min_x <= b.max_x && b.min_y <= r.max_y && r.min_y <= b.max_y;
}

void traverse(const datatree::Skeleton& s, uint32_t node, const View& view, const Rect& rect,
              const FrontOptions& options, std::vector<FrontItem>& out)
{
    const auto& n = s.nodes[node];
    if (!visible(n.box, rect)) {
        return;
    }
    const double w = (double(n.box.max_x) - n.box.min_x) / view.units_per_pixel;
    const double h = (double(n.box.max_y) - n.box.min_y) / view.units_per_pixel;
    // A node without chains (the root of a line layer in tiles) is never drawn itself.
    if (n.child_count == 0 || (n.chains > 0 && w * h < options.node_fraction * double(view.width) * view.height)) {
        out.push_back({node, select_lod(s, node, view, options)});
        return;
    }
    for (uint32_t c = n.first_child; c < n.first_child + n.child_count; ++c) {
        traverse(s, c, view, rect, options, out);
    }
}

} // namespace

datatree::Box main_extent(const Tree& tree, double fraction)
{
    const auto& s = tree.skeleton();
    const datatree::Box root = s.nodes.front().box;
    uint32_t deepest = 0;
    for (const auto& n : s.nodes) {
        deepest = std::max(deepest, n.level);
    }
    std::vector<int64_t> xs, ys;
    for (uint32_t i = 0; i < s.nodes.size(); ++i) {
        if (s.nodes[i].level != deepest) {
            continue;
        }
        datatree::UnitTable t;
        if (tree.read_units(i, t).ok() && !t.units.empty()) {
            for (const auto& u : t.units) {
                xs.push_back(u.point.x);
                ys.push_back(u.point.y);
            }
        }
    }
    if (xs.empty()) { // no units payloads (a line layer, a tree before 2.2): the leaves' centres
        for (const auto& n : s.nodes) {
            if (n.child_count == 0 && n.chains > 0) {
                xs.push_back((int64_t{n.box.min_x} + n.box.max_x) / 2);
                ys.push_back((int64_t{n.box.min_y} + n.box.max_y) / 2);
            }
        }
    }
    if (xs.size() < 20 || !(fraction > 0 && fraction <= 1)) {
        return root;
    }
    auto range = [&](std::vector<int64_t>& v, int32_t lo_limit, int32_t hi_limit) {
        std::sort(v.begin(), v.end());
        const double cut = (1 - fraction) / 2 * double(v.size() - 1);
        const int64_t lo = v[static_cast<size_t>(std::floor(cut))];
        const int64_t hi = v[static_cast<size_t>(std::ceil(double(v.size() - 1) - cut))];
        const int64_t pad = (hi - lo) / 20;
        return std::pair{static_cast<int32_t>(std::max<int64_t>(lo - pad, lo_limit)),
                         static_cast<int32_t>(std::min<int64_t>(hi + pad, hi_limit))};
    };
    const auto [x0, x1] = range(xs, root.min_x, root.max_x);
    const auto [y0, y1] = range(ys, root.min_y, root.max_y);
    // The nodes of the finest map whose boxes centre in that range, whole:
    // the main part's own outline, not the cloud of its units' points.
    datatree::Box out{INT32_MAX, INT32_MAX, INT32_MIN, INT32_MIN};
    for (const auto& n : s.nodes) {
        const int64_t cx = (int64_t{n.box.min_x} + n.box.max_x) / 2, cy = (int64_t{n.box.min_y} + n.box.max_y) / 2;
        if (n.level == deepest && n.chains > 0 && cx >= x0 && cx <= x1 && cy >= y0 && cy <= y1) {
            out = {std::min(out.min_x, n.box.min_x), std::min(out.min_y, n.box.min_y), std::max(out.max_x, n.box.max_x),
                   std::max(out.max_y, n.box.max_y)};
        }
    }
    return out.min_x < out.max_x && out.min_y < out.max_y ? out : root;
}

uint32_t select_lod(const datatree::Skeleton& s, uint32_t node, const View& view, const FrontOptions& options)
{
    const double metres_per_pixel = view.units_per_pixel * s.grid_m();
    const auto& lods = s.nodes[node].lods;
    for (size_t i = lods.size(); i-- > 1;) {
        if (lods[i].error_m / metres_per_pixel < options.pixel_error) {
            return static_cast<uint32_t>(i);
        }
    }
    return 0;
}

std::vector<FrontItem> select_front(const datatree::Skeleton& s, const View& view, const FrontOptions& options)
{
    std::vector<FrontItem> out;
    if (!s.nodes.empty() && view.units_per_pixel > 0 && view.width > 0 && view.height > 0) {
        traverse(s, 0, view, view_rect(view, 0.0), options, out);
    }
    return out;
}

// --- what to draw -----------------------------------------------------------------------------------

NodeChains node_chains(const Tree& tree, uint32_t node, const datatree::ChainTable& table)
{
    const auto& s = tree.skeleton();
    const auto& n = s.nodes[node];
    NodeChains out;
    out.ids.reserve(table.chains.size());
    out.flags.reserve(table.chains.size());
    out.across.reserve(table.chains.size());
    for (const auto& c : table.chains) {
        out.ids.push_back(c.id);
        out.flags.push_back(c.flags);
        uint32_t across = datatree::no_node;
        for (const uint32_t side : {c.left, c.right}) {
            const std::string& code = table.strings[side];
            if (code.empty()) {
                continue;
            }
            // A unit of this map with a node: a child of this node's, or a neighbour's across the outline.
            const uint32_t u = tree.unit_node(n.level, code);
            if (u != datatree::no_node && s.nodes[u].parent != node) {
                across = u;
            }
        }
        out.across.push_back(across);
    }
    return out;
}

std::vector<DrawChain> draw_list(const datatree::Skeleton& s, const std::vector<Drawable>& front)
{
    auto ready = [&](const Drawable& d) { return d.geometry && d.chains; };
    // Each front node and every node above one: whether all front nodes at or below it are ready.
    std::unordered_map<uint32_t, bool> covered;
    for (const auto& d : front) {
        for (uint32_t n = d.wanted.node; n != datatree::no_node; n = s.nodes[n].parent) {
            auto [it, fresh] = covered.try_emplace(n, ready(d));
            it->second = it->second && ready(d);
        }
    }
    auto left_to_finer = [&](uint32_t across) {
        if (across == datatree::no_node) {
            return false;
        }
        const auto it = covered.find(across);
        return it != covered.end() && it->second;
    };
    // (level, chain id) -> the item that draws it: the finer LOD, then the earlier item.
    struct Key {
        uint32_t level;
        uint64_t id;
        bool operator==(const Key&) const = default;
    };
    struct KeyHash {
        size_t operator()(const Key& k) const noexcept { return std::hash<uint64_t>()(k.id * 31 + k.level); }
    };
    std::unordered_map<Key, uint32_t, KeyHash> drawer;
    for (uint32_t i = 0; i < front.size(); ++i) {
        const auto& d = front[i];
        if (!ready(d)) {
            continue;
        }
        const uint32_t level = s.nodes[d.wanted.node].level;
        for (size_t k = 0; k < d.chains->ids.size(); ++k) {
            if (left_to_finer(d.chains->across[k])) {
                continue;
            }
            auto [it, fresh] = drawer.try_emplace(Key{level, d.chains->ids[k]}, i);
            if (!fresh && d.lod < front[it->second].lod) {
                it->second = i;
            }
        }
    }
    std::vector<DrawChain> out;
    for (uint32_t i = 0; i < front.size(); ++i) {
        const auto& d = front[i];
        if (!ready(d)) {
            continue;
        }
        const uint32_t level = s.nodes[d.wanted.node].level;
        for (uint32_t k = 0; k < d.chains->ids.size(); ++k) {
            if (left_to_finer(d.chains->across[k])) {
                continue;
            }
            if (drawer.at(Key{level, d.chains->ids[k]}) == i) {
                out.push_back({i, k});
            }
        }
    }
    return out;
}

LineStyle line_style(uint32_t level, uint32_t levels) noexcept
{
    if (levels <= 1) {
        return {1.0F, 60, 60, 60};
    }
    static constexpr LineStyle styles[] = {
        {3.0F, 0, 0, 0}, {2.4F, 30, 30, 30}, {1.4F, 110, 110, 110}, {1.0F, 150, 150, 150}, {1.0F, 185, 185, 185}};
    constexpr uint32_t n = sizeof styles / sizeof styles[0];
    return styles[std::min(level, n - 1)];
}

// --- streamer -------------------------------------------------------------------------------------

Streamer::Streamer(std::shared_ptr<const Tree> tree, StreamOptions options)
    : m_tree(std::move(tree)), m_options(options), m_thread([this] { run(); })
{
}

Streamer::~Streamer()
{
    {
        std::lock_guard lock(m_mutex);
        m_stop = true;
    }
    m_work.notify_all();
    m_thread.join();
}

size_t Streamer::charge(FrontItem item) const
{
    const auto& n = m_tree->skeleton().nodes[item.node];
    if (item.lod == table_lod) {
        return NodeChains::bytes(n.chains);
    }
    return datatree::geometry_bytes(n.chains, n.lods[item.lod].vertices);
}

size_t Streamer::in_flight_cost(FrontItem item) const
{
    const auto& n = m_tree->skeleton().nodes[item.node];
    if (item.lod == table_lod) {
        // While decoding: the payload bytes, the decoded table (its entries,
        // and at most one string per payload byte: a string object and its
        // characters), and the result.
        const uint64_t payload = n.table.size;
        return charge(item) + payload + n.chains * sizeof(datatree::ChainTable::Entry) +
               payload * (sizeof(std::string) + 1) + payload;
    }
    // While decoding: the payload bytes, Draco's attribute buffer and our copy
    // of the new points (each at most 8 bytes a vertex), and the result.
    const auto& lod = n.lods[item.lod];
    return charge(item) + lod.payload.size + 2 * lod.vertices * sizeof(GridPoint);
}

namespace {

/// A prefetch candidate and how soon the views are likely to need it
/// (smaller: sooner).
struct Candidate {
    double score = 0;
    FrontItem item;
};

/// The view zoomed by `factor` (above 1: out) about its centre.
View zoomed(View v, double factor)
{
    v.units_per_pixel *= factor;
    return v;
}

/// The camera's motion from the last view to this one: the zoom in
/// doublings of the scale (above 0: out) and the pan in grid units.
struct Motion {
    bool moving = false;
    double zoom = 0, dx = 0, dy = 0;
};

Motion motion_of(const std::optional<View>& last, const View& view)
{
    Motion m;
    if (!last || !(last->units_per_pixel > 0) || !(view.units_per_pixel > 0) || last->width != view.width ||
        last->height != view.height) {
        return m;
    }
    m.zoom = std::log2(view.units_per_pixel / last->units_per_pixel);
    m.dx = view.center_x - last->center_x;
    m.dy = view.center_y - last->center_y;
    const double pixel = view.units_per_pixel;
    m.moving = std::abs(m.zoom) > 1e-6 || std::abs(m.dx) > 1e-3 * pixel || std::abs(m.dy) > 1e-3 * pixel;
    return m;
}

/// The views the prefetch list looks ahead to while the camera moves: the
/// last motion kept up for this many views. Always the first three; the
/// further ones only where the disk needs the time (see prefetch_candidates):
/// looking far ahead always loads what a turn of the camera leaves unused (on
/// the reader test's zoom-pan-zoom path under a budget that binds, 1.14x the
/// loads without prefetching looking 4 views ahead, 1.39x at 8 and 1.68x at
/// 16, for the same misses).
constexpr int lookahead[] = {1, 2, 4, 8, 16, 32};
constexpr size_t always_ahead = 3;

/// What prefetch_candidates knows of the disk and the caller's pace.
struct Pace {
    double load_seconds = 0; ///< the mean time a load takes lately (0: none yet)
    double view_seconds = 0; ///< between the last views (0: not known)
    int max_views = 32;      ///< StreamOptions::max_lookahead_views
    /// The budget's room beside the front; a payload's bytes. The list looks
    /// past 4 views only while what those views bring fits in half the
    /// room: under a budget that binds, the front would evict it before it
    /// is drawn (on the 100 M nation at 10 MiB, 591 evictions against 297,
    /// and a worse p95 than no prefetching).
    uint64_t room = 0;
    std::function<uint64_t(FrontItem)> bytes;
};

/// Candidates by score, ties by item.
std::vector<Candidate> sorted(const std::map<FrontItem, double>& best)
{
    std::vector<Candidate> out;
    out.reserve(best.size());
    for (const auto& [item, score] : best) {
        out.push_back({score, item});
    }
    std::stable_sort(out.begin(), out.end(), [](const Candidate& a, const Candidate& b) { return a.score < b.score; });
    return out;
}

/// The prefetch candidates of a front, each once at its lowest score, in
/// order of score (ties by item).
/// - While the camera moves, the fronts of the views ahead (the last
///   motion kept up for 1, 2 and 4 views: `lookahead`): an item's score is the
///   first of those it is in. Zooms, pans and the LOD and node switches
///   they bring are all Algorithm 6.1's own on those views, so what is
///   loaded is what those views will draw, not what this view's neighbours
///   would be at this scale.
/// - While it stands still (the first view, or the same view again),
///   Section 6.2.2's events, scored
///   by how far the view must go before Algorithm 6.1 picks the item (the
///   paper's priority by closeness to the thresholds): a zoom in doublings
///   to the parent or the children (semantic switches) or to the coarser
///   or finer LOD (geometric), a pan in sides of the view to the front of a
///   view widened by `margin` of its size on each side (visibility events).
std::vector<Candidate> prefetch_candidates(const datatree::Skeleton& s, const View& view,
                                           const std::vector<FrontItem>& front, const FrontOptions& options,
                                           double margin, const Motion& motion, const Pace& pace)
{
    std::map<FrontItem, double> best;
    const std::set<FrontItem> in_front(front.begin(), front.end());
    auto want = [&](FrontItem it, double score) {
        if (in_front.contains(it) || !std::isfinite(score)) {
            return;
        }
        const auto [pos, fresh] = best.emplace(it, score);
        if (!fresh) {
            pos->second = std::min(pos->second, score);
        }
    };
    if (motion.moving) {
        // The views ahead. Past the first three, the view t ahead is looked
        // at only when what the views up to it bring into the front (each
        // item a load at the disk's recent time, resident or not, so that
        // the horizon holds while they come) would take longer than the
        // views there would be left to load it in had the list stopped one
        // step nearer (t / 2 views). So a switch that brings many nodes at
        // once (state to county) is loaded early enough, and the list looks
        // no further than the disk needs. With a fast disk, the first three alone.
        std::map<FrontItem, double> ahead_items;
        double loads = 0;    // the loads the views ahead need, so far
        uint64_t weight = 0; // and their bytes
        size_t last = always_ahead;
        for (size_t k = 0; k < std::size(lookahead) && (k < always_ahead || lookahead[k] <= pace.max_views); ++k) {
            const int t = lookahead[k];
            View ahead = view;
            ahead.units_per_pixel *= std::exp2(motion.zoom * t);
            ahead.center_x += motion.dx * t;
            ahead.center_y += motion.dy * t;
            for (const auto& f : select_front(s, ahead, options)) {
                if (!in_front.contains(f) && ahead_items.emplace(f, t).second) {
                    loads += 1; // resident or not: what the views bring, so the horizon holds while they come
                    weight += pace.bytes(f);
                }
            }
            if (k >= always_ahead && 2 * weight > pace.room) {
                break;
            }
            if (k >= always_ahead && pace.view_seconds > 0 &&
                loads * pace.load_seconds > lookahead[k - 1] * pace.view_seconds) {
                last = k + 1;
            }
        }
        for (const auto& [item, t] : ahead_items) {
            if (t <= lookahead[last - 1]) {
                want(item, t);
            }
        }
        // The events too would load what the turns of a path leave unused
        // (2.1x the loads without prefetching on that path, not 1.14x).
        return sorted(best);
    }
    const double mpp = view.units_per_pixel * s.grid_m();
    const double pe = options.pixel_error;
    const double screen = options.node_fraction * double(view.width) * view.height;
    auto pixel_area = [&](const datatree::Box& b) {
        return ((double(b.max_x) - b.min_x) / view.units_per_pixel) *
               ((double(b.max_y) - b.min_y) / view.units_per_pixel);
    };
    auto event = [&](FrontItem it, double doublings) { want(it, std::max(doublings, 0.0)); };
    for (const auto& f : front) {
        const auto& n = s.nodes[f.node];
        const auto nlods = static_cast<uint32_t>(n.lods.size());
        // LOD k is drawn while error(k) / mpp < pe <= error(k + 1) / mpp.
        if (f.lod > 0 && n.lods[f.lod].error_m > 0) {
            event({f.node, f.lod - 1}, std::log2(mpp * pe / n.lods[f.lod].error_m));
        }
        if (f.lod + 1 < nlods && pe > 0) {
            event({f.node, f.lod + 1}, std::log2(n.lods[f.lod + 1].error_m / (pe * mpp)));
        }
        // A node is drawn itself while its box covers less than `screen`:
        // its children replace it after a zoom in by sqrt(screen / area).
        if (const double area = pixel_area(n.box); n.child_count > 0 && area > 0) {
            const double z = std::sqrt(screen / area);
            for (uint32_t c = n.first_child; c < n.first_child + n.child_count; ++c) {
                event({c, select_lod(s, c, zoomed(view, 1 / z), options)}, std::log2(z));
            }
        }
        // Its parent replaces it after a zoom out by sqrt(area / screen).
        if (n.parent != datatree::no_node && s.nodes[n.parent].chains > 0 && screen > 0) {
            const double z = std::max(std::sqrt(pixel_area(s.nodes[n.parent].box) / screen), 1.0);
            event({n.parent, select_lod(s, n.parent, zoomed(view, z), options)}, std::log2(z));
        }
    }
    if (margin > 0) {
        View wide = view;
        wide.width = static_cast<uint32_t>(std::ceil(view.width * (1.0 + 2.0 * margin)));
        wide.height = static_cast<uint32_t>(std::ceil(view.height * (1.0 + 2.0 * margin)));
        const Rect r = view_rect(view, 0.0);
        const double side = std::max(r.max_x - r.min_x, r.max_y - r.min_y);
        for (const auto& f : select_front(s, wide, options)) {
            const auto& b = s.nodes[f.node].box;
            const double gap =
                std::max({0.0, r.min_x - b.max_x, b.min_x - r.max_x, r.min_y - b.max_y, b.min_y - r.max_y});
            event(f, side > 0 ? gap / side : 0.0);
        }
    }
    return sorted(best);
}

} // namespace

std::vector<FrontItem> Streamer::set_view(const View& view)
{
    const auto& s = m_tree->skeleton();
    std::vector<FrontItem> front = select_front(s, view, m_options.front);
    // The front, each node's chain table before its first payload (a payload
    // without it cannot be drawn; tables are small: a few bytes a chain).
    std::vector<FrontItem> wanted;
    wanted.reserve(2 * front.size());
    std::set<uint32_t> tabled;
    uint64_t front_bytes = 0;
    for (const auto& f : front) {
        if (tabled.insert(f.node).second) {
            wanted.push_back({f.node, table_lod});
            front_bytes += charge(wanted.back());
        }
        wanted.push_back(f);
        front_bytes += charge(f);
    }
    const size_t front_ranks = wanted.size();
    // Then what to load ahead, soonest needed first, as much as fits beside
    // the front: the list is cut where the next item would not fit, so a
    // prefetch never has to push out another wanted payload (run() lets it
    // evict only what nothing wants), and under a budget that binds the
    // list stays what the budget can hold rather than churning through it.
    bool cut = false;
    if (m_options.prefetch) {
        // (m_last_view is set_view's alone: a streamer's views come from one thread.)
        const uint64_t room = m_options.budget_bytes > front_bytes ? m_options.budget_bytes - front_bytes : 0;
        uint64_t used = 0;
        const Motion motion = motion_of(m_last_view, view);
        Pace pace;
        pace.max_views = m_options.max_lookahead_views;
        pace.room = room;
        pace.bytes = [this](FrontItem it) { return uint64_t{charge(it)}; };
        const auto now = std::chrono::steady_clock::now();
        {
            std::lock_guard lock(m_mutex);
            pace.load_seconds = m_load_seconds;
            pace.view_seconds = m_last_view ? std::chrono::duration<double>(now - m_last_time).count() : 0.0;
        }
        m_last_time = now;
        for (const auto& c :
             prefetch_candidates(s, view, front, m_options.front, m_options.prefetch_margin, motion, pace)) {
            const bool table = !tabled.contains(c.item.node);
            const uint64_t bytes = charge(c.item) + (table ? charge({c.item.node, table_lod}) : 0);
            if (used + bytes > room) {
                cut = true;
                break;
            }
            used += bytes;
            if (table) {
                tabled.insert(c.item.node);
                wanted.push_back({c.item.node, table_lod});
            }
            wanted.push_back(c.item);
        }
    }
    {
        std::lock_guard lock(m_mutex);
        m_front = front;
        m_front_ranks = front_ranks;
        m_wanted = std::move(wanted);
        m_rank.clear();
        for (size_t i = 0; i < m_wanted.size(); ++i) {
            m_rank.emplace(m_wanted[i], i);
        }
        m_cursor = 0;
        m_stats.prefetch_cuts += cut ? 1 : 0;
        m_last_view = view;
        ++m_generation;
        m_busy = true;
    }
    m_work.notify_all();
    return front;
}

std::vector<Drawable> Streamer::resident_front()
{
    std::lock_guard lock(m_mutex);
    std::vector<Drawable> out;
    out.reserve(m_front.size());
    for (const auto& f : m_front) {
        Drawable d{f, f.lod, nullptr, nullptr};
        ++m_tick;
        if (auto it = m_cache.find({f.node, table_lod}); it != m_cache.end()) {
            it->second.last_used = m_tick;
            d.chains = it->second.chains;
        }
        if (auto it = m_cache.find(f); it != m_cache.end()) {
            ++m_stats.hits;
            it->second.last_used = m_tick;
            d.geometry = it->second.geometry;
        } else {
            ++m_stats.misses;
            // The nearest resident LOD of the node, coarser first.
            const auto nlods = static_cast<uint32_t>(m_tree->skeleton().lod_eps_m.size());
            for (uint32_t k = 1; k < nlods && !d.geometry; ++k) {
                for (const uint32_t lod : {f.lod + k, f.lod - k}) {
                    if (lod >= nlods) { // f.lod - k wrapped around, or past the coarsest
                        continue;
                    }
                    if (auto jt = m_cache.find({f.node, lod}); jt != m_cache.end()) {
                        jt->second.last_used = m_tick;
                        d.geometry = jt->second.geometry;
                        d.lod = lod;
                        break;
                    }
                }
            }
        }
        out.push_back(std::move(d));
    }
    return out;
}

bool Streamer::settled_locked(FrontItem item) const
{
    if (m_cache.contains(item) || m_failed.contains(item)) {
        return true;
    }
    const auto it = m_skipped.find(item);
    return it != m_skipped.end() && it->second == m_generation;
}

bool Streamer::front_done_locked() const
{
    for (const auto& f : m_front) {
        if (!settled_locked(f) || !settled_locked({f.node, table_lod})) {
            return false;
        }
    }
    return true;
}

bool Streamer::wait_front(std::chrono::milliseconds timeout)
{
    const auto start = std::chrono::steady_clock::now();
    std::unique_lock lock(m_mutex);
    m_changed.wait_for(lock, timeout, [&] { return front_done_locked(); });
    bool all = true;
    for (const auto& f : m_front) {
        all = all && m_cache.contains(f) && m_cache.contains({f.node, table_lod});
    }
    m_stats.seconds_waiting += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return all;
}

size_t Streamer::missing() const
{
    std::lock_guard lock(m_mutex);
    size_t n = 0;
    std::set<uint32_t> nodes;
    for (const auto& f : m_front) {
        n += m_cache.contains(f) ? 0 : 1;
        if (nodes.insert(f.node).second) {
            n += m_cache.contains({f.node, table_lod}) ? 0 : 1;
        }
    }
    return n;
}

void Streamer::wait_idle()
{
    std::unique_lock lock(m_mutex);
    m_changed.wait(lock, [&] { return !m_busy; });
}

Stats Streamer::stats() const
{
    std::lock_guard lock(m_mutex);
    return m_stats;
}

std::vector<std::string> Streamer::errors() const
{
    std::lock_guard lock(m_mutex);
    std::set<std::string> distinct;
    for (const auto& [item, message] : m_failed) {
        distinct.insert(message);
    }
    return {distinct.begin(), distinct.end()};
}

std::vector<Streamer::Resident> Streamer::resident() const
{
    std::lock_guard lock(m_mutex);
    std::vector<Resident> out;
    for (const auto& [item, e] : m_cache) {
        out.push_back({item, e.bytes, e.geometry, e.chains});
    }
    return out;
}

void Streamer::run()
{
    std::unique_lock lock(m_mutex);
    while (!m_stop) {
        // The most important wanted payload that is not resident, failed or
        // skipped. Those before the cursor stay settled until the next view:
        // a load evicts only what ranks after it, or nothing wants.
        while (m_cursor < m_wanted.size() && settled_locked(m_wanted[m_cursor])) {
            ++m_cursor;
        }
        if (m_cursor == m_wanted.size()) {
            m_busy = false;
            m_changed.notify_all();
            m_work.wait(lock, [&] { return m_stop || m_busy; });
            continue;
        }
        const FrontItem item = m_wanted[m_cursor];
        const size_t rank = m_cursor;
        const bool in_front = rank < m_front_ranks;
        const size_t cost = in_flight_cost(item);
        // Make room: first what is no longer wanted (least recently used
        // first), then, for a front payload only, wanted payloads of lower
        // priority (lowest first). A prefetch never evicts what the front or
        // the rest of the list wants: it only takes room nothing wants.
        // Payloads the caller still holds are never evicted: their memory
        // would not be freed.
        bool fits = cost <= m_options.budget_bytes;
        while (fits && m_stats.resident_bytes + m_in_flight + cost > m_options.budget_bytes) {
            auto victim = m_cache.end();
            size_t victim_rank = 0;
            uint64_t victim_used = 0;
            for (auto it = m_cache.begin(); it != m_cache.end(); ++it) {
                if (it->second.held()) {
                    continue;
                }
                const auto r = m_rank.find(it->first);
                const size_t rk = r == m_rank.end() ? SIZE_MAX : r->second;
                if (rk <= rank || (!in_front && rk != SIZE_MAX)) {
                    continue;
                }
                const uint64_t used = it->second.last_used;
                if (victim == m_cache.end() || rk > victim_rank || (rk == victim_rank && used < victim_used)) {
                    victim = it;
                    victim_rank = rk;
                    victim_used = used;
                }
            }
            if (victim == m_cache.end()) {
                fits = false;
                break;
            }
            m_stats.resident_bytes -= victim->second.bytes;
            m_cache.erase(victim);
            ++m_stats.evictions;
        }
        if (!fits) {
            m_skipped[item] = m_generation;
            ++m_stats.skipped;
            continue;
        }
        m_in_flight += cost;
        m_stats.peak_bytes = std::max(m_stats.peak_bytes, m_stats.resident_bytes + m_in_flight);
        lock.unlock();
        const auto t_load = std::chrono::steady_clock::now();
        std::shared_ptr<datatree::Geometry> geometry;
        std::shared_ptr<NodeChains> chains;
        Status st;
        const auto& node = m_tree->skeleton().nodes[item.node];
        uint64_t size = 0;
        if (item.lod == table_lod) {
            datatree::ChainTable table;
            st = m_tree->read_table(item.node, table);
            if (st.ok()) {
                chains = std::make_shared<NodeChains>(node_chains(*m_tree, item.node, table));
            }
            size = node.table.size;
        } else {
            geometry = std::make_shared<datatree::Geometry>();
            st = m_tree->read_geometry(item.node, item.lod, *geometry);
            size = node.lods[item.lod].payload.size;
        }
        const double load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_load).count();
        lock.lock();
        // The mean time a load takes, lately (the lookahead's estimate of the disk).
        m_load_seconds = m_load_seconds == 0 ? load_s : 0.8 * m_load_seconds + 0.2 * load_s;
        m_in_flight -= cost;
        if (!st.ok()) {
            m_failed.emplace(item, st.error);
            ++m_stats.errors;
        } else {
            const size_t bytes = charge(item);
            m_cache[item] = Entry{std::move(geometry), std::move(chains), bytes, ++m_tick};
            m_stats.resident_bytes += bytes;
            ++m_stats.loads;
            m_stats.bytes_read += size;
            if (!in_front) {
                ++m_stats.prefetches;
            }
        }
        m_changed.notify_all();
    }
}

} // namespace tigerlod::reader
