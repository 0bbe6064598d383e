#include "stages/render/camera.hpp"

#include "core/errors.hpp"
#include "core/projection.hpp"
#include "reader/tree_view.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>

namespace tigerlod::render {

namespace {

double centre_x(const datatree::Box& b)
{
    return 0.5 * (double(b.min_x) + double(b.max_x));
}
double centre_y(const datatree::Box& b)
{
    return 0.5 * (double(b.min_y) + double(b.max_y));
}

/// From view a to view b in `frames` steps (b last): the scale
/// geometrically, the centre in proportion to the change of scale (a zoom
/// keeps its target in place on the screen), or linearly when the scale
/// does not change.
void move(const reader::View& a, const reader::View& b, uint32_t frames, std::vector<reader::View>& out)
{
    for (uint32_t f = 1; f <= frames; ++f) {
        const double t = double(f) / double(frames);
        reader::View v = a;
        v.units_per_pixel = a.units_per_pixel * std::pow(b.units_per_pixel / a.units_per_pixel, t);
        const double w = std::fabs(b.units_per_pixel - a.units_per_pixel) > 1e-9 * a.units_per_pixel
                             ? (v.units_per_pixel - a.units_per_pixel) / (b.units_per_pixel - a.units_per_pixel)
                             : t;
        v.center_x = a.center_x + w * (b.center_x - a.center_x);
        v.center_y = a.center_y + w * (b.center_y - a.center_y);
        out.push_back(v);
    }
}

} // namespace

reader::View fit(const datatree::Box& box, uint32_t width, uint32_t height)
{
    reader::View v;
    v.width = width;
    v.height = height;
    v.center_x = centre_x(box);
    v.center_y = centre_y(box);
    const double w = std::max(1.0, double(box.max_x) - box.min_x), h = std::max(1.0, double(box.max_y) - box.min_y);
    v.units_per_pixel = 1.05 * std::max(w / width, h / height);
    return v;
}

std::vector<Keyframe> read_path_file(const std::filesystem::path& file)
{
    std::ifstream in(file);
    if (!in) {
        throw input_error(file.string() + ": cannot read the camera path");
    }
    std::vector<Keyframe> keys;
    std::string line;
    for (size_t number = 1; std::getline(in, line); ++number) {
        const auto hash = line.find('#');
        if (hash != std::string::npos) {
            line.resize(hash);
        }
        std::istringstream words(line);
        std::vector<std::string> w;
        for (std::string s; words >> s;) {
            w.push_back(s);
        }
        if (w.empty()) {
            continue;
        }
        const std::string where = file.string() + ":" + std::to_string(number) + ": ";
        if (w.size() < 3 || w.size() > 4) {
            throw input_error(where + "expected LON LAT METRES_PER_PIXEL [FRAMES], found " + std::to_string(w.size()) +
                              " fields");
        }
        auto number_of = [&](const std::string& text, const char* what) {
            size_t used = 0;
            double v = 0;
            try {
                v = std::stod(text, &used);
            } catch (const std::exception&) {
                used = 0;
            }
            if (used != text.size() || !std::isfinite(v)) {
                throw input_error(where + what + " '" + text + "' is not a number");
            }
            return v;
        };
        Keyframe k;
        k.lon = number_of(w[0], "LON");
        k.lat = number_of(w[1], "LAT");
        k.metres_per_pixel = number_of(w[2], "METRES_PER_PIXEL");
        if (k.lon < -180 || k.lon > 180 || k.lat < -90 || k.lat > 90) {
            throw input_error(where + "LON must be in -180..180 and LAT in -90..90");
        }
        if (k.metres_per_pixel <= 0) {
            throw input_error(where + "METRES_PER_PIXEL must be > 0");
        }
        if (w.size() == 4) {
            const double f = number_of(w[3], "FRAMES");
            if (f != std::floor(f) || f < 1 || f > 100000) {
                throw input_error(where + "FRAMES must be a whole number in 1..100000");
            }
            k.frames = static_cast<uint32_t>(f);
        }
        keys.push_back(k);
    }
    if (keys.empty()) {
        throw input_error(file.string() + ": no keyframes (one a line: LON LAT METRES_PER_PIXEL [FRAMES])");
    }
    return keys;
}

std::vector<reader::View> keyframe_views(const std::vector<Keyframe>& keys, const datatree::Skeleton& s, uint32_t width,
                                         uint32_t height)
{
    const Projection proj(view::projection_of(s));
    std::vector<reader::View> views;
    reader::View last;
    for (size_t i = 0; i < keys.size(); ++i) {
        const auto g = proj.to_grid(keys[i].lon, keys[i].lat);
        if (!g) {
            throw input_error("keyframe " + std::to_string(i + 1) + " (" + std::to_string(keys[i].lon) + ", " +
                              std::to_string(keys[i].lat) + ") is outside the tree's projection");
        }
        reader::View v;
        v.width = width;
        v.height = height;
        v.center_x = g->x;
        v.center_y = g->y;
        v.units_per_pixel = keys[i].metres_per_pixel / s.grid_m();
        if (i == 0) {
            views.push_back(v);
        } else {
            move(last, v, keys[i].frames, views);
        }
        last = v;
    }
    return views;
}

std::vector<reader::View> builtin_path(const std::string& name, const datatree::Skeleton& s, uint32_t width,
                                       uint32_t height, uint32_t frames, uint32_t seed)
{
    std::vector<reader::View> views;
    if (s.nodes.empty()) {
        return views;
    }
    const reader::View whole = fit(s.nodes[0].box, width, height);
    frames = std::max(frames, 2U);
    if (name == "zoom") {
        // Down the tree to the leaf under the centre (or nearest it).
        const double px = whole.center_x, py = whole.center_y;
        uint32_t n = 0;
        while (s.nodes[n].child_count > 0) {
            const auto& node = s.nodes[n];
            uint32_t best = node.first_child;
            double best_d = INFINITY;
            for (uint32_t c = node.first_child; c < node.first_child + node.child_count; ++c) {
                const auto& b = s.nodes[c].box;
                const bool inside = px >= b.min_x && px <= b.max_x && py >= b.min_y && py <= b.max_y;
                const double d = inside ? 0.0 : std::hypot(centre_x(b) - px, centre_y(b) - py);
                if (d < best_d) {
                    best_d = d;
                    best = c;
                }
            }
            n = best;
        }
        // Its finest units: about sqrt(chains) of them across its box.
        reader::View target = fit(s.nodes[n].box, width, height);
        target.units_per_pixel /= std::max(2.0, 0.5 * std::sqrt(double(s.nodes[n].chains)));
        views.push_back(whole);
        move(whole, target, frames / 2 - 1, views);
        move(target, whole, frames - frames / 2, views);
    } else if (name == "pan") {
        // At the scale of the median leaf, across the map through its centre.
        std::vector<double> sizes;
        for (const auto& node : s.nodes) {
            if (node.child_count == 0 && node.chains > 0) {
                sizes.push_back(
                    std::max(double(node.box.max_x) - node.box.min_x, double(node.box.max_y) - node.box.min_y));
            }
        }
        std::sort(sizes.begin(), sizes.end());
        const double leaf = sizes.empty() ? 1.0 : std::max(1.0, sizes[sizes.size() / 2]);
        reader::View a = whole;
        a.units_per_pixel = leaf / std::min(width, height);
        const auto& b = s.nodes[0].box;
        const double half = std::min(3 * leaf, 0.5 * (double(b.max_x) - b.min_x));
        reader::View z = a;
        a.center_x = whole.center_x - half;
        z.center_x = whole.center_x + half;
        views.push_back(a);
        move(a, z, frames - 1, views);
    } else if (name == "jumpy") {
        std::mt19937 rng(seed);
        std::vector<uint32_t> shown;
        for (uint32_t n = 0; n < s.nodes.size(); ++n) {
            if (s.nodes[n].chains > 0) {
                shown.push_back(n);
            }
        }
        if (shown.empty()) {
            shown.push_back(0);
        }
        std::uniform_real_distribution<double> unit(0.0, 1.0);
        reader::View v = whole;
        for (uint32_t f = 0; f < frames; ++f) {
            if (f % 12 == 0) {
                const uint32_t n = shown[rng() % shown.size()];
                v = fit(s.nodes[n].box, width, height);
                v.units_per_pixel *= std::exp2(2 * unit(rng) - 1);
            } else {
                v.center_x += 0.02 * width * v.units_per_pixel;
                v.units_per_pixel *= 0.99;
            }
            views.push_back(v);
        }
    } else {
        throw usage_error("render: no built-in path '" + name + "' (zoom, pan or jumpy)");
    }
    return views;
}

} // namespace tigerlod::render
