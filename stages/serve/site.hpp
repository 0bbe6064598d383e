#pragma once
/// @file site.hpp
/// What tigerlod-serve answers, without the socket: a request (method, the
/// path as decoded, the query, the caching headers) in, a response out. The
/// transport (serve_stage.cpp, cpp-httplib) only moves bytes and applies
/// HTTP ranges to the bodies this gives; so everything a request can ask is
/// here, tested and fuzzed without a network.
///
/// What it serves, and nothing else (every other path is 404):
///   /                       the viewer's index.html (or a page naming the API)
///   /viewer/NAME            a file of the viewer folder, by an exact name listed at start
///   /tree/skeleton.tls      the skeleton
///   /tree/tiles/NAME.tlt    a tile the skeleton names (immutable: its name follows its bytes)
///   /api/tree               the tree as JSON: levels, LODs, projection, nodes' boxes and tiles
///   /api/front?cx=&cy=&upp=&w=&h=[&pixel_error=&node_fraction=]
///                           the front for a view (reader::select_front, Algorithm 6.1)
///   /api/node/N/K           node N's geometry at LOD K, decoded (see geometry_bytes)
///   /api/table/N            node N's chain table as JSON
///   /api/units/N            node N's units (codes, names, internal points, attributes)
///   /api/verify             the verify report given with --verify
/// Payload responses come from a cache bounded in bytes (least recently
/// used first out).

#include "reader/reader.hpp"

#include <cstdint>
#include <filesystem>
#include <functional>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

namespace tigerlod::serve {

struct Request {
    std::string method = "GET";
    std::string path;                         ///< decoded, as the transport gives it
    std::map<std::string, std::string> query; ///< decoded parameters
    std::string if_none_match;                ///< the If-None-Match header, "" for none
};

struct Response {
    int status = 200;
    std::string content_type = "application/json";
    std::string body;
    std::vector<std::pair<std::string, std::string>> headers; ///< ETag, Cache-Control
};

struct SiteOptions {
    std::filesystem::path viewer;       ///< the viewer's folder ("" for none)
    std::filesystem::path verify;       ///< a verify-report.json to serve ("" for none)
    uint64_t cache_bytes = 64ULL << 20; ///< what the payload cache may hold
};

/// A node's geometry as /api/node sends it, little-endian: u32 chains,
/// u32 points, u32 x (chains + 1) offsets, then i32 x, y per point in grid
/// units (absolute), chain i being points [offsets[i], offsets[i + 1]).
std::string geometry_bytes(const datatree::Geometry& g);

class Site {
  public:
    /// Reads the skeleton's bytes and lists the viewer's files; throws
    /// environment_error naming what it cannot read.
    Site(std::shared_ptr<const reader::Tree> tree, SiteOptions options);
    /// Thread-safe: the transport calls it from its worker threads.
    Response handle(const Request& request) const;
    /// Bytes the cache holds now (at most SiteOptions::cache_bytes).
    uint64_t cached_bytes() const;

  private:
    Response route(const Request& r) const;
    Response tile(const std::string& name, const std::string& if_none_match) const;
    Response api_tree() const;
    Response api_front(const Request& r) const;
    Response api_node(uint32_t node, uint32_t lod) const;
    Response api_table(uint32_t node) const;
    Response api_units(uint32_t node) const;
    /// The cached body of `key`, or `make()` put in the cache.
    std::shared_ptr<const std::string> cached(const std::string& key, const std::function<std::string()>& make) const;

    std::shared_ptr<const reader::Tree> m_tree;
    SiteOptions m_options;
    std::string m_skeleton_bytes;
    std::string m_etag;                    ///< of the skeleton: a digest of its bytes, quoted
    datatree::Box m_frame;                 ///< reader::main_extent, for the viewer's first view
    std::map<std::string, size_t> m_tiles; ///< tile file name (no folder) -> index in the skeleton
    std::map<std::string, std::filesystem::path> m_viewer_files;
    mutable std::mutex m_mutex;
    mutable std::list<std::string> m_lru; ///< keys, most recent first
    mutable std::unordered_map<std::string,
                               std::pair<std::shared_ptr<const std::string>, std::list<std::string>::iterator>>
        m_cache;
    mutable uint64_t m_cached = 0;
    /// Chain tables as the draw lists need them (reader::node_chains), at
    /// most a quarter of cache_bytes: emptied when a new one would not fit.
    std::shared_ptr<const reader::NodeChains> chains_of(uint32_t node) const;
    mutable std::map<uint32_t, std::shared_ptr<const reader::NodeChains>> m_chains;
    mutable uint64_t m_chains_bytes = 0;
};

} // namespace tigerlod::serve
