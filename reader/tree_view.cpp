#include "reader/tree_view.hpp"

#include "core/errors.hpp"
#include "core/geometry.hpp"

#include <cpl_conv.h>
#include <cpl_string.h>
#include <gdal.h>
#include <ogr_api.h>
#include <ogr_srs_api.h>

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <map>
#include <mutex>
#include <sstream>

namespace tigerlod::view {

ProjectionParams projection_of(const datatree::Skeleton& s)
{
    ProjectionParams p;
    p.kind = static_cast<ProjectionParams::Kind>(s.projection_kind);
    p.utm_north = s.utm_north != 0;
    p.utm_zone = s.utm_zone;
    p.lon0_deg = s.projection[0];
    p.lat0_deg = s.projection[1];
    p.stdlat1_deg = s.projection[2];
    p.stdlat2_deg = s.projection[3];
    p.k0 = s.projection[4];
    p.false_easting_m = s.projection[5];
    p.false_northing_m = s.projection[6];
    p.grid_m = s.projection[7];
    p.a_m = s.projection[8];
    p.f = s.projection[9];
    return p;
}

uint32_t find_node(const datatree::Skeleton& s, const std::string& spec)
{
    if (spec.empty() || spec == "root") {
        return 0;
    }
    uint32_t index = 0;
    const auto [p, ec] = std::from_chars(spec.data(), spec.data() + spec.size(), index);
    for (uint32_t n = 0; n < s.nodes.size(); ++n) {
        if (s.strings[s.nodes[n].code] == spec) {
            return n;
        }
    }
    if (ec == std::errc() && p == spec.data() + spec.size() && index < s.nodes.size()) {
        return index;
    }
    throw usage_error("no node '" + spec + "' in the tree (a node index below " + std::to_string(s.nodes.size()) +
                      " or a unit code)");
}

namespace {

const char* metric_name(uint8_t m)
{
    return m == 1 ? "l1" : m == 2 ? "linf" : "l2";
}

std::string ref_text(const datatree::PayloadRef& r)
{
    return "tile=" + std::to_string(r.tile) + " offset=" + std::to_string(r.offset) +
           " size=" + std::to_string(r.size) + " crc=" + std::to_string(r.crc);
}

std::string flags_text(uint32_t f)
{
    std::string s = "---";
    if (f & 1U) {
        s[0] = 'c';
    }
    if (f & 4U) {
        s[2] = 'p';
    }
    return s;
}

} // namespace

std::string skeleton_text(const reader::Tree& tree)
{
    const auto& s = tree.skeleton();
    std::ostringstream out;
    out << "data-tree " << datatree::major_version << "." << s.minor << "\n";
    out << "projection " << Projection(projection_of(s)).describe() << "\n";
    out << "metric " << metric_name(s.metric) << "\n";
    out << "levels";
    for (const auto& l : s.level_names) {
        out << " " << l;
    }
    out << "\nlods";
    for (double e : s.lod_eps_m) {
        out << " " << e;
    }
    out << "\nskeleton_bytes " << tree.skeleton_bytes() << " tree_bytes " << tree.tree_bytes() << "\n";
    for (size_t t = 0; t < s.tiles.size(); ++t) {
        out << "tile " << t << " " << s.tiles[t].file << " size=" << s.tiles[t].size << "\n";
    }
    for (size_t i = 0; i < s.nodes.size(); ++i) {
        const auto& n = s.nodes[i];
        out << "node " << i << " code=" << s.strings[n.code] << " name=" << s.strings[n.name]
            << " map=" << s.level_names[n.level]
            << " parent=" << (n.parent == datatree::no_node ? std::string("-") : std::to_string(n.parent))
            << " children=";
        if (n.child_count == 0) {
            out << "-";
        } else {
            out << n.first_child << ".." << (n.first_child + n.child_count - 1);
        }
        out << " chains=" << n.chains << " box=" << n.box.min_x << "," << n.box.min_y << "," << n.box.max_x << ","
            << n.box.max_y << " table " << ref_text(n.table) << "\n";
        for (size_t k = 0; k < n.lods.size(); ++k) {
            char err[32];
            std::snprintf(err, sizeof err, "%.3f", n.lods[k].error_m);
            out << "  lod " << k << " eps=" << s.lod_eps_m[k] << " error_m=" << err
                << " vertices=" << n.lods[k].vertices << " " << ref_text(n.lods[k].payload) << "\n";
        }
        if (s.minor >= 2) {
            datatree::UnitTable units;
            const auto st = tree.read_units(static_cast<uint32_t>(i), units);
            out << "  units " << (st.ok() ? "n=" + std::to_string(units.units.size()) : "error: " + st.error);
            for (const auto& f : units.fields) {
                out << " field=" << f.name << ":" << int{f.type};
            }
            out << "\n";
        }
    }
    return out.str();
}

NodeMap read_node(const reader::Tree& tree, uint32_t node, uint32_t lod)
{
    NodeMap m;
    m.node = node;
    m.lod = lod;
    if (lod >= tree.skeleton().lod_eps_m.size()) {
        throw usage_error("no LOD " + std::to_string(lod) + " (the tree has " +
                          std::to_string(tree.skeleton().lod_eps_m.size()) + ")");
    }
    if (auto st = tree.read_table(node, m.table); !st.ok()) {
        throw input_error(st.error);
    }
    if (auto st = tree.read_geometry(node, lod, m.geometry); !st.ok()) {
        throw input_error(st.error);
    }
    return m;
}

std::string node_text(const reader::Tree& tree, const NodeMap& m)
{
    const auto& s = tree.skeleton();
    std::ostringstream out;
    out << "node " << m.node << " code=" << s.strings[s.nodes[m.node].code] << " lod " << m.lod
        << " eps=" << s.lod_eps_m[m.lod] << " chains=" << m.table.chains.size()
        << " vertices=" << m.geometry.points.size() << "\n";
    for (size_t i = 0; i < m.table.chains.size(); ++i) {
        const auto& c = m.table.chains[i];
        const auto pts = m.geometry.chain(i);
        out << "chain " << c.id << " left=" << m.table.strings[c.left] << " right=" << m.table.strings[c.right]
            << " class=" << m.table.strings[c.feature_class] << " flags=" << flags_text(c.flags)
            << (c.border_level() ? " border=" + std::to_string(c.border_level()) : std::string()) << " n=" << pts.size()
            << " :";
        for (const auto& p : pts) {
            out << " " << p.x << "," << p.y;
        }
        out << "\n";
    }
    datatree::UnitTable units;
    if (const auto st = tree.read_units(m.node, units); !st.ok()) {
        throw input_error(st.error);
    }
    for (const auto& u : units.units) {
        out << "unit " << u.code << " point=" << u.point.x << "," << u.point.y << " name=" << u.name;
        for (size_t k = 0; k < units.fields.size(); ++k) {
            out << " " << units.fields[k].name << "=" << u.values[k];
        }
        out << "\n";
    }
    return out.str();
}

void write_node_geojson(const reader::Tree& tree, const NodeMap& m, const std::string& path)
{
    // GDAL's GeoJSON driver, the writer export uses too.
    static std::once_flag registered;
    std::call_once(registered, [] { GDALAllRegister(); });
    const Projection proj(projection_of(tree.skeleton()));
    GDALDriverH driver = GDALGetDriverByName("GeoJSON");
    GDALDatasetH ds = driver ? GDALCreate(driver, path.c_str(), 0, 0, 0, GDT_Unknown, nullptr) : nullptr;
    if (ds == nullptr) {
        throw environment_error(path + ": cannot write GeoJSON: " + CPLGetLastErrorMsg());
    }
    OGRSpatialReferenceH srs = OSRNewSpatialReference(nullptr);
    OSRImportFromEPSG(srs, 4269);
    OSRSetAxisMappingStrategy(srs, OAMS_TRADITIONAL_GIS_ORDER);
    char** options = CSLSetNameValue(nullptr, "COORDINATE_PRECISION", "7");
    OGRLayerH layer = GDALDatasetCreateLayer(ds, "chains", srs, wkbLineString, options);
    CSLDestroy(options);
    OSRDestroySpatialReference(srs);
    bool ok = layer != nullptr;
    auto field = [&](const char* name, OGRFieldType type, OGRFieldSubType sub = OFSTNone) {
        if (!ok) {
            return;
        }
        OGRFieldDefnH fd = OGR_Fld_Create(name, type);
        OGR_Fld_SetSubType(fd, sub);
        ok = OGR_L_CreateField(layer, fd, TRUE) == OGRERR_NONE;
        OGR_Fld_Destroy(fd);
    };
    field("id", OFTInteger64);
    field("left", OFTString);
    field("right", OFTString);
    field("class", OFTString);
    field("closed", OFTInteger, OFSTBoolean);
    for (size_t i = 0; ok && i < m.table.chains.size(); ++i) {
        const auto& c = m.table.chains[i];
        OGRFeatureH f = OGR_F_Create(OGR_L_GetLayerDefn(layer));
        OGR_F_SetFieldInteger64(f, 0, static_cast<GIntBig>(c.id));
        OGR_F_SetFieldString(f, 1, m.table.strings[c.left].c_str());
        OGR_F_SetFieldString(f, 2, m.table.strings[c.right].c_str());
        OGR_F_SetFieldString(f, 3, m.table.strings[c.feature_class].c_str());
        OGR_F_SetFieldInteger(f, 4, (c.flags & 1U) ? 1 : 0);
        OGRGeometryH line = OGR_G_CreateGeometry(wkbLineString);
        for (const auto& p : m.geometry.chain(i)) {
            double lon = 0, lat = 0;
            proj.to_lonlat(p.x, p.y, lon, lat);
            OGR_G_AddPoint_2D(line, lon, lat);
        }
        OGR_F_SetGeometryDirectly(f, line);
        ok = OGR_L_CreateFeature(layer, f) == OGRERR_NONE;
        OGR_F_Destroy(f);
    }
    GDALClose(ds);
    if (!ok) {
        throw environment_error(path + ": cannot write GeoJSON: " + CPLGetLastErrorMsg());
    }
}

std::vector<Ring> unit_rings(const datatree::ChainTable& table, const datatree::Geometry& g, uint32_t unit)
{
    // The unit's boundary as directed chains with the unit on their left.
    struct Directed {
        size_t chain;
        bool reversed;
    };
    std::vector<Directed> parts;
    for (size_t i = 0; i < table.chains.size(); ++i) {
        const auto& c = table.chains[i];
        if (c.left == c.right) {
            continue;
        }
        if (c.left == unit) {
            parts.push_back({i, false});
        } else if (c.right == unit) {
            parts.push_back({i, true});
        }
    }
    auto first = [&](const Directed& d) { return d.reversed ? g.chain(d.chain).back() : g.chain(d.chain).front(); };
    auto last = [&](const Directed& d) { return d.reversed ? g.chain(d.chain).front() : g.chain(d.chain).back(); };
    std::multimap<GridPoint, size_t> starts;
    for (size_t i = 0; i < parts.size(); ++i) {
        starts.emplace(first(parts[i]), i);
    }
    std::vector<bool> used(parts.size(), false);
    std::vector<Ring> rings;
    for (size_t s = 0; s < parts.size(); ++s) {
        if (used[s]) {
            continue;
        }
        Ring ring;
        size_t cur = s;
        const GridPoint origin = first(parts[s]);
        while (true) {
            used[cur] = true;
            const auto pts = g.chain(parts[cur].chain);
            const size_t from = ring.points.empty() ? 0 : 1;
            for (size_t k = from; k < pts.size(); ++k) {
                ring.points.push_back(parts[cur].reversed ? pts[pts.size() - 1 - k] : pts[k]);
            }
            const GridPoint end = last(parts[cur]);
            if (end == origin) {
                break;
            }
            size_t next = SIZE_MAX;
            for (auto [it, stop] = starts.equal_range(end); it != stop; ++it) {
                if (!used[it->second]) {
                    next = it->second;
                    break;
                }
            }
            if (next == SIZE_MAX) {
                ring.closed = false;
                break;
            }
            cur = next;
        }
        rings.push_back(std::move(ring));
    }
    return rings;
}

namespace {

/// Split a closed walk (first == last) at every vertex it passes twice into
/// simple closed loops.
void split_simple(const std::vector<GridPoint>& walk, std::vector<std::vector<GridPoint>>& out)
{
    std::vector<GridPoint> stack;
    std::map<GridPoint, size_t> at; // a point on the stack -> its index
    auto emit = [&](size_t from) {
        std::vector<GridPoint> loop(stack.begin() + static_cast<std::ptrdiff_t>(from), stack.end());
        loop.push_back(stack[from]);
        out.push_back(std::move(loop));
    };
    for (size_t i = 0; i + 1 < walk.size(); ++i) {
        const GridPoint p = walk[i];
        const auto it = at.find(p);
        if (it == at.end()) {
            at.emplace(p, stack.size());
            stack.push_back(p);
            continue;
        }
        const size_t from = it->second;
        emit(from);
        for (size_t k = from + 1; k < stack.size(); ++k) {
            at.erase(stack[k]);
        }
        stack.resize(from + 1);
    }
    if (!stack.empty()) {
        emit(0);
    }
}

} // namespace

UnitPolygons unit_polygons(const datatree::ChainTable& table, const datatree::Geometry& g, uint32_t unit)
{
    UnitPolygons result;
    std::vector<std::vector<GridPoint>> loops;
    for (const Ring& r : unit_rings(table, g, unit)) {
        if (!r.closed) {
            result.complete = false;
            return result;
        }
        split_simple(r.points, loops);
    }
    // With the unit on the left, outer rings run counter-clockwise and holes
    // clockwise.
    std::vector<std::pair<int128, size_t>> outers; // |area|, loop
    std::vector<size_t> holes;
    for (size_t i = 0; i < loops.size(); ++i) {
        const int128 a = twice_area(loops[i]);
        if (a > 0) {
            outers.emplace_back(a, i);
        } else if (a < 0) {
            holes.push_back(i);
        }
    }
    // Smallest first: a hole belongs to the smallest outer ring around it.
    std::stable_sort(outers.begin(), outers.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    std::vector<std::vector<size_t>> holes_of(outers.size());
    for (const size_t h : holes) {
        for (size_t o = 0; o < outers.size(); ++o) {
            const auto& outer = loops[outers[o].second];
            // Inside if a vertex of the hole off the outer ring is inside it
            // (a hole may touch its outer ring, never cross it).
            PointLocation where = PointLocation::boundary;
            for (size_t k = 0; k + 1 < loops[h].size() && where == PointLocation::boundary; ++k) {
                PointInPolygon pip(loops[h][k]);
                for (size_t j = 0; j + 1 < outer.size(); ++j) {
                    pip.add_segment(outer[j], outer[j + 1]);
                }
                where = pip.location();
            }
            if (where == PointLocation::inside) {
                holes_of[o].push_back(h);
                break;
            }
        }
    }
    // In the order the walk found the outer rings: the same for every run.
    std::vector<size_t> order(outers.size());
    for (size_t o = 0; o < outers.size(); ++o) {
        order[o] = o;
    }
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return outers[a].second < outers[b].second; });
    for (const size_t o : order) {
        UnitPolygon p;
        p.outer = std::move(loops[outers[o].second]);
        for (const size_t h : holes_of[o]) {
            p.holes.push_back(std::move(loops[h]));
        }
        result.polygons.push_back(std::move(p));
    }
    return result;
}

} // namespace tigerlod::view
