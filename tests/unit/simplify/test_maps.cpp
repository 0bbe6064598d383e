// The numbered map cases of tests/maps/ (README.md there): hand-made maps as
// text, each with the chains tigerlod-simplify must give, compared exactly,
// and no two output chains meeting where the input's did not. TIGERLOD_UPDATE_GOLDEN=1 rewrites each
// case's expected.txt from what the code gives (review it with git diff).

#include "../../support/simplify_fixture.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace fs = std::filesystem;
using namespace tigerlod;
using namespace tigerlod::simplify;
using namespace tigerlod::simplify::testing;

namespace {

struct MapCase {
    fs::path dir;
    double eps_m = 0;
    SimplifyOptions options = plain();
    MapBuilder map;
};

/// "LINESTRING (0 0, 500 90)" or "POINT (5 6)": the points, integers (grid units).
Pts parse_wkt(const std::string& wkt, const std::string& where)
{
    const auto open = wkt.find('('), close = wkt.rfind(')');
    if (open == std::string::npos || close == std::string::npos || close < open) {
        throw std::runtime_error(where + ": not WKT: " + wkt);
    }
    Pts pts;
    std::stringstream list(wkt.substr(open + 1, close - open - 1));
    for (std::string xy; std::getline(list, xy, ',');) {
        std::istringstream in(xy);
        GridPoint p;
        if (!(in >> p.x >> p.y)) {
            throw std::runtime_error(where + ": not a point: '" + xy + "'");
        }
        pts.push_back(p);
    }
    return pts;
}

std::string wkt_of(const Pts& pts)
{
    std::string s = "LINESTRING (";
    for (size_t i = 0; i < pts.size(); ++i) {
        s += (i ? ", " : "") + std::to_string(pts[i].x) + " " + std::to_string(pts[i].y);
    }
    return s + ")";
}

/// The lines of a file without comments (from '#') and blank lines.
std::vector<std::string> content_lines(const fs::path& file)
{
    std::ifstream in(file);
    std::vector<std::string> out;
    for (std::string line; std::getline(in, line);) {
        line = line.substr(0, line.find('#'));
        line.erase(line.find_last_not_of(" \t\r") + 1);
        if (!line.empty()) {
            out.push_back(line);
        }
    }
    return out;
}

MapCase read_case(const fs::path& dir)
{
    MapCase c;
    c.dir = dir;
    size_t n = 0;
    for (const std::string& line : content_lines(dir / "case.txt")) {
        const std::string where = (dir / "case.txt").string() + ": '" + line + "'";
        std::istringstream in(line);
        std::string word;
        in >> word;
        if (word == "eps") {
            in >> c.eps_m;
        } else if (word == "metric") {
            std::string m;
            in >> m;
            c.options = plain(*parse_metric(m));
        } else if (word == "class_scale") {
            std::string cls;
            double f = 0;
            in >> cls >> f;
            c.options.class_scale[cls] = f;
        } else if (word == "point_constraints") {
            std::string v;
            in >> v;
            c.options.point_constraints = v != "off";
        } else if (word == "chain" || word == "halo") {
            uint64_t id = 0;
            std::string left, right, cls;
            in >> id >> left >> right;
            std::string rest;
            std::getline(in, rest);
            if (const auto eq = rest.find("class="); eq != std::string::npos) {
                const auto end = rest.find(' ', eq);
                cls = rest.substr(eq + 6, end - eq - 6);
            }
            c.map.chain(id, parse_wkt(rest, where), left == "-" ? "" : left, right == "-" ? "" : right, cls,
                        word == "halo" ? chains::chain_halo : 0U);
        } else if (word == "point") {
            std::string unit, rest;
            in >> unit;
            std::getline(in, rest);
            c.map.point(unit, parse_wkt(rest, where).at(0));
        } else {
            throw std::runtime_error(where + ": unknown line");
        }
        ++n;
    }
    if (!(c.eps_m > 0) || n == 0) {
        throw std::runtime_error((dir / "case.txt").string() + ": needs 'eps' and chains");
    }
    return c;
}

/// The case folders, in order.
std::vector<fs::path> case_dirs()
{
    const fs::path root = fs::path(TIGERLOD_SOURCE_DIR) / "tests" / "maps";
    std::vector<fs::path> dirs;
    for (const auto& e : fs::directory_iterator(root)) {
        if (e.is_directory()) {
            dirs.push_back(e.path());
        }
    }
    std::sort(dirs.begin(), dirs.end());
    return dirs;
}

/// `out`'s chains against `file` (expected.txt or expected-exact.txt), or
/// written into it, below its comments, with TIGERLOD_UPDATE_GOLDEN=1.
void compare_or_update(const ChainStore& out, const fs::path& file)
{
    std::vector<std::pair<uint64_t, std::string>> got;
    for (const auto& chain : out.chains) {
        const auto p = out.chain_points(chain);
        got.emplace_back(chain.id, std::to_string(chain.id) + " " + wkt_of(Pts(p.begin(), p.end())));
    }
    std::sort(got.begin(), got.end());
    std::vector<std::string> lines;
    for (const auto& [id, line] : got) {
        lines.push_back(line);
    }
    const char* update = std::getenv("TIGERLOD_UPDATE_GOLDEN");
    if (update != nullptr && std::string(update) == "1") {
        // Keep the file's comment lines at its head.
        std::ifstream old(file);
        std::string head;
        for (std::string line; std::getline(old, line) && line.rfind('#', 0) == 0;) {
            head += line + "\n";
        }
        std::ofstream f(file);
        f << head;
        for (const auto& line : lines) {
            f << line << "\n";
        }
        return;
    }
    ASSERT_TRUE(fs::exists(file)) << file;
    EXPECT_EQ(lines, content_lines(file));
}

} // namespace

TEST(MapCases, EachGivesItsExpectedChainsAndNoneMeet)
{
    const auto dirs = case_dirs();
    ASSERT_GE(dirs.size(), 10U);
    for (const auto& dir : dirs) {
        SCOPED_TRACE(dir.filename().string());
        const MapCase c = read_case(dir);
        const ChainStore out = run(c.map.s, c.eps_m, c.options);
        // No two chains meet where they did not in the input (case 008's
        // chain touches itself there; simplify leaves input problems be).
        EXPECT_LE(count_intersections({&out}), count_intersections({&c.map.s}));
        EXPECT_EQ(count_lod_meetings(out, c.map.s), 0U);
        compare_or_update(out, dir / "expected.txt");
    }
}

// The same maps with the exact rules alone (`--shortcut-test exact`): the
// chains of expected-exact.txt, none meeting, and each simplified chain
// clear of every other chain's original (the LODs mix). The cases where the
// eps-Voronoi test alone kept a vertex take the shortcut here.
TEST(MapCases, TheExactRulesAloneGiveTheirExpectedChainsAndNoneMeetAtAnyLod)
{
    const auto dirs = case_dirs();
    ASSERT_GE(dirs.size(), 10U);
    for (const auto& dir : dirs) {
        SCOPED_TRACE(dir.filename().string());
        const MapCase c = read_case(dir);
        const ChainStore out = run_exact(c.map.s, c.eps_m, c.options);
        EXPECT_LE(count_intersections({&out}), count_intersections({&c.map.s}));
        EXPECT_EQ(count_lod_meetings(out, c.map.s), 0U);
        compare_or_update(out, dir / "expected-exact.txt");
    }
}
