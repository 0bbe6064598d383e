#include "reader/reader.hpp"

#include "core/digest.hpp"
#include "core/errors.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fcntl.h>
#include <set>
#include <sys/stat.h>
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
    return t;
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
    return datatree::geometry_bytes(n.chains, n.lods[item.lod].vertices);
}

size_t Streamer::in_flight_cost(FrontItem item) const
{
    // While decoding: the payload bytes, Draco's attribute buffer and our copy
    // of the new points (each at most 8 bytes a vertex), and the result.
    const auto& lod = m_tree->skeleton().nodes[item.node].lods[item.lod];
    return charge(item) + lod.payload.size + 2 * lod.vertices * sizeof(GridPoint);
}

std::vector<FrontItem> Streamer::set_view(const View& view)
{
    const auto& s = m_tree->skeleton();
    std::vector<FrontItem> front = select_front(s, view, m_options.front);
    std::vector<FrontItem> wanted = front;
    if (m_options.prefetch) {
        std::set<FrontItem> seen(front.begin(), front.end());
        auto want = [&](FrontItem it) {
            if (seen.insert(it).second) {
                wanted.push_back(it);
            }
        };
        const auto nlods = static_cast<uint32_t>(s.lod_eps_m.size());
        // Coarser and finer LODs of the front's nodes.
        for (const auto& f : front) {
            if (f.lod + 1 < nlods) {
                want({f.node, f.lod + 1});
            }
            if (f.lod > 0) {
                want({f.node, f.lod - 1});
            }
        }
        // The front of a view larger than the screen.
        View wide = view;
        wide.width = static_cast<uint32_t>(std::ceil(view.width * (1.0 + 2.0 * m_options.prefetch_margin)));
        wide.height = static_cast<uint32_t>(std::ceil(view.height * (1.0 + 2.0 * m_options.prefetch_margin)));
        for (const auto& f : select_front(s, wide, m_options.front)) {
            want(f);
        }
        // Parents and children, for semantic switches.
        for (const auto& f : front) {
            const auto& n = s.nodes[f.node];
            if (n.parent != datatree::no_node) {
                want({n.parent, select_lod(s, n.parent, view, m_options.front)});
            }
            for (uint32_t c = n.first_child; c < n.first_child + n.child_count; ++c) {
                want({c, select_lod(s, c, view, m_options.front)});
            }
        }
    }
    {
        std::lock_guard lock(m_mutex);
        m_front = front;
        m_wanted = std::move(wanted);
        m_rank.clear();
        for (size_t i = 0; i < m_wanted.size(); ++i) {
            m_rank.emplace(m_wanted[i], i);
        }
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
        Drawable d{f, f.lod, nullptr};
        ++m_tick;
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

bool Streamer::front_done_locked() const
{
    for (const auto& f : m_front) {
        if (!m_cache.contains(f) && !m_failed.contains(f)) {
            auto it = m_skipped.find(f);
            if (it == m_skipped.end() || it->second != m_generation) {
                return false;
            }
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
        all = all && m_cache.contains(f);
    }
    m_stats.seconds_waiting += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return all;
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
        out.push_back({item, e.bytes, e.geometry});
    }
    return out;
}

void Streamer::run()
{
    std::unique_lock lock(m_mutex);
    while (!m_stop) {
        // The most important wanted payload that is not resident, failed or skipped.
        const FrontItem* next = nullptr;
        for (const auto& w : m_wanted) {
            if (m_cache.contains(w) || m_failed.contains(w)) {
                continue;
            }
            if (auto it = m_skipped.find(w); it != m_skipped.end() && it->second == m_generation) {
                continue;
            }
            next = &w;
            break;
        }
        if (next == nullptr) {
            m_busy = false;
            m_changed.notify_all();
            m_work.wait(lock, [&] { return m_stop || m_busy; });
            continue;
        }
        const FrontItem item = *next;
        const size_t rank = m_rank.at(item);
        const bool in_front = rank < m_front.size();
        const size_t cost = in_flight_cost(item);
        // Make room: first what is no longer wanted (least recently used
        // first), then wanted payloads of lower priority (lowest first).
        // Payloads the caller still holds are never evicted: their memory
        // would not be freed.
        bool fits = cost <= m_options.budget_bytes;
        while (fits && m_stats.resident_bytes + m_in_flight + cost > m_options.budget_bytes) {
            auto victim = m_cache.end();
            size_t victim_rank = 0;
            uint64_t victim_used = 0;
            for (auto it = m_cache.begin(); it != m_cache.end(); ++it) {
                if (it->second.geometry.use_count() > 1) {
                    continue;
                }
                const auto r = m_rank.find(it->first);
                const size_t rk = r == m_rank.end() ? SIZE_MAX : r->second;
                if (rk <= rank) {
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
        auto geometry = std::make_shared<datatree::Geometry>();
        const Status st = m_tree->read_geometry(item.node, item.lod, *geometry);
        const uint64_t size = m_tree->skeleton().nodes[item.node].lods[item.lod].payload.size;
        lock.lock();
        m_in_flight -= cost;
        if (!st.ok()) {
            m_failed.emplace(item, st.error);
            ++m_stats.errors;
        } else {
            const size_t bytes = charge(item);
            m_cache[item] = Entry{std::move(geometry), bytes, ++m_tick};
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
