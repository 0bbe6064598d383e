#include "config/config_file.hpp"

#include "config/schema.hpp"
#include "core/errors.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>
#include <set>
#include <sstream>

namespace fs = std::filesystem;

namespace tigerlod::config {

namespace {

/// What a key's value must be, after "must be ".
std::string wanted(const Key& k)
{
    switch (k.type) {
    case Type::text:
    case Type::path:
        return "a string";
    case Type::choice:
        return choices_text(k.choices);
    case Type::integer:
        return "an integer";
    case Type::number:
        return "a number";
    case Type::boolean:
        return "true or false";
    case Type::numbers:
        return "a list of numbers, e.g. [1, 4, 16, 64]";
    case Type::class_map:
        return "a map of class to number, e.g. {S1400: 0.5}";
    case Type::paths:
        return "a file name or a list of them";
    case Type::mapping:
        return "a mapping";
    case Type::levels:
        return "a non-empty list";
    case Type::codes:
        return "a code or a list of codes, e.g. [51063, 51067]";
    case Type::fields:
        return "a list of attribute names, none twice, e.g. [ALAND, AWATER]";
    case Type::viewport:
        return "WIDTHxHEIGHT, each " + k.limits.text();
    }
    return {};
}

// Strings are built by appending: GCC 12 at -O3 warns falsely (-Wrestrict,
// its bug 105329) on `"literal" + std::string` here.
std::string bracketed(const std::string& s)
{
    std::string out = "[";
    out += s;
    out += ']';
    return out;
}

void append_item(std::string& list, const std::string& item)
{
    if (!list.empty()) {
        list += ',';
    }
    list += item;
}

std::optional<double> number_of(const YAML::Node& n)
{
    if (!n.IsScalar()) {
        return std::nullopt;
    }
    try {
        const double v = n.as<double>();
        if (std::isfinite(v)) {
            return v;
        }
    } catch (const YAML::Exception&) {
    }
    return std::nullopt;
}

/// Throws config_error at the second of two equal keys in any mapping of
/// the document: yaml-cpp reads the first, PyYAML (the workflow) the last,
/// so a duplicate would give the stages and the workflow two ladders.
void refuse_duplicate_keys(const ConfigFile& cfg, const YAML::Node& node)
{
    if (node.IsSequence()) {
        for (const auto& item : node) {
            refuse_duplicate_keys(cfg, item);
        }
    } else if (node.IsMap()) {
        std::map<std::string, int> first_line;
        for (const auto& kv : node) {
            if (kv.first.IsScalar()) {
                const auto [it, fresh] = first_line.emplace(kv.first.Scalar(), kv.first.Mark().line + 1);
                if (!fresh) {
                    cfg.fail(kv.first, "duplicate key '" + kv.first.Scalar() + "' (first at line " +
                                           std::to_string(it->second) + "): give each key once");
                }
            }
            refuse_duplicate_keys(cfg, kv.second);
        }
    }
}

class Checker {
  public:
    explicit Checker(const ConfigFile& cfg) : m_cfg(cfg) {}

    void mapping(const YAML::Node& node, const std::string& prefix) const
    {
        if (!node.IsMap()) {
            m_cfg.fail(node, "'" + (prefix.empty() ? std::string("the config") : prefix) + "' must be a mapping");
        }
        for (const auto& kv : node) {
            const auto name = kv.first.as<std::string>();
            const std::string full = prefix.empty() ? name : prefix + "." + name;
            const Key* k = find(full);
            if (k == nullptr) {
                std::string known;
                for (const Key& other : keys()) {
                    const auto dot = other.name.rfind('.');
                    const std::string parent = dot == std::string::npos ? "" : other.name.substr(0, dot);
                    if (parent == prefix) {
                        known += (known.empty() ? "" : ", ") + other.name.substr(parent.empty() ? 0 : dot + 1);
                    }
                }
                m_cfg.fail(kv.first, "unknown key '" + full + "' (known: " + known + ")");
            }
            value(kv.second, *k);
        }
    }

