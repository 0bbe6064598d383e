#include "stages/render/render_stage.hpp"

#include "core/progress.hpp"
#include "core/digest.hpp"

#include "config/config_file.hpp"
#include "config/schema.hpp"
#include "core/errors.hpp"
#include "core/fs.hpp"
#include "core/timing.hpp"
#include "stages/render/camera.hpp"
#include "stages/render/line_renderer.hpp"

#include <gdal.h>
#include <GL/osmesa.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <thread>

namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

namespace tigerlod::render {

namespace {

using Clock = std::chrono::steady_clock;

const std::vector<std::string> all_modes = {"incore", "ooc-noprefetch", "ooc-prefetch"};

/// One frame's row of the CSV.
struct Row {
    double ms = 0;
    double select_ms = 0; ///< choosing the front (and, prefetching, what to load ahead): part of ms
    size_t front_nodes = 0;
    std::string lods; ///< "lod:count ..." of the front
    uint64_t chains = 0, vertices = 0, segments = 0;
    uint64_t resident_bytes = 0, misses = 0, bytes_read = 0;
    bool complete = false; ///< every front item drawn at its own LOD
};

/// A mode's run over the path.
struct ModeRun {
    std::string mode;
    std::vector<Row> rows;
    double first_complete_s = -1; ///< from the mode's start to the end of its first complete frame
    double load_s = 0;            ///< incore: loading everything first
    uint64_t peak_bytes = 0;      ///< every byte the reader held, at most (skeleton included)
    uint64_t duplicate_chains = 0;
    uint64_t loads = 0, prefetches = 0, evictions = 0, skipped = 0, prefetch_cuts = 0, errors = 0;
    std::vector<std::string> error_messages;
    /// Out of core: the budget bound somewhere on the path (a payload
    /// evicted or skipped, or the prefetch list cut to fit).
    bool bound() const noexcept { return evictions + skipped + prefetch_cuts > 0; }
};

/// "0:3 2:10": how many front items are at each LOD (drawn LOD).
std::string lod_histogram(const std::vector<reader::Drawable>& front)
{
    std::map<uint32_t, size_t> n;
    for (const auto& d : front) {
        ++n[d.lod];
    }
    std::ostringstream s;
    for (const auto& [lod, count] : n) {
        s << (s.tellp() > 0 ? " " : "") << lod << ':' << count;
    }
    return s.str();
}

/// Chains a draw list holds twice (the same level and id): must be none.
uint64_t duplicates(const datatree::Skeleton& s, const std::vector<reader::Drawable>& front,
                    const std::vector<reader::DrawChain>& list)
{
    std::set<std::pair<uint32_t, uint64_t>> seen;
    uint64_t dup = 0;
    for (const auto& dc : list) {
        const auto& d = front[dc.item];
        dup += seen.insert({s.nodes[d.wanted.node].level, d.chains->ids[dc.chain]}).second ? 0 : 1;
    }
    return dup;
}

/// Write RGB pixels as a PNG through GDAL (a MEM dataset copied to the PNG driver).
void write_png(const fs::path& path, const std::vector<uint8_t>& rgb, uint32_t width, uint32_t height)
{
    GDALAllRegister();
    GDALDriverH mem = GDALGetDriverByName("MEM"), png = GDALGetDriverByName("PNG");
    if (mem == nullptr || png == nullptr) {
        throw environment_error("render: GDAL has no MEM or PNG driver");
    }
    GDALDatasetH ds = GDALCreate(mem, "", int(width), int(height), 3, GDT_Byte, nullptr);
    for (int b = 0; b < 3; ++b) {
        std::vector<uint8_t> band(size_t(width) * height);
        for (size_t i = 0; i < band.size(); ++i) {
            band[i] = rgb[3 * i + size_t(b)];
        }
        if (GDALRasterIO(GDALGetRasterBand(ds, b + 1), GF_Write, 0, 0, int(width), int(height), band.data(), int(width),
                         int(height), GDT_Byte, 0, 0) != CE_None) {
            GDALClose(ds);
            throw environment_error("render: GDAL cannot fill an image for " + path.string());
        }
    }
    GDALDatasetH out = GDALCreateCopy(png, path.c_str(), ds, FALSE, nullptr, nullptr, nullptr);
    GDALClose(ds);
    if (out == nullptr) {
        throw environment_error("render: cannot write " + path.string());
    }
    GDALClose(out);
    std::error_code ec;
    fs::remove(path.string() + ".aux.xml", ec);
}

/// Everything a mode shares.
struct Run {
    std::shared_ptr<reader::Tree> tree;
    const std::vector<reader::View>& views;
    LineRenderer& renderer;
    reader::FrontOptions front_options;
    uint64_t budget = 0; ///< bytes, the skeleton included
    fs::path out;
    int png_every = 0;
    double fps = 0;
    Progress* progress = nullptr; ///< a frame drawn on the path: one step

