#pragma once
/// @file zip_writer.hpp
/// A zip archive written in one pass (PKWARE APPNOTE 6.3: local headers,
/// raw deflate through libdeflate, a central directory; no Zip64, so each member
/// and the archive stay under 4 GiB). Every member carries one fixed date,
/// so the same members give the same bytes: GDAL's own zip writer stamps
/// the time of writing.

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace tigerlod::synth {

class ZipWriter {
  public:
    /// Members are deflated at `level` (libdeflate's 0..12; 0 stores).
    explicit ZipWriter(int level = 6) : m_level(level) {}
    /// Add a member. Throws std::runtime_error when deflate fails or a size passes 4 GiB.
    void add(const std::string& name, std::string_view data);
    /// The archive's bytes.
    std::string finish();

  private:
    struct Member {
        std::string name;
        uint32_t crc = 0, compressed = 0, size = 0, offset = 0;
    };
    int m_level;
    std::string m_out;
    std::vector<Member> m_members;
}; // class ZipWriter

} // namespace tigerlod::synth
