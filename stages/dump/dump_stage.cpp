#include "stages/dump/dump_stage.hpp"

#include "formats/chains/chain_store.hpp"
#include "reader/tree_view.hpp"

#include <filesystem>
#include <iostream>

namespace fs = std::filesystem;

namespace tigerlod::dump {

void DumpStage::add_args(ArgSet& args)
{
    args.positional("INPUT", &m_input, "a chain store (.tlc), or a Data Tree folder or its skeleton.tls");
    args.group("Data Tree");
    args.add("node", &m_node, "print this node's map (a node index or a unit code; root for the root)", "NODE");
    args.add("lod", &m_lod, "with --node: the LOD, 0 for the original chains", "K");
    args.add("geojson", &m_geojson, "with --node: GeoJSON in lon/lat instead of text");
}

void DumpStage::initialize()
{
    if (m_lod < 0) {
        throw usage_error("dump: option '--lod' must be >= 0");
    }
    if ((m_geojson || m_lod != 0) && m_node.empty()) {
        throw usage_error("dump: '--lod' and '--geojson' need '--node'");
    }
}

std::vector<std::string> DumpStage::versions() const
{
    return {chains::format_version_text(), datatree::format_version_text()};
}

std::string DumpStage::help_notes() const
{
    return "Exit codes: 0 done; 1 the file is not valid (the message names the file, the node and the fault);\n"
           "  2 usage error (including an unknown node, and an INPUT that does not exist or a folder\n"
           "  that is not a Data Tree); 3 environment (cannot read).\n";
}

int DumpStage::run(const StageContext&)
{
    const fs::path in(m_input);
    std::error_code ec;
    if (!fs::exists(in, ec)) {
        throw usage_error("dump: " + m_input + ": no such file or folder");
    }
    if (fs::is_directory(in, ec) && !fs::exists(in / "skeleton.tls", ec)) {
        throw usage_error("dump: " + m_input + ": a folder without skeleton.tls, not a Data Tree");
    }
    const bool tree = fs::is_directory(in) || in.filename() == "skeleton.tls";
    if (!tree) {
        if (!m_node.empty()) {
            throw usage_error("dump: '--node' needs a Data Tree, " + m_input + " is a file");
        }
        std::cout << chains::to_text(chains::read(in));
        return exit_ok;
    }
    std::string error;
    const auto t = reader::Tree::open(fs::is_directory(in) ? in : in.parent_path(), error);
    if (!t) {
        throw format_error(error);
    }
    if (m_node.empty()) {
        std::cout << view::skeleton_text(*t);
        return exit_ok;
    }
    const auto m = view::read_node(*t, view::find_node(t->skeleton(), m_node), static_cast<uint32_t>(m_lod));
    if (m_geojson) {
        std::cout.flush();
        view::write_node_geojson(*t, m, "/vsistdout/");
    } else {
        std::cout << view::node_text(*t, m);
    }
    return exit_ok;
}

} // namespace tigerlod::dump