    /// Wait for frame f's slot from `start` (frames at `fps` a second).
    void pace(Clock::time_point start, size_t f) const
    {
        if (fps > 0) {
            std::this_thread::sleep_until(
                start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(double(f) / fps)));
        }
    }

    const datatree::Skeleton& sk() const { return tree->skeleton(); }
    uint32_t levels() const { return static_cast<uint32_t>(sk().level_names.size()); }

    void draw(ModeRun& m, Row& row, size_t frame, const std::vector<reader::Drawable>& front)
    {
        const auto list = reader::draw_list(sk(), front);
        m.duplicate_chains += duplicates(sk(), front, list);
        const DrawStats ds = renderer.draw(views[frame], front, list, levels());
        if (progress != nullptr) {
            progress->advance(ds.vertices);
        }
        row.front_nodes = front.size();
        row.lods = lod_histogram(front);
        row.chains = ds.chains;
        row.vertices = ds.vertices;
        row.segments = ds.segments;
    }

    void maybe_png(const ModeRun& m, size_t frame)
    {
        if (png_every > 0 && frame % size_t(png_every) == 0) {
            char name[64];
            std::snprintf(name, sizeof name, "%s-%05zu.png", m.mode.c_str(), frame);
            write_png(out / "frames" / name, renderer.read_rgb(), renderer.width(), renderer.height());
        }
    }

    /// One view drawn out of core under the budget, once its front is resident: RGB rows.
    std::vector<uint8_t> still(const reader::View& view)
    {
        reader::StreamOptions so;
        so.budget_bytes = budget - tree->skeleton_memory();
        so.prefetch = false;
        so.front = front_options;
        reader::Streamer streamer(tree, so);
        streamer.set_view(view);
        streamer.wait_front(std::chrono::seconds(60));
        const auto items = streamer.resident_front();
        renderer.draw(view, items, reader::draw_list(sk(), items), levels());
        return renderer.read_rgb();
    }

    /// In core: every payload and table loaded first, then each frame's front drawn from memory.
    ModeRun incore()
    {
        ModeRun m;
        m.mode = "incore";
        const auto t_start = Clock::now();
        const auto& s = sk();
        std::vector<std::shared_ptr<const reader::NodeChains>> tables(s.nodes.size());
        std::vector<std::vector<std::shared_ptr<const datatree::Geometry>>> geometry(s.nodes.size());
        uint64_t bytes = tree->skeleton_memory();
        for (uint32_t n = 0; n < s.nodes.size(); ++n) {
            datatree::ChainTable table;
            if (const auto st = tree->read_table(n, table); !st.ok()) {
                m.error_messages.push_back(st.error);
                continue;
            }
            auto c = std::make_shared<reader::NodeChains>(reader::node_chains(*tree, n, table));
            bytes += c->memory_bytes();
            tables[n] = std::move(c);
            for (uint32_t k = 0; k < s.lod_eps_m.size(); ++k) {
                auto g = std::make_shared<datatree::Geometry>();
                if (const auto st = tree->read_geometry(n, k, *g); !st.ok()) {
                    m.error_messages.push_back(st.error);
                    geometry[n].push_back(nullptr);
                    continue;
                }
                bytes += g->memory_bytes();
                geometry[n].push_back(std::move(g));
                ++m.loads;
            }
        }
        m.errors = m.error_messages.size();
        m.load_s = seconds_since(t_start);
        m.peak_bytes = bytes;
        const auto t_path = Clock::now();
        for (size_t f = 0; f < views.size(); ++f) {
            pace(t_path, f);
            const auto t0 = Clock::now();
            Row row;
            std::vector<reader::Drawable> front;
            bool complete = true;
            const auto t_select = Clock::now();
            const auto items = reader::select_front(s, views[f], front_options);
            row.select_ms = 1000 * seconds_since(t_select);
            for (const auto& item : items) {
                reader::Drawable d{item, item.lod,
                                   geometry[item.node].empty() ? nullptr : geometry[item.node][item.lod],
                                   tables[item.node]};
                complete = complete && d.geometry && d.chains;
                front.push_back(std::move(d));
            }
            draw(m, row, f, front);
            row.ms = 1000 * seconds_since(t0);
            row.resident_bytes = bytes;
            row.complete = complete;
            if (complete && m.first_complete_s < 0) {
                m.first_complete_s = seconds_since(t_start);
            }
            m.rows.push_back(std::move(row));
            maybe_png(m, f);
        }
        return m;
    }