  private:
    [[noreturn]] void wrong(const YAML::Node& at, const Key& k, const std::string& got = "") const
    {
        m_cfg.fail(at, "'" + k.name + "' must be " + wanted(k) + got);
    }
    void in_limits(const YAML::Node& at, const Key& k, double v, const std::string& which = "") const
    {
        if (!k.limits.contains(v)) {
            m_cfg.fail(at, "'" + k.name + "'" + which + " must be " + k.limits.text());
        }
    }
    void value(const YAML::Node& v, const Key& k) const
    {
        switch (k.type) {
        case Type::mapping:
            mapping(v, k.name);
            return;
        case Type::text:
        case Type::path:
            if (!v.IsScalar()) {
                wrong(v, k);
            }
            return;
        case Type::viewport:
            if (!v.IsScalar() || !parse_viewport(v.as<std::string>(), k.limits)) {
                wrong(v, k, v.IsScalar() ? " (got '" + v.as<std::string>() + "')" : "");
            }
            return;
        case Type::choice: {
            if (!v.IsScalar()) {
                wrong(v, k);
            }
            const auto s = v.as<std::string>();
            if (std::find(k.choices.begin(), k.choices.end(), s) == k.choices.end()) {
                wrong(v, k, ", got '" + s + "'");
            }
            return;
        }
        case Type::integer: {
            const auto n = number_of(v);
            if (!n || *n != std::floor(*n)) {
                wrong(v, k);
            }
            in_limits(v, k, *n);
            return;
        }
        case Type::number: {
            const auto n = number_of(v);
            if (!n) {
                wrong(v, k);
            }
            in_limits(v, k, *n);
            return;
        }
        case Type::boolean:
            try {
                if (v.IsScalar()) {
                    (void)v.as<bool>();
                    return;
                }
            } catch (const YAML::Exception&) {
            }
            wrong(v, k);
        case Type::numbers: {
            if (!v.IsSequence() || v.size() == 0) {
                wrong(v, k);
            }
            std::optional<double> previous;
            for (size_t i = 0; i < v.size(); ++i) {
                const auto n = number_of(v[i]);
                if (!n) {
                    wrong(v[i], k);
                }
                in_limits(v[i], k, *n, bracketed(std::to_string(i)));
                if (previous && *n <= *previous) {
                    m_cfg.fail(v[i], "'" + k.name + "' must increase: " + v[i].as<std::string>() + " follows " +
                                         v[i - 1].as<std::string>());
                }
                previous = n;
            }
            return;
        }
        case Type::class_map:
            if (!v.IsMap()) {
                wrong(v, k);
            }
            for (const auto& kv : v) {
                const auto n = number_of(kv.second);
                if (!kv.first.IsScalar() || !n) {
                    wrong(kv.second, k);
                }
                in_limits(kv.second, k, *n, bracketed(kv.first.as<std::string>()));
            }
            return;
        case Type::paths:
        case Type::codes:
            if (v.IsScalar()) {
                return;
            }
            if (!v.IsSequence()) {
                wrong(v, k);
            }
            for (const auto& item : v) {
                if (!item.IsScalar()) {
                    wrong(item, k);
                }
            }
            return;
        case Type::levels:
            if (!v.IsSequence() || v.size() == 0) {
                wrong(v, k);
            }
            return;
        case Type::fields: {
            if (!v.IsSequence()) {
                wrong(v, k);
            }
            std::set<std::string> seen;
            for (const auto& item : v) {
                if (!item.IsScalar() || item.as<std::string>().empty() || !seen.insert(item.as<std::string>()).second) {
                    wrong(item, k);
                }
            }
            return;
        }
        }
    }

    const ConfigFile& m_cfg;
};

} // namespace

ConfigFile ConfigFile::load(const fs::path& file)
{
    ConfigFile cfg;
    cfg.m_file = file;
    std::error_code ec;
    if (!fs::exists(file, ec)) {
        throw config_error(file.string() + ": no such config file");
    }
    if (fs::is_directory(file, ec)) {
        throw config_error(file.string() + ": is a folder, not a config file");
    }
    try {
        cfg.m_root = YAML::LoadFile(file.string());
    } catch (const YAML::ParserException& e) {
        throw config_error(file.string() + ":" + std::to_string(e.mark.line + 1) + ": not valid YAML: " + e.msg);
    } catch (const YAML::Exception& e) {
        throw config_error(file.string() + ": cannot read: " + e.what());
    }
    refuse_duplicate_keys(cfg, cfg.m_root);
    Checker(cfg).mapping(cfg.m_root, "");
    return cfg;
}

namespace {

/// The node at a dotted path below `n`, without inserting anything (the
/// const operator[] of yaml-cpp; assigning Nodes would rewrite the tree).
YAML::Node find_node(const YAML::Node& n, std::string_view path)
{
    const auto dot = path.find('.');
    if (!n.IsMap()) {
        return YAML::Node(YAML::NodeType::Undefined);
    }
    const YAML::Node child = n[std::string(path.substr(0, dot))];
    if (!child.IsDefined() || dot == std::string_view::npos) {
        return child;
    }
    return find_node(child, path.substr(dot + 1));
}

} // namespace

YAML::Node ConfigFile::node(std::string_view name) const
{
    return find_node(m_root, name);
}

fs::path ConfigFile::resolve(const std::string& name) const
{
    fs::path p = name;
    if (p.is_relative()) {
        p = m_file.parent_path() / p;
    }
    return p.lexically_normal();
}

void ConfigFile::fail(const YAML::Node& at, const std::string& what) const
{
    std::string where = m_file.string();
    if (at.IsDefined() && at.Mark().line >= 0) {
        where += ':';
        where += std::to_string(at.Mark().line + 1);
    }
    throw config_error(where + ": " + what);
}

std::vector<std::string> stage_args(const fs::path& file, std::string_view stage)
{
    const ConfigFile cfg = ConfigFile::load(file);
    std::vector<std::string> args;
    for (const Key& k : keys()) {
        std::istringstream takers(k.stages);
        bool takes = false;
        for (std::string s; takers >> s;) {
            takes = takes || s == stage;
        }
        const YAML::Node v = takes ? cfg.node(k.name) : YAML::Node();
        if (!v.IsDefined() || v.IsNull()) {
            continue;
        }
        const std::string flag = "--" + k.flag;
        switch (k.type) {
        case Type::boolean:
            if (v.as<bool>() == k.flag_when) {
                args.push_back(flag);
            }
            break;
        case Type::numbers: {
            std::string list;
            for (const auto& item : v) {
                append_item(list, item.as<std::string>());
            }
            args.push_back(flag + "=" + list);
            break;
        }
        case Type::class_map: {
            std::string list;
            for (const auto& kv : v) {
                append_item(list, kv.first.as<std::string>() + '=' + kv.second.as<std::string>());
            }
            args.push_back(flag + "=" + list);
            break;
        }
        case Type::path:
            args.push_back(flag + "=" + cfg.resolve(v.as<std::string>()).string());
            break;
        default:
            args.push_back(flag + "=" + v.as<std::string>());
            break;
        }
    }
    return args;
}

} // namespace tigerlod::config
