#include "stages/synth/synth_stage.hpp"

#include "config/config_file.hpp"
#include "config/schema.hpp"
#include "core/fs.hpp"
#include "core/manifest.hpp"
#include "core/memory.hpp"
#include "core/parallel.hpp"
#include "core/timing.hpp"
#include "stages/synth/nation.hpp"
#include "stages/synth/tiger_files.hpp"

#include <gdal.h>
#include <nlohmann/json.hpp>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <thread>

namespace tigerlod::synth {

namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

namespace {

/// What one county's files hold.
struct CountyCounts {
    uint64_t edge_features = 0, vertex_records = 0; ///< as written, border edges in both files
    uint64_t edges = 0, vertices = 0;               ///< the edges this county owns (each edge once over the nation)
    uint64_t faces = 0, water_faces = 0, face_vertex_records = 0, bytes = 0;
    double geometry_s = 0, files_s = 0;      ///< a thread's seconds building the county, and writing its files
    WriteSeconds write_s;                    ///< and in the shapefile driver and the zip
    std::vector<uint32_t> vertices_per_edge; ///< owned edges
    std::vector<float> edge_m;               ///< owned edges' lengths
    std::vector<uint32_t> face_blocks;       ///< each face's block

    /// Another county's counts and values added to these (not its blocks).
    void add(const CountyCounts& k)
    {
        for (auto [to, from] : {std::pair{&edge_features, k.edge_features},
                                {&vertex_records, k.vertex_records},
                                {&edges, k.edges},
                                {&vertices, k.vertices},
                                {&faces, k.faces},
                                {&water_faces, k.water_faces},
                                {&face_vertex_records, k.face_vertex_records},
                                {&bytes, k.bytes}}) {
            *to += from;
        }
        geometry_s += k.geometry_s;
        files_s += k.files_s;
        write_s.shapefile += k.write_s.shapefile;
        write_s.deflate += k.write_s.deflate;
        vertices_per_edge.insert(vertices_per_edge.end(), k.vertices_per_edge.begin(), k.vertices_per_edge.end());
        edge_m.insert(edge_m.end(), k.edge_m.begin(), k.edge_m.end());
    }
};

double length_m(const std::vector<Pt>& pts)
{
    double m = 0;
    for (size_t k = 0; k + 1 < pts.size(); ++k) {
        const double dx = double(pts[k + 1].x - pts[k].x) * 0.111319 * cos_turns(double(pts[k].y) / 1e6 / 360);
        const double dy = double(pts[k + 1].y - pts[k].y) * 0.110574;
        m += std::sqrt(dx * dx + dy * dy);
    }
    return m;
}

/// Quantiles 0, 10, 25, 50, 75, 90, 99, 100 % and the mean.
template <class T> json quantiles(std::vector<T> v)
{
    json q = json::object();
    if (v.empty()) {
        return q;
    }
    std::sort(v.begin(), v.end());
    double sum = 0;
    for (const T x : v) {
        sum += double(x);
    }
    for (const int p : {0, 10, 25, 50, 75, 90, 99, 100}) {
        const size_t k = size_t(double(p) / 100 * double(v.size() - 1));
        std::string key = "p"; // not "p" + to_string: GCC 12's -Wrestrict false positive at -O3
        key += std::to_string(p);
        q[key] = std::round(double(v[k]) * 10) / 10;
    }
    q["mean"] = std::round(sum / double(v.size()) * 10) / 10;
    return q;
}

} // namespace

void SynthStage::add_args(ArgSet& args)
{
    args.positional("OUTPUT", &m_output, "the folder to write, under a temporary name renamed when done");
    config::add_option(args, "synth.seed", &m_seed);
    config::add_option(args, "synth.states", &m_states);
    config::add_option(args, "synth.counties_per_state", &m_counties);
    config::add_option(args, "synth.target_vertices", &m_target);
    config::add_option(args, "synth.cell_m", &m_cell_m);
    config::add_option(args, "synth.threads", &m_threads);
    args.add("overwrite", &m_overwrite, "replace OUTPUT if it exists");
}

void SynthStage::initialize()
{
    if (m_output.empty()) {
        throw usage_error("synth: OUTPUT must not be empty");
    }
}

std::vector<std::string> SynthStage::config_args(const fs::path& file) const
{
    return config::stage_args(file, name);
}

std::vector<std::string> SynthStage::versions() const
{
    return {std::string("GDAL ") + GDALVersionInfo("RELEASE_NAME"), std::string("zlib ") + zlibVersion()};
}

std::string SynthStage::help_notes() const
{
    return "Outputs:\n"
           "  OUTPUT/tl_2020_SSCCC_edges.zip  per county (SS state, CCC county): TLID, TFIDL, TFIDR, TNIDF, TNIDT,\n"
           "                                  MTFCC, STATEFP, COUNTYFP; an edge on a county border is in both files\n"
           "  OUTPUT/tl_2020_SSCCC_faces.zip  TFID, STATEFP20, COUNTYFP20, TRACTCE20, BLKGRPCE20, BLOCKCE20, LWFLAG,\n"
           "                                  ATOTAL, INTPTLAT, INTPTLON\n"
           "  OUTPUT/manifest.json            options, units per level, edges, vertices and faces written, and the\n"
           "                                  distributions of vertices per edge, edge length and faces per block\n"
           "  OUTPUT/synth-timings.json       seconds, vertices per second, peak memory (varies by run)\n"
           "The same options give the same bytes, whatever the thread count. A config's `synth` section gives\n"
           "the options (--config); `tigerlod-ingest` reads the files as a `tiger` dataset.\n"
           "Exit codes: 0 done; 2 usage or config error; 3 environment (cannot write).\n";
}

int SynthStage::run(const StageContext& ctx)
{
    const auto t0 = std::chrono::steady_clock::now();
    auto seconds = [&] { return seconds_since(t0); };
    GDALAllRegister();
    OutputDir out(m_output, m_overwrite); // an existing OUTPUT is refused before the plan's seconds
    log_removed_leftovers(ctx.log, out.removed_leftovers());
    SynthOptions opt;
    opt.seed = uint64_t(m_seed);
    opt.states = m_states;
    opt.counties_per_state = m_counties;
    opt.target_vertices = m_target;
    opt.cell_m = m_cell_m;
    const Nation nation(opt);
    const double t_plan = seconds();
    ctx.log.info("synth: a lattice of " + std::to_string(nation.width()) + " x " + std::to_string(nation.height()) +
                 " cells, " + std::to_string(nation.units(county).size()) + " counties, planned in " +
                 std::to_string(t_plan) + " s");

    const unsigned threads = m_threads > 0 ? unsigned(m_threads) : std::max(1U, std::thread::hardware_concurrency());
    const size_t counties = nation.units(county).size();
    std::vector<CountyCounts> counts(counties);
    Progress progress(ctx.progress, "synth", counties, "counties", "vertices");
    parallel_each(counties, threads, [&](size_t c) {
        const auto& cty = nation.units(county)[c];
        const auto& st = nation.units(state)[cty.parent];
        const std::string ssccc = st.code + cty.code;
        auto& k = counts[c];
        const auto built = std::chrono::steady_clock::now();
        const auto parts = nation.county_parts(uint32_t(c));
        k.geometry_s = seconds_since(built);
        auto timed_write = [&](const fs::path& file, const std::string& bytes) {
            const auto started = std::chrono::steady_clock::now();
            write_file(file, bytes);
            k.files_s += seconds_since(started);
        };
        const auto& edges = parts.edges;
        for (const auto& e : edges) {
            ++k.edge_features;
            k.vertex_records += e.points.size();
            const int64_t side = e.tfidl != 0 ? e.tfidl : e.tfidr;
            if (nation.county_of_face(side) == c) {
                ++k.edges;
                k.vertices += e.points.size();
                k.vertices_per_edge.push_back(uint32_t(e.points.size()));
                k.edge_m.push_back(float(length_m(e.points)));
            }
        }
        const std::string ez = edges_zip(ssccc, st.code, cty.code, edges, k.write_s);
        timed_write(out.path() / ("tl_2020_" + ssccc + "_edges.zip"), ez);
        const auto& faces = parts.faces;
        for (const auto& f : faces) {
            ++k.faces;
            k.water_faces += f.water ? 1 : 0;
            k.face_blocks.push_back(f.block);
            for (const auto& ring : f.rings) {
                k.face_vertex_records += ring.size();
            }
        }
        const std::string fz = faces_zip(ssccc, nation, faces, k.write_s);
        timed_write(out.path() / ("tl_2020_" + ssccc + "_faces.zip"), fz);
        k.bytes = ez.size() + fz.size();
        progress.advance(k.vertices);
    });

    CountyCounts all;
    std::vector<uint32_t> faces_per_block(nation.units(block).size(), 0);
    for (auto& k : counts) {
        for (const uint32_t b : k.face_blocks) {
            ++faces_per_block[b];
        }
        all.add(k);
    }
    json manifest = new_manifest(name, versions());
    manifest["options"] = {{"seed", m_seed},
                           {"states", m_states},
                           {"counties_per_state", m_counties},
                           {"target_vertices", m_target},
                           {"cell_m", m_cell_m}};
    json levels = json::object();
    for (int l = 0; l < level_count; ++l) {
        levels[level_names[l]] = nation.units(Level(l)).size();
    }
    manifest["counts"] = {{"units", levels},
                          {"files", 2 * counties},
                          {"edges", all.edges},
                          {"vertices", all.vertices},
                          {"edge_features", all.edge_features},
                          {"vertex_records", all.vertex_records},
                          {"faces", all.faces},
                          {"water_faces", all.water_faces},
                          {"face_vertex_records", all.face_vertex_records},
                          {"lattice_cells", {nation.width(), nation.height()}}};
    manifest["distributions"] = {{"vertices_per_edge", quantiles(all.vertices_per_edge)},
                                 {"edge_length_m", quantiles(all.edge_m)},
                                 {"faces_per_block", quantiles(faces_per_block)}};
    write_file(out.path() / "manifest.json", manifest_text(manifest));
    const double total = seconds();
    // The dataset's vertices a second (each edge once), and every vertex
    // written a second (EDGES with border edges twice, and FACES' rings).
    const double written = double(all.vertex_records + all.face_vertex_records);
    json timings = {{"plan_s", t_plan},
                    {"total_s", total},
                    {"threads", threads},
                    {"vertices_per_s", total > 0 ? double(all.vertices) / total : 0.0},
                    {"written_vertices_per_s", total > 0 ? written / total : 0.0},
                    {"bytes", all.bytes},
                    // Where the threads' time went, summed over threads
                    // (the plan and the manifest are plan_s and the rest).
                    {"thread_s",
                     {{"geometry", all.geometry_s},
                      {"shapefile", all.write_s.shapefile},
                      {"deflate", all.write_s.deflate},
                      {"files", all.files_s}}},
                    {"peak_rss_mb", peak_rss_mb()}};
    write_file(out.path() / "synth-timings.json", timings.dump(2) + "\n");
    out.commit();
    std::printf("synth: %zu states, %zu counties, %zu tracts, %zu block groups, %zu blocks; %llu faces; %llu edges, "
                "%llu vertices (each edge once) in %.1f s, %.2f M vertices/s\n",
                nation.units(state).size(), counties, nation.units(tract).size(), nation.units(block_group).size(),
                nation.units(block).size(), (unsigned long long)all.faces, (unsigned long long)all.edges,
                (unsigned long long)all.vertices, total, double(all.vertices) / total / 1e6);
    return exit_ok;
}

} // namespace tigerlod::synth
