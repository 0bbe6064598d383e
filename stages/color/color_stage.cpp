#include "stages/color/color_stage.hpp"

#include "config/config_file.hpp"
#include "core/fs.hpp"
#include "formats/chains/chain_store.hpp"
#include "simplification/color_io.hpp"
#include "simplification/stage_output.hpp"

#include <GeographicLib/Config.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdio>

namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

namespace tigerlod::color {

std::vector<std::string> ColorStage::config_args(const fs::path& file) const
{
    return config::stage_args(file, name);
}

std::vector<std::string> ColorStage::versions() const
{
    // The colouring is on the CPU: no OpenGL. GeographicLib gives the projection scale of eps.
    return {std::string("GeographicLib ") + GEOGRAPHICLIB_VERSION_STRING, chains::format_version_text()};
}

std::string ColorStage::help_notes() const
{
    return "Outputs:\n"
           "  OUTPUT/eps-<E>m/<level>/<partition>.colors.json  tiles and the class of each chain per tile\n"
           "  OUTPUT/color-report.json                         per tolerance: tiles, classes (max, mean), splits\n"
           "  OUTPUT/manifest.json                             the input's manifest digest and the options used\n"
           "tigerlod-simplify --colors OUTPUT uses them; it needs the same tolerance, metric and pixel options.\n"
           "Exit codes: 0 done; 1 bad input data (corrupt store, a tile past the class limit even at the\n"
           "  smallest tile); 2 usage error; 3 environment (cannot write).\n";
}

int ColorStage::run(const StageContext& ctx)
{
    refuse_to_replace_inputs(m_common.output, {m_common.input});
    const auto all = simplify::list_stores(m_common.input, m_common.level);
    const auto stores =
        m_common.partitions.empty() ? all : simplify::select_stores(all, m_common.partitions, m_common.input);
    const Manifest ingest = read_manifest(m_common.input, "ingest");
    simplify::StageOutput out(m_common, {m_common.input}, name);
    json manifest = new_manifest("color", versions());
    add_input(manifest, "ingest", ingest);
    manifest["options"] = m_common.manifest_options();
    if (m_common.finish) {
        for (const auto& p : simplify::finish_in_place(out.path(), all, m_common.tolerances, ".colors.json")) {
            ctx.log.info("color: removed " + p.string() + " (a store or tolerance this run no longer has)");
        }
        out.commit(manifest_text(manifest));
        log_removed_leftovers(ctx.log, out.removed_leftovers());
        std::printf("color: %s holds the colours of all %zu stores\n", m_common.output.c_str(), all.size());
        return exit_ok;
    }
    struct Total {
        size_t tiles = 0, splits = 0, conflict_edges = 0, stores = 0;
        uint32_t max_classes = 0;
        double class_sum = 0;
    };
    std::vector<Total> totals(m_common.tolerances.size());
    Progress progress(ctx.progress, "color", stores.size(), "stores");
    for (const auto& sf : stores) {
        const auto store = chains::read(sf.path);
        simplify::check_store(store, sf);
        simplify::check_ladder(store, sf, m_common.tolerances, m_common.options);
        for (size_t ti = 0; ti < m_common.tolerances.size(); ++ti) {
            const double eps_m = m_common.tolerances[ti];
            simplify::ColorResult r;
            try {
                r = simplify::color_store(store, eps_m, m_common.options);
            } catch (const input_error& e) {
                throw input_error(sf.path.string() + " at eps " + std::to_string(eps_m) + " m: " + e.what());
            }
            out.write(fs::path(simplify::tolerance_dir(eps_m)) / sf.level / (sf.partition + ".colors.json"),
                      simplify::colors_to_json(store, eps_m, m_common.options.metric, r));
            auto& t = totals[ti];
            ++t.stores;
            t.tiles += r.tiles.size();
            t.splits += r.splits;
            t.conflict_edges += r.conflict_edges;
            t.max_classes = std::max(t.max_classes, r.max_classes_used);
            t.class_sum += r.mean_classes * double(r.tiles.size());
        }
        ctx.log.info("color: " + sf.level + "/" + sf.partition + " done");
        progress.advance();
    }
    json report;
    report["schema"] = "tigerlod.color-report/1";
    report["input"] = m_common.input;
    report["metric"] = metric_name(m_common.options.metric);
    report["pixel_fraction"] = m_common.options.color.pixel_fraction;
    report["tile_pixels"] = m_common.options.color.tile_pixels;
    report["max_classes_allowed"] = m_common.options.color.max_classes;
    json tols = json::array();
    for (size_t ti = 0; ti < totals.size(); ++ti) {
        const auto& t = totals[ti];
        tols.push_back({{"eps_m", m_common.tolerances[ti]},
                        {"stores", t.stores},
                        {"tiles", t.tiles},
                        {"splits", t.splits},
                        {"conflict_edges", t.conflict_edges},
                        {"classes_max", t.max_classes},
                        {"classes_mean", t.tiles ? t.class_sum / double(t.tiles) : 0.0}});
    }
    report["tolerances"] = std::move(tols);
    out.write_report(report.dump(2) + "\n");
    out.commit(manifest_text(manifest));
    log_removed_leftovers(ctx.log, out.removed_leftovers());
    std::printf("color: %zu stores\n", stores.size());
    for (size_t ti = 0; ti < totals.size(); ++ti) {
        std::printf("  eps %g m: %zu tiles, %zu splits, classes max %u\n", m_common.tolerances[ti], totals[ti].tiles,
                    totals[ti].splits, totals[ti].max_classes);
    }
    std::printf("outputs in %s\n", m_common.output.c_str());
    return exit_ok;
}

} // namespace tigerlod::color
