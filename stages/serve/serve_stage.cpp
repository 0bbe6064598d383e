#include "stages/serve/serve_stage.hpp"

#include "stages/serve/site.hpp"

#include <httplib.h>

#include <cstdio>
#include <filesystem>

namespace fs = std::filesystem;

namespace tigerlod::serve {

void ServeStage::add_args(ArgSet& args)
{
    args.positional("TREE", &m_tree, "a Data Tree folder");
    args.group("Server");
    args.add("host", &m_host, "the address to listen on (default 127.0.0.1: this machine only)", "ADDR");
    args.add("port", &m_port, "the port (default 8765; 0: a free one, printed)", "N");
    args.add("verify", &m_verify, "a verify-report.json to serve at /api/verify (the viewer's violations layer)",
             "REPORT");
    args.add("viewer", &m_viewer, "the viewer's folder (default: the one of this build's source)", "DIR");
    args.add("cache-mb", &m_cache_mb, "the most the payload cache holds, MiB (default 64)", "MB");
}

void ServeStage::initialize()
{
    if (m_port < 0 || m_port > 65535) {
        throw usage_error("serve: option '--port' must be in 0..65535");
    }
    if (!(m_cache_mb >= 0) || m_cache_mb > 1 << 20) {
        throw usage_error("serve: option '--cache-mb' must be in 0..1048576");
    }
}

std::vector<std::string> ServeStage::versions() const
{
    return {std::string("cpp-httplib ") + CPPHTTPLIB_VERSION, datatree::format_version_text()};
}

std::string ServeStage::help_notes() const
{
    return "Prints 'serving http://HOST:PORT/' once it listens, then serves until stopped (docs/viewer.md).\n"
           "Exit codes: 0 stopped; 1 the tree is not valid; 2 usage error (TREE is not a Data Tree, --verify names no "
           "file);\n"
           "  3 environment (cannot listen on the port, cannot read the viewer folder).\n";
}

int ServeStage::run(const StageContext& ctx)
{
    std::error_code ec;
    if (!fs::exists(fs::path(m_tree) / "skeleton.tls", ec)) {
        throw usage_error("serve: " + m_tree + ": no skeleton.tls, not a Data Tree");
    }
    if (!m_verify.empty() && !fs::is_regular_file(m_verify, ec)) {
        throw usage_error("serve: --verify " + m_verify + ": no such file");
    }
    std::string error;
    const auto tree = reader::Tree::open(m_tree, error);
    if (!tree) {
        throw format_error(error);
    }
    SiteOptions options;
    options.viewer = m_viewer.empty() ? fs::path(TIGERLOD_VIEWER_DIR) : fs::path(m_viewer);
    if (!fs::is_directory(options.viewer, ec)) {
        if (!m_viewer.empty()) {
            throw usage_error("serve: --viewer " + m_viewer + ": no such folder");
        }
        options.viewer.clear(); // an installed binary without its source: the API alone
    }
    options.verify = m_verify;
    options.cache_bytes = static_cast<uint64_t>(m_cache_mb * 1024 * 1024);
    const Site site(tree, options);

    httplib::Server server;
    server.set_payload_max_length(4096);
    auto answer = [&](const httplib::Request& req, httplib::Response& res) {
        Request r;
        r.method = req.method;
        r.path = req.path;
        for (const auto& [k, v] : req.params) {
            r.query.emplace(k, v);
        }
        r.if_none_match = req.get_header_value("If-None-Match");
        Response out = site.handle(r);
        for (const auto& [k, v] : out.headers) {
            res.set_header(k, v);
        }
        res.set_content(std::move(out.body), out.content_type);
        // Ranges (206, 416) are the transport's, on this body, for a 200.
        if (out.status != 200) {
            res.status = out.status;
        }
    };
    server.Get(".*", answer);
    // Other methods reach the site too, which answers 405.
    server.Post(".*", [&](const httplib::Request& req, httplib::Response& res) { answer(req, res); });
    server.Put(".*", [&](const httplib::Request& req, httplib::Response& res) { answer(req, res); });
    server.Delete(".*", [&](const httplib::Request& req, httplib::Response& res) { answer(req, res); });
    server.Patch(".*", [&](const httplib::Request& req, httplib::Response& res) { answer(req, res); });
    int port = m_port;
    if (port == 0) {
        port = server.bind_to_any_port(m_host);
    } else if (!server.bind_to_port(m_host, port)) {
        port = -1;
    }
    if (port < 0) {
        throw environment_error("serve: cannot listen on " + m_host + ":" + std::to_string(m_port));
    }
    ctx.log.info("serve: " + m_tree + ", " + std::to_string(tree->skeleton().nodes.size()) + " nodes, viewer " +
                 (options.viewer.empty() ? std::string("none") : options.viewer.string()));
    std::printf("serving http://%s:%d/\n", m_host.c_str(), port);
    std::fflush(stdout);
    if (!server.listen_after_bind()) {
        throw environment_error("serve: the server stopped listening on " + m_host + ":" + std::to_string(port));
    }
    return exit_ok;
}

} // namespace tigerlod::serve
