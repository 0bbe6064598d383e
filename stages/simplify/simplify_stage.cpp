#include "stages/simplify/simplify_stage.hpp"

#include "config/config_file.hpp"
#include "config/schema.hpp"
#include "core/digest.hpp"
#include "core/errors.hpp"
#include "core/fs.hpp"
#include "core/parallel.hpp"
#include "core/serial_queue.hpp"
#include "gl/context.hpp"
#include "simplification/color_io.hpp"
#include "simplification/simplifier.hpp"
#include "simplification/stage_output.hpp"

#include <GeographicLib/Config.h>
#include <GL/osmesa.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>

namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

namespace tigerlod::simplify {

void SimplifyStage::add_args(ArgSet& args)
{
    m_common.add(args);
    args.group("Simplification");
    config::add_option(args, "simplify.max_reach", &m_max_reach);
    config::add_option(args, "simplify.end_sample", &m_end_sample);
    config::add_option(args, "simplify.point_constraints", &m_no_point_constraints);
    config::add_option(args, "simplify.points", &m_points);
    args.add("lazy", &m_lazy, "the default, said explicitly: see --exhaustive");
    config::add_option(args, "simplify.lazy", &m_exhaustive);
    config::add_option(args, "simplify.shortcut_test", &m_shortcut_test);
    config::add_option(args, "simplify.compliance", &m_compliance);
    config::add_option(args, "simplify.gl", &m_gl);
    config::add_option(args, "simplify.window_pixels", &m_window_pixels);
    args.add("colors", &m_colors, "use the tiles and classes tigerlod-color wrote to DIR instead of computing them",
             "DIR");
}

void SimplifyStage::initialize()
{
    m_common.initialize(name);
    auto& o = m_common.options;
    o.max_reach = static_cast<uint32_t>(m_max_reach);
    o.end_sample = static_cast<uint32_t>(m_end_sample);
    o.point_constraints = !m_no_point_constraints;
    if (m_lazy && m_exhaustive) {
        throw usage_error("simplify: options '--lazy' and '--exhaustive' exclude each other");
    }
    o.lazy = !m_exhaustive;
    if (m_shortcut_test == "exact" && !m_colors.empty()) {
        throw usage_error("simplify: '--colors' gives the eps-Voronoi test its classes, and '--shortcut-test exact' "
                          "makes no such test");
    }
}

std::vector<std::string> SimplifyStage::config_args(const fs::path& file) const
{
    return config::stage_args(file, name);
}

std::vector<std::string> SimplifyStage::versions() const
{
    return {std::string("OSMesa API ") + std::to_string(OSMESA_MAJOR_VERSION) + "." +
                std::to_string(OSMESA_MINOR_VERSION) + " (EGL with --gl egl)",
            std::string("GeographicLib ") + GEOGRAPHICLIB_VERSION_STRING, chains::format_version_text()};
}

std::string SimplifyStage::help_notes() const
{
    return "Outputs:\n"
           "  OUTPUT/eps-<E>m/<level>/<partition>.tlc  the owned chains simplified at tolerance E (chain store 1.1)\n"
           "  OUTPUT/simplify-report.json              per tolerance: vertices, candidates, bans, repairs, seconds\n"
           "  OUTPUT/manifest.json                     inputs' manifest digests; the options and user points used\n"
           "Exit codes: 0 done; 1 bad input data (corrupt store, a tile past 255 classes, bad points file);\n"
           "  2 usage error; 3 environment (no OpenGL context, cannot write).\n";
}

int SimplifyStage::run(const StageContext& ctx)
{
    auto& o = m_common.options;
    // --points is read whole before the output is made; INPUT and --colors as the stores go.
    const std::vector<fs::path> reads{m_common.input, m_colors};
    refuse_to_replace_inputs(m_common.output, reads);
    const auto all = list_stores(m_common.input, m_common.level);
    const auto stores = m_common.partitions.empty() ? all : select_stores(all, m_common.partitions, m_common.input);
    const Manifest ingest = read_manifest(m_common.input, "ingest");
    std::optional<Manifest> colored;
    if (!m_colors.empty()) {
        colored = read_manifest(m_colors, "color");
        m_common.check_colors(*colored, ingest);
    }
    std::string points_sha256;
    if (!m_points.empty()) {
        o.user_points = read_points(m_points);
        points_sha256 = sha256_file(m_points);
    }
    // --shortcut-test auto: the raster where a GPU draws it, the exact
    // rules elsewhere (the same guarantee; on llvmpipe the raster takes 2-4x
    // their time: BENCHMARKS.md). What ran goes into the manifest and report.
    std::unique_ptr<gl::Context> context;
    m_test = resolve_shortcut_test(context);
    if (m_shortcut_test == "auto") {
        ctx.log.info("simplify: --shortcut-test auto: " + m_test.name + " (" + m_test.why + ")");
    }
    StageOutput out(m_common, reads, name);
    const std::string manifest = manifest_text(manifest_json(ingest, colored, points_sha256));
    if (m_common.finish) {
        for (const auto& p : finish_in_place(out.path(), all, m_common.tolerances, ".tlc")) {
            ctx.log.info("simplify: removed " + p.string() + " (a store or tolerance this run no longer has)");
        }
        out.commit(manifest);
        log_removed_leftovers(ctx.log, out.removed_leftovers());
        std::printf("simplify: %s holds the simplified stores of all %zu stores\n", m_common.output.c_str(),
                    all.size());
        return exit_ok;
    }
    // llvmpipe (Mesa's software rasterizer, behind OSMesa and EGL without a
    // GPU) starts a rasterizer thread per core. When several stores keep
    // every core busy with workers, those threads only add hand-offs: on 2
    // cores, LP_NUM_THREADS=0 took the tract ladder from 41.4 to 32.0 s and
    // the tract level at 1 m from 6.0 to 4.1 s. With one store the GL work is
    // the critical path and the threads pay (contours: 3.8-4.2 s with them,
    // 5.2-5.3 s without). So with more than one store and a worker per core,
    // llvmpipe draws on the GL thread itself, unless the user set LP_NUM_THREADS.
    // Results do not depend on it (the same pixels either way).
    const bool raster_test = m_test.name == "voronoi";
    const bool llvmpipe_inline = raster_test && stores.size() > 1 && o.threads >= std::thread::hardware_concurrency() &&
                                 std::getenv("LP_NUM_THREADS") == nullptr && !context;
    if (llvmpipe_inline) {
        ::setenv("LP_NUM_THREADS", "0", 0);
    }
    // The exact rules draw nothing: no OpenGL context is made.
    std::optional<Raster> raster;
    std::string gl_name = m_shortcut_test == "auto" ? "none (--shortcut-test auto took exact: " + m_test.why + ")"
                                                    : "none (--shortcut-test exact)";
    if (raster_test) {
        if (!context) {
            std::string why;
            context = m_gl == "auto" ? gl::Context::create_auto(why) : gl::Context::create(*gl::parse_backend(m_gl));
            if (!why.empty()) {
                ctx.log.info("simplify: --gl auto: " + why);
            }
        }
        RasterOptions ropt;
        ropt.metric = o.metric;
        ropt.compliance = m_compliance == "ssbo" ? Compliance::ssbo : Compliance::readback;
        ropt.window_pixels = static_cast<uint32_t>(m_window_pixels);
        ropt.max_tile_pixels = o.color.tile_pixels;
        raster.emplace(*context, ropt);
        gl_name = context->describe();
    }
    ctx.log.info("simplify: " + std::to_string(stores.size()) + " stores, " + gl_name +
                 (llvmpipe_inline ? " (LP_NUM_THREADS=0: every core has a worker)" : ""));

    const auto t_start = std::chrono::steady_clock::now();
    const auto totals = simplify_stores(stores, out, raster ? &*raster : nullptr, llvmpipe_inline, ctx);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
    out.write_report(report_json(stores.size(), gl_name, totals, seconds).dump(2) + "\n");
    out.commit(manifest);
    log_removed_leftovers(ctx.log, out.removed_leftovers());
    print_summary(stores.size(), gl_name, totals, seconds);
    return exit_ok;
}

SimplifyStage::ShortcutTest SimplifyStage::resolve_shortcut_test(std::unique_ptr<gl::Context>& gpu) const
{
    if (m_shortcut_test != "auto") {
        return {m_shortcut_test, "given"};
    }
    if (!m_colors.empty()) {
        return {"voronoi", "--colors gives the raster its classes"};
    }
    std::string why;
    gpu = gl::Context::create_gpu(why);
    if (gpu) {
        return {"voronoi", why + ": the eps-Voronoi raster on it"};
    }
    return {"exact", why + ": the exact rules on the CPU, where the raster would run on llvmpipe"};
}

std::vector<ToleranceStats> SimplifyStage::simplify_one(const StoreFile& sf, const SimplifyOptions& so, Raster* raster,
                                                        const StageOutput& out) const
{
    std::vector<ToleranceStats> stats(m_common.tolerances.size());
    const auto store = chains::read(sf.path);
    check_store(store, sf);
    check_ladder(store, sf, m_common.tolerances, so);
    if (so.point_constraints) {
        if (const auto fault = partition_contract_fault(store)) {
            throw input_error(sf.path.string() + ": " + *fault);
        }
    }
    // Every tolerance of the store in one go (simplify_ladder shares work
    // between them); each result is written as it comes.
    const auto& tolerances = m_common.tolerances;
    ColorResult given;
    auto colors = [&](size_t ti) -> const ColorResult* {
        if (m_colors.empty()) {
            return nullptr;
        }
        const double eps_m = tolerances[ti];
        given = colors_from_json(fs::path(m_colors) / tolerance_dir(eps_m) / sf.level / (sf.partition + ".colors.json"),
                                 store, eps_m, so.metric, tile_pixel(chain_tolerances(store, eps_m, so), so.color));
        return &given;
    };
    size_t at = 0; // the tolerance being simplified, for the message of a failure
    auto write = [&](size_t ti, const chains::ChainStore& result) {
        out.write(fs::path(tolerance_dir(tolerances[ti])) / sf.level / (sf.partition + ".tlc"), chains::encode(result));
        at = ti + 1;
    };
    try {
        simplify_ladder(store, tolerances, so, raster, colors, stats, write);
    } catch (const input_error& e) {
        throw input_error(sf.path.string() + " at eps " +
                          std::to_string(tolerances[std::min(at, tolerances.size() - 1)]) + " m: " + e.what());
    }
    return stats;
}

std::vector<ToleranceStats> SimplifyStage::simplify_stores(const std::vector<StoreFile>& stores, const StageOutput& out,
                                                           Raster* raster, bool llvmpipe_inline,
                                                           const StageContext& ctx) const
{
    const auto& o = m_common.options;
    // Several stores at once, each on one worker with its share of the
    // threads; the GL context stays on this thread, which runs the workers'
    // raster batches one at a time (SerialQueue). Each store's result depends on
    // nothing else, and the totals are summed in store order afterwards.
    // A worker waits while the GL thread draws its tiles; with llvmpipe
    // drawing on that thread, one worker more than the threads keeps the
    // cores busy meanwhile (tract level at 16 m on 2 cores: 3.04-3.09 s with
    // two workers, 2.75-2.83 s with three, 2.76-2.87 s with four).
    const unsigned want = o.threads + (llvmpipe_inline ? 1U : 0U);
    const auto workers = static_cast<unsigned>(std::max<size_t>(1, std::min<size_t>(want, stores.size())));
    SimplifyOptions per_store = o;
    per_store.threads = std::max(1U, o.threads / workers);
    SerialQueue gl_queue;
    per_store.gl_thread = [&gl_queue](const std::function<void()>& work) { gl_queue.run(work); };
    std::vector<std::vector<ToleranceStats>> per_store_stats(stores.size());
    std::mutex log_mutex;
    Progress progress(ctx.progress, "simplify", stores.size(), "stores", "vertices");
    // Items after a failed one are skipped; every earlier one still runs, so
    // the error reported is the lowest store's, whatever the threads.
    std::atomic<size_t> first_failed{SIZE_MAX};
    std::exception_ptr failure;
    std::thread driver([&] {
        try {
            parallel_each(stores.size(), workers, [&](size_t si) {
                if (si > first_failed.load()) {
                    return;
                }
                try {
                    per_store_stats[si] = simplify_one(stores[si], per_store, raster, out);
                } catch (...) {
                    for (size_t f = first_failed.load(); si < f && !first_failed.compare_exchange_weak(f, si);) {
                    }
                    throw;
                }
                progress.advance(per_store_stats[si].empty() ? 0 : per_store_stats[si].front().input_vertices);
                std::lock_guard lock(log_mutex);
                ctx.log.info("simplify: " + stores[si].level + "/" + stores[si].partition + " done");
            });
        } catch (...) {
            failure = std::current_exception();
        }
        gl_queue.close();
    });
    gl_queue.serve();
    driver.join();
    if (failure) {
        std::rethrow_exception(failure);
    }
    std::vector<ToleranceStats> totals(m_common.tolerances.size());
    for (const auto& list : per_store_stats) {
        for (size_t ti = 0; ti < list.size(); ++ti) {
            totals[ti].add(list[ti]);
            totals[ti].eps_m = m_common.tolerances[ti];
        }
    }
    return totals;
}

json SimplifyStage::report_json(size_t stores, const std::string& gl, const std::vector<ToleranceStats>& totals,
                                double seconds) const
{
    const auto& o = m_common.options;
    json report;
    report["schema"] = "tigerlod.simplify-report/1";
    report["input"] = m_common.input;
    report["stores"] = stores;
    report["gl"] = gl;
    report["options"] = {{"metric", metric_name(o.metric)},
                         {"projection_scale", o.projection_scale},
                         {"class_scale", o.class_scale},
                         {"max_reach", o.max_reach},
                         {"end_sample", o.end_sample},
                         {"point_constraints", o.point_constraints},
                         {"user_points", o.user_points.size()},
                         {"shortcut_test", m_test.name},
                         {"shortcut_test_choice", m_shortcut_test == "auto" ? "auto: " + m_test.why : "given"},
                         {"lazy", o.lazy},
                         {"compliance", m_compliance},
                         {"pixel_fraction", o.color.pixel_fraction},
                         {"tile_pixels", o.color.tile_pixels},
                         {"window_pixels", m_window_pixels},
                         {"max_classes", o.color.max_classes},
                         {"threads", o.threads}};
    json tols = json::array();
    for (const auto& t : totals) {
        json j;
        j["eps_m"] = t.eps_m;
        j["chains"] = t.chains;
        j["input_vertices"] = t.input_vertices;
        j["output_vertices"] = t.output_vertices;
        j["candidates"] = t.candidates;
        j["drawn_segments"] = t.drawn_segments;
        j["drawn_parts"] = t.drawn_parts;
        j["drawn_pixels"] = std::llround(t.drawn_pixels);
        j["tents_drawn"] = t.tent_segments;
        j["tents_skipped"] = t.tent_segments_skipped;
        j["proved_far"] = t.proved_far;
        j["proved_short"] = t.proved_short;
        j["banned"] = {{"raster", t.banned_raster},
                       {"exact", t.banned_exact},
                       {"region", t.banned_region},
                       {"point_constraints", t.banned_points}};
        j["self_intersection_repairs"] = t.self_intersection_repairs;
        j["orientation_repairs"] = t.orientation_repairs;
        j["input_conflicts"] = t.input_conflicts;
        j["reach_capped_chains"] = t.reach_capped_chains;
        j["rounds"] = t.rounds;
        j["tiles"] = t.tiles;
        j["tile_splits"] = t.splits;
        j["max_classes"] = t.max_classes;
        j["seconds"] = {{"color", t.seconds_color},
                        {"candidates", t.seconds_candidates},
                        {"step1_voronoi", t.seconds_voronoi},
                        {"step2_compliance", t.seconds_compliance},
                        {"step3_constraints", t.seconds_constraints},
                        {"far_rule", t.seconds_far},
                        {"step4_shortest_path", t.seconds_shortest_path},
                        {"exact_check", t.seconds_exact}};
        tols.push_back(std::move(j));
    }
    report["tolerances"] = std::move(tols);
    report["seconds"] = seconds;
    return report;
}

json SimplifyStage::manifest_json(const Manifest& ingest, const std::optional<Manifest>& colored,
                                  const std::string& points_sha256) const
{
    const auto& o = m_common.options;
    json manifest = new_manifest("simplify", versions());
    add_input(manifest, "ingest", ingest);
    if (colored) {
        add_input(manifest, "color", *colored);
    }
    // What verify needs to check the result is here, the user points
    // themselves included: a tree is verified against the contract it was
    // made under, never one retyped by hand.
    json options = m_common.manifest_options();
    json lonlat = json::array();
    for (const auto& p : o.user_points) {
        lonlat.push_back({p.lon, p.lat});
    }
    options["max_reach"] = o.max_reach;
    options["end_sample"] = o.end_sample;
    options["point_constraints"] = o.point_constraints;
    options["points"] = {{"file", m_points}, {"sha256", points_sha256}, {"lonlat", std::move(lonlat)}};
    options["shortcut_test"] = m_test.name;
    options["lazy"] = o.lazy;
    options["compliance"] = m_compliance;
    options["window_pixels"] = m_window_pixels;
    manifest["options"] = std::move(options);
    return manifest;
}

void SimplifyStage::print_summary(size_t stores, const std::string& gl, const std::vector<ToleranceStats>& totals,
                                  double seconds) const
{
    {
        std::printf("simplify: %zu stores in %.2f s on %s\n", stores, seconds, gl.c_str());
        for (const auto& t : totals) {
            std::printf("  eps %g m: %zu -> %zu vertices (%.1f%%), %zu candidates, %zu drawn, banned raster %zu "
                        "exact %zu region %zu points %zu\n",
                        t.eps_m, t.input_vertices, t.output_vertices,
                        t.input_vertices ? 100.0 * double(t.output_vertices) / double(t.input_vertices) : 0.0,
                        t.candidates, t.drawn_segments, t.banned_raster, t.banned_exact, t.banned_region,
                        t.banned_points);
            if (t.reach_capped_chains > 0) {
                std::printf("  eps %g m: %zu chains had more proximate shortcuts than a chain may hold: their reach "
                            "was capped (reach_capped_chains in the report)\n",
                            t.eps_m, t.reach_capped_chains);
            }
        }
        std::printf("outputs in %s\n", m_common.output.c_str());
    }
}

} // namespace tigerlod::simplify