    /// Out of core: the streamer under the budget (less the skeleton); each
    /// frame sets the view, waits for its front (as the paper's renderer
    /// waits for the maps it lacks), and draws it.
    ModeRun out_of_core(bool prefetch)
    {
        ModeRun m;
        m.mode = prefetch ? "ooc-prefetch" : "ooc-noprefetch";
        const auto t_start = Clock::now();
        const uint64_t skeleton = tree->skeleton_memory();
        reader::StreamOptions so;
        so.budget_bytes = budget - skeleton;
        so.prefetch = prefetch;
        so.front = front_options;
        reader::Streamer streamer(tree, so);
        uint64_t last_read = 0;
        for (size_t f = 0; f < views.size(); ++f) {
            pace(t_start, f);
            const auto t0 = Clock::now();
            Row row;
            streamer.set_view(views[f]);
            row.select_ms = 1000 * seconds_since(t0);
            row.misses = streamer.missing();
            row.complete = streamer.wait_front(std::chrono::seconds(60));
            const auto front = streamer.resident_front();
            draw(m, row, f, front);
            row.ms = 1000 * seconds_since(t0);
            const reader::Stats st = streamer.stats();
            row.resident_bytes = skeleton + st.resident_bytes;
            row.bytes_read = st.bytes_read - last_read;
            last_read = st.bytes_read;
            if (row.complete && m.first_complete_s < 0) {
                m.first_complete_s = seconds_since(t_start);
            }
            m.rows.push_back(std::move(row));
            maybe_png(m, f);
        }
        streamer.wait_idle();
        const reader::Stats st = streamer.stats();
        m.peak_bytes = skeleton + st.peak_bytes;
        m.loads = st.loads;
        m.prefetches = st.prefetches;
        m.evictions = st.evictions;
        m.skipped = st.skipped;
        m.prefetch_cuts = st.prefetch_cuts;
        m.errors = st.errors;
        m.error_messages = streamer.errors();
        return m;
    }
};

double percentile(std::vector<double> v, double p)
{
    if (v.empty()) {
        return 0;
    }
    std::sort(v.begin(), v.end());
    const size_t i = std::min(v.size() - 1, static_cast<size_t>(std::ceil(p * double(v.size())) - 1));
    return v[i];
}

json summary_of(const ModeRun& m, uint64_t budget)
{
    std::vector<double> ms, select;
    uint64_t read = 0, misses = 0, incomplete = 0;
    for (const auto& r : m.rows) {
        ms.push_back(r.ms);
        select.push_back(r.select_ms);
        read += r.bytes_read;
        misses += r.misses;
        incomplete += r.complete ? 0 : 1;
    }
    const double median = percentile(ms, 0.5);
    const auto over = std::count_if(ms.begin(), ms.end(), [&](double v) { return v > 2 * median; });
    json j;
    j["mode"] = m.mode;
    j["frames"] = m.rows.size();
    j["median_ms"] = median;
    j["p95_ms"] = percentile(ms, 0.95);
    j["max_ms"] = ms.empty() ? 0.0 : *std::max_element(ms.begin(), ms.end());
    j["frames_over_2x_median"] = over;
    j["select_median_ms"] = percentile(select, 0.5);
    j["select_p95_ms"] = percentile(select, 0.95);
    j["select_max_ms"] = select.empty() ? 0.0 : *std::max_element(select.begin(), select.end());
    j["first_complete_frame_s"] = m.first_complete_s;
    j["incomplete_frames"] = incomplete;
    j["load_s"] = m.load_s;
    j["peak_bytes"] = m.peak_bytes;
    j["budget_bytes"] = m.mode == "incore" ? json(nullptr) : json(budget);
    j["within_budget"] = m.mode == "incore" ? json(nullptr) : json(m.peak_bytes <= budget);
    j["misses"] = misses;
    j["bytes_read"] = read;
    j["loads"] = m.loads;
    j["evictions"] = m.evictions;
    if (m.mode != "incore") {
        j["prefetches"] = m.prefetches;
        j["skipped"] = m.skipped;
        j["prefetch_cuts"] = m.prefetch_cuts;
        j["budget_bound"] = m.bound();
    }
    j["duplicate_chains"] = m.duplicate_chains;
    j["errors"] = m.errors;
    return j;
}

std::string csv_of(const ModeRun& m, const std::vector<reader::View>& views)
{
    std::ostringstream out;
    out << "frame,ms,front_nodes,lods,chains,vertices,segments,resident_bytes,misses,bytes_read,complete,select_ms,"
           "center_x,center_y,units_per_pixel\n";
    for (size_t f = 0; f < m.rows.size(); ++f) {
        const auto& r = m.rows[f];
        char ms[32], select[32];
        std::snprintf(ms, sizeof ms, "%.3f", r.ms);
        std::snprintf(select, sizeof select, "%.3f", r.select_ms);
        out << f << "," << ms << "," << r.front_nodes << "," << r.lods << "," << r.chains << "," << r.vertices << ","
            << r.segments << "," << r.resident_bytes << "," << r.misses << "," << r.bytes_read << ","
            << (r.complete ? 1 : 0) << "," << select;
        char view[96];
        std::snprintf(view, sizeof view, ",%.17g,%.17g,%.17g", views[f].center_x, views[f].center_y,
                      views[f].units_per_pixel);
        out << view << "\n";
    }
    return out.str();
}

} // namespace

