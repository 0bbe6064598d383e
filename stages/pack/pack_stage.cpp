#include "stages/pack/pack_stage.hpp"

#include "config/config_file.hpp"
#include "config/schema.hpp"
#include "core/fs.hpp"
#include "core/manifest.hpp"
#include "formats/chains/chain_store.hpp"
#include "stages/pack/packer.hpp"

#include <draco/core/draco_version.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <thread>

namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

namespace tigerlod::pack {

void PackStage::add_args(ArgSet& args)
{
    args.positional("ORIGINAL", &m_original, "a tigerlod-ingest output folder: LOD 0, the original chains");
    args.positional("SIMPLIFIED", &m_simplified, "a tigerlod-simplify output folder: one LOD per eps-<E>m folder");
    args.positional("OUTPUT", &m_output, "the Data Tree folder, created or updated in place");
    args.group("Packing");
    config::add_option(args, "pack.tile_mb", &m_tile_mb);
    config::add_option(args, "pack.draco_speed", &m_draco_speed);
    config::add_option(args, "pack.threads", &m_threads);
}

void PackStage::initialize()
{
    refuse_to_replace_inputs(m_output, {m_original, m_simplified});
    const fs::path out(m_output);
    std::error_code ec;
    // A Data Tree is updated in place; a folder a killed first pack left
    // (no skeleton yet, only pack's own files) is resumed.
    if (fs::exists(out, ec) &&
        !(fs::is_directory(out, ec) && (fs::exists(out / "skeleton.tls", ec) || is_pack_leftover(out)))) {
        throw usage_error("pack: " + m_output +
                          " exists and is not a Data Tree (no skeleton.tls, and files pack does not write); "
                          "pick another OUTPUT");
    }
}

std::string PackStage::help_notes() const
{
    return "Outputs:\n"
           "  OUTPUT/skeleton.tls        the skeleton (formats/datatree/SPEC.md)\n"
           "  OUTPUT/tiles/*.tlt         tile files, named by their content\n"
           "  OUTPUT/pack-report.json    nodes, tiles, bytes and vertices per LOD, skeleton fraction\n"
           "  OUTPUT/manifest.json       inputs' manifest digests, options, and simplify's options (verify's "
           "contract)\n"
           "Exit codes: 0 done; 1 bad input data (corrupt or inconsistent stores); 2 usage error;\n"
           "  3 environment (cannot read or write).\n";
}

std::vector<std::string> PackStage::config_args(const fs::path& file) const
{
    return config::stage_args(file, name);
}

std::vector<std::string> PackStage::versions() const
{
    return {std::string("Draco ") + draco::kDracoVersion, chains::format_version_text(),
            datatree::format_version_text()};
}

int PackStage::run(const StageContext& ctx)
{
    const auto t0 = std::chrono::steady_clock::now();
    PackOptions options;
    options.tile_bytes = static_cast<uint64_t>(m_tile_mb * 1024 * 1024);
    options.draco_speed = m_draco_speed;
    options.threads =
        m_threads > 0 ? static_cast<unsigned>(m_threads) : std::max(1U, std::thread::hardware_concurrency());
    // The manifests first: simplify's output must have been made from this
    // ingest output, and its ladder is the one simplify finished (a tolerance
    // folder lost since would give a tree with an LOD fewer).
    const Manifest ingest = read_manifest(m_original, "ingest");
    const Manifest simplified = read_manifest(m_simplified, "simplify");
    require_made_from(simplified, "ingest", ingest);
    std::vector<double> ladder;
    try {
        ladder = simplified.option("tolerances_m").get<std::vector<double>>();
    } catch (const json::exception& e) {
        throw input_error((fs::path(m_simplified) / "manifest.json").string() + ": tolerances_m: " + e.what());
    }
    const PackedTree tree = build_tree(m_original, m_simplified, options);
    std::vector<double> found(tree.skeleton.lod_eps_m.begin() + 1, tree.skeleton.lod_eps_m.end());
    std::sort(ladder.begin(), ladder.end());
    if (found != ladder) {
        auto list = [](const std::vector<double>& v) {
            std::string out;
            for (const double e : v) {
                char buf[32];
                std::snprintf(buf, sizeof buf, "%s%g", out.empty() ? "" : ", ", e);
                out += buf;
            }
            return out.empty() ? std::string("none") : out + " m";
        };
        throw input_error(m_simplified + ": its manifest lists the tolerances " + list(ladder) +
                          ", but the eps-<E>m folders hold " + list(found) +
                          "; re-run tigerlod-simplify rather than pack a partial ladder");
    }
    ctx.log.info("pack: built " + std::to_string(tree.skeleton.nodes.size()) + " nodes in " +
                 std::to_string(tree.skeleton.tiles.size()) + " tiles");
    // The tree's manifest carries simplify's tolerance contract, so that
    // tigerlod-verify checks the tree against the options it was made with.
    json manifest = new_manifest("pack", versions());
    add_input(manifest, "ingest", ingest);
    add_input(manifest, "simplify", simplified);
    manifest["options"] = {{"tile_mb", m_tile_mb}, {"draco_speed", m_draco_speed}};
    manifest["simplify"] = simplified.doc.at("options");
    const WriteStats ws = write_tree(m_output, tree, manifest_text(manifest));
    log_removed_leftovers(ctx.log, ws.leftovers_removed);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

    json report;
    report["schema"] = "tigerlod.pack-report/1";
    report["original"] = m_original;
    report["simplified"] = m_simplified;
    report["nodes"] = tree.skeleton.nodes.size();
    json levels = json::array();
    for (uint32_t l = 0; l < tree.skeleton.level_names.size(); ++l) {
        size_t n = 0;
        for (const auto& node : tree.skeleton.nodes) {
            n += node.level == l;
        }
        levels.push_back({{"map_level", tree.skeleton.level_names[l]}, {"nodes", n}});
    }
    report["levels"] = std::move(levels);
    report["tiles"] = {{"count", tree.skeleton.tiles.size()},
                       {"written", ws.tiles_written},
                       {"kept", ws.tiles_kept},
                       {"repaired", ws.tiles_repaired},
                       {"removed", ws.tiles_removed}};
    json lods = json::array();
    uint64_t vertices = 0, bytes = 0;
    for (const auto& l : tree.lods) {
        lods.push_back({{"eps_m", l.eps_m},
                        {"vertices", l.vertices},
                        {"payload_bytes", l.payload_bytes},
                        {"bytes_per_vertex", l.vertices ? double(l.payload_bytes) / double(l.vertices) : 0.0},
                        {"raw_int32_bytes", l.raw_bytes}});
        vertices += l.vertices;
        bytes += l.payload_bytes;
    }
    report["lods"] = std::move(lods);
    report["geometry_bytes_per_vertex"] = vertices ? double(bytes) / double(vertices) : 0.0;
    report["chain_table_bytes"] = tree.table_bytes;
    report["skeleton_bytes"] = ws.skeleton_bytes;
    report["tree_bytes"] = ws.tree_bytes;
    report["skeleton_fraction"] = ws.tree_bytes ? double(ws.skeleton_bytes) / double(ws.tree_bytes) : 0.0;
    report["seconds"] = seconds;
    write_file_atomic(fs::path(m_output) / "pack-report.json", report.dump(2) + "\n");

    std::printf("pack: %zu nodes, %zu tiles (%zu written, %zu kept, %zu repaired, %zu removed), %llu bytes\n",
                tree.skeleton.nodes.size(), tree.skeleton.tiles.size(), ws.tiles_written, ws.tiles_kept,
                ws.tiles_repaired, ws.tiles_removed, static_cast<unsigned long long>(ws.tree_bytes));
    for (const auto& l : tree.lods) {
        std::printf("  LOD eps %g m: %llu vertices, %.2f bytes/vertex\n", l.eps_m,
                    static_cast<unsigned long long>(l.vertices),
                    l.vertices ? double(l.payload_bytes) / double(l.vertices) : 0.0);
    }
    std::printf("  skeleton %llu bytes (%.3f%% of the tree)\noutputs in %s\n",
                static_cast<unsigned long long>(ws.skeleton_bytes),
                ws.tree_bytes ? 100.0 * double(ws.skeleton_bytes) / double(ws.tree_bytes) : 0.0, m_output.c_str());
    return exit_ok;
}

} // namespace tigerlod::pack
