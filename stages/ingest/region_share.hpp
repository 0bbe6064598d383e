#pragma once
/// @file region_share.hpp
/// What a region's ingest job hands to the finish job (`tigerlod-ingest
/// --region`, then `--finish`): its counts, the edges and units of the coarse
/// levels, and the stores it wrote, as bytes (little-endian; doubles by
/// their bits, so the finish sums exactly what an in-process build sums).

#include "stages/ingest/regions.hpp"

#include <span>
#include <string>
#include <vector>

namespace tigerlod::ingest {

/// An input file as a read job found it: the plan takes the job's part only
/// while the file still has this size and time.
struct FileStamp {
    std::string path;
    uint64_t bytes = 0;
    int64_t mtime_ns = 0;
    std::string sha256; ///< of the file, for the manifest
};

/// One part as a read job (`tigerlod-ingest --read`) hands it to the plan:
/// its files, the digest of its bytes (the part file's name) and its summary.
struct PartRead {
    uint64_t part = 0;            ///< its number among the dataset's parts when it was read
    std::vector<FileStamp> files; ///< a TIGER county's FACES and EDGES, or the polygon file
    std::string sha256;           ///< of the part's bytes
    PartSummary summary;
};

/// What a read job hands on: how it read (the config's dataset fields and
/// levels, which a part's codes come from: the plan takes its parts only
/// under the same) and its parts.
struct ReadJob {
    std::string reading;
    std::vector<PartRead> parts;
};

/// A read job's parts as bytes and back (format_error naming `name` and the
/// byte where the bytes are not a read job's of this version).
std::string encode_reads(const ReadJob& job);
ReadJob decode_reads(std::span<const std::byte> bytes, const std::string& name);

struct RegionJobShare {
    std::string job;                 ///< the job's name (`r-<code>`, `whole`)
    std::string spec_sha256;         ///< of the region's spec the job ran on
    std::vector<std::string> stores; ///< "level/partition" of each store it wrote, sorted
    /// Each store's size and modification time (ns) when the job ended: the
    /// next plan reruns the job of a store changed or removed since.
    std::vector<uint64_t> store_bytes;
    std::vector<int64_t> store_mtimes;
    RegionShare share;
    uint64_t points_read = 0; ///< a whole job: the input points as read
};

std::string encode_share(const RegionJobShare& s);
/// The job, spec digest and stores of a share alone (what the plan checks).
RegionJobShare decode_share_head(std::span<const std::byte> bytes, const std::string& name);
/// Throws format_error naming `name` and the byte where the bytes are not a share of this version.
RegionJobShare decode_share(std::span<const std::byte> bytes, const std::string& name);

} // namespace tigerlod::ingest
