#pragma once
/// @file reader.hpp
/// The reader runtime: opens a Data Tree, selects the front for a 2D view
/// (the paper's Algorithm 6.1), and streams payloads through a cache with a
/// hard byte budget, an I/O thread and prefetching. No GL, no GDAL: a
/// renderer links this (CMake: `find_package(tigerlod-reader)`, target
/// `tigerlod::reader`) and draws what `Streamer::resident_front()` returns.
///
/// Bad data never throws out of this API and never crashes: calls return a
/// Status whose message names the file and the node, and the streamer records
/// the error and goes on with what it has.

#include "formats/datatree/datatree.hpp"

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace tigerlod::reader {

/// Empty when the operation succeeded, else what went wrong (file, node, fault).
struct Status {
    std::string error;
    bool ok() const noexcept { return error.empty(); }
};

/// An open Data Tree: the skeleton in memory, payloads read on demand. Thread-safe.
class Tree {
  public:
    /// Opens `dir` (its skeleton.tls). Returns null and sets `error` on failure.
    static std::shared_ptr<Tree> open(const std::filesystem::path& dir, std::string& error);

    const datatree::Skeleton& skeleton() const noexcept { return m_skeleton; }
    const std::filesystem::path& dir() const noexcept { return m_dir; }
    /// Size of the skeleton file, and of skeleton plus tile files.
    uint64_t skeleton_bytes() const noexcept { return m_skeleton_bytes; }
    uint64_t tree_bytes() const noexcept;
    /// The origin payload coordinates are relative to: the node box's minimum corner.
    GridPoint origin(uint32_t node) const noexcept;

    /// Read a payload's bytes, checking the tile header and the payload's CRC.
    /// `lod` -1 is the node's chain table.
    Status read_payload(uint32_t node, int lod, std::string& bytes) const;
    Status read_geometry(uint32_t node, uint32_t lod, datatree::Geometry& out) const;
    Status read_table(uint32_t node, datatree::ChainTable& out) const;
    /// The node's units (format 2.2: codes, internal points, names and the
    /// config's attributes). A tree of an earlier minor version has none:
    /// an empty table and ok.
    Status read_units(uint32_t node, datatree::UnitTable& out) const;

    /// The node of unit `code` of the map of level `map_level` (a unit that
    /// has units below it is a node of level map_level + 1), or no_node.
    uint32_t unit_node(uint32_t map_level, const std::string& code) const;

    /// Bytes the skeleton takes in memory once decoded (an upper estimate:
    /// every vector's and string's heap block, and this object).
    uint64_t skeleton_memory() const noexcept;

    /// A simulated disk, for machines whose page cache hides the real one:
    /// every payload read then takes `latency` plus its size at
    /// `bytes_per_second` (0: no limit), as a sleep before it returns. Set
    /// before the tree is shared with a streamer.
    void simulate_disk(std::chrono::microseconds latency, double bytes_per_second);

  private:
    Tree() = default;
    std::filesystem::path m_dir;
    datatree::Skeleton m_skeleton;
    uint64_t m_skeleton_bytes = 0;
    std::map<std::pair<uint32_t, std::string>, uint32_t> m_unit_node; ///< (level, code) -> node
    std::chrono::microseconds m_latency{0};
    double m_bytes_per_second = 0;
}; // class Tree

/// A 2D camera over the projected grid.
struct View {
    double center_x = 0.0; ///< grid units
    double center_y = 0.0;
    double units_per_pixel = 1.0; ///< grid units per screen pixel
    uint32_t width = 1024;        ///< viewport in pixels
    uint32_t height = 768;
};

struct FrontOptions {
    /// A LOD may be drawn when its error, projected, is below this many pixels.
    double pixel_error = 1.0;
    /// A node is drawn itself, not its children, when its box covers less than
    /// this fraction of the viewport's area.
    double node_fraction = 0.25;
};

/// A FrontItem's `lod` for a node's chain table (ids, border levels).
inline constexpr uint32_t table_lod = 0xFFFFFFFFU;

struct FrontItem {
    uint32_t node = 0;
    uint32_t lod = 0; ///< or table_lod: the node's chain table
    friend bool operator==(const FrontItem&, const FrontItem&) = default;
    friend auto operator<=>(const FrontItem&, const FrontItem&) = default;
};

/// Algorithm 6.1: cull by the view, take a node when its projected box is
/// small enough (or it is a leaf), then its coarsest LOD whose projected error
/// is below the threshold (LOD 0, the original, when none is). Depth-first order.
std::vector<FrontItem> select_front(const datatree::Skeleton& s, const View& view, const FrontOptions& options = {});

/// Where most of the map is, to frame an overview: the boxes, whole, of the
/// nodes showing the finest map whose centres lie in the range, in x and in
/// y apart, that holds the central `fraction` of that map's units (their
/// internal points, from the units payloads; the leaf nodes' box centres
/// for a tree without units), widened by 5 % of it on each side. A national
/// map with territories far out (Alaska, Hawaii and the Pacific for the US)
/// frames its main part; a compact one (a county) its whole box. The root's
/// box when the units are too few (fewer than 20) or no node centres there.
datatree::Box main_extent(const Tree& tree, double fraction = 0.95);

/// The LOD Algorithm 6.1 picks for `node` in `view`.
uint32_t select_lod(const datatree::Skeleton& s, uint32_t node, const View& view, const FrontOptions& options = {});

struct StreamOptions {
    /// Hard limit on the bytes of decoded payloads held, plus the I/O thread's
    /// buffers while it decodes. Never exceeded.
    uint64_t budget_bytes = 64ULL << 20;
    /// Load ahead what the next views are likely to need, into room the
    /// front does not need (Section 6.2.2), soonest needed first: while the
    /// camera moves, the fronts of the views its last motion leads to; while
    /// it stands still, the paper's events (parent, children, coarser and
    /// finer LODs, a wider view) by how far the view must zoom or pan before
    /// Algorithm 6.1 picks them. The list is cut to what fits beside the
    /// front, and a prefetch never evicts a payload the front or the list wants.
    bool prefetch = true;
    /// While the camera moves, the furthest view ahead the prefetch list may
    /// look to (1, 2 and 4 always; 8, 16 and 32 only when the disk, at its
    /// recent pace, needs that long to load what the views up to there need).
    int max_lookahead_views = 32;
    /// The prefetch view extends the view by this fraction of its size on each side.
    double prefetch_margin = 0.5;
    FrontOptions front;
};

struct Stats {
    uint64_t hits = 0;       ///< front items resident when asked for
    uint64_t misses = 0;     ///< front items not resident when asked for
    uint64_t loads = 0;      ///< payloads read and decoded
    uint64_t prefetches = 0; ///< of those, loaded for the prefetch list
    uint64_t bytes_read = 0;
    uint64_t evictions = 0;
    uint64_t skipped = 0; ///< wanted payloads that did not fit in the budget
    /// Views whose prefetch list was cut to what fits beside the front: the
    /// budget bound (with evictions and skipped, the sign that it did).
    uint64_t prefetch_cuts = 0;
    uint64_t errors = 0; ///< payloads that failed to read or decode
    uint64_t resident_bytes = 0;
    uint64_t peak_bytes = 0;      ///< largest resident + in-flight bytes seen
    double seconds_waiting = 0.0; ///< time callers spent in wait_front()
};

/// What a renderer needs of a node's chain table: per chain, in the
/// geometry's order, its id, its flags (border level in bits 8-15), and the
/// node across it when it lies on the node's outline and the unit on the
/// other side has a node (no_node otherwise).
struct NodeChains {
    std::vector<uint64_t> ids;
    std::vector<uint32_t> flags;
    std::vector<uint32_t> across;
    /// The bytes a table of `chains` chains is charged (exact: the three arrays).
    static constexpr size_t bytes(size_t chains) noexcept { return chains * (sizeof(uint64_t) + 2 * sizeof(uint32_t)); }
    /// The bytes its arrays hold.
    size_t memory_bytes() const noexcept
    {
        return ids.capacity() * sizeof(uint64_t) + (flags.capacity() + across.capacity()) * sizeof(uint32_t);
    }
};

/// A node's table as NodeChains: the outline's units looked up in `tree`.
NodeChains node_chains(const Tree& tree, uint32_t node, const datatree::ChainTable& table);

/// A decoded payload the caller may draw; it stays valid while held.
struct Drawable {
    FrontItem wanted;
    uint32_t lod = 0; ///< the LOD drawn: `wanted.lod` on a hit, else the nearest resident one
    std::shared_ptr<const datatree::Geometry> geometry;
    std::shared_ptr<const NodeChains> chains; ///< the node's table, once resident
};

/// One chain of a front to draw: `item` indexes the front, `chain` the node's chains.
struct DrawChain {
    uint32_t item = 0;
    uint32_t chain = 0;
    friend bool operator==(const DrawChain&, const DrawChain&) = default;
};

/// The chains to draw for a front (resident_front's), each once:
/// - a chain that several front nodes show (a border between two nodes of
///   one level, the same id) is drawn by the one drawn at the finer LOD (the
///   smaller LOD index; on a tie, the earlier in the front). Any two LODs of
///   a level meet only at shared ends (formats/chains/SPEC.md), so it meets
///   the neighbours' chains at their LODs without a crossing;
/// - a border between front nodes of different levels is drawn by the finer
///   node: a chain of a node's outline whose other side is a unit with a
///   node that is in the front, or has front nodes below it, is left to
///   them, as long as all of those are resident (else the coarser node
///   draws it, so that no border goes missing while they load). The finer
///   map has every junction of the coarser one on that border, so the
///   coarser node's chains end on it.
/// Items without geometry or chains draw nothing.
std::vector<DrawChain> draw_list(const datatree::Skeleton& s, const std::vector<Drawable>& front);

/// How a border of level `level` of a tree of `levels` levels is drawn:
/// width in pixels and colour. The top level 3 px black, the next 2.4 px,
/// then lighter and thinner down to 1 px light grey from the fifth on; a tree
/// of one level (a line layer) 1 px dark grey. tigerlod-render draws with
/// it, and tigerlod-serve hands it to the viewer, so both draw alike.
struct LineStyle {
    float width = 1;
    uint8_t r = 0, g = 0, b = 0;
};
LineStyle line_style(uint32_t level, uint32_t levels) noexcept;

/// The out-of-core streamer: a payload cache with a byte budget and an I/O
/// thread that loads the front's missing payloads first, then prefetches.
class Streamer {
  public:
    Streamer(std::shared_ptr<const Tree> tree, StreamOptions options);
    ~Streamer();
    Streamer(const Streamer&) = delete;
    Streamer& operator=(const Streamer&) = delete;

    /// Set the view: computes the front and the prefetch list and hands them
    /// to the I/O thread. Never waits for the disk. Views come from one
    /// thread: the prefetch list follows their motion.
    std::vector<FrontItem> set_view(const View& view);
    /// For each front item, what is resident now: its own LOD, else the
    /// nearest resident LOD of the node, else no geometry. Never waits for the disk.
    std::vector<Drawable> resident_front();
    /// Wait until the front is resident (or cannot be: budget, errors), at most `timeout`.
    /// Returns true when it all is. The time is counted in Stats::seconds_waiting.
    bool wait_front(std::chrono::milliseconds timeout);
    /// Wait until the I/O thread has nothing left to do.
    void wait_idle();
    /// The front's payloads and tables not resident now. Never waits.
    size_t missing() const;

    Stats stats() const;
    /// Each distinct error so far, naming file and node.
    std::vector<std::string> errors() const;
    /// Resident payloads and the bytes charged for each.
    struct Resident {
        FrontItem item;
        size_t bytes = 0;
        std::shared_ptr<const datatree::Geometry> geometry; ///< null for a table
        std::shared_ptr<const NodeChains> chains;           ///< a table's (item.lod == table_lod)
    };
    std::vector<Resident> resident() const;

  private:
    struct Entry {
        std::shared_ptr<const datatree::Geometry> geometry;
        std::shared_ptr<const NodeChains> chains;
        size_t bytes = 0;
        uint64_t last_used = 0;
        bool held() const noexcept { return geometry.use_count() > 1 || chains.use_count() > 1; }
    };
    void run();
    bool front_done_locked() const;
    bool settled_locked(FrontItem item) const;
    size_t charge(FrontItem item) const;
    size_t in_flight_cost(FrontItem item) const;

    std::shared_ptr<const Tree> m_tree;
    StreamOptions m_options;
    mutable std::mutex m_mutex;
    std::condition_variable m_work;    ///< the I/O thread waits here
    std::condition_variable m_changed; ///< callers wait here
    bool m_stop = false;
    bool m_busy = false;
    uint64_t m_generation = 0;
    uint64_t m_tick = 0;
    std::vector<FrontItem> m_front;
    size_t m_front_ranks = 0;        ///< m_wanted's first entries: the front and its tables
    std::vector<FrontItem> m_wanted; ///< front, then prefetch list, by priority
    std::map<FrontItem, size_t> m_rank;
    size_t m_cursor = 0;             ///< m_wanted's entries before it are settled (resident, failed or skipped)
    std::optional<View> m_last_view; ///< the view before, for the camera's motion (set_view's own)
    std::chrono::steady_clock::time_point m_last_time; ///< when it was set (set_view's own)
    double m_load_seconds = 0;                         ///< the mean time a load took lately
    std::map<FrontItem, Entry> m_cache;
    std::map<FrontItem, std::string> m_failed;
    std::map<FrontItem, uint64_t> m_skipped; ///< item -> generation it was skipped in
    uint64_t m_in_flight = 0;
    Stats m_stats;
    std::thread m_thread;
}; // class Streamer

} // namespace tigerlod::reader
