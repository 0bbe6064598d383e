#pragma once
/// @file schema.hpp
/// Every key a tigerlod config may hold, in one table: its name, type,
/// range or choices, default, the line that documents it, and the stage
/// option it becomes. Everything else reads keys from here: the config
/// loader checks a file against it (config_file.hpp), each stage declares
/// the options that mirror a key through add_option (same name in --help,
/// same range, same message), the stages that take `--config FILE` turn
/// their section into those options (stage_args), and configs/README.md is
/// generated from it (reference_markdown; a test keeps the two equal).

#include "core/stage.hpp"

#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace tigerlod::config {

enum class Type {
    text,      ///< a string
    choice,    ///< one of Key::choices
    integer,   ///< within Key::limits
    number,    ///< finite, within Key::limits
    boolean,   ///< true or false
    numbers,   ///< a list of numbers within Key::limits, strictly increasing
    class_map, ///< a map of feature class to a number within Key::limits
    path,      ///< a file name, relative to the config's folder
    paths,     ///< a file name or a list of them, relative to the config's folder
    mapping,   ///< a section holding further keys
    levels,    ///< the list of semantic levels (checked by ingest, which knows the data)
    codes,     ///< a unit code or a list of them (strings or integers)
    fields,    ///< a list of attribute names, none twice
    viewport,  ///< `WIDTHxHEIGHT` pixels, each an integer within Key::limits
};

struct Key {
    std::string name; ///< dotted: "simplify.tile_pixels"
    Type type = Type::text;
    std::string doc;          ///< one line of Markdown
    std::string default_text; ///< as configs/README.md shows it ("" for none)
    Limits limits;
    std::vector<std::string> choices;
    /// The stage option this key becomes ("" for none): the value as
    /// `--flag=VALUE`, or for a boolean `--flag` when the value equals
    /// flag_when.
    std::string flag;
    bool flag_when = true;
    /// The stages that take the key through `--config`, space-separated.
    std::string stages;
};

/// Every key, sections before the keys in them, in the order the reference shows them.
const std::vector<Key>& keys();

/// The key of this dotted name, or nullptr.
const Key* find(std::string_view name);

/// The key of this dotted name; std::logic_error if the table has none (a
/// programming error, caught by the tests).
const Key& key(std::string_view name);

/// Declare the stage option that mirrors config key `name`: its flag, its
/// doc line as help, its limits and choices. A `boolean` key's target is the
/// flag (true when given).
void add_option(ArgSet& args, std::string_view name, ArgSet::Target target);

/// A `viewport` value (`1280x720`): its width and height, each within
/// `limits`; nullopt for anything else. The config loader and the stage
/// option that mirrors the key (tigerlod-render --size) both use it, so they
/// take the same values.
std::optional<std::pair<unsigned, unsigned>> parse_viewport(std::string_view text, const Limits& limits);

/// configs/README.md: the reference of every key, generated from the table.
std::string reference_markdown();

} // namespace tigerlod::config