void RenderStage::add_args(ArgSet& args)
{
    args.positional("TREE", &m_tree, "a Data Tree folder (tigerlod-pack's output)");
    args.positional("OUTPUT", &m_output, "the folder to write, under a temporary name renamed when done");
    args.group("Camera");
    config::add_option(args, "render.path", &m_path);
    config::add_option(args, "render.frames", &m_frames);
    args.add("seed", &m_seed, "the jumpy path's seed", "N", {0, 2147483647, false, false, true});
    config::add_option(args, "render.size", &m_size);
    config::add_option(args, "render.fps", &m_fps);
    args.add("pixel-error", &m_pixel_error, "a LOD is drawn when its error is below this many pixels", "PX",
             {0, 1e6, true, false, false});
    args.group("Memory and disk");
    config::add_option(args, "render.mode", &m_mode);
    config::add_option(args, "render.budget_mb", &m_budget_mb);
    config::add_option(args, "render.disk_latency_ms", &m_disk_latency_ms);
    config::add_option(args, "render.disk_mbps", &m_disk_mbps);
    args.group("Output");
    args.add("png-every", &m_png_every, "also write every N-th frame as OUTPUT/frames/MODE-NNNNN.png (0: none)", "N",
             {0, 1000000, false, false, true});
    config::add_option(args, "render.gl", &m_gl);
    args.add("overwrite", &m_overwrite, "replace OUTPUT if it exists");
}

void RenderStage::initialize()
{
    const auto& limits = config::key("render.size").limits;
    const auto size = config::parse_viewport(m_size, limits);
    if (!size) {
        throw usage_error("render: option '--size' must be WIDTHxHEIGHT, each " + limits.text() + " (got '" + m_size +
                          "')");
    }
    m_width = size->first;
    m_height = size->second;
    refuse_to_replace_inputs(m_output, {m_tree});
}

std::vector<std::string> RenderStage::config_args(const fs::path& file) const
{
    return config::stage_args(file, name);
}

std::vector<std::string> RenderStage::versions() const
{
    return {std::string("OSMesa API ") + std::to_string(OSMESA_MAJOR_VERSION) + "." +
                std::to_string(OSMESA_MINOR_VERSION) + " (EGL with --gl egl)",
            std::string("GDAL ") + GDALVersionInfo("RELEASE_NAME"), datatree::format_version_text()};
}

