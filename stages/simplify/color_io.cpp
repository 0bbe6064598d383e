#include "stages/simplify/color_io.hpp"

#include "core/errors.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <sstream>
#include <unordered_map>

namespace tigerlod::simplify {

using json = nlohmann::ordered_json;

std::string colors_to_json(const chains::ChainStore& store, double eps_m, Metric metric, const ColorResult& colors)
{
    json j;
    j["schema"] = "tigerlod.colors/1";
    j["level"] = store.level_name;
    j["partition"] = store.partition;
    j["eps_m"] = eps_m;
    j["metric"] = metric_name(metric);
    j["pixel"] = colors.pixel;
    j["splits"] = colors.splits;
    j["conflict_edges"] = colors.conflict_edges;
    json tiles = json::array();
    for (const auto& t : colors.tiles) {
        json jt;
        jt["x0"] = t.spec.x0;
        jt["y0"] = t.spec.y0;
        jt["width"] = t.spec.width;
        jt["height"] = t.spec.height;
        jt["depth"] = t.depth;
        json ids = json::array();
        for (const uint32_t c : t.chains) {
            ids.push_back(store.chains[c].id);
        }
        jt["chains"] = std::move(ids);
        jt["classes"] = t.classes;
        tiles.push_back(std::move(jt));
    }
    j["tiles"] = std::move(tiles);
    return j.dump() + "\n";
}

ColorResult colors_from_json(const std::filesystem::path& path, const chains::ChainStore& store, double eps_m,
                             Metric metric, double expected_pixel)
{
    const std::string name = path.string();
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        throw usage_error(name + ": cannot open the colours file (run tigerlod-color with the same options)");
    }
    std::stringstream ss;
    ss << in.rdbuf();
    json j;
    try {
        j = json::parse(ss.str());
    } catch (const json::exception& e) {
        throw format_error(name + ": not a colours file: " + e.what());
    }
    try {
        if (j.at("schema") != "tigerlod.colors/1") {
            throw format_error(name + ": unknown schema " + j.at("schema").dump());
        }
        const double file_eps = j.at("eps_m").get<double>();
        const double pixel = j.at("pixel").get<double>();
        if (file_eps != eps_m || j.at("metric") != metric_name(metric) ||
            std::abs(pixel - expected_pixel) > 1e-9 * expected_pixel) {
            throw usage_error(name + ": made at eps " + std::to_string(file_eps) + " m, metric " +
                              j.at("metric").get<std::string>() + ", pixel " + std::to_string(pixel) +
                              "; this run needs eps " + std::to_string(eps_m) + " m, metric " + metric_name(metric) +
                              ", pixel " + std::to_string(expected_pixel) +
                              " (run tigerlod-color with the same options)");
        }
        std::unordered_map<uint64_t, uint32_t> index;
        for (uint32_t i = 0; i < store.chains.size(); ++i) {
            index.emplace(store.chains[i].id, i);
        }
        ColorResult out;
        out.pixel = pixel;
        out.splits = j.at("splits").get<size_t>();
        out.conflict_edges = j.at("conflict_edges").get<size_t>();
        for (const auto& jt : j.at("tiles")) {
            ColoredTile t;
            t.spec.x0 = jt.at("x0").get<double>();
            t.spec.y0 = jt.at("y0").get<double>();
            t.spec.width = jt.at("width").get<uint32_t>();
            t.spec.height = jt.at("height").get<uint32_t>();
            t.spec.pixel = pixel;
            t.depth = jt.at("depth").get<uint32_t>();
            for (const auto& id : jt.at("chains")) {
                const auto it = index.find(id.get<uint64_t>());
                if (it == index.end()) {
                    throw format_error(name + ": chain " + id.dump() + " is not in the store " + store.level_name +
                                       "/" + store.partition);
                }
                t.chains.push_back(it->second);
            }
            for (const auto& c : jt.at("classes")) {
                const auto v = c.get<int>();
                if (v < 1 || v > 255) {
                    throw format_error(name + ": class " + std::to_string(v) + " outside 1..255");
                }
                t.classes.push_back(static_cast<uint8_t>(v));
            }
            if (t.classes.size() != t.chains.size() || t.spec.width == 0 || t.spec.height == 0) {
                throw format_error(name + ": a tile has " + std::to_string(t.chains.size()) + " chains and " +
                                   std::to_string(t.classes.size()) + " classes");
            }
            out.max_classes_used =
                std::max<uint32_t>(out.max_classes_used, *std::max_element(t.classes.begin(), t.classes.end()));
            out.tiles.push_back(std::move(t));
        }
        return out;
    } catch (const json::exception& e) {
        throw format_error(name + ": not a colours file: " + e.what());
    }
}

} // namespace tigerlod::simplify
