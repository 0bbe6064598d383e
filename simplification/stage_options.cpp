#include "simplification/stage_options.hpp"

#include "config/schema.hpp"
#include "core/errors.hpp"
#include "core/metric.hpp"
#include "core/projection.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>
#include <thread>

namespace fs = std::filesystem;

namespace tigerlod::simplify {

using json = nlohmann::ordered_json;

void CommonOptions::add(ArgSet& args)
{
    args.positional("INPUT", &input, "a tigerlod-ingest output folder (INPUT/<level>/<partition>.tlc)");
    args.positional("OUTPUT", &output, "the output folder, written under a temporary name and renamed on success");
    args.group("Tolerances");
    config::add_option(args, "simplify.tolerances_m", &m_tolerances);
    config::add_option(args, "simplify.metric", &m_metric);
    config::add_option(args, "simplify.class_scale", &m_class_scale);
    config::add_option(args, "simplify.projection_scale", &m_no_projection_scale);
    args.group("Rendering");
    config::add_option(args, "simplify.pixel_fraction", &m_pixel_fraction);
    config::add_option(args, "simplify.tile_pixels", &m_tile_pixels);
    config::add_option(args, "simplify.max_classes", &m_max_classes);
    args.group("Run");
    args.add("level", &level, "only this level (default: all)", "NAME");
    config::add_option(args, "simplify.threads", &m_threads);
    args.add("overwrite", &overwrite, "replace OUTPUT if it exists");
    args.group("Partitions (the workflow's jobs)");
    args.add("partitions", &partitions,
             "only these stores, OUTPUT updated in place (each file renamed alone, other partitions' files "
             "untouched, the bytes a whole run writes): LEVEL/PARTITION, LEVEL/PREFIX* or LEVEL/*, separated by "
             "commas, or @FILE with one a line",
             "LIST");
    args.add("report", &report,
             "with --partitions: write this job's report to FILE (a whole run writes "
             "OUTPUT/<stage>-report.json)",
             "FILE");
    args.add("finish", &finish,
             "after the --partitions jobs: check that every store has its files in OUTPUT, remove those of "
             "stores and tolerances this run no longer has, write OUTPUT/manifest.json");
}

void CommonOptions::initialize(const std::string& stage)
{
    auto fail = [&](const std::string& opt, const std::string& what) {
        throw usage_error(stage + ": option '--" + opt + "' " + what);
    };
    tolerances.clear();
    std::stringstream ss(m_tolerances);
    std::string item;
    std::string previous; // as the user wrote it
    while (std::getline(ss, item, ',')) {
        double v = 0;
        const auto [p, ec] = std::from_chars(item.data(), item.data() + item.size(), v);
        if (item.empty() || ec != std::errc() || p != item.data() + item.size()) {
            fail("tolerances", "has '" + item + "', not a number");
        }
        // The config's limits (config::key), so that the command line and
        // the config refuse the same ladders: a kilometre-scale world map
        // fits under 1e6 m, and nothing needs less than the finest grid.
        if (const Limits& limits = config::key("simplify.tolerances_m").limits; !limits.contains(v)) {
            fail("tolerances", "has " + item + "; every tolerance must be " + limits.text() + " metres");
        }
        if (!tolerances.empty() && v <= tolerances.back()) {
            fail("tolerances", "must increase: " + item + " follows " + previous);
        }
        tolerances.push_back(v);
        previous = item;
    }
    if (tolerances.empty()) {
        fail("tolerances", "is empty: give at least one tolerance in metres");
    }
    options.metric = *parse_metric(m_metric); // one of the option's choices
    options.class_scale = parse_class_scale(m_class_scale, stage);
    options.projection_scale = !m_no_projection_scale;
    options.color.pixel_fraction = m_pixel_fraction;
    options.color.tile_pixels = static_cast<uint32_t>(m_tile_pixels);
    options.color.max_classes = static_cast<uint32_t>(m_max_classes);
    options.color.metric = options.metric;
    if (finish && !partitions.empty()) {
        throw usage_error(stage + ": options '--finish' and '--partitions' exclude each other");
    }
    if (!report.empty() && partitions.empty()) {
        throw usage_error(stage + ": option '--report' goes with '--partitions' (a whole run writes OUTPUT/" + stage +
                          "-report.json)");
    }
    options.threads = m_threads == 0 ? std::max(1U, std::thread::hardware_concurrency()) : unsigned(m_threads);
}

json CommonOptions::manifest_options() const
{
    return {{"tolerances_m", tolerances},
            {"metric", metric_name(options.metric)},
            {"class_scale", options.class_scale},
            {"projection_scale", options.projection_scale},
            {"pixel_fraction", options.color.pixel_fraction},
            {"tile_pixels", options.color.tile_pixels},
            {"max_classes", options.color.max_classes},
            {"level", level}};
}

void CommonOptions::check_colors(const Manifest& colors, const Manifest& ingest) const
{
    require_made_from(colors, "ingest", ingest);
    const json mine = manifest_options();
    const json theirs = colors.doc.value("options", json::object());
    for (const auto& [key, value] : mine.items()) {
        if (key == "tolerances_m" || key == "level") {
            continue;
        }
        if (!theirs.contains(key) || theirs.at(key) != value) {
            throw usage_error("simplify: --colors " + colors.folder.string() + " was made with " + key + " " +
                              (theirs.contains(key) ? theirs.at(key).dump() : std::string("unset")) +
                              ", this run has " + value.dump() +
                              ": run tigerlod-color with the options given here, or give these its options");
        }
    }
    const json ladder = theirs.value("tolerances_m", json::array());
    for (const double eps : tolerances) {
        if (std::find(ladder.begin(), ladder.end(), json(eps)) == ladder.end()) {
            throw usage_error("simplify: --colors " + colors.folder.string() + " has no colours at tolerance " +
                              json(eps).dump() + " m (its ladder: " + ladder.dump() +
                              "): run tigerlod-color with this run's --tolerances");
        }
    }
    const std::string their_level = theirs.value("level", "");
    if (!their_level.empty() && their_level != level) {
        throw usage_error("simplify: --colors " + colors.folder.string() + " holds level '" + their_level +
                          "' only; this run needs " + (level.empty() ? std::string("every level") : "'" + level + "'"));
    }
}

SimplifyOptions tolerance_contract(const json& o, const std::string& where)
{
    SimplifyOptions s;
    try {
        const auto metric = parse_metric(o.at("metric").get<std::string>());
        if (!metric) {
            throw input_error(where + ": unknown metric " + o.at("metric").dump());
        }
        s.metric = *metric;
        s.class_scale = o.at("class_scale").get<std::map<std::string, double>>();
        s.projection_scale = o.at("projection_scale").get<bool>();
        s.point_constraints = o.at("point_constraints").get<bool>();
        for (const auto& p : o.at("points").at("lonlat")) {
            s.user_points.push_back({p.at(0).get<double>(), p.at(1).get<double>()});
        }
    } catch (const json::exception& e) {
        throw input_error(where + ": the options of tigerlod-simplify: " + e.what());
    }
    return s;
}

std::map<std::string, double> parse_class_scale(const std::string& list, const std::string& stage)
{
    std::map<std::string, double> out;
    std::stringstream cs(list);
    std::string item;
    while (std::getline(cs, item, ',')) {
        const auto eq = item.find('=');
        double v = 0;
        if (eq == std::string::npos || eq == 0 ||
            std::from_chars(item.data() + eq + 1, item.data() + item.size(), v).ptr != item.data() + item.size() ||
            !(v > 0)) {
            throw usage_error(stage + ": option '--class-scale' has '" + item +
                              "'; expected CLASS=FACTOR with FACTOR > 0");
        }
        out[item.substr(0, eq)] = v;
    }
    return out;
}

std::vector<StoreFile> list_stores(const fs::path& input, const std::string& level)
{
    std::error_code ec;
    if (!fs::is_directory(input, ec)) {
        throw usage_error(input.string() + ": not a folder (expected a tigerlod-ingest output)");
    }
    std::vector<StoreFile> out;
    for (const auto& d : fs::directory_iterator(input)) {
        if (!d.is_directory() || (!level.empty() && d.path().filename() != level)) {
            continue;
        }
        for (const auto& f : fs::directory_iterator(d.path())) {
            if (f.is_regular_file() && f.path().extension() == ".tlc") {
                out.push_back({d.path().filename().string(), f.path().stem().string(), f.path(), ""});
            }
        }
    }
    std::sort(out.begin(), out.end(), [](const StoreFile& a, const StoreFile& b) {
        return std::tie(a.level, a.partition) < std::tie(b.level, b.partition);
    });
    if (out.empty()) {
        throw usage_error(input.string() + ": no chain store" +
                          (level.empty() ? std::string() : " of level '" + level + "'") +
                          " (expected <level>/<partition>.tlc files)");
    }
    // Against what ingest says it wrote: a store lost, or one copied in from
    // another run, would otherwise be simplified as if it belonged.
    const fs::path report_path = input / "ingest-report.json";
    std::map<std::string, size_t> wrote; // level -> stores
    std::string projection;
    try {
        std::ifstream in(report_path);
        if (!in) {
            throw input_error(input.string() + ": no ingest-report.json: not a finished tigerlod-ingest output");
        }
        const auto report = nlohmann::json::parse(in);
        projection = report.at("projection").get<std::string>();
        for (const auto& l : report.at("levels")) {
            wrote[l.at("name").get<std::string>()] = l.at("partitions").get<size_t>();
        }
    } catch (const nlohmann::json::exception& e) {
        throw input_error(report_path.string() + ": " + e.what());
    }
    std::map<std::string, size_t> found;
    for (auto& f : out) {
        ++found[f.level];
        f.projection = projection;
    }
    for (const auto& [name, count] : found) {
        const auto it = wrote.find(name);
        if (it == wrote.end()) {
            throw input_error((input / name).string() + ": a level tigerlod-ingest did not write (ingest-report.json " +
                              "lists no level '" + name + "')");
        }
        if (it->second != count) {
            throw input_error((input / name).string() + ": " + std::to_string(count) + " chain stores, but " +
                              "tigerlod-ingest wrote " + std::to_string(it->second) +
                              " (ingest-report.json): a store is missing or foreign; re-run tigerlod-ingest");
        }
    }
    for (const auto& [name, count] : wrote) {
        if ((level.empty() || level == name) && count > 0 && !found.contains(name)) {
            throw input_error((input / name).string() + ": tigerlod-ingest wrote " + std::to_string(count) +
                              " chain stores of level '" + name + "' here, and none is left; re-run tigerlod-ingest");
        }
    }
    return out;
}

void check_store(const chains::ChainStore& store, const StoreFile& file)
{
    if (store.level_name != file.level || store.partition != file.partition) {
        throw input_error(file.path.string() + ": holds partition '" + store.partition + "' of level '" +
                          store.level_name + "', not what its place names (another store under this name?); " +
                          "re-run tigerlod-ingest");
    }
    const std::string p = Projection(store.projection).describe();
    if (!file.projection.empty() && p != file.projection) {
        throw input_error(file.path.string() + ": projection " + p + ", but tigerlod-ingest wrote the others in " +
                          file.projection + "; re-run tigerlod-ingest");
    }
}

void check_ladder(const chains::ChainStore& store, const StoreFile& file, const std::vector<double>& tolerances,
                  const SimplifyOptions& options)
{
    // Below the grid step a tolerance keeps every vertex, and its raster
    // tiles (a few tolerances wide) would number in the trillions.
    const double grid_m = store.projection.grid_m;
    if (!tolerances.empty() && tolerances.front() < grid_m) {
        throw usage_error(file.path.string() + ": tolerance " + std::to_string(tolerances.front()) +
                          " m is below the store's grid step of " + std::to_string(grid_m) +
                          " m (projection.grid_m): give tolerances of one grid step or more");
    }
    // Partitions are simplified independently only if each sees every
    // chain within eps_i + eps_j of its own: its halo must be that wide.
    double max_scale = 1.0;
    for (const auto& [cls, f] : options.class_scale) {
        max_scale = std::max(max_scale, f);
    }
    const double need = halo_needed_m(tolerances.back(), max_scale, options.metric);
    if (store.partition != "all" && store.halo_m < need) {
        throw usage_error(file.path.string() + ": cut with a halo of " + std::to_string(store.halo_m) +
                          " m, but tolerance " + std::to_string(tolerances.back()) + " m needs at least " +
                          std::to_string(need) + " m so that partitions cannot cross; re-run tigerlod-ingest " +
                          "with a larger ingest.halo_m (or --halo-m), or lower the tolerances");
    }
}

namespace {

std::vector<std::string> split_csv_line(const std::string& line)
{
    std::vector<std::string> out;
    std::string cur;
    bool quoted = false;
    for (char c : line) {
        if (c == '"') {
            quoted = !quoted;
        } else if (c == ',' && !quoted) {
            out.push_back(cur);
            cur.clear();
        } else if (c != '\r') {
            cur += c;
        }
    }
    out.push_back(cur);
    return out;
}

} // namespace

std::vector<LonLat> read_points(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        throw usage_error(path + ": cannot open the points file");
    }
    std::stringstream ss;
    ss << in.rdbuf();
    const std::string text = ss.str();
    std::vector<LonLat> out;
    auto check = [&](double lon, double lat, const std::string& where) {
        if (!(lon >= -180 && lon <= 180 && lat >= -90 && lat <= 90)) {
            throw input_error(path + ": " + where + ": lon/lat (" + std::to_string(lon) + ", " + std::to_string(lat) +
                              ") out of range");
        }
        out.push_back({lon, lat});
    };
    const auto first = text.find_first_not_of(" \t\r\n");
    if (first != std::string::npos && text[first] == '{') {
        json j;
        try {
            j = json::parse(text);
        } catch (const json::exception& e) {
            throw input_error(path + ": invalid GeoJSON: " + e.what());
        }
        const json features =
            j.value("type", "") == "FeatureCollection" ? j.value("features", json::array()) : json::array({j});
        size_t i = 0;
        for (const auto& f : features) {
            const std::string where = "feature " + std::to_string(i++);
            const json& g = f.contains("geometry") ? f["geometry"] : f;
            try {
                const std::string type = g.at("type");
                if (type == "Point") {
                    check(g.at("coordinates").at(0), g.at("coordinates").at(1), where);
                } else if (type == "MultiPoint") {
                    for (const auto& c : g.at("coordinates")) {
                        check(c.at(0), c.at(1), where);
                    }
                } else {
                    throw input_error(path + ": " + where + ": geometry type " + type +
                                      ", expected Point or MultiPoint");
                }
            } catch (const json::exception& e) {
                throw input_error(path + ": " + where + ": " + e.what());
            }
        }
        return out;
    }
    std::istringstream lines(text);
    std::string line;
    size_t lineno = 0;
    int ilon = -1, ilat = -1;
    while (std::getline(lines, line)) {
        ++lineno;
        if (line.find_first_not_of(" \t\r") == std::string::npos) {
            continue;
        }
        const auto cols = split_csv_line(line);
        if (ilon < 0) {
            for (int c = 0; c < int(cols.size()); ++c) {
                std::string h = cols[size_t(c)];
                std::transform(h.begin(), h.end(), h.begin(), [](unsigned char ch) { return std::tolower(ch); });
                if (h == "lon" || h == "lng" || h == "longitude" || h == "x") {
                    ilon = c;
                } else if (h == "lat" || h == "latitude" || h == "y") {
                    ilat = c;
                }
            }
            if (ilon < 0 || ilat < 0) {
                throw input_error(path + ": line " + std::to_string(lineno) +
                                  ": the header needs lon and lat columns (lon/lng/longitude/x, lat/latitude/y)");
            }
            continue;
        }
        const std::string where = "line " + std::to_string(lineno);
        if (int(cols.size()) <= std::max(ilon, ilat)) {
            throw input_error(path + ": " + where + ": too few columns");
        }
        try {
            size_t p1 = 0, p2 = 0;
            const double lon = std::stod(cols[size_t(ilon)], &p1), lat = std::stod(cols[size_t(ilat)], &p2);
            if (p1 != cols[size_t(ilon)].size() || p2 != cols[size_t(ilat)].size()) {
                throw std::invalid_argument("trailing text");
            }
            check(lon, lat, where);
        } catch (const std::logic_error&) {
            throw input_error(path + ": " + where + ": lon/lat are not numbers");
        }
    }
    return out;
}

} // namespace tigerlod::simplify
