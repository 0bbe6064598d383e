#include "stages/serve/site.hpp"

#include "core/digest.hpp"
#include "core/errors.hpp"
#include "core/fs.hpp"

#include <nlohmann/json.hpp>

#include <charconv>
#include <cmath>
#include <cstring>

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace tigerlod::serve {

namespace {

Response error(int status, const std::string& what)
{
    Response r;
    r.status = status;
    r.body = json{{"error", what}}.dump() + "\n";
    return r;
}

Response json_response(const json& j, const std::string& etag)
{
    Response r;
    r.body = j.dump() + "\n";
    if (!etag.empty()) {
        r.headers.emplace_back("ETag", etag);
        r.headers.emplace_back("Cache-Control", "no-cache"); // the tree may be repacked: ask again, by ETag
    }
    return r;
}

/// A viewer file's name: letters, digits, '.', '-', '_', not beginning with '.'.
bool plain_name(const std::string& s)
{
    if (s.empty() || s.front() == '.' || s.size() > 128) {
        return false;
    }
    for (const char c : s) {
        if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-' || c == '_')) {
            return false;
        }
    }
    return true;
}

const char* content_type_of(const std::string& name)
{
    const auto ends = [&](const char* e) {
        const size_t n = std::strlen(e);
        return name.size() >= n && name.compare(name.size() - n, n, e) == 0;
    };
    if (ends(".html")) {
        return "text/html; charset=utf-8";
    }
    if (ends(".js") || ends(".mjs")) {
        return "text/javascript; charset=utf-8";
    }
    if (ends(".css")) {
        return "text/css; charset=utf-8";
    }
    if (ends(".json")) {
        return "application/json";
    }
    if (ends(".png")) {
        return "image/png";
    }
    if (ends(".wasm")) {
        return "application/wasm";
    }
    return "application/octet-stream";
}

/// A node index in the path segment `s`, or nullopt.
std::optional<uint32_t> index_of(const std::string& s, uint64_t below)
{
    uint64_t v = 0;
    const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
    if (s.empty() || s.size() > 10 || r.ec != std::errc() || r.ptr != s.data() + s.size() || v >= below) {
        return std::nullopt;
    }
    return static_cast<uint32_t>(v);
}

/// A finite number in query parameter `key`; `fallback` when absent; nullopt when malformed.
std::optional<double> number(const Request& r, const char* key, std::optional<double> fallback)
{
    const auto it = r.query.find(key);
    if (it == r.query.end()) {
        return fallback;
    }
    double v = 0;
    const auto& s = it->second;
    const auto res = std::from_chars(s.data(), s.data() + s.size(), v);
    if (s.empty() || res.ec != std::errc() || res.ptr != s.data() + s.size() || !std::isfinite(v)) {
        return std::nullopt;
    }
    return v;
}

std::vector<std::string> split_path(const std::string& path)
{
    std::vector<std::string> parts;
    size_t at = 1;
    while (at <= path.size()) {
        const size_t next = path.find('/', at);
        parts.push_back(path.substr(at, next == std::string::npos ? std::string::npos : next - at));
        if (next == std::string::npos) {
            break;
        }
        at = next + 1;
    }
    return parts;
}

} // namespace

std::string geometry_bytes(const datatree::Geometry& g)
{
    std::string out;
    const auto put = [&](uint32_t v) {
        char b[4];
        std::memcpy(b, &v, 4);
        out.append(b, 4);
    };
    out.reserve(8 + 4 * g.offsets.size() + 8 * g.points.size());
    put(static_cast<uint32_t>(g.chain_count()));
    put(static_cast<uint32_t>(g.points.size()));
    for (const uint32_t o : g.offsets) {
        put(o);
    }
    for (const auto& p : g.points) {
        put(static_cast<uint32_t>(p.x));
        put(static_cast<uint32_t>(p.y));
    }
    return out;
}

