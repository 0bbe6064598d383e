#include "stages/pack/pack_stage.hpp"

#include "config/config_file.hpp"
#include "config/schema.hpp"
#include "core/fs.hpp"
#include "core/manifest.hpp"
#include "core/partitions.hpp"
#include "core/progress.hpp"
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
#include <iterator>
#include <optional>
#include <sstream>
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
    config::add_option(args, "simplify.tolerances_m", &m_tolerances);
    args.describe_default("tolerances", "SIMPLIFIED's ladder (its manifest), every eps-<E>m folder with --partitions");
    args.group("Partition jobs (the workflow's)");
    args.add("parts", &m_parts,
             "the folder of part files the jobs below share: DIR/plan.json, DIR/<level>/<partition>.tlp", "DIR");
    args.add("plan", &m_plan,
             "write DIR/plan.json from ORIGINAL alone: the stores each store's job reads beside its own (rewritten "
             "only when it changes); OUTPUT is not touched");
    args.add("partitions", &m_partitions,
             "pack these stores' nodes into part files in DIR (OUTPUT not touched): LEVEL/PARTITION, "
             "LEVEL/PREFIX* or LEVEL/*, separated by commas, or @FILE with one a line",
             "LIST");
    args.add("report", &m_report, "with --partitions: write this job's report to FILE", "FILE");
    args.add("finish", &m_finish,
             "after the --partitions jobs: assemble OUTPUT from every store's part, byte for byte the tree a whole "
             "run writes, and remove parts of stores ORIGINAL no longer has");
}

void PackStage::initialize()
{
    refuse_to_replace_inputs(m_output, {m_original, m_simplified});
    const int modes = int(m_plan) + int(!m_partitions.empty()) + int(m_finish);
    if (modes > 1) {
        throw usage_error("pack: options '--plan', '--partitions' and '--finish' exclude each other");
    }
    if (modes == 1 && m_parts.empty()) {
        throw usage_error(std::string("pack: option '") +
                          (m_plan     ? "--plan"
                           : m_finish ? "--finish"
                                      : "--partitions") +
                          "' needs '--parts DIR'");
    }
    if (modes == 0 && !m_parts.empty()) {
        throw usage_error("pack: option '--parts' goes with '--plan', '--partitions' or '--finish'");
    }
    if (!m_report.empty() && m_partitions.empty()) {
        throw usage_error("pack: option '--report' goes with '--partitions' (a whole run writes "
                          "OUTPUT/pack-report.json)");
    }
    if (!m_parts.empty()) {
        refuse_to_replace_inputs(m_parts, {m_original, m_simplified, m_output});
    }
    // What OUTPUT holds is checked under the tree's lock (run): seen before
    // it, a pack holding the tree would look half-written. A file is not a
    // folder to lock.
    std::error_code ec;
    if (fs::exists(m_output, ec) && !fs::is_directory(m_output, ec)) {
        throw usage_error("pack: " + m_output + " exists and is not a Data Tree (a file); pick another OUTPUT");
    }
}