std::string RenderStage::help_notes() const
{
    return "Outputs:\n"
           "  OUTPUT/frames-<mode>.csv   per frame: frame, ms, front_nodes, lods (LOD:count), chains, vertices,\n"
           "                             segments (drawn in view), resident_bytes (skeleton included), misses\n"
           "                             (front payloads and tables not resident when the view was set),\n"
           "                             bytes_read, complete (the whole front at its own LODs), select_ms (choosing\n"
           "                             the front, and out of core what to load ahead, within ms), center_x,\n"
           "                             center_y, units_per_pixel (the view, grid units: tigerlod-serve's)\n"
           "  OUTPUT/summary.json        per mode: median, p95 and max frame time, frames over 2x the median,\n"
           "                             the median, p95 and max time choosing the front (select_*_ms),\n"
           "                             time to the first complete frame, peak bytes against the budget,\n"
           "                             misses, bytes read, chains drawn twice (none)\n"
           "  OUTPUT/overview.png, OUTPUT/zoom.png  the whole tree, and the path's closest view\n"
           "Each chain is drawn once a frame: a border two nodes of one level show, at the finer of their\n"
           "LODs; a border between nodes of two levels, by the finer node (reader.hpp, draw_list).\n"
           "Path file: one keyframe a line, 'LON LAT METRES_PER_PIXEL [FRAMES]' (# comments).\n"
           "Exit codes: 0 done; 1 bad data (a missing or damaged tree, a malformed path file); 2 usage error\n"
           "  (a budget below what the skeleton needs); 3 environment (no OpenGL context, cannot write).\n";
}

