#include "simplification/color_io.hpp"

#include "core/errors.hpp"
#include "formats/colors/colors.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <unordered_map>

namespace tigerlod::simplify {

std::string colors_to_json(const chains::ChainStore& store, double eps_m, Metric metric, const ColorResult& colors)
{
    colors::ColorFile f;
    f.level = store.level_name;
    f.partition = store.partition;
    f.eps_m = eps_m;
    f.metric = metric;
    f.pixel = colors.pixel;
    f.splits = colors.splits;
    f.conflict_edges = colors.conflict_edges;
    for (const auto& t : colors.tiles) {
        colors::Tile ft;
        ft.x0 = t.spec.x0;
        ft.y0 = t.spec.y0;
        ft.width = t.spec.width;
        ft.height = t.spec.height;
        ft.depth = t.depth;
        for (const uint32_t c : t.chains) {
            ft.chains.push_back(store.chains[c].id);
        }
        ft.classes = t.classes;
        f.tiles.push_back(std::move(ft));
    }
    return colors::encode(f);
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
    const colors::ColorFile f = colors::decode(ss.str(), name);
    if (f.eps_m != eps_m || f.metric != metric || std::abs(f.pixel - expected_pixel) > 1e-9 * expected_pixel) {
        throw usage_error(name + ": made at eps " + std::to_string(f.eps_m) + " m, metric " + metric_name(f.metric) +
                          ", pixel " + std::to_string(f.pixel) + "; this run needs eps " + std::to_string(eps_m) +
                          " m, metric " + metric_name(metric) + ", pixel " + std::to_string(expected_pixel) +
                          " (run tigerlod-color with the same options)");
    }
    std::unordered_map<uint64_t, uint32_t> index;
    for (uint32_t i = 0; i < store.chains.size(); ++i) {
        index.emplace(store.chains[i].id, i);
    }
    ColorResult out;
    out.pixel = f.pixel;
    out.splits = f.splits;
    out.conflict_edges = f.conflict_edges;
    for (const auto& ft : f.tiles) {
        ColoredTile t;
        t.spec.x0 = ft.x0;
        t.spec.y0 = ft.y0;
        t.spec.width = ft.width;
        t.spec.height = ft.height;
        t.spec.pixel = f.pixel;
        t.depth = ft.depth;
        for (const uint64_t id : ft.chains) {
            const auto it = index.find(id);
            if (it == index.end()) {
                throw format_error(name + ": chain " + std::to_string(id) + " is not in the store " + store.level_name +
                                   "/" + store.partition);
            }
            t.chains.push_back(it->second);
        }
        t.classes = ft.classes;
        if (!t.classes.empty()) {
            out.max_classes_used =
                std::max<uint32_t>(out.max_classes_used, *std::max_element(t.classes.begin(), t.classes.end()));
        }
        out.tiles.push_back(std::move(t));
    }
    return out;
}

} // namespace tigerlod::simplify