Site::Site(std::shared_ptr<const reader::Tree> tree, SiteOptions options)
    : m_tree(std::move(tree)), m_options(std::move(options))
{
    m_skeleton_bytes = read_file(m_tree->dir() / "skeleton.tls");
    Sha256 sha;
    sha.update(std::as_bytes(std::span(m_skeleton_bytes.data(), m_skeleton_bytes.size())));
    m_etag = "\"" + sha.hex_digest().substr(0, 32) + "\"";
    m_frame = reader::main_extent(*m_tree);
    const auto& tiles = m_tree->skeleton().tiles;
    for (size_t t = 0; t < tiles.size(); ++t) {
        const fs::path file(tiles[t].file);
        if (file.parent_path() == "tiles" && plain_name(file.filename().string())) {
            m_tiles.emplace(file.filename().string(), t);
        }
    }
    if (!m_options.viewer.empty()) {
        std::error_code ec;
        for (const auto& e : fs::directory_iterator(m_options.viewer, ec)) {
            const std::string name = e.path().filename().string();
            if (e.is_regular_file(ec) && plain_name(name)) {
                m_viewer_files.emplace(name, e.path());
            }
        }
        if (ec) {
            throw environment_error("serve: cannot list the viewer folder " + m_options.viewer.string() + ": " +
                                    ec.message());
        }
    }
}

uint64_t Site::cached_bytes() const
{
    std::lock_guard lock(m_mutex);
    return m_cached;
}

std::shared_ptr<const std::string> Site::cached(const std::string& key, const std::function<std::string()>& make) const
{
    {
        std::lock_guard lock(m_mutex);
        if (const auto it = m_cache.find(key); it != m_cache.end()) {
            m_lru.splice(m_lru.begin(), m_lru, it->second.second);
            return it->second.first;
        }
    }
    auto body = std::make_shared<const std::string>(make()); // outside the lock: decoding takes a while
    std::lock_guard lock(m_mutex);
    if (body->size() > m_options.cache_bytes || m_cache.contains(key)) {
        return body; // too big to keep, or another thread put it in meanwhile
    }
    m_lru.push_front(key);
    m_cache.emplace(key, std::pair{body, m_lru.begin()});
    m_cached += body->size();
    while (m_cached > m_options.cache_bytes) {
        const auto it = m_cache.find(m_lru.back());
        m_cached -= it->second.first->size();
        m_cache.erase(it);
        m_lru.pop_back();
    }
    return body;
}

Response Site::handle(const Request& request) const
{
    if (request.method != "GET" && request.method != "HEAD") {
        Response r = error(405, "only GET and HEAD");
        r.headers.emplace_back("Allow", "GET, HEAD");
        return r;
    }
    if (request.path.empty() || request.path.front() != '/' || request.path.size() > 512 ||
        request.path.find('\0') != std::string::npos) {
        return error(400, "malformed path");
    }
    try {
        Response r = route(request);
        if (r.status == 200 && !request.if_none_match.empty()) {
            for (const auto& [k, v] : r.headers) {
                if (k == "ETag" && v == request.if_none_match) {
                    r.status = 304;
                    r.body.clear();
                }
            }
        }
        return r;
    } catch (const std::exception& e) {
        return error(500, e.what()); // a tile removed by a repack, a damaged payload
    }
}

Response Site::route(const Request& r) const
{
    const auto parts = split_path(r.path);
    const auto& sk = m_tree->skeleton();
    if (r.path == "/") {
        if (const auto it = m_viewer_files.find("index.html"); it != m_viewer_files.end()) {
            Response res;
            res.content_type = content_type_of("index.html");
            res.body = read_file(it->second);
            return res;
        }
        Response res;
        res.content_type = "text/plain; charset=utf-8";
        res.body = "tigerlod-serve: no viewer folder; the tree is at /tree/skeleton.tls and /api/tree\n";
        return res;
    }
    if (parts.size() == 2 && parts[0] == "viewer") {
        const auto it = m_viewer_files.find(parts[1]);
        if (it == m_viewer_files.end()) {
            return error(404, "no such viewer file");
        }
        Response res;
        res.content_type = content_type_of(parts[1]);
        res.body = read_file(it->second);
        res.headers.emplace_back("Cache-Control", "no-cache");
        return res;
    }
    if (parts.size() == 2 && parts[0] == "tree" && parts[1] == "skeleton.tls") {
        Response res;
        res.content_type = "application/octet-stream";
        res.body = m_skeleton_bytes;
        res.headers.emplace_back("ETag", m_etag);
        res.headers.emplace_back("Cache-Control", "no-cache");
        return res;
    }
    if (parts.size() == 3 && parts[0] == "tree" && parts[1] == "tiles") {
        return tile(parts[2], r.if_none_match);
    }
    if (parts.size() == 2 && parts[0] == "api" && parts[1] == "tree") {
        return api_tree();
    }
    if (parts.size() == 2 && parts[0] == "api" && parts[1] == "front") {
        return api_front(r);
    }
    if (parts.size() == 2 && parts[0] == "api" && parts[1] == "verify") {
        if (m_options.verify.empty()) {
            return error(404, "no verify report (tigerlod-serve --verify REPORT)");
        }
        Response res;
        res.body = read_file(m_options.verify);
        return res;
    }
    if (parts.size() >= 3 && parts[0] == "api") {
        const auto node = index_of(parts[2], sk.nodes.size());
        if (!node) {
            return error(404, "no node " + parts[2]);
        }
        if (parts[1] == "node" && parts.size() == 4) {
            const auto lod = index_of(parts[3], sk.lod_eps_m.size());
            if (!lod) {
                return error(404, "no LOD " + parts[3]);
            }
            return api_node(*node, *lod);
        }
        if (parts[1] == "table" && parts.size() == 3) {
            return api_table(*node);
        }
        if (parts[1] == "units" && parts.size() == 3) {
            return api_units(*node);
        }
    }
    return error(404, "not found");
}

