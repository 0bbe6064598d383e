#pragma once
/// @file packer.hpp
/// Building a Data Tree from chain stores: the node hierarchy, each node's
/// chain table and geometry at every LOD (LOD 0 the original chains, then
/// the simplified ladder), and tiles that group subtrees.

#include "formats/datatree/datatree.hpp"

#include <cstdint>
#include <filesystem>
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
};

/// Build from an ingest output folder (LOD 0) and a simplify output folder
/// (its eps-<E>m subfolders). Throws input_error naming the store at fault.
PackedTree build_tree(const std::filesystem::path& original, const std::filesystem::path& simplified,
                      const PackOptions& options);

/// Place the payloads ([node][0] the chain table, [node][1 + k] LOD k) into
/// tiles and set the skeleton's tiles and payload references. Tiles are
/// named by their content. Each payload is released once it is in its tile,
/// so the payloads and the tiles are not held twice (a national tree's peak).
void layout_tiles(PackedTree& tree, std::vector<std::vector<std::string>>&& payloads, uint64_t tile_bytes);

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