void PackStage::refuse_foreign_output() const
{
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
           "  DIR/plan.json, DIR/<level>/<partition>.tlp   with --parts: the jobs' plan and part files\n"
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

namespace {

/// `--tolerances` (simplify.tolerances_m) as numbers; empty when not given.
std::vector<double> parse_tolerances(const std::string& text)
{
    std::vector<double> out;
    std::stringstream ss(text);
    for (std::string item; std::getline(ss, item, ',');) {
        try {
            size_t used = 0;
            out.push_back(std::stod(item, &used));
            if (used != item.size()) {
                throw std::invalid_argument(item);
            }
        } catch (const std::exception&) {
            throw usage_error("pack: option '--tolerances' has '" + item + "', not a number");
        }
    }
    return out;
}

std::string ladder_text(const std::vector<double>& v)
{
    std::string out;
    for (const double e : v) {
        char buf[32];
        std::snprintf(buf, sizeof buf, "%s%g", out.empty() ? "" : ", ", e);
        out += buf;
    }
    return out.empty() ? std::string("none") : out + " m";
}

} // namespace

int PackStage::run_plan(const StageContext& ctx)
{
    const Manifest ingest = read_manifest(m_original, "ingest");
    const unsigned threads =
        m_threads > 0 ? static_cast<unsigned>(m_threads) : std::max(1U, std::thread::hardware_concurrency());
    // The parts folder alone while its plan changes: partition jobs read
    // the plan and share the folder, a --finish prunes it alone.
    const FolderLock lock(m_parts, "pack");
    PackPlan plan = plan_parts(m_original, threads);
    plan.ingest_sha256 = ingest.sha256;
    const std::string text = plan_json(plan);
    const fs::path path = fs::path(m_parts) / "plan.json";
    std::string old;
    if (std::ifstream in(path, std::ios::binary); in) {
        old.assign(std::istreambuf_iterator<char>(in), {});
    }
    // Rewritten only when it changes: its time says when the plan last did.
    if (old != text) {
        std::error_code ec;
        fs::create_directories(m_parts, ec);
        if (ec) {
            throw environment_error(m_parts + ": cannot create: " + ec.message());
        }
        write_file_atomic(path, text);
    }
    ctx.log.info("pack: the plan of " + std::to_string(plan.reads.size()) + " stores" +
                 (old == text ? ", unchanged" : ""));
    std::printf("pack: plan of %zu stores in %s%s\n", plan.reads.size(), path.c_str(),
                old == text ? " (unchanged)" : "");
    return exit_ok;
}

int PackStage::run_partitions(const StageContext& ctx)
{
    const auto t0 = std::chrono::steady_clock::now();
    const Manifest ingest = read_manifest(m_original, "ingest");
    const auto all = stores_of(m_original);
    const auto chosen = select_partitions(all, m_partitions, m_original);
    std::vector<std::string> stores;
    for (size_t i = 0; i < all.size(); ++i) {
        if (chosen[i]) {
            stores.push_back(all[i].first + "/" + all[i].second);
        }
    }
    const fs::path plan_path = fs::path(m_parts) / "plan.json";
    if (!fs::exists(plan_path)) {
        throw usage_error(plan_path.string() + " is missing: run tigerlod-pack --plan --parts " + m_parts + " first");
    }
    // Shared with the run's other partition jobs; a --plan or a --finish
    // (which prunes parts) waits for them, and they for it.
    const FolderLock lock(m_parts, "pack", FolderLock::Mode::shared);
    std::ifstream in(plan_path, std::ios::binary);
    if (!in) {
        throw usage_error(plan_path.string() + " is missing: run tigerlod-pack --plan --parts " + m_parts + " first");
    }
    const PackPlan plan = plan_from_json(std::string(std::istreambuf_iterator<char>(in), {}), plan_path.string());
    if (plan.ingest_sha256 != ingest.sha256) {
        throw usage_error(plan_path.string() + " is the plan of another tigerlod-ingest output than " + m_original +
                          "'s: run tigerlod-pack --plan again");
    }
    PackOptions options;
    options.draco_speed = m_draco_speed;
    options.threads =
        m_threads > 0 ? static_cast<unsigned>(m_threads) : std::max(1U, std::thread::hardware_concurrency());
    options.lods = parse_tolerances(m_tolerances);
    Progress progress(ctx.progress, "pack", stores.size(), "stores");
    options.on_level = [&](size_t done) {
        for (size_t i = 0; i < done; ++i) {
            progress.advance();
        }
    };
    std::map<std::string, uint32_t> content;
    const auto totals = write_parts(m_original, m_simplified, stores, plan, m_parts, options, &content);
    ctx.log.info("pack: " + std::to_string(stores.size()) + " parts written in " +
                 std::to_string(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()) + " s");
    if (!m_report.empty()) {
        json report;
        report["schema"] = "tigerlod.pack-share/1";
        report["stores"] = stores.size();
        json lods = json::array();
        for (const auto& l : totals) {
            lods.push_back({{"eps_m", l.eps_m}, {"vertices", l.vertices}, {"payload_bytes", l.payload_bytes}});
        }
        report["lods"] = std::move(lods);
        // Each part's content, and no seconds (the job's benchmark file has
        // them): the report changes exactly when a part does, so the engine,
        // which compares checksums, reruns the verify jobs that read a
        // changed node and none after a job that wrote the same parts.
        report["parts"] = content;
        write_file_atomic(m_report, report.dump(2) + "\n");
    }
    std::printf("pack: %zu parts in %s\n", stores.size(), m_parts.c_str());
    return exit_ok;
}

int PackStage::run(const StageContext& ctx)
{
    if (m_plan) {
        return run_plan(ctx);
    }
    if (!m_partitions.empty()) {
        return run_partitions(ctx);
    }
    const auto t0 = std::chrono::steady_clock::now();
    // One pack at a time on a tree: two interleaved would each remove the
    // tiles the other's skeleton names.
    const FolderLock lock(m_output, "pack");
    refuse_foreign_output();
    // A --finish reads every part and prunes the folder: alone on it, after
    // the partition jobs (which share it) are done. (Without the folder
    // assemble_parts says what is missing.)
    std::optional<FolderLock> parts_lock;
    if (m_finish && fs::is_directory(m_parts)) {
        parts_lock.emplace(m_parts, "pack");
    }
    // A tree this run began (no OUTPUT, or an empty folder, when the lock
    // was taken) is removed whole if the run fails before its report is
    // written (a full disk): nothing half-written is left. An existing tree
    // keeps its old tiles (write_tree removes only the tiles it added).
    struct FreshTree {
        fs::path path;
        bool fresh;
        bool done = false;
        ~FreshTree()
        {
            if (fresh && !done) {
                std::error_code ec;
                fs::remove_all(path, ec);
            }
        }
    } fresh_tree{m_output, lock.was_empty()};
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
    std::sort(ladder.begin(), ladder.end());
    if (const auto asked = parse_tolerances(m_tolerances); !asked.empty() && asked != ladder) {
        throw usage_error("pack: " + m_simplified + " was simplified at " + ladder_text(ladder) +
                          ", the tolerances given (--tolerances, simplify.tolerances_m) are " + ladder_text(asked) +
                          "; re-run tigerlod-simplify with them first");
    }
    // Every eps folder, checked against the ladder (simplify --finish removed
    // those of other tolerances; one lost since would give an LOD fewer).
    // Progress by stores: packed (a whole run), or their parts assembled (--finish).
    Progress progress(ctx.progress, "pack", stores_of(m_original).size(), "stores");
    options.on_level = [&](size_t stores) {
        for (size_t i = 0; i < stores; ++i) {
            progress.advance();
        }
    };
    const PackedTree tree = m_finish ? assemble_parts(m_original, m_simplified, m_parts, options)
                                     : build_tree(m_original, m_simplified, options);
    const std::vector<double> found(tree.skeleton.lod_eps_m.begin() + 1, tree.skeleton.lod_eps_m.end());
    if (found != ladder) {
        throw input_error(m_simplified + ": its manifest lists the tolerances " + ladder_text(ladder) +
                          ", but the eps-<E>m folders hold " + ladder_text(found) +
                          "; re-run tigerlod-simplify rather than pack a partial ladder");
    }
    if (m_finish) {
        for (const auto& p : prune_parts(m_original, m_parts)) {
            ctx.log.info("pack: removed " + p.string() + " (a store this run no longer has, or a dead run's)");
        }
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
    report["unit_table_bytes"] = tree.unit_bytes;
    report["skeleton_bytes"] = ws.skeleton_bytes;
    report["tree_bytes"] = ws.tree_bytes;
    report["skeleton_fraction"] = ws.tree_bytes ? double(ws.skeleton_bytes) / double(ws.tree_bytes) : 0.0;
    report["seconds"] = seconds;
    write_file_atomic(fs::path(m_output) / "pack-report.json", report.dump(2) + "\n");
    fresh_tree.done = true;

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
