// libFuzzer target: tigerlod-serve's answers (serve::Site, no socket) to any
// request over a synthetic tree. The input is the request: byte 0 picks the
// method, then lines: the path, `key=value` query parameters, and a line
// starting with '"' as If-None-Match. Every answer must be one of the
// statuses the site gives, a 200 for a tile must be that tile's bytes, and
// no answer may hold the contents of the files beside the tree that are
// never to be served (unless the request itself spelled them out).
#include "core/fs.hpp"
#include "stages/serve/site.hpp"
#include "../tests/support/synthetic_tree.hpp"

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>

using namespace tigerlod;
namespace fs = std::filesystem;

namespace {

const std::string secret = "TIGERLOD-FUZZ-SECRET-0123456789";

struct Fixture {
    fs::path dir;
    std::shared_ptr<const reader::Tree> tree;
    std::unique_ptr<serve::Site> site;
    Fixture()
    {
        dir = fs::temp_directory_path() / ("tigerlod-fuzz-serve-" + std::to_string(::getpid()));
        fs::remove_all(dir);
        testing::make_synthetic_tree(2, 1 << 16, 7).write(dir / "tree");
        fs::create_directories(dir / "viewer");
        std::ofstream(dir / "viewer" / "index.html") << "<!doctype html>";
        std::ofstream(dir / "secret.txt") << secret;
        std::ofstream(dir / "tree" / "secret.txt") << secret;
        std::ofstream(dir / "viewer" / ".secret") << secret;
        std::string error;
        tree = reader::Tree::open(dir / "tree", error);
        if (!tree) {
            __builtin_trap();
        }
        serve::SiteOptions o;
        o.viewer = dir / "viewer";
        o.cache_bytes = 4096;
        site = std::make_unique<serve::Site>(tree, o);
    }
    ~Fixture()
    {
        std::error_code ec;
        fs::remove_all(dir, ec);
    }
};

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    static Fixture f;
    if (size == 0) {
        return 0;
    }
    serve::Request r;
    static const char* methods[] = {"GET", "HEAD", "POST", "PUT", "DELETE", "OPTIONS", "get", ""};
    r.method = methods[data[0] % 8];
    const std::string text(reinterpret_cast<const char*>(data + 1), size - 1);
    size_t at = 0;
    bool first = true;
    while (at <= text.size()) {
        const size_t end = std::min(text.find('\n', at), text.size());
        const std::string line = text.substr(at, end - at);
        if (first) {
            r.path = line;
            first = false;
        } else if (!line.empty() && line.front() == '"') {
            r.if_none_match = line;
        } else if (const size_t eq = line.find('='); eq != std::string::npos) {
            r.query[line.substr(0, eq)] = line.substr(eq + 1);
        }
        at = end + 1;
    }
    const serve::Response out = f.site->handle(r);
    switch (out.status) {
    case 200:
    case 304:
    case 400:
    case 404:
    case 405:
    case 500:
        break;
    default:
        __builtin_trap();
    }
    // (An error may name what the request asked for: the secret counts only when the request lacks it.)
    if (out.body.find(secret) != std::string::npos && text.find(secret) == std::string::npos) {
        __builtin_trap();
    }
    if (out.status == 200 && r.path.rfind("/tree/tiles/", 0) == 0) {
        bool named = false;
        for (const auto& t : f.tree->skeleton().tiles) {
            named = named || ("/tree/" + t.file == r.path && read_file(f.dir / "tree" / t.file) == out.body);
        }
        if (!named) {
            __builtin_trap();
        }
    }
    if (f.site->cached_bytes() > 4096) {
        __builtin_trap();
    }
    return 0;
}