Response Site::tile(const std::string& name, const std::string&) const
{
    const auto it = m_tiles.find(name);
    if (it == m_tiles.end()) {
        return error(404, "no such tile in this tree");
    }
    const auto body = cached("tile/" + name, [&] { return read_file(m_tree->dir() / "tiles" / name); });
    Response res;
    res.content_type = "application/octet-stream";
    res.body = *body;
    // Its name ends in the digest of its bytes: the same URL never changes.
    res.headers.emplace_back("ETag", "\"" + name + "\"");
    res.headers.emplace_back("Cache-Control", "public, max-age=31536000, immutable");
    return res;
}

Response Site::api_tree() const
{
    const auto& sk = m_tree->skeleton();
    json nodes = json::array();
    for (const auto& n : sk.nodes) {
        json lods = json::array();
        for (const auto& l : n.lods) {
            lods.push_back({{"error_m", l.error_m}, {"vertices", l.vertices}});
        }
        nodes.push_back({{"parent", n.parent == datatree::no_node ? -1 : int64_t{n.parent}},
                         {"first_child", n.first_child},
                         {"children", n.child_count},
                         {"level", n.level},
                         {"code", sk.strings[n.code]},
                         {"name", sk.strings[n.name]},
                         {"chains", n.chains},
                         {"box", {n.box.min_x, n.box.min_y, n.box.max_x, n.box.max_y}},
                         {"lods", lods}});
    }
    std::vector<double> projection(std::begin(sk.projection), std::end(sk.projection));
    // How each border level is drawn (reader::line_style, as tigerlod-render draws it).
    json styles = json::array();
    const auto levels = static_cast<uint32_t>(sk.level_names.size());
    for (uint32_t l = 0; l < std::max(levels, 1U); ++l) {
        const auto st = reader::line_style(l, levels);
        styles.push_back({{"width", st.width}, {"rgb", {st.r, st.g, st.b}}});
    }
    return json_response(
        {{"format", "Data Tree " + std::to_string(datatree::major_version) + "." + std::to_string(sk.minor)},
         {"projection",
          {{"kind", sk.projection_kind},
           {"utm_zone", sk.utm_zone},
           {"utm_north", sk.utm_north != 0},
           {"lon0_lat0_stdlat1_stdlat2_k0_fe_fn_grid_a_f", projection}}},
         {"grid_m", sk.grid_m()},
         {"levels", sk.level_names},
         {"styles", styles},
         {"lod_eps_m", sk.lod_eps_m},
         {"verify", !m_options.verify.empty()},
         {"frame", {m_frame.min_x, m_frame.min_y, m_frame.max_x, m_frame.max_y}},
         {"nodes", nodes}},
        m_etag);
}

