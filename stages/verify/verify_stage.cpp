#include "stages/verify/verify_stage.hpp"

#include "config/config_file.hpp"
#include "config/schema.hpp"
#include "core/digest.hpp"
#include "core/fs.hpp"
#include "core/gdal_output.hpp"
#include "core/manifest.hpp"
#include "core/partitions.hpp"
#include "core/progress.hpp"
#include "simplification/stage_options.hpp"
#include "stages/pack/packer.hpp"
#include "stages/verify/cgal_check.hpp"
#include "reader/tree_view.hpp"
#include "stages/verify/verifier.hpp"

#include <GeographicLib/Config.h>
#include <gdal.h>
#include <nlohmann/json.hpp>
#include <ogr_api.h>
#include <ogr_srs_api.h>

#include <charconv>
#include <cstdio>
#include <fstream>
#include <optional>
#include <set>
#include <sstream>
#include <thread>

namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

namespace tigerlod::verify {

void VerifyStage::add_args(ArgSet& args)
{
    args.positional("TREE", &m_tree, "a Data Tree folder (tigerlod-pack)");
    args.positional("ORIGINAL", &m_original, "the tigerlod-ingest output the tree was built from");
    args.positional("OUTPUT", &m_output, "a folder for verify-report.json and violations.gpkg (written atomically)");
    args.group("Report");
    args.add("compare", &m_compare, "an earlier verify-report.json: report new and fixed violations and vertex counts",
             "FILE");
    config::add_option(args, "verify.max_items", &m_max_items);
    args.add("cgal", &m_cgal,
             "check the meetings again with a second exact checker on CGAL (its exact kernel and box-intersection "
             "sweep, no code shared with verify's) and fail if the two disagree (whole runs and --finish)");
    args.group("Run");
    config::add_option(args, "verify.threads", &m_threads);
    args.add("overwrite", &m_overwrite, "replace OUTPUT if it exists");
    args.group("Partition jobs (the workflow's)");
    args.add("partitions", &m_partitions,
             "check only these stores' nodes (and the meetings filed under them), OUTPUT not touched: "
             "LEVEL/PARTITION, LEVEL/PREFIX* or LEVEL/*, separated by commas, or @FILE with one a line",
             "LIST");
    args.add("plan", &m_plan,
             "with --partitions: tigerlod-pack's plan (--plan), whose 'near' names the nodes "
             "decoded beside them",
             "FILE");
    args.add("report", &m_report, "with --partitions: this job's share of the report", "FILE");
    args.add("finish", &m_finish,
             "merge the --partitions jobs' shares (--shares) into OUTPUT: the report of a whole run");
    args.add("shares", &m_shares, "with --finish: the shares, separated by commas, or @FILE with one a line", "LIST");
}

void VerifyStage::initialize()
{
    if (m_finish && !m_partitions.empty()) {
        throw usage_error("verify: options '--finish' and '--partitions' exclude each other");
    }
    if (!m_partitions.empty() && (m_plan.empty() || m_report.empty())) {
        throw usage_error("verify: option '--partitions' needs '--plan FILE' and '--report FILE'");
    }
    if (m_partitions.empty() && (!m_plan.empty() || !m_report.empty())) {
        throw usage_error("verify: options '--plan' and '--report' go with '--partitions'");
    }
    if (!m_partitions.empty() && !m_compare.empty()) {
        throw usage_error("verify: option '--compare' goes with a whole run or '--finish', not '--partitions'");
    }
    if (m_cgal && !m_partitions.empty()) {
        throw usage_error("verify: option '--cgal' checks the whole tree: with a whole run or '--finish', not "
                          "'--partitions'");
    }
    if (m_finish != !m_shares.empty()) {
        throw usage_error("verify: options '--finish' and '--shares LIST' go together");
    }
    if (!m_compare.empty() && !fs::is_regular_file(m_compare)) {
        throw usage_error("verify: --compare " + m_compare + ": no such file");
    }
    if (!fs::is_directory(m_original)) {
        throw usage_error("verify: " + m_original + ": not a folder");
    }
}

std::vector<std::string> VerifyStage::config_args(const fs::path& file) const
{
    return config::stage_args(file, name);
}

std::vector<std::string> VerifyStage::versions() const
{
    return {std::string("GDAL ") + GDALVersionInfo("RELEASE_NAME"),
            std::string("GeographicLib ") + GEOGRAPHICLIB_VERSION_STRING, chains::format_version_text(),
            datatree::format_version_text()};
}

std::string VerifyStage::help_notes() const
{
    return "Outputs:\n"
           "  OUTPUT/verify-report.json  counts checked, violations by kind and by level and LOD, each violation\n"
           "                             with node, chain ids, kind and lon/lat (schema: stages/verify/REPORT.md)\n"
           "  OUTPUT/violations.gpkg     the violations as points, and their chains as lines with their units, for "
           "QGIS\n"
           "  OUTPUT/manifest.json       the tree's and the original's manifest digests, the options\n"
           "Exit codes: 0 clean; 1 a violation was found (or the tree is unreadable); 2 usage error;\n"
           "  3 environment (cannot write).\n";
}

namespace {

std::string ids_text(const std::vector<uint64_t>& ids)
{
    std::string s;
    for (uint64_t id : ids) {
        if (!s.empty()) {
            s += ',';
        }
        s += std::to_string(id);
    }
    return s;
}

std::string key_of(const json& item)
{
    std::string chains;
    for (const auto& c : item.at("chains")) {
        chains += c.get<std::string>() + ",";
    }
    return item.at("kind").get<std::string>() + "|" + item.at("level").get<std::string>() + "|" +
           std::to_string(item.at("lod").get<int>()) + "|" + item.at("node").get<std::string>() + "|" + chains + "|" +
           item.at("detail").get<std::string>();
}

/// The offending chains of each item, as the tree holds them at its LOD: a
/// line each, with the units on its sides. Items of a node the tree cannot
/// decode (the damage verify found) have none.
struct ItemChain {
    size_t item = 0; ///< index in Report::items
    uint64_t id = 0;
    std::string left, right;
    double eps_m = 0;
    std::vector<GridPoint> points;
};
std::vector<ItemChain> item_chains(const reader::Tree* tree, const Report& r)
{
    std::vector<ItemChain> out;
    if (tree == nullptr) {
        return out;
    }
    const auto& s = tree->skeleton();
    std::map<std::pair<uint32_t, uint32_t>, std::optional<view::NodeMap>> maps; // by (node, LOD)
    for (size_t i = 0; i < r.items.size(); ++i) {
        const Violation& v = r.items[i];
        if (v.chains.empty() || v.lod >= s.lod_eps_m.size()) {
            continue;
        }
        uint32_t n = 0;
        try {
            n = view::find_node(s, v.node);
        } catch (const usage_error&) {
            continue; // not a node of this tree (an item of the manifest, say)
        }
        auto [it, fresh] = maps.try_emplace({n, v.lod});
        if (fresh) {
            try {
                it->second = view::read_node(*tree, n, v.lod);
            } catch (const Error&) {
                // A payload that does not decode: the item says so, no lines.
            }
        }
        if (!it->second) {
            continue;
        }
        const view::NodeMap& m = *it->second;
        for (size_t c = 0; c < m.table.chains.size(); ++c) {
            const auto& ch = m.table.chains[c];
            if (std::binary_search(v.chains.begin(), v.chains.end(), ch.id)) {
                const auto pts = m.geometry.chain(c);
                out.push_back({i, ch.id, m.table.strings[ch.left], m.table.strings[ch.right], s.lod_eps_m[v.lod],
                               std::vector<GridPoint>(pts.begin(), pts.end())});
            }
        }
    }
    return out;
}

} // namespace

void write_violations_gpkg(const fs::path& path, const Report& r, const reader::Tree* tree)
{
    GDALAllRegister();
    fix_gdal_dates();
    const std::vector<ItemChain> lines = item_chains(tree, r);
    GdalErrorTrap trap;
    GDALDatasetH ds = GDALCreate(GDALGetDriverByName("GPKG"), path.c_str(), 0, 0, 0, GDT_Unknown, nullptr);
    if (ds == nullptr) {
        throw environment_error("verify: cannot create " + path.string() + ": " + trap.first());
    }
    OGRSpatialReferenceH srs = OSRNewSpatialReference(nullptr);
    OSRImportFromEPSG(srs, 4269);
    OSRSetAxisMappingStrategy(srs, OAMS_TRADITIONAL_GIS_ORDER);
    OGRLayerH layer = GDALDatasetCreateLayer(ds, "violations", srs, wkbPoint, nullptr);
    OSRDestroySpatialReference(srs);
    auto add_fields = [](OGRLayerH l, std::initializer_list<std::pair<const char*, OGRFieldType>> fields) {
        for (const auto& [name, type] : fields) {
            if (l != nullptr) {
                OGRFieldDefnH fd = OGR_Fld_Create(name, type);
                OGR_L_CreateField(l, fd, TRUE);
                OGR_Fld_Destroy(fd);
            }
        }
    };
    add_fields(layer, {{"kind", OFTString},
                       {"level", OFTString},
                       {"lod", OFTInteger},
                       {"node", OFTString},
                       {"chains", OFTString},
                       {"detail", OFTString}});
    // The chains, in the tree's own projection, where their segments are
    // straight (in lon/lat a GIS would bow them, and move the meeting).
    OGRLayerH chain_layer = nullptr;
    if (tree != nullptr) {
        OGRSpatialReferenceH tsrs = nullptr;
        try {
            tsrs = tree_srs(view::projection_of(tree->skeleton()), "verify");
        } catch (const usage_error&) {
            tsrs = nullptr; // a conic with k0 != 1: the lines without a CRS
        }
        chain_layer = GDALDatasetCreateLayer(ds, "violation_chains", tsrs, wkbLineString, nullptr);
        if (tsrs != nullptr) {
            OSRDestroySpatialReference(tsrs);
        }
        add_fields(chain_layer, {{"violation", OFTInteger64},
                                 {"kind", OFTString},
                                 {"level", OFTString},
                                 {"lod", OFTInteger},
                                 {"eps_m", OFTReal},
                                 {"node", OFTString},
                                 {"chain_id", OFTInteger64},
                                 {"left", OFTString},
                                 {"right", OFTString}});
    }
    // One transaction for all the features: the file is whole or the error is seen.
    const bool in_transaction = layer != nullptr && GDALDatasetStartTransaction(ds, FALSE) == OGRERR_NONE;
    bool ok = layer != nullptr && (tree == nullptr || chain_layer != nullptr);
    for (const auto& v : r.items) {
        if (!ok || trap.failed()) {
            break;
        }
        OGRFeatureH f = OGR_F_Create(OGR_L_GetLayerDefn(layer));
        OGR_F_SetFieldString(f, 0, v.kind.c_str());
        OGR_F_SetFieldString(f, 1, v.level.c_str());
        OGR_F_SetFieldInteger(f, 2, static_cast<int>(v.lod));
        OGR_F_SetFieldString(f, 3, v.node.c_str());
        OGR_F_SetFieldString(f, 4, ids_text(v.chains).c_str());
        OGR_F_SetFieldString(f, 5, v.detail.c_str());
        OGRGeometryH pt = OGR_G_CreateGeometry(wkbPoint);
        OGR_G_SetPoint_2D(pt, 0, v.lon, v.lat);
        OGR_F_SetGeometryDirectly(f, pt);
        ok = OGR_L_CreateFeature(layer, f) == OGRERR_NONE;
        OGR_F_Destroy(f);
    }
    const double g = tree != nullptr ? tree->skeleton().grid_m() : 1.0;
    for (const auto& c : lines) {
        if (!ok || trap.failed()) {
            break;
        }
        const Violation& v = r.items[c.item];
        OGRFeatureH f = OGR_F_Create(OGR_L_GetLayerDefn(chain_layer));
        OGR_F_SetFieldInteger64(f, 0, static_cast<GIntBig>(c.item + 1)); // the point's fid
        OGR_F_SetFieldString(f, 1, v.kind.c_str());
        OGR_F_SetFieldString(f, 2, v.level.c_str());
        OGR_F_SetFieldInteger(f, 3, static_cast<int>(v.lod));
        OGR_F_SetFieldDouble(f, 4, c.eps_m);
        OGR_F_SetFieldString(f, 5, v.node.c_str());
        OGR_F_SetFieldInteger64(f, 6, static_cast<GIntBig>(c.id));
        OGR_F_SetFieldString(f, 7, c.left.c_str());
        OGR_F_SetFieldString(f, 8, c.right.c_str());
        OGRGeometryH line = OGR_G_CreateGeometry(wkbLineString);
        for (const auto& p : c.points) {
            OGR_G_AddPoint_2D(line, double(p.x) * g, double(p.y) * g);
        }
        OGR_F_SetGeometryDirectly(f, line);
        ok = OGR_L_CreateFeature(chain_layer, f) == OGRERR_NONE;
        OGR_F_Destroy(f);
    }
    ok = ok && (!in_transaction || GDALDatasetCommitTransaction(ds) == OGRERR_NONE);
    if (!ok) {
        GDALClose(ds);
        throw environment_error("verify: cannot write " + path.string() + ": " +
                                (trap.failed() ? trap.first() : std::string("GDAL refused a layer or a feature")));
    }
    std::map<std::string, int64_t> expected{{"violations", static_cast<int64_t>(r.items.size())}};
    if (tree != nullptr) {
        expected["violation_chains"] = static_cast<int64_t>(lines.size());
    }
    close_and_check(ds, path, expected, trap, "verify");
}

namespace {

/// The count of violations of kind `k` (0 when none was counted).
uint64_t count_of(const Report& r, const char* k)
{
    const auto it = r.violations.find(k);
    return it == r.violations.end() ? 0 : it->second;
}

/// The violations of every kind at one level and LOD.
uint64_t total_of(const LevelLod& ll)
{
    uint64_t n = 0;
    for (const auto& [k, c] : ll.violations) {
        n += c;
    }
    return n;
}

/// The earlier report of --compare, checked to be one.
json read_earlier_report(const std::string& path)
{
    try {
        std::ifstream in(path);
        json old = json::parse(in);
        if (old.value("schema", "") != "tigerlod.verify-report/1" || !old.contains("items") ||
            !old.contains("by_level_lod")) {
            throw input_error("not a tigerlod.verify-report/1");
        }
        return old;
    } catch (const std::exception& e) {
        throw input_error("verify: --compare " + path + ": " + e.what());
    }
}

/// verify-report.json without its comparison.
json report_json(const Report& r, const Options& options, const std::string& tree, const std::string& original)
{
    json report;
    report["schema"] = "tigerlod.verify-report/1";
    report["tree"] = tree;
    report["original"] = original;
    report["clean"] = r.total() == 0;
    report["contract"] = {{"class_scale", options.tolerance.class_scale},
                          {"projection_scale", options.tolerance.projection_scale},
                          {"point_constraints", options.tolerance.point_constraints},
                          {"user_points", options.user_points.size()}};
    report["checked"] = {
        {"nodes", r.nodes}, {"lods", r.lods}, {"chains", r.chains}, {"segments", r.segments}, {"points", r.points}};
    json counts = json::object();
    for (const char* k : kinds) {
        counts[k] = count_of(r, k);
    }
    report["violations"] = counts;
    report["input_problems"] = r.input_problems;
    report["ground"] = {{"checked", r.ground}, {"ratio_max", r.ground_ratio_max}, {"geodesics", r.ground_geodesics}};
    json by = json::array();
    for (const auto& ll : r.by_level_lod) {
        json v = json::object();
        for (const char* k : kinds) {
            v[k] = ll.violations.at(k);
        }
        by.push_back({{"level", ll.level},
                      {"lod", ll.lod},
                      {"eps_m", ll.eps_m},
                      {"nodes", ll.nodes},
                      {"chains", ll.chains},
                      {"segments", ll.segments},
                      {"vertices", ll.vertices},
                      {"points", ll.points},
                      {"violations", v},
                      {"input_problems", ll.input_problems},
                      {"ground_ratio_max", ll.ground_ratio_max},
                      {"ground_geodesics", ll.ground_geodesics}});
    }
    report["by_level_lod"] = by;
    json items = json::array();
    for (const auto& v : r.items) {
        json ids = json::array();
        for (uint64_t id : v.chains) {
            ids.push_back(std::to_string(id)); // strings: 64-bit ids do not survive JavaScript numbers
        }
        items.push_back({{"kind", v.kind},
                         {"level", v.level},
                         {"lod", v.lod},
                         {"node", v.node},
                         {"chains", ids},
                         {"lon", v.lon},
                         {"lat", v.lat},
                         {"x", v.x},
                         {"y", v.y},
                         {"detail", v.detail}});
    }
    report["items"] = items;
    report["items_dropped"] = r.items_dropped;
    report["seconds"] = r.seconds;
    report["ground_seconds"] = r.ground_seconds;
    report["segments_per_second"] = r.seconds > 0 ? double(r.segments) / r.seconds : 0.0;

    return report;
}

/// The comparison with an earlier report: new and fixed violations (input
/// problems are the input's, not the run's: not compared), vertex counts
/// per level and LOD. Adds report["compare"]; returns the line for people.
std::string compare_reports(json& report, const json& old, const std::string& against)
{
    try {
        // Input problems are the input's, not the run's: not compared.
        auto counted = [](const json& it) { return it.at("kind") != "input_problem"; };
        std::set<std::string> was, now;
        for (const auto& it : old.at("items")) {
            if (counted(it)) {
                was.insert(key_of(it));
            }
        }
        json fresh = json::array(), fixed = json::array();
        for (const auto& it : report["items"]) {
            if (counted(it)) {
                now.insert(key_of(it));
                if (!was.contains(key_of(it))) {
                    fresh.push_back(it);
                }
            }
        }
        for (const auto& it : old.at("items")) {
            if (counted(it) && !now.contains(key_of(it))) {
                fixed.push_back(it);
            }
        }
        json vertices = json::array();
        for (const auto& ll : report["by_level_lod"]) {
            int64_t before = -1;
            for (const auto& o : old.at("by_level_lod")) {
                if (o.at("level") == ll.at("level") && o.at("lod") == ll.at("lod")) {
                    before = o.at("vertices").get<int64_t>();
                }
            }
            const auto after = ll.at("vertices").get<int64_t>();
            vertices.push_back({{"level", ll.at("level")},
                                {"lod", ll.at("lod")},
                                {"before", before < 0 ? json(nullptr) : json(before)},
                                {"after", after},
                                {"change", before < 0 ? json(nullptr) : json(after - before)}});
        }
        report["compare"] = {{"against", against}, {"new", fresh.size()},  {"fixed", fixed.size()},
                             {"new_items", fresh}, {"fixed_items", fixed}, {"vertices", vertices}};
        return "since " + against + ": " + std::to_string(fresh.size()) + " new, " + std::to_string(fixed.size()) +
               " fixed violations\n";
    } catch (const std::exception& e) {
        throw input_error("verify: --compare " + against + ": " + e.what());
    }
}

/// One screen for people.
void print_summary(const Report& r, const std::string& tree, const std::string& original, const std::string& output,
                   const std::string& compare_text)
{
    // One screen for people.
    std::printf("verify: %s against %s\n", tree.c_str(), original.c_str());
    std::printf("  checked %llu nodes x %llu LODs: %llu chains, %llu segments, %llu points in %.2f s\n",
                static_cast<unsigned long long>(r.nodes), static_cast<unsigned long long>(r.lods),
                static_cast<unsigned long long>(r.chains), static_cast<unsigned long long>(r.segments),
                static_cast<unsigned long long>(r.points), r.seconds);
    if (r.ground) {
        std::printf("  on the ellipsoid: skipped vertices at most %.6f of their eps from their shortcuts "
                    "(%llu measured by geodesics; %.1f s of the threads' time)\n",
                    r.ground_ratio_max, static_cast<unsigned long long>(r.ground_geodesics), r.ground_seconds);
    } else {
        std::printf("  on the ellipsoid: not checked (the tree's eps are projected metres: projection_scale off)\n");
    }
    if (r.total() == 0) {
        std::printf("  CLEAN: no violations\n");
    } else {
        std::printf("  %llu VIOLATIONS:\n", static_cast<unsigned long long>(r.total()));
        for (const char* k : kinds) {
            if (count_of(r, k) > 0) {
                std::printf("    %-20s %llu\n", k, static_cast<unsigned long long>(count_of(r, k)));
            }
        }
        for (const auto& ll : r.by_level_lod) {
            const uint64_t n = total_of(ll);
            if (n > 0) {
                std::printf("    at %s LOD %u (eps %g m): %llu\n", ll.level.c_str(), ll.lod, ll.eps_m,
                            static_cast<unsigned long long>(n));
            }
        }
        size_t shown = 0;
        for (const auto& v : r.items) {
            if (v.kind == "input_problem") {
                continue;
            }
            if (shown++ == 5) {
                break;
            }
            std::printf("    e.g. %s at %s LOD %u node %s chains %s (%.6f, %.6f): %s\n", v.kind.c_str(),
                        v.level.c_str(), v.lod, v.node.c_str(), ids_text(v.chains).c_str(), v.lon, v.lat,
                        v.detail.c_str());
        }
    }
    if (r.input_problems > 0) {
        std::printf("  %llu input problems: chains that already meet in the original map (see the ingest report);\n"
                    "  listed as kind input_problem, not counted as violations\n",
                    static_cast<unsigned long long>(r.input_problems));
    }
    std::printf("%s", compare_text.c_str());
    std::printf("report: %s/verify-report.json, summary: %s/verify-summary.md, violations: %s/violations.gpkg\n",
                output.c_str(), output.c_str(), output.c_str());
}

/// A table cell: Markdown's column bar and line breaks escaped.
std::string cell(const std::string& text)
{
    std::string out;
    for (const char c : text) {
        if (c == '|') {
            out += "\\|";
        } else if (c == '\n') {
            out += ' ';
        } else {
            out += c;
        }
    }
    return out;
}

/// verify-summary.md: the report for a person, beside the JSON: the verdict
/// first, then the violations by kind, by level and LOD, and the first
/// items with their places. No timings: the same tree gives the same bytes.
std::string summary_markdown(const Report& r, const std::string& tree, const std::string& original,
                             const std::string& compare_text, const std::optional<CgalCheck>& cgal)
{
    std::string md;
    auto line = [&md](const std::string& text) { md += text + "\n"; };
    auto num = [](uint64_t v) { return std::to_string(v); };
    auto fixed = [](double v, int digits) {
        char b[64];
        std::snprintf(b, sizeof b, "%.*f", digits, v);
        return std::string(b);
    };
    auto general = [](double v) {
        char b[64];
        std::snprintf(b, sizeof b, "%g", v);
        return std::string(b);
    };
    line("# Verification of `" + tree + "`");
    line("");
    line("Against `" + original + "`: " + num(r.nodes) + " nodes x " + num(r.lods) + " LODs, " + num(r.chains) +
         " chains, " + num(r.segments) + " segments, " + num(r.points) + " points checked.");
    line("");
    line(r.total() == 0 ? "**CLEAN: no violations.**"
                        : "**" + num(r.total()) + (r.total() == 1 ? " VIOLATION.**" : " VIOLATIONS.**"));
    line("");
    if (r.ground) {
        line("- On the ellipsoid: skipped vertices at most " + fixed(r.ground_ratio_max, 6) +
             " of their eps from their shortcuts (" + num(r.ground_geodesics) + " measured by geodesics).");
    } else {
        line("- On the ellipsoid: not checked (the tree's eps are projected metres: projection_scale off).");
    }
    if (!cgal) {
        line("- CGAL check: not run (`tigerlod-verify --cgal` runs it).");
    } else if (cgal->disagreements.empty()) {
        line("- CGAL check: agrees (" + num(cgal->segments) + " segments, " + num(cgal->within_pairs) +
             " meetings within LODs, " + num(cgal->across_pairs) + " across).");
    } else {
        line("- CGAL check: **DISAGREES** with verify's predicates:");
        for (const auto& d : cgal->disagreements) {
            line("  - " + d);
        }
    }
    if (r.input_problems > 0) {
        line("- " + num(r.input_problems) +
             " input problems: chains that already meet in the original map (see the ingest report), listed as "
             "kind input_problem, not counted as violations.");
    }
    if (!compare_text.empty()) {
        // "since EARLIER: N new, M fixed violations\n"
        line("- " + std::string(compare_text, 0, compare_text.size() - 1) + ".");
    }
    if (r.total() > 0) {
        line("");
        line("## Violations by kind");
        line("");
        line("| kind | count |");
        line("|---|---:|");
        for (const char* k : kinds) {
            if (count_of(r, k) > 0) {
                line(std::string("| ") + k + " | " + num(count_of(r, k)) + " |");
            }
        }
    }
    line("");
    line("## By level and LOD");
    line("");
    line("| level | LOD | eps (m) | nodes | chains | segments | ground: largest ratio to eps | violations | input "
         "problems |");
    line("|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for (const auto& ll : r.by_level_lod) {
        const uint64_t n = total_of(ll);
        line("| " + cell(ll.level) + " | " + num(ll.lod) + " | " + general(ll.eps_m) + " | " + num(ll.nodes) + " | " +
             num(ll.chains) + " | " + num(ll.segments) + " | " + (r.ground ? fixed(ll.ground_ratio_max, 6) : "-") +
             " | " + num(n) + " | " + num(ll.input_problems) + " |");
    }
    if (!r.items.empty()) {
        constexpr size_t shown_at_most = 50;
        line("");
        line("## The first " + std::to_string(std::min(r.items.size(), shown_at_most)) + " of " +
             std::to_string(r.items.size() + r.items_dropped) + " items");
        line("");
        line("Each with its place in longitude and latitude and its node (the unit whose map holds it); "
             "`violations.gpkg` holds the same items as points and their chains as lines, `verify-report.json` as "
             "JSON.");
        line("");
        line("| kind | level | LOD | node | chains | lon | lat | detail |");
        line("|---|---|---:|---|---|---:|---:|---|");
        for (size_t i = 0; i < r.items.size() && i < shown_at_most; ++i) {
            const Violation& v = r.items[i];
            line("| " + v.kind + " | " + cell(v.level) + " | " + num(v.lod) + " | " +
                 (v.node.empty() ? std::string("(root)") : cell(v.node)) + " | " + ids_text(v.chains) + " | " +
                 fixed(v.lon, 6) + " | " + fixed(v.lat, 6) + " | " + cell(v.detail) + " |");
        }
    }
    return md;
}

/// A report as report_json wrote it (a job's share), back.
Report report_from_json(const json& j)
{
    Report r;
    const auto& checked = j.at("checked");
    r.nodes = checked.at("nodes");
    r.lods = checked.at("lods");
    r.chains = checked.at("chains");
    r.segments = checked.at("segments");
    r.points = checked.at("points");
    for (const auto& [k, v] : j.at("violations").items()) {
        r.violations[k] = v.get<uint64_t>();
    }
    r.input_problems = j.at("input_problems");
    r.ground = j.at("ground").at("checked");
    r.ground_ratio_max = j.at("ground").at("ratio_max");
    r.ground_geodesics = j.at("ground").at("geodesics");
    for (const auto& b : j.at("by_level_lod")) {
        LevelLod ll;
        ll.level = b.at("level");
        ll.lod = b.at("lod");
        ll.eps_m = b.at("eps_m");
        ll.nodes = b.at("nodes");
        ll.chains = b.at("chains");
        ll.segments = b.at("segments");
        ll.vertices = b.at("vertices");
        ll.points = b.at("points");
        for (const auto& [k, v] : b.at("violations").items()) {
            ll.violations[k] = v.get<uint64_t>();
        }
        ll.input_problems = b.at("input_problems");
        ll.ground_ratio_max = b.at("ground_ratio_max");
        ll.ground_geodesics = b.at("ground_geodesics");
        r.by_level_lod.push_back(std::move(ll));
    }
    for (const auto& it : j.at("items")) {
        Violation v;
        v.kind = it.at("kind");
        v.level = it.at("level");
        v.lod = it.at("lod");
        v.node = it.at("node");
        for (const auto& id : it.at("chains")) {
            v.chains.push_back(std::stoull(id.get<std::string>()));
        }
        v.lon = it.at("lon");
        v.lat = it.at("lat");
        v.x = it.at("x");
        v.y = it.at("y");
        v.detail = it.at("detail");
        r.items.push_back(std::move(v));
    }
    r.items_dropped = j.at("items_dropped");
    r.seconds = j.at("seconds");
    r.ground_seconds = j.value("ground_seconds", 0.0);
    return r;
}

/// What a job's result for a node depends on in the tree: its skeleton
/// record (box, chains, each LOD's error and vertex count) and its payloads'
/// CRCs. A share whose nodes' fingerprints still hold is the tree's.
uint32_t fingerprint(const datatree::Skeleton& sk, uint32_t n)
{
    const auto& node = sk.nodes[n];
    std::string bytes;
    auto put = [&](const auto& v) { bytes.append(reinterpret_cast<const char*>(&v), sizeof v); };
    put(node.level);
    put(node.chains);
    put(node.box.min_x);
    put(node.box.min_y);
    put(node.box.max_x);
    put(node.box.max_y);
    put(node.table.crc);
    put(node.table.size);
    for (const auto& l : node.lods) {
        put(l.error_m);
        put(l.vertices);
        put(l.payload.crc);
        put(l.payload.size);
    }
    return crc32(std::as_bytes(std::span(bytes.data(), bytes.size())));
}

/// "level/partition" of node n (the root's partition is "all").
std::string store_of(const datatree::Skeleton& sk, uint32_t n)
{
    return sk.level_names[sk.nodes[n].level] + "/" + (n == 0 ? std::string("all") : sk.code(sk.nodes[n]));
}

/// The tree's stores that have a node to check (not the root of a line
/// layer in tiles, which shows nothing), as (level, partition), sorted.
std::vector<std::pair<std::string, std::string>> checked_stores(const datatree::Skeleton& sk)
{
    std::vector<std::pair<std::string, std::string>> all;
    for (uint32_t n = 0; n < sk.nodes.size(); ++n) {
        const bool tiles_root = n == 0 && sk.nodes[n].chains == 0 && sk.nodes[n].child_count > 0 &&
                                sk.nodes[sk.nodes[n].first_child].level == sk.nodes[n].level;
        if (!tiles_root) {
            const std::string s = store_of(sk, n);
            all.emplace_back(s.substr(0, s.find('/')), s.substr(s.find('/') + 1));
        }
    }
    std::sort(all.begin(), all.end());
    return all;
}

/// --finish: the shares as the report of a whole run, after checking that
/// they cover every node once and that every node they read is as it was.
Report merge_shares(const reader::Tree& tree, const std::vector<std::string>& files, const Options& options)
{
    const auto& sk = tree.skeleton();
    std::map<std::string, uint32_t> node_of;
    for (uint32_t n = 0; n < sk.nodes.size(); ++n) {
        node_of[store_of(sk, n)] = n;
    }
    std::map<std::string, std::string> covered; // store -> share
    std::vector<Report> reports;
    for (const auto& file : files) {
        std::ifstream in(file, std::ios::binary);
        if (!in) {
            throw usage_error("verify: " + file + ": no such share (its verify job has not run)");
        }
        json j;
        try {
            j = json::parse(in);
            if (j.at("schema") != "tigerlod.verify-share/1") {
                throw input_error(file + ": not a verify share (schema tigerlod.verify-share/1)");
            }
            for (const auto& s : j.at("stores")) {
                if (!covered.emplace(s.get<std::string>(), file).second) {
                    throw usage_error("verify: " + s.get<std::string>() + " is in two shares, " +
                                      covered.at(s.get<std::string>()) + " and " + file);
                }
            }
            for (const auto& [s, print] : j.at("fingerprints").items()) {
                const auto it = node_of.find(s);
                if (it == node_of.end() || fingerprint(sk, it->second) != print.get<uint32_t>()) {
                    throw usage_error("verify: " + file + " is stale: the node of " + s +
                                      " has changed since it was checked; run its verify job again");
                }
            }
            reports.push_back(report_from_json(j));
        } catch (const json::exception& e) {
            throw input_error(file + ": not a verify share: " + e.what());
        }
    }
    for (const auto& [level, partition] : checked_stores(sk)) {
        if (!covered.contains(level + "/" + partition)) {
            throw usage_error("verify: " + level + "/" + partition +
                              " is in no share: its verify job has not run (--partitions " + level + "/" + partition +
                              ")");
        }
    }
    return merge_reports(std::move(reports), sk.level_names, options.max_items);
}

} // namespace

int VerifyStage::run_partitions(const StageContext& ctx)
{
    const Manifest packed = read_manifest(m_tree, "pack");
    const Manifest ingest = read_manifest(m_original, "ingest");
    require_made_from(packed, "ingest", ingest);
    if (!packed.doc.contains("simplify")) {
        throw input_error((fs::path(m_tree) / "manifest.json").string() + ": no 'simplify' section");
    }
    std::string error;
    const auto tree = reader::Tree::open(m_tree, error);
    if (!tree) {
        throw input_error(error + " (the skeleton is checked by verify --finish, or a whole verify)");
    }
    const auto& sk = tree->skeleton();
    // The tree's stores; the job's are some of them.
    const auto all = checked_stores(sk);
    const auto chosen = select_partitions(all, m_partitions, m_tree);
    std::ifstream plan_in(m_plan, std::ios::binary);
    if (!plan_in) {
        throw usage_error("verify: --plan " + m_plan + ": no such file (tigerlod-pack --plan writes it)");
    }
    const pack::PackPlan plan = pack::plan_from_json(std::string(std::istreambuf_iterator<char>(plan_in), {}), m_plan);
    if (plan.ingest_sha256 != ingest.sha256) {
        throw usage_error("verify: " + m_plan + " is the plan of another tigerlod-ingest output than " + m_original +
                          "'s: run tigerlod-pack --plan again");
    }
    Selection selection;
    for (size_t i = 0; i < all.size(); ++i) {
        if (chosen[i]) {
            const std::string s = all[i].first + "/" + all[i].second;
            selection.stores.insert(s);
            const auto it = plan.near.find(s);
            if (it == plan.near.end()) {
                throw usage_error("verify: the plan " + m_plan + " has no store " + s +
                                  ": it is not the plan of this tree's stores (run tigerlod-pack --plan again)");
            }
            selection.near[s] = it->second;
        }
    }
    Options options;
    options.threads =
        m_threads > 0 ? static_cast<unsigned>(m_threads) : std::max(1U, std::thread::hardware_concurrency());
    options.max_items = static_cast<size_t>(m_max_items);
    options.tolerance =
        simplify::tolerance_contract(packed.doc.at("simplify"), (fs::path(m_tree) / "manifest.json").string());
    options.user_points = options.tolerance.user_points;
    options.ground = options.tolerance.projection_scale;
    // Progress by level and LOD, of the levels the job's stores are in (a
    // level without one is not checked here).
    std::set<std::string> levels;
    for (const auto& s : selection.stores) {
        levels.insert(s.substr(0, s.find('/')));
    }
    Progress progress(ctx.progress, "verify", levels.size() * tree->skeleton().lod_eps_m.size(), "level LODs",
                      "segments");
    options.on_level_lod = [&](uint64_t segments) { progress.advance(segments); };
    const Report r = verify_tree(*tree, m_original, options, &selection);
    json share = report_json(r, options, m_tree, m_original);
    share["schema"] = "tigerlod.verify-share/1";
    share["stores"] = selection.stores;
    // The fingerprints of every node the job read: its own and those beside them.
    json prints = json::object();
    for (uint32_t n = 0; n < sk.nodes.size(); ++n) {
        const std::string s = store_of(sk, n);
        bool read = selection.stores.contains(s);
        for (const auto& [own, near] : selection.near) {
            read = read || std::find(near.begin(), near.end(), s) != near.end();
        }
        if (read) {
            prints[s] = fingerprint(sk, n);
        }
    }
    share["fingerprints"] = std::move(prints);
    write_file_atomic(m_report, share.dump(1) + "\n");
    ctx.log.info("verify: " + std::to_string(selection.stores.size()) + " stores checked");
    std::printf("verify: %zu stores' nodes checked, %llu violations; share in %s\n", selection.stores.size(),
                static_cast<unsigned long long>(r.total()), m_report.c_str());
    return exit_ok;
}

int VerifyStage::run(const StageContext& ctx)
{
    if (!m_partitions.empty()) {
        return run_partitions(ctx);
    }
    // The earlier report and the date violations.gpkg will carry first: a
    // bad one is found before the work, not after.
    const json old = m_compare.empty() ? json() : read_earlier_report(m_compare);
    fix_gdal_dates();
    // The tree's manifest says what it was made from and under which
    // contract (simplify's options, its user points included): the tree is
    // checked against that, and against the ingest output it was packed from.
    const Manifest packed = read_manifest(m_tree, "pack");
    const Manifest ingest = read_manifest(m_original, "ingest");
    require_made_from(packed, "ingest", ingest);
    if (!packed.doc.contains("simplify")) {
        throw input_error((fs::path(m_tree) / "manifest.json").string() + ": no 'simplify' section");
    }
    std::string error;
    const auto tree = reader::Tree::open(m_tree, error);
    // --compare is read whole above: an output over it replaces it only on success.
    OutputDir out(m_output, m_overwrite, {m_tree, m_original});
    log_removed_leftovers(ctx.log, out.removed_leftovers());
    Options options;
    options.threads =
        m_threads > 0 ? static_cast<unsigned>(m_threads) : std::max(1U, std::thread::hardware_concurrency());
    options.max_items = static_cast<size_t>(m_max_items);
    options.tolerance =
        simplify::tolerance_contract(packed.doc.at("simplify"), (fs::path(m_tree) / "manifest.json").string());
    options.user_points = options.tolerance.user_points;
    options.ground = options.tolerance.projection_scale;
    Report r;
    if (!tree) {
        // An unreadable skeleton is the tree's failure: one violation, nothing else can be checked.
        r.violations["skeleton"] = 1;
        r.items.push_back({"skeleton", "", 0, "", {}, 0, 0, 0, 0, error});
    } else if (m_finish) {
        r = merge_shares(*tree, list_items(m_shares, "--shares"), options);
    } else {
        const auto& sk = tree->skeleton();
        Progress progress(ctx.progress, "verify", sk.level_names.size() * sk.lod_eps_m.size(), "level LODs",
                          "segments");
        options.on_level_lod = [&](uint64_t segments) { progress.advance(segments); };
        r = verify_tree(*tree, m_original, options);
    }
    ctx.log.info("verify: checked");
    std::optional<CgalCheck> cgal;
    if (m_cgal && tree) {
        cgal = cgal_check(*tree, r);
        ctx.log.info("verify: CGAL check done");
    }

    json report = report_json(r, options, m_tree, m_original);
    if (cgal) {
        report["cgal"] = {{"segments", cgal->segments},
                          {"within_pairs", cgal->within_pairs},
                          {"across_pairs", cgal->across_pairs},
                          {"input_pairs", cgal->input_pairs},
                          {"agrees", cgal->disagreements.empty()},
                          {"disagreements", cgal->disagreements},
                          {"seconds", cgal->seconds}};
    }
    const std::string compare_text = m_compare.empty() ? std::string() : compare_reports(report, old, m_compare);
    write_file_atomic(out.path() / "verify-report.json", report.dump(2) + "\n");
    write_violations_gpkg(out.path() / "violations.gpkg", r, tree ? &*tree : nullptr);
    write_file_atomic(out.path() / "verify-summary.md", summary_markdown(r, m_tree, m_original, compare_text, cgal));
    json manifest = new_manifest("verify", versions());
    add_input(manifest, "pack", packed);
    add_input(manifest, "ingest", ingest);
    manifest["options"] = {{"max_items", m_max_items}, {"compare", m_compare}};
    write_file_atomic(out.path() / "manifest.json", manifest_text(manifest));
    out.commit();
    print_summary(r, m_tree, m_original, m_output, compare_text);
    if (cgal) {
        if (cgal->disagreements.empty()) {
            std::printf("  CGAL check: agrees (%llu segments, %llu meetings within LODs, %llu across, %.2f s)\n",
                        static_cast<unsigned long long>(cgal->segments),
                        static_cast<unsigned long long>(cgal->within_pairs),
                        static_cast<unsigned long long>(cgal->across_pairs), cgal->seconds);
        } else {
            std::printf("  CGAL check: DISAGREES with verify's predicates:\n");
            for (const auto& d : cgal->disagreements) {
                std::printf("    %s\n", d.c_str());
            }
            return exit_data;
        }
    }
    return r.total() == 0 ? exit_ok : exit_data;
}

} // namespace tigerlod::verify
