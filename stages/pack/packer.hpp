#pragma once
/// @file packer.hpp
/// Building a Data Tree from chain stores: the node hierarchy, each node's
/// chain table and geometry at every LOD (LOD 0 the original chains, then
/// the simplified ladder), and tiles that group subtrees.

#include "formats/datatree/datatree.hpp"

#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace tigerlod::pack {

struct PackOptions {
    /// A subtree whose payloads fit in this many bytes goes into one tile;
    /// small sibling subtrees are grouped up to it.
    uint64_t tile_bytes = 4ULL << 20;
    int draco_speed = 0;
    unsigned threads = 1;
    /// The tolerances to pack, one LOD each (the simplify ladder); empty:
    /// every eps-<E>m folder of SIMPLIFIED.
    std::vector<double> lods;
    /// Called after each level is packed, with its number of stores (a
    /// stage's progress; write_parts: the level's stores of the job;
    /// assemble_parts: 1 as each store's part goes into its tile); from the
    /// calling thread.
    std::function<void(size_t stores)> on_level;
};

/// Per-LOD totals, for the report and the benchmarks.
struct LodTotals {
    double eps_m = 0.0;
    uint64_t vertices = 0;      ///< points of all nodes' chains
    uint64_t payload_bytes = 0; ///< geometry payloads
    uint64_t raw_bytes = 0;     ///< the same points as int32 pairs
};

/// The tree in memory: skeleton plus each tile's bytes.
struct PackedTree {
    datatree::Skeleton skeleton;
    std::vector<std::string> tile_bytes; ///< parallel to skeleton.tiles
    std::vector<LodTotals> lods;
    uint64_t table_bytes = 0;
    uint64_t unit_bytes = 0; ///< units payloads (format 2.2)
};

/// Build from an ingest output folder (LOD 0) and a simplify output folder
/// (its eps-<E>m subfolders). Throws input_error naming the store at fault.
/// The same as pack_parts on every store, then assemble_parts.
PackedTree build_tree(const std::filesystem::path& original, const std::filesystem::path& simplified,
                      const PackOptions& options);

// ---------------------------------------------------------------------------
// Pack by partitions: the workflow's jobs. A node is a store of ORIGINAL
// (<level>/<partition>.tlc); its payloads at every LOD depend on its own
// stores and on the simplified stores of the neighbours that own the border
// chains of its units it shows, and on nothing else (the border levels of its
// table, which need the whole hierarchy, are set when the tree is assembled).
// So a job packs some nodes into part files, and one job assembles the tree
// from every part: the bytes of build_tree.

/// The stores of ORIGINAL as (level, partition), sorted.
std::vector<std::pair<std::string, std::string>> stores_of(const std::filesystem::path& original);

/// For each store of ORIGINAL ("level/partition"), other stores of its level.
struct PackPlan {
    /// Those that own a chain its node shows: what its pack job reads beside its own.
    std::map<std::string, std::vector<std::string>> reads;
    /// Those that own a chain of its halo (a superset): the nodes a verify
    /// job decodes beside its own to look for meetings near them.
    std::map<std::string, std::vector<std::string>> near;
    /// The digest of the ingest manifest it was made from: jobs refuse a
    /// plan of another ingest output (a neighbour it lacks would be missed).
    std::string ingest_sha256;
};

/// The plan, from every store of ORIGINAL (one at a time per thread). Throws
/// input_error naming a store whose node shows a chain no store owns.
PackPlan plan_parts(const std::filesystem::path& original, unsigned threads);
/// As JSON (tigerlod.pack-plan/1), and back (input_error naming `name`).
std::string plan_json(const PackPlan& plan);
PackPlan plan_from_json(const std::string& text, const std::string& name);

/// Pack the nodes of `stores` ("level/partition" of ORIGINAL) into part
/// files `parts`/<level>/<partition>.tlp (each written under a temporary
/// name and renamed), reading beside each store the ones `plan` names. Each
/// part records the files it was made from and their checksums. Returns
/// per-LOD totals of the parts written; `content` gets each store's CRC-32
/// of what its part holds for the tree (its node and payloads, not the
/// files it was made from): a job's report names what changed downstream.
std::vector<LodTotals> write_parts(const std::filesystem::path& original, const std::filesystem::path& simplified,
                                   const std::vector<std::string>& stores, const PackPlan& plan,
                                   const std::filesystem::path& parts, const PackOptions& options,
                                   std::map<std::string, uint32_t>* content = nullptr);

/// The tree of every store's part in `parts` (write_parts), as build_tree
/// builds it. Throws usage_error naming a part that is missing, made with
/// other options or LODs, or stale (a file it was made from has changed
/// since), and input_error for a damaged one. Payloads are read from the
/// parts as their tiles are laid out, so memory follows a tile, not the tree.
PackedTree assemble_parts(const std::filesystem::path& original, const std::filesystem::path& simplified,
                          const std::filesystem::path& parts, const PackOptions& options);

/// Remove from `parts` the part files of stores ORIGINAL no longer has,
/// level folders of levels it no longer has, and dead runs' temporaries.
/// Returns what it removed.
std::vector<std::filesystem::path> prune_parts(const std::filesystem::path& original,
                                               const std::filesystem::path& parts);

/// Place the payloads ([node][0] the chain table, [node][1 + k] LOD k) into
/// tiles and set the skeleton's tiles and payload references. Tiles are
/// named by their content. Each payload is released once it is in its tile,
/// so the payloads and the tiles are not held twice (a national tree's peak).
void layout_tiles(PackedTree& tree, std::vector<std::vector<std::string>>&& payloads, uint64_t tile_bytes);

/// The same, with the payloads' sizes known beforehand and each payload
/// fetched (`fetch(node, j)`) when its tile is built.
void layout_tiles(PackedTree& tree, const std::vector<std::vector<uint64_t>>& sizes,
                  const std::function<std::string(uint32_t, size_t)>& fetch, uint64_t tile_bytes);

/// What writing a tree did.
struct WriteStats {
    size_t tiles_written = 0;                             ///< new tile files
    size_t tiles_kept = 0;                                ///< files already there holding exactly the tile
    size_t tiles_repaired = 0;                            ///< files of a tile's name with other bytes, rewritten
    size_t tiles_removed = 0;                             ///< tile files the new skeleton does not name
    std::vector<std::filesystem::path> leftovers_removed; ///< of dead runs (remove_dead_leftovers)
    uint64_t skeleton_bytes = 0, tree_bytes = 0;
};

/// Write into `dir`, updating a tree already there. First what dead runs
/// left (temporaries) is removed. Tile files are named by their content: a
/// file that holds exactly its tile's bytes is kept, one of the name with
/// other bytes (damaged) is rewritten, a missing one written, each under a
/// temporary name and renamed; then `manifest` is written to manifest.json
/// and the skeleton is replaced atomically;
/// then tile files it no longer names are removed. If writing fails, the
/// tile files this call created are removed again and the old tree, if
/// any, is as it was.
WriteStats write_tree(const std::filesystem::path& dir, const PackedTree& tree, std::string_view manifest);

/// Whether `dir` (a folder without skeleton.tls) holds only what a pack
/// that did not finish leaves: tiles/ with tile files and their
/// temporaries, pack-report.json, manifest.json, and temporaries of the
/// skeleton, the manifest and the report. Such a folder is resumed; any other is refused.
bool is_pack_leftover(const std::filesystem::path& dir);

} // namespace tigerlod::pack
