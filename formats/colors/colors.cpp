#include "formats/colors/colors.hpp"

#include "core/errors.hpp"

#include <nlohmann/json.hpp>

namespace tigerlod::colors {

using json = nlohmann::ordered_json;

namespace {
constexpr const char* schema = "tigerlod.colors/1";
} // namespace

std::string encode(const ColorFile& f)
{
    json j;
    j["schema"] = schema;
    j["level"] = f.level;
    j["partition"] = f.partition;
    j["eps_m"] = f.eps_m;
    j["metric"] = metric_name(f.metric);
    j["pixel"] = f.pixel;
    j["splits"] = f.splits;
    j["conflict_edges"] = f.conflict_edges;
    json tiles = json::array();
    for (const auto& t : f.tiles) {
        json jt;
        jt["x0"] = t.x0;
        jt["y0"] = t.y0;
        jt["width"] = t.width;
        jt["height"] = t.height;
        jt["depth"] = t.depth;
        jt["chains"] = t.chains;
        jt["classes"] = t.classes;
        tiles.push_back(std::move(jt));
    }
    j["tiles"] = std::move(tiles);
    return j.dump() + "\n";
}

ColorFile decode(std::string_view text, const std::string& name)
{
    json j;
    try {
        j = json::parse(text);
    } catch (const json::exception& e) {
        throw format_error(name + ": not a colours file: " + e.what());
    }
    try {
        if (j.at("schema") != schema) {
            throw format_error(name + ": unknown schema " + j.at("schema").dump());
        }
        ColorFile f;
        f.level = j.at("level").get<std::string>();
        f.partition = j.at("partition").get<std::string>();
        f.eps_m = j.at("eps_m").get<double>();
        const auto metric = parse_metric(j.at("metric").get<std::string>());
        if (!metric) {
            throw format_error(name + ": unknown metric " + j.at("metric").dump());
        }
        f.metric = *metric;
        f.pixel = j.at("pixel").get<double>();
        f.splits = j.at("splits").get<uint64_t>();
        f.conflict_edges = j.at("conflict_edges").get<uint64_t>();
        for (const auto& jt : j.at("tiles")) {
            Tile t;
            t.x0 = jt.at("x0").get<double>();
            t.y0 = jt.at("y0").get<double>();
            t.width = jt.at("width").get<uint32_t>();
            t.height = jt.at("height").get<uint32_t>();
            t.depth = jt.at("depth").get<uint32_t>();
            for (const auto& id : jt.at("chains")) {
                t.chains.push_back(id.get<uint64_t>());
            }
            for (const auto& c : jt.at("classes")) {
                const auto v = c.get<int>();
                if (v < 1 || v > 255) {
                    throw format_error(name + ": class " + std::to_string(v) + " outside 1..255");
                }
                t.classes.push_back(static_cast<uint8_t>(v));
            }
            if (t.classes.size() != t.chains.size() || t.width == 0 || t.height == 0) {
                throw format_error(name + ": a tile has " + std::to_string(t.chains.size()) + " chains and " +
                                   std::to_string(t.classes.size()) + " classes");
            }
            f.tiles.push_back(std::move(t));
        }
        return f;
    } catch (const json::exception& e) {
        throw format_error(name + ": not a colours file: " + e.what());
    }
}

} // namespace tigerlod::colors