Response Site::api_front(const Request& r) const
{
    const auto cx = number(r, "cx", std::nullopt), cy = number(r, "cy", std::nullopt),
               upp = number(r, "upp", std::nullopt), w = number(r, "w", std::nullopt), h = number(r, "h", std::nullopt);
    const auto pixel_error = number(r, "pixel_error", 1.0), node_fraction = number(r, "node_fraction", 0.25);
    if (!cx || !cy || !upp || !w || !h || !pixel_error || !node_fraction) {
        return error(400, "the front needs finite cx, cy, upp, w, h (and pixel_error, node_fraction if given)");
    }
    if (!(*upp > 0) || !(*w >= 1 && *w <= 16384) || !(*h >= 1 && *h <= 16384) || !(*pixel_error > 0) ||
        !(*node_fraction > 0 && *node_fraction <= 1)) {
        return error(400, "upp > 0, w and h in 1..16384, pixel_error > 0, node_fraction in (0, 1]");
    }
    reader::View view{*cx, *cy, *upp, static_cast<uint32_t>(*w), static_cast<uint32_t>(*h)};
    reader::FrontOptions fo{*pixel_error, *node_fraction};
    const auto& sk = m_tree->skeleton();
    const auto front = reader::select_front(sk, view, fo);
    // What to draw of it, once all of it is loaded (reader::draw_list, as
    // tigerlod-render draws): per item, its chains to draw, each as its
    // index and its border level (the style: /api/tree's `styles`).
    static const auto no_geometry = std::make_shared<const datatree::Geometry>(); // draw_list reads none
    std::vector<reader::Drawable> drawables;
    drawables.reserve(front.size());
    json items = json::array();
    for (const auto& it : front) {
        items.push_back({it.node, it.lod});
        drawables.push_back({it, it.lod, no_geometry, chains_of(it.node)});
    }
    std::vector<json> draw(front.size(), json::array());
    for (const auto& dc : reader::draw_list(sk, drawables)) {
        draw[dc.item].push_back(dc.chain);
        draw[dc.item].push_back((drawables[dc.item].chains->flags[dc.chain] & datatree::border_level_mask) >>
                                datatree::border_level_shift);
    }
    return json_response({{"front", items}, {"draw", draw}}, "");
}

Response Site::api_node(uint32_t node, uint32_t lod) const
{
    const auto body = cached("node/" + std::to_string(node) + "/" + std::to_string(lod), [&] {
        datatree::Geometry g;
        if (const auto st = m_tree->read_geometry(node, lod, g); !st.ok()) {
            throw format_error(st.error);
        }
        return geometry_bytes(g);
    });
    Response res;
    res.content_type = "application/octet-stream";
    res.body = *body;
    res.headers.emplace_back("ETag", m_etag.substr(0, m_etag.size() - 1) + "-" + std::to_string(node) + "-" +
                                         std::to_string(lod) + "\"");
    res.headers.emplace_back("Cache-Control", "no-cache");
    return res;
}

std::shared_ptr<const reader::NodeChains> Site::chains_of(uint32_t node) const
{
    {
        std::lock_guard lock(m_mutex);
        if (const auto it = m_chains.find(node); it != m_chains.end()) {
            return it->second;
        }
    }
    datatree::ChainTable t;
    if (!m_tree->read_table(node, t).ok()) {
        return nullptr; // drawn as nothing; /api/table/N says what is wrong
    }
    auto c = std::make_shared<const reader::NodeChains>(reader::node_chains(*m_tree, node, t));
    std::lock_guard lock(m_mutex);
    const uint64_t bytes = c->memory_bytes();
    if (m_chains_bytes + bytes > m_options.cache_bytes / 4) {
        m_chains.clear();
        m_chains_bytes = 0;
    }
    if (bytes <= m_options.cache_bytes / 4 && m_chains.emplace(node, c).second) {
        m_chains_bytes += bytes;
    }
    return c;
}

Response Site::api_table(uint32_t node) const
{
    datatree::ChainTable t;
    if (const auto st = m_tree->read_table(node, t); !st.ok()) {
        throw format_error(st.error);
    }
    json ids = json::array(), left = json::array(), right = json::array(), cls = json::array(), flags = json::array();
    for (const auto& c : t.chains) {
        ids.push_back(std::to_string(c.id)); // 64 bits: more than a JavaScript number holds
        left.push_back(t.strings[c.left]);
        right.push_back(t.strings[c.right]);
        cls.push_back(t.strings[c.feature_class]);
        flags.push_back(c.flags);
    }
    return json_response({{"ids", ids}, {"left", left}, {"right", right}, {"class", cls}, {"flags", flags}},
                         m_etag.substr(0, m_etag.size() - 1) + "-t" + std::to_string(node) + "\"");
}

Response Site::api_units(uint32_t node) const
{
    datatree::UnitTable t;
    if (const auto st = m_tree->read_units(node, t); !st.ok()) {
        throw format_error(st.error);
    }
    json fields = json::array(), units = json::array();
    for (const auto& f : t.fields) {
        fields.push_back({{"name", f.name}, {"type", f.type == 1 ? "integer" : f.type == 2 ? "real" : "text"}});
    }
    for (const auto& u : t.units) {
        units.push_back({{"code", u.code}, {"name", u.name}, {"point", {u.point.x, u.point.y}}, {"values", u.values}});
    }
    return json_response({{"fields", fields}, {"units", units}},
                         m_etag.substr(0, m_etag.size() - 1) + "-u" + std::to_string(node) + "\"");
}

} // namespace tigerlod::serve
