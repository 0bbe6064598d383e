#include "core/manifest.hpp"

#include "core/digest.hpp"
#include "core/errors.hpp"
#include "core/stage.hpp"

#include <fstream>
#include <iterator>
#include <span>

namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

namespace tigerlod {

namespace {

constexpr const char* schema_name = "tigerlod.manifest/1";

} // namespace

const json& Manifest::option(const std::string& key) const
{
    const auto options = doc.find("options");
    if (options == doc.end() || !options->is_object() || !options->contains(key)) {
        throw input_error((folder / "manifest.json").string() + ": no option '" + key + "'");
    }
    return options->at(key);
}

std::string Manifest::input_sha256(const std::string& role) const
{
    const auto inputs = doc.find("inputs");
    if (inputs == doc.end() || !inputs->is_object() || !inputs->contains(role) ||
        !inputs->at(role).contains("sha256") || !inputs->at(role).at("sha256").is_string()) {
        throw input_error((folder / "manifest.json").string() + ": no input '" + role + "'");
    }
    return inputs->at(role).at("sha256").get<std::string>();
}

json new_manifest(const std::string& stage, const std::vector<std::string>& libraries)
{
    json m;
    m["schema"] = schema_name;
    m["stage"] = stage;
    m["version"] = tigerlod_version();
    m["libraries"] = libraries;
    m["inputs"] = json::object();
    m["options"] = json::object();
    return m;
}

void add_input(json& manifest, const std::string& role, const Manifest& input)
{
    manifest["inputs"][role] = {{"stage", input.doc.value("stage", "")}, {"sha256", input.sha256}};
}

Manifest read_manifest(const fs::path& folder, const std::string& stage)
{
    Manifest m;
    m.folder = folder;
    const fs::path file = folder / "manifest.json";
    std::ifstream in(file, std::ios::binary);
    if (!in) {
        throw input_error(folder.string() + ": no manifest.json: not a finished tigerlod-" + stage +
                          " output (or one written before manifests; run tigerlod-" + stage + " again)");
    }
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    try {
        m.doc = json::parse(text);
    } catch (const json::exception& e) {
        throw input_error(file.string() + ": not JSON: " + e.what());
    }
    if (!m.doc.is_object() || m.doc.value("schema", "") != schema_name) {
        throw input_error(file.string() + ": not a " + schema_name);
    }
    if (m.doc.value("stage", "") != stage) {
        throw input_error(file.string() + ": written by tigerlod-" + m.doc.value("stage", "?") + ", not tigerlod-" +
                          stage + ": give a tigerlod-" + stage + " output here");
    }
    Sha256 sha;
    sha.update(std::as_bytes(std::span(text.data(), text.size())));
    m.sha256 = sha.hex_digest();
    return m;
}

void require_made_from(const Manifest& made, const std::string& role, const Manifest& input)
{
    if (made.input_sha256(role) != input.sha256) {
        const std::string stage = made.doc.value("stage", "?");
        throw input_error(made.folder.string() + " was made by tigerlod-" + stage + " from another " + role +
                          " output than " + input.folder.string() + " (their manifests differ): give the " + role +
                          " output it was made from, or run tigerlod-" + stage + " again on this one");
    }
}

std::string manifest_text(const json& manifest)
{
    return manifest.dump(2) + "\n";
}

} // namespace tigerlod
