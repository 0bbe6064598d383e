#pragma once
/// @file config_file.hpp
/// A config file read and checked against the schema (schema.hpp): every
/// key known, of its type, in its range or among its choices. What the
/// schema cannot say (a tiger dataset needs edges and faces, levels that
/// nest) is checked by the stage that knows it: tigerlod-ingest.

#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace tigerlod::config {

class ConfigFile {
  public:
    /// Read `file` and check every key. Throws config_error naming the file,
    /// the line and the key: no such file, not YAML, an unknown key (with
    /// the keys known there), a value of the wrong type, out of range, not
    /// among the choices, a ladder that does not increase.
    static ConfigFile load(const std::filesystem::path& file);

    const std::filesystem::path& file() const noexcept { return m_file; }
    const YAML::Node& root() const noexcept { return m_root; }
    /// The node of a dotted key; an undefined node when the file has none.
    YAML::Node node(std::string_view name) const;
    /// A file name as the config gives it, resolved against its folder.
    std::filesystem::path resolve(const std::string& name) const;
    /// Throws config_error "FILE:LINE: what", the line of `at` when it has one.
    [[noreturn]] void fail(const YAML::Node& at, const std::string& what) const;

  private:
    std::filesystem::path m_file;
    YAML::Node m_root;
};

/// The options `stage` takes from the config's keys (schema Key::stages),
/// as `--flag=VALUE` (or `--flag` for a boolean), in the schema's order;
/// a path resolved against the config's folder. Throws config_error as
/// ConfigFile::load.
std::vector<std::string> stage_args(const std::filesystem::path& file, std::string_view stage);

} // namespace tigerlod::config