int RenderStage::run(const StageContext& ctx)
{
    std::string error;
    auto tree = reader::Tree::open(m_tree, error);
    if (!tree) {
        throw input_error(error);
    }
    const auto& sk = tree->skeleton();
    const uint64_t budget = static_cast<uint64_t>(m_budget_mb * 1024 * 1024);
    const uint64_t skeleton = tree->skeleton_memory();
    if (budget <= skeleton) { // the previews are drawn out of core in every mode
        throw usage_error("render: --budget-mb " + std::to_string(m_budget_mb) + " (" + std::to_string(budget) +
                          " bytes) does not hold the skeleton of " + m_tree + " in memory (" +
                          std::to_string(skeleton) + " bytes), let alone a payload");
    }
    const bool builtin = std::find(builtin_paths.begin(), builtin_paths.end(), m_path) != builtin_paths.end();
    const auto views = builtin ? builtin_path(m_path, sk, m_width, m_height, uint32_t(m_frames), uint32_t(m_seed))
                               : keyframe_views(read_path_file(m_path), sk, m_width, m_height);
    tree->simulate_disk(std::chrono::microseconds(std::llround(m_disk_latency_ms * 1000)), m_disk_mbps * 1e6);
    OutputDir out(m_output, m_overwrite, {m_tree});
    log_removed_leftovers(ctx.log, out.removed_leftovers());
    if (m_png_every > 0) {
        fs::create_directories(out.path() / "frames");
    }
    std::string gl_why = "--gl " + m_gl;
    auto context = m_gl == "auto" ? gl::Context::create_auto(gl_why) : gl::Context::create(*gl::parse_backend(m_gl));
    ctx.log.info("render: " + context->describe() + (m_gl == "auto" ? " (--gl auto: " + gl_why + ")" : ""));
    LineRenderer renderer(*context, m_width, m_height);
    reader::FrontOptions fo;
    fo.pixel_error = m_pixel_error;
    Run run{tree, views, renderer, fo, budget, out.path(), m_png_every, m_fps};
    ctx.log.info("render: " + m_tree + ", " + std::to_string(views.size()) + " frames of " + m_path + " at " +
                 std::to_string(m_width) + "x" + std::to_string(m_height) + " on " + context->describe());

    size_t nmodes = 0;
    for (const auto& mode : all_modes) {
        nmodes += m_mode == "all" || m_mode == mode ? 1 : 0;
    }
    Progress progress(ctx.progress, "render", nmodes * views.size(), "frames", "vertices");
    run.progress = &progress;
    std::vector<ModeRun> runs;
    for (const auto& mode : all_modes) { // none: the previews alone
        if (m_mode != "all" && m_mode != mode) {
            continue;
        }
        runs.push_back(mode == "incore" ? run.incore() : run.out_of_core(mode == "ooc-prefetch"));
        if (!runs.back().error_messages.empty()) {
            std::string msg = m_tree + ": the tree has damaged or missing payloads (" +
                              std::to_string(runs.back().error_messages.size()) + "):";
            for (size_t i = 0; i < std::min<size_t>(5, runs.back().error_messages.size()); ++i) {
                msg += "\n  " + runs.back().error_messages[i];
            }
            throw input_error(msg);
        }
        write_file(out.path() / ("frames-" + mode + ".csv"), csv_of(runs.back(), views));
    }

    run.progress = nullptr; // the previews are not on the path
    // The previews: where most of the map is (reader::main_extent: the
    // central 95 % of its finest units, so that far territories do not
    // leave the main part a corner of the frame), and the path's closest view.
    const auto closest = *std::min_element(
        views.begin(), views.end(), [](const auto& a, const auto& b) { return a.units_per_pixel < b.units_per_pixel; });
    write_png(out.path() / "overview.png", run.still(fit(reader::main_extent(*tree), m_width, m_height)), m_width,
              m_height);
    write_png(out.path() / "zoom.png", run.still(closest), m_width, m_height);

    json summary;
    summary["schema"] = "tigerlod.render-summary/1";
    summary["tree"] = m_tree;
    // Which tree it drew: a workflow reruns the experiment for a new renderer, not for every new tree.
    if (std::error_code ec; fs::is_regular_file(fs::path(m_tree) / "manifest.json", ec)) {
        summary["tree_manifest_sha256"] = sha256_file(fs::path(m_tree) / "manifest.json");
    }
    summary["path"] = m_path;
    summary["frames"] = views.size();
    summary["viewport"] = {m_width, m_height};
    summary["gl"] = context->describe();
    summary["gl_choice"] = m_gl == "auto" ? "auto: " + gl_why : gl_why;
    summary["skeleton_bytes"] = skeleton;
    summary["disk"] = {{"latency_ms", m_disk_latency_ms}, {"mbps", m_disk_mbps}};
    summary["fps"] = m_fps;
    json modes = json::array();
    const ModeRun* incore = nullptr;
    for (const auto& m : runs) {
        incore = m.mode == "incore" ? &m : incore;
    }
    for (const auto& m : runs) {
        json j = summary_of(m, budget);
        if (incore != nullptr && &m != incore) {
            // Against the in-core renderer on the same frames: what the disk costs.
            int64_t over = 0;
            std::vector<double> a, b;
            for (size_t f = 0; f < m.rows.size() && f < incore->rows.size(); ++f) {
                over += m.rows[f].ms > 2 * incore->rows[f].ms ? 1 : 0;
                a.push_back(m.rows[f].ms);
                b.push_back(incore->rows[f].ms);
            }
            j["frames_over_2x_incore"] = over;
            j["p95_vs_incore"] = percentile(b, 0.95) > 0 ? percentile(a, 0.95) / percentile(b, 0.95) : 0.0;
        }
        modes.push_back(std::move(j));
    }
    summary["modes"] = modes;
    if (incore != nullptr) { // the whole tree decoded, against the budget
        summary["incore_bytes_vs_budget"] = double(incore->peak_bytes) / double(budget);
    }
    write_file(out.path() / "summary.json", summary.dump(2) + "\n");
    out.commit();

    std::printf("render: %zu frames of %s at %ux%u, budget %.1f MiB (skeleton %.2f MiB), %s\n", views.size(),
                m_path.c_str(), m_width, m_height, m_budget_mb, double(skeleton) / (1 << 20),
                context->describe().c_str());
    std::printf("  %-15s %9s %9s %9s %8s %9s %9s %9s %9s %7s\n", "mode", "median ms", "p95 ms", "max ms", ">2x med",
                "p95/inc", ">2x inc", "first s", "peak MiB", "misses");
    for (const auto& j : modes) {
        const bool vs = j.contains("p95_vs_incore");
        std::printf("  %-15s %9.2f %9.2f %9.2f %8lld %9s %9s %9.2f %9.2f %7llu\n", j["mode"].get<std::string>().c_str(),
                    j["median_ms"].get<double>(), j["p95_ms"].get<double>(), j["max_ms"].get<double>(),
                    static_cast<long long>(j["frames_over_2x_median"].get<int64_t>()),
                    vs ? std::to_string(j["p95_vs_incore"].get<double>()).substr(0, 4).c_str() : "-",
                    vs ? std::to_string(j["frames_over_2x_incore"].get<int64_t>()).c_str() : "-",
                    j["first_complete_frame_s"].get<double>(), double(j["peak_bytes"].get<uint64_t>()) / (1 << 20),
                    static_cast<unsigned long long>(j["misses"].get<uint64_t>()));
    }
    for (const auto& m : runs) {
        if (m.mode != "incore" && !m.bound()) {
            std::printf("  %s: the budget did not bind (nothing evicted, skipped or left out of the prefetch list): "
                        "this run measured no paging\n",
                        m.mode.c_str());
        }
    }
    if (incore != nullptr) {
        std::printf("  the whole tree decoded takes %.1fx the budget\n", double(incore->peak_bytes) / double(budget));
    }
    std::printf("outputs in %s\n", m_output.c_str());
    return exit_ok;
}

} // namespace tigerlod::render
