// tigerlod-synth: the synthetic nation is planar on the 1e-6 degree lattice
// (every pair of segments checked exactly, and through tigerlod-ingest), its
// faces' ids and internal points agree with its edges, a border edge is in
// both counties' files, the same seed gives the same bytes whatever the
// threads, ingest counts what the manifest says, and the distributions of
// vertices per edge, edge length and faces per block are within a factor of
// 2 of Floyd County's (../shared/data; that test skips without it).
#include "../../support/run_tool.hpp"
#include "core/geometry.hpp"
#include "core/segment_grid.hpp"
#include "stages/synth/nation.hpp"

#include <gdal.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <ogr_api.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <numbers>
#include <set>
#include <unordered_map>

namespace fs = std::filesystem;
using namespace tigerlod;
using namespace tigerlod::synth;
using tigerlod::testing::slurp;

namespace {

const fs::path bin_dir = TIGERLOD_BIN_DIR;
const fs::path floyd = fs::path(TIGERLOD_SOURCE_DIR).parent_path() / "shared" / "data" / "tiger";

GridPoint grid(Pt p)
{
    return {int32_t(p.x), int32_t(p.y)};
}

/// Every edge of the nation once (by TLID), and every face.
struct Whole {
    std::map<int64_t, Edge> edges;
    std::map<int64_t, Face> faces;
};

Whole whole(const Nation& n)
{
    Whole w;
    for (uint32_t c = 0; c < n.units(county).size(); ++c) {
        auto parts = n.county_parts(c);
        for (auto& e : parts.edges) {
            const auto [it, fresh] = w.edges.emplace(e.tlid, e);
            if (!fresh) { // a border edge: the same in both counties' files
                EXPECT_EQ(it->second.points, e.points) << "TLID " << e.tlid;
                EXPECT_EQ(it->second.tfidl, e.tfidl);
                EXPECT_EQ(it->second.tfidr, e.tfidr);
            }
        }
        for (auto& f : parts.faces) {
            EXPECT_TRUE(w.faces.emplace(f.tfid, f).second) << "TFID " << f.tfid << " twice";
        }
    }
    return w;
}

/// The nation's edges meet only at their end nodes: no two segments cross,
/// touch or overlap (exact), and no inner vertex is any other vertex.
void expect_planar(const Whole& w)
{
    std::vector<Segment> segs;
    std::map<std::pair<int64_t, int64_t>, int> inner, ends;
    for (const auto& [tlid, e] : w.edges) {
        ASSERT_GE(e.points.size(), 2U);
        for (size_t k = 0; k + 1 < e.points.size(); ++k) {
            segs.push_back({grid(e.points[k]), grid(e.points[k + 1]), uint32_t(segs.size())});
        }
        for (size_t k = 1; k + 1 < e.points.size(); ++k) {
            ++inner[{e.points[k].x, e.points[k].y}];
        }
        ++ends[{e.points.front().x, e.points.front().y}];
        ++ends[{e.points.back().x, e.points.back().y}];
    }
    const auto found = find_intersections(segs, 2);
    EXPECT_TRUE(found.empty()) << found.size() << " pairs meet, the first at " << found.front().x / 1e6 << ", "
                               << found.front().y / 1e6;
    size_t repeated = 0;
    for (const auto& [p, count] : inner) {
        repeated += count > 1 || ends.contains(p) ? 1 : 0;
    }
    EXPECT_EQ(repeated, 0U) << "inner vertices that are another vertex too";
}

SynthOptions small(uint64_t seed, double cell_m = 150)
{
    SynthOptions o;
    o.seed = seed;
    o.states = 2;
    o.counties_per_state = 3;
    o.target_vertices = 60'000;
    o.cell_m = cell_m;
    return o;
}

struct Result {
    int code;
    std::string out, err;
};

class SynthCli : public ::testing::Test {
  protected:
    void SetUp() override
    {
        m_dir = fs::temp_directory_path() / ("tigerlod-synth-" + std::to_string(::getpid()) + "-" +
                                             ::testing::UnitTest::GetInstance()->current_test_info()->name());
        fs::remove_all(m_dir);
        fs::create_directories(m_dir);
    }
    void TearDown() override { fs::remove_all(m_dir); }
    Result run(const std::string& tool, const std::string& args)
    {
        const std::string cmd = (bin_dir / ("tigerlod-" + tool)).string() + " " + args + " >" +
                                (m_dir / "out.txt").string() + " 2>" + (m_dir / "err.txt").string();
        const int status = std::system(cmd.c_str());
        return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, slurp(m_dir / "out.txt"), slurp(m_dir / "err.txt")};
    }
    /// Three states of three counties as TIGER files (synth), and the config
    /// reading them.
    void nine_counties(std::string& cfg)
    {
        const fs::path synth = m_dir / "synth";
        const Result r = run("synth", synth.string() + " --seed 5 --states 3 --counties-per-state 3 "
                                                       "--target-vertices 90000 --cell-m 200");
        ASSERT_EQ(r.code, 0) << r.err;
        cfg = config(synth).string();
    }
    /// A pipeline config reading `folder`'s files as a tiger dataset.
    fs::path config(const fs::path& folder)
    {
        const fs::path p = m_dir / "synth.yaml";
        std::ofstream(p) << "name: synth-test\n"
                            "dataset:\n"
                            "  kind: tiger\n"
                            "  edges: ["
                         << (folder / "tl_2020_*_edges.zip").string()
                         << "]\n"
                            "  faces: ["
                         << (folder / "tl_2020_*_faces.zip").string() << "]\n";
        return p;
    }
    fs::path m_dir;
};

nlohmann::json read_json(const fs::path& p)
{
    return nlohmann::json::parse(slurp(p));
}

} // namespace

TEST(Synth, SinTurnsIsLibmsSineToOneInTenMillion)
{
    for (int k = -20000; k <= 20000; ++k) {
        const double x = k / 7919.0;
        ASSERT_NEAR(sin_turns(x), std::sin(2 * std::numbers::pi * x), 1e-7) << x;
        ASSERT_NEAR(cos_turns(x), std::cos(2 * std::numbers::pi * x), 1e-7) << x;
    }
}

TEST(Synth, EdgesMeetOnlyAtTheirNodesExactly)
{
    // Small cells (150 m) make thin rows a few metres wide: narrow gaps,
    // lakes near edges and dangles near corners on every seed.
    for (const uint64_t seed : {1, 2, 3}) {
        SCOPED_TRACE(seed);
        const Nation n(small(seed));
        const Whole w = whole(n);
        ASSERT_GT(w.edges.size(), 1000U);
        expect_planar(w);
        size_t rings = 0, dangles = 0;
        for (const auto& [tlid, e] : w.edges) {
            rings += e.tnidf == e.tnidt ? 1 : 0;
            dangles += e.tfidl == e.tfidr ? 1 : 0;
        }
        EXPECT_GT(rings, 10U); // lakes and islands
        EXPECT_GT(dangles, 100U);
    }
}

TEST(Synth, FacesAgreeWithTheirEdges)
{
    const Nation n(small(4, 400));
    const Whole w = whole(n);
    // Every side of every edge names a face that exists (or the outside).
    std::set<int64_t> named;
    for (const auto& [tlid, e] : w.edges) {
        for (const int64_t f : {e.tfidl, e.tfidr}) {
            if (f != 0) {
                EXPECT_TRUE(w.faces.contains(f)) << "TLID " << tlid << " names face " << f;
                named.insert(f);
            }
        }
        if (e.tnidf == e.tnidt) {
            // A ring runs counter-clockwise around its left face.
            std::vector<GridPoint> pts;
            for (const Pt p : e.points) {
                pts.push_back(grid(p));
            }
            EXPECT_GT(twice_area(pts), 0) << "TLID " << tlid;
            PointInPolygon pip(grid(w.faces.at(e.tfidl).intpt));
            for (size_t k = 0; k + 1 < pts.size(); ++k) {
                pip.add_segment(pts[k], pts[k + 1]);
            }
            EXPECT_EQ(pip.location(), PointLocation::inside) << "TLID " << tlid;
        }
    }
    EXPECT_EQ(named.size(), w.faces.size()) << "faces no edge bounds";
    // Each face's internal point lies strictly inside its polygon (outer
    // ring counter-clockwise, holes taken off) and on no edge.
    for (const auto& [tfid, f] : w.faces) {
        ASSERT_FALSE(f.rings.empty());
        std::vector<GridPoint> outer;
        for (const Pt p : f.rings[0]) {
            outer.push_back(grid(p));
        }
        EXPECT_EQ(outer.front(), outer.back());
        EXPECT_GT(twice_area(outer), 0) << "face " << tfid;
        PointInPolygon pip(grid(f.intpt));
        for (const auto& ring : f.rings) {
            for (size_t k = 0; k + 1 < ring.size(); ++k) {
                pip.add_segment(grid(ring[k]), grid(ring[k + 1]));
            }
        }
        EXPECT_EQ(pip.location(), PointLocation::inside) << "face " << tfid;
    }
    for (const auto& [tlid, e] : w.edges) {
        if (e.tfidl == e.tfidr) { // a dangle: the face's point is not on it
            const Pt ip = w.faces.at(e.tfidl).intpt;
            for (size_t k = 0; k + 1 < e.points.size(); ++k) {
                EXPECT_FALSE(orientation(grid(e.points[k]), grid(e.points[k + 1]), grid(ip)) == 0 &&
                             in_span(grid(e.points[k]), grid(e.points[k + 1]), grid(ip)))
                    << "TLID " << tlid;
            }
        }
    }
}

TEST(Synth, UnitsNestAndCoverTheNation)
{
    const Nation n(small(5));
    EXPECT_EQ(n.units(state).size(), 2U);
    EXPECT_EQ(n.units(county).size(), 6U);
    for (int l = 0; l < level_count; ++l) {
        size_t cells = 0;
        std::set<std::pair<uint32_t, std::string>> codes;
        for (const auto& u : n.units(Level(l))) {
            EXPECT_GT(u.cells, 0U);
            cells += u.cells;
            EXPECT_TRUE(codes.emplace(u.parent, u.code).second) << "a code twice in one parent: " << u.code;
        }
        EXPECT_EQ(cells, size_t(n.width()) * size_t(n.height())) << level_names[l];
    }
    for (int j = 0; j < n.height(); ++j) {
        for (int i = 0; i < n.width(); ++i) {
            for (int l = 1; l < level_count; ++l) {
                ASSERT_EQ(n.units(Level(l))[n.unit_of(i, j, Level(l))].parent, n.unit_of(i, j, Level(l - 1)));
            }
        }
    }
    // A block code starts with its block group's digit, as in TIGER.
    for (const auto& b : n.units(block)) {
        EXPECT_EQ(b.code.size(), 4U);
        EXPECT_EQ(b.code[0], n.units(block_group)[b.parent].code[0]);
    }
}

TEST_F(SynthCli, SameSeedSameBytesWhateverTheThreads)
{
    const std::string opts = " --seed 7 --states 2 --counties-per-state 2 --target-vertices 40000";
    ASSERT_EQ(run("synth", (m_dir / "a").string() + opts + " --threads 1").code, 0);
    const Result b = run("synth", (m_dir / "b").string() + opts + " --threads 2");
    ASSERT_EQ(b.code, 0) << b.err;
    EXPECT_TRUE(b.err.empty()) << b.err; // no progress off a terminal
    size_t files = 0;
    for (const auto& e : fs::directory_iterator(m_dir / "a")) {
        if (e.path().filename() != "synth-timings.json") {
            EXPECT_EQ(slurp(e.path()), slurp(m_dir / "b" / e.path().filename())) << e.path().filename();
            ++files;
        }
    }
    EXPECT_EQ(files, 9U); // 4 counties x 2, and the manifest
    // The timings say where the threads' time went: each part measured, and
    // together no more than the threads had.
    const auto timings = nlohmann::json::parse(slurp(m_dir / "b" / "synth-timings.json"));
    double parts = 0;
    for (const char* part : {"geometry", "shapefile", "deflate", "files"}) {
        const double s = timings.at("thread_s").at(part).get<double>();
        EXPECT_GT(s, 0.0) << part;
        parts += s;
    }
    EXPECT_LE(parts, 2 * timings.at("total_s").get<double>());
    ASSERT_EQ(run("synth", (m_dir / "c").string() + " --seed 8 --states 2 --counties-per-state 2 "
                                                    "--target-vertices 40000")
                  .code,
              0);
    EXPECT_NE(slurp(m_dir / "a" / "manifest.json"), slurp(m_dir / "c" / "manifest.json"));
    // An existing output is kept unless --overwrite; bad options are usage errors.
    EXPECT_EQ(run("synth", (m_dir / "a").string() + opts).code, 2);
    EXPECT_EQ(run("synth", (m_dir / "d").string() + " --states 0").code, 2);
    EXPECT_EQ(run("synth", (m_dir / "d").string() + " --target-vertices 10").code, 2);
    EXPECT_FALSE(fs::exists(m_dir / "d"));
    // A broken synth section of a config: the file, line and key, exit 2, nothing written.
    std::ofstream(m_dir / "bad.yaml") << "name: bad\nsynth:\n  states: many\n";
    const Result word = run("synth", "--config " + (m_dir / "bad.yaml").string() + " " + (m_dir / "d").string());
    EXPECT_EQ(word.code, 2);
    EXPECT_NE(word.err.find("bad.yaml:3"), std::string::npos) << word.err;
    EXPECT_NE(word.err.find("synth.states"), std::string::npos) << word.err;
    std::ofstream(m_dir / "bad.yaml") << "name: bad\nsynth:\n  counties: 4\n";
    const Result unknown = run("synth", "--config " + (m_dir / "bad.yaml").string() + " " + (m_dir / "d").string());
    EXPECT_EQ(unknown.code, 2);
    EXPECT_NE(unknown.err.find("unknown key 'synth.counties'"), std::string::npos) << unknown.err;
    EXPECT_FALSE(fs::exists(m_dir / "d"));
}

TEST_F(SynthCli, IngestFindsItPlanarAndCountsWhatTheManifestSays)
{
    const fs::path out = m_dir / "synth";
    const Result s = run("synth", out.string() + " --seed 3 --states 3 --counties-per-state 3 --target-vertices 150000 "
                                                 "--cell-m 200");
    ASSERT_EQ(s.code, 0) << s.err;
    const auto manifest = read_json(out / "manifest.json");
    const Result r = run("ingest", config(out).string() + " " + (m_dir / "ingest").string());
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("problems: none"), std::string::npos) << r.out;
    const auto report = read_json(m_dir / "ingest" / "ingest-report.json");
    EXPECT_EQ(report["input_vertices"], manifest["counts"]["vertices"]);
    EXPECT_EQ(report["edges"], manifest["counts"]["edges"]);
    for (const auto& level : report["levels"]) {
        EXPECT_EQ(level["units"], manifest["counts"]["units"][level["name"].get<std::string>()]) << level["name"];
    }
    for (const auto& [kind, count] : report["problems"].items()) {
        EXPECT_EQ(count, 0) << kind;
    }
    EXPECT_EQ(manifest["counts"]["files"], 18);
    // A pattern that matches nothing is a config error naming it, and nothing is written.
    const Result none = run("ingest", config(m_dir / "nowhere").string() + " " + (m_dir / "ingest2").string());
    EXPECT_EQ(none.code, 2);
    EXPECT_NE(none.err.find("tl_2020_*_edges.zip: the pattern matches no file"), std::string::npos) << none.err;
    EXPECT_FALSE(fs::exists(m_dir / "ingest2"));
}

namespace {

/// Every file under `dir` but the timings, by path relative to it: its bytes.
std::map<std::string, std::string> folder_bytes(const fs::path& dir)
{
    std::map<std::string, std::string> out;
    for (const auto& e : fs::recursive_directory_iterator(dir)) {
        if (e.is_regular_file() && e.path().filename() != "ingest-timings.json") {
            out[e.path().lexically_relative(dir).string()] = slurp(e.path());
        }
    }
    return out;
}

std::vector<std::string> planned_jobs(const fs::path& parts)
{
    return read_json(parts / "plan.json")["jobs"].get<std::vector<std::string>>();
}

} // namespace

TEST_F(SynthCli, IngestInRegionJobsWritesTheWholeRunsBytesAndRepairsADamagedStore)
{
    // Three states of three counties as TIGER files, a part per county: the
    // plan, a job per state (run in reverse order), the finish; the folder is
    // the one a whole ingest writes, byte for byte.
    std::string cfg;
    ASSERT_NO_FATAL_FAILURE(nine_counties(cfg));
    const fs::path whole = m_dir / "whole", jobs = m_dir / "jobs", parts = m_dir / "parts";
    ASSERT_EQ(run("ingest", cfg + " " + whole.string()).code, 0);
    const std::string common = " --parts " + parts.string() + " " + cfg + " " + jobs.string();
    const Result plan = run("ingest", "--plan" + common);
    ASSERT_EQ(plan.code, 0) << plan.err;
    EXPECT_NE(plan.out.find("9 parts (0 from read jobs, 9 read here, 9 rewritten), 3 jobs"), std::string::npos)
        << plan.out;
    auto names = planned_jobs(parts);
    ASSERT_EQ(names, (std::vector<std::string>{"r-01", "r-02", "r-04"})); // FIPS codes: no 03
    for (auto it = names.rbegin(); it != names.rend(); ++it) {
        const Result r = run("ingest", "--region " + *it + " --threads 1" + common);
        ASSERT_EQ(r.code, 0) << r.err;
    }
    // The finish refuses a missing share, naming the job to run.
    fs::rename(parts / "shares" / "r-02.share", m_dir / "r-02.share");
    const Result missing = run("ingest", "--finish" + common);
    EXPECT_EQ(missing.code, 2);
    EXPECT_NE(missing.err.find("r-02.share is missing: run --region r-02 first"), std::string::npos) << missing.err;
    fs::rename(m_dir / "r-02.share", parts / "shares" / "r-02.share");
    const Result finish = run("ingest", "--finish" + common);
    ASSERT_EQ(finish.code, 0) << finish.err;
    const auto want = folder_bytes(whole);
    EXPECT_EQ(folder_bytes(jobs), want);

    // Planned again with nothing changed: no part or spec is written.
    const auto spec_time = fs::last_write_time(parts / "jobs" / "r-01.json");
    const Result again = run("ingest", "--plan" + common);
    ASSERT_EQ(again.code, 0) << again.err;
    EXPECT_NE(again.out.find("9 parts (0 from read jobs, 9 read here, 0 rewritten), 3 jobs (0 specs changed, 0 with a "
                             "store changed since)"),
              std::string::npos)
        << again.out;
    EXPECT_EQ(fs::last_write_time(parts / "jobs" / "r-01.json"), spec_time);

    // A store damaged by hand: the plan gives its job a new spec (a workflow
    // engine reruns it), the job writes the store again, and the folder is
    // the whole run's again. Another state's job, rerun, writes nothing.
    const fs::path victim = jobs / "tract" / "02001.tlc";
    ASSERT_TRUE(fs::exists(victim));
    std::ofstream(victim, std::ios::binary | std::ios::trunc) << "not a store";
    const Result damaged = run("ingest", "--plan" + common);
    ASSERT_EQ(damaged.code, 0) << damaged.err;
    EXPECT_NE(damaged.out.find("(1 specs changed, 1 with a store changed since)"), std::string::npos) << damaged.out;
    EXPECT_NE(slurp(parts / "jobs" / "r-02.json").find("\"repair\": \"tract/02001 changed since the job wrote it"),
              std::string::npos);
    EXPECT_EQ(fs::last_write_time(parts / "jobs" / "r-01.json"), spec_time);
    const Result repair = run("ingest", "--region r-02" + common);
    ASSERT_EQ(repair.code, 0) << repair.err;
    EXPECT_NE(repair.out.find("(1 rewritten)"), std::string::npos) << repair.out;
    const Result other = run("ingest", "--region r-04" + common);
    EXPECT_NE(other.out.find("(0 rewritten)"), std::string::npos) << other.out;
    ASSERT_EQ(run("ingest", "--finish" + common).code, 0);
    EXPECT_EQ(folder_bytes(jobs), want);
    // Repaired, the next plan keeps the spec as it is (the job does not run again).
    const auto repaired_time = fs::last_write_time(parts / "jobs" / "r-02.json");
    ASSERT_EQ(run("ingest", "--plan" + common).code, 0);
    EXPECT_EQ(fs::last_write_time(parts / "jobs" / "r-02.json"), repaired_time);

    // A job run at other options than the plan's; a share built from another
    // spec than the job's now.
    const Result options = run("ingest", "--region r-01 --halo-m 5" + common);
    EXPECT_EQ(options.code, 2);
    EXPECT_NE(options.err.find("r-01.json: planned with other options"), std::string::npos) << options.err;
    std::ofstream(parts / "jobs" / "r-01.json", std::ios::app) << "\n";
    const Result older = run("ingest", "--finish" + common);
    EXPECT_EQ(older.code, 2);
    EXPECT_NE(older.err.find("r-01.share: built from an older plan of the job; run --region r-01 again"),
              std::string::npos)
        << older.err;
    EXPECT_EQ(folder_bytes(jobs), want); // the refused finish wrote nothing

    // A job the plan does not have, and a part changed behind the plan's back.
    const Result unknown = run("ingest", "--region r-99" + common);
    EXPECT_EQ(unknown.code, 2);
    EXPECT_NE(unknown.err.find("no job 'r-99' in the plan"), std::string::npos) << unknown.err;
    // A spec without a field it needs: a data error naming the folder, not an internal one.
    std::ofstream(parts / "jobs" / "r-04.json", std::ios::trunc)
        << R"({"schema": "tigerlod.ingest-job/1", "job": "r-04", "mode": "region"})";
    const Result torn = run("ingest", "--region r-04" + common);
    EXPECT_EQ(torn.code, 1);
    EXPECT_NE(torn.err.find("a job file is not what this version of tigerlod-ingest writes"), std::string::npos)
        << torn.err;
    const std::string first = nlohmann::json::parse(slurp(parts / "jobs" / "r-01.json"))["parts"][0]["sha256"];
    std::ofstream(parts / "parts" / (first + ".raw"), std::ios::binary | std::ios::app) << "x";
    const Result changed = run("ingest", "--region r-01" + common);
    EXPECT_EQ(changed.code, 2);
    EXPECT_NE(changed.err.find(first + ".raw: the part changed since the plan; run --plan again"), std::string::npos)
        << changed.err;
}

TEST_F(SynthCli, ReadJobsGiveThePlanTheSpecsOfAPlanThatReadsAlone)
{
    // Nine counties listed, read by two jobs (the workflow's read groups),
    // planned from what they put aside: the specs and the index are those of
    // a plan that reads every input itself.
    std::string cfg;
    ASSERT_NO_FATAL_FAILURE(nine_counties(cfg));
    const fs::path alone = m_dir / "alone", parts = m_dir / "parts", out = m_dir / "out";
    ASSERT_EQ(run("ingest", "--plan --parts " + alone.string() + " " + cfg + " " + out.string()).code, 0);
    const std::string common = " --parts " + parts.string() + " " + cfg + " " + out.string();
    const Result list = run("ingest", "--list" + common);
    ASSERT_EQ(list.code, 0) << list.err;
    const auto listing = nlohmann::json::parse(slurp(parts / "reads.json"));
    ASSERT_EQ(listing["parts"].size(), 9U);
    EXPECT_EQ(listing["mode"], "parts");
    EXPECT_EQ(listing["parts"][0]["files"].size(), 2U); // a county's FACES and EDGES
    const Result a = run("ingest", "--read a --select 5-8" + common);
    ASSERT_EQ(a.code, 0) << a.err;
    const Result b = run("ingest", "--read b --select 0-2,4,3" + common);
    ASSERT_EQ(b.code, 0) << b.err;
    EXPECT_NE(b.out.find("5 parts (5 rewritten)"), std::string::npos) << b.out;
    const Result plan = run("ingest", "--plan" + common);
    ASSERT_EQ(plan.code, 0) << plan.err;
    EXPECT_NE(plan.out.find("9 parts (9 from read jobs, 0 read here, 0 rewritten), 3 jobs"), std::string::npos)
        << plan.out;
    const auto same_plan = [&] {
        EXPECT_EQ(folder_bytes(parts / "jobs"), folder_bytes(alone / "jobs"));
        EXPECT_EQ(slurp(parts / "index.json"), slurp(alone / "index.json"));
        EXPECT_EQ(folder_bytes(parts / "parts"), folder_bytes(alone / "parts"));
    };
    same_plan();

    // A county's file touched since its read job: the plan reads that part itself.
    const fs::path touched = listing["parts"][7]["files"][1].get<std::string>();
    fs::last_write_time(touched, fs::last_write_time(touched) + std::chrono::seconds(2));
    const Result stale = run("ingest", "--plan" + common);
    ASSERT_EQ(stale.code, 0) << stale.err;
    EXPECT_NE(stale.out.find("9 parts (8 from read jobs, 1 read here, 0 rewritten)"), std::string::npos) << stale.out;
    same_plan();
    // A read job's file that is not one: removed, and its parts read by the plan.
    std::ofstream(parts / "reads" / "b.sum", std::ios::binary | std::ios::app) << "x";
    const Result torn = run("ingest", "--plan" + common);
    ASSERT_EQ(torn.code, 0) << torn.err;
    EXPECT_NE(torn.out.find("9 parts (3 from read jobs, 6 read here, 0 rewritten)"), std::string::npos) << torn.out;
    EXPECT_FALSE(fs::exists(parts / "reads" / "b.sum"));
    same_plan();
    // Planned under other levels: a part's codes come from them, so the read
    // jobs' parts do not serve, and their file goes.
    const fs::path other = m_dir / "other.yaml";
    std::ofstream(other) << slurp(cfg)
                         << "levels:\n  - {name: state, fields: [STATEFP20]}\n"
                            "  - {name: county, fields: [STATEFP20, COUNTYFP20]}\n";
    const Result levels = run("ingest", "--plan --parts " + parts.string() + " " + other.string() + " " + out.string());
    ASSERT_EQ(levels.code, 0) << levels.err;
    EXPECT_NE(levels.out.find("9 parts (0 from read jobs, 9 read here"), std::string::npos) << levels.out;
    EXPECT_FALSE(fs::exists(parts / "reads" / "a.sum"));

    // Selections that are not parts of this dataset, and steps mixed.
    for (const auto& [args, message] : std::vector<std::pair<std::string, std::string>>{
             {"--read c --select 9", "--select '9': part 9 is not in this dataset (it has 9 parts, from 0)"},
             {"--read c --select 3-1", "the range 3-1 runs backwards"},
             {"--read c --select 1,x", "'x' is not a part number"},
             {"--read c", "--read needs --select PARTS"},
             {"--read c/d --select 1", "a read job's name is letters, digits"},
             {"--plan --select 1", "--select goes with --read"},
             {"--list --plan", "are steps of their own: give one"}}) {
        const Result r = run("ingest", args + common);
        EXPECT_EQ(r.code, 2) << args;
        EXPECT_NE(r.err.find(message), std::string::npos) << args << ": " << r.err;
    }
}

namespace {

/// Quantile p of v (sorted in place), as the manifest takes it.
double quantile(std::vector<double>& v, int p)
{
    std::sort(v.begin(), v.end());
    return v[size_t(double(p) / 100 * double(v.size() - 1))];
}

} // namespace

TEST_F(SynthCli, DistributionsWithinAFactorOfTwoOfFloydCountys)
{
    const fs::path edges = floyd / "tl_2020_51063_edges.zip", faces = floyd / "tl_2020_51063_faces.zip";
    if (!fs::exists(edges) || !fs::exists(faces)) {
        GTEST_SKIP() << "no " << edges << " (../shared/data absent)";
    }
    GDALAllRegister();
    std::vector<double> vertices, length;
    GDALDatasetH ds = GDALOpenEx(("/vsizip/" + edges.string()).c_str(), GDAL_OF_VECTOR, nullptr, nullptr, nullptr);
    ASSERT_NE(ds, nullptr);
    OGRLayerH layer = GDALDatasetGetLayer(ds, 0);
    OGR_L_ResetReading(layer);
    for (OGRFeatureH f; (f = OGR_L_GetNextFeature(layer)) != nullptr; OGR_F_Destroy(f)) {
        OGRGeometryH g = OGR_F_GetGeometryRef(f);
        const int n = OGR_G_GetPointCount(g);
        vertices.push_back(n);
        double m = 0;
        for (int k = 0; k + 1 < n; ++k) {
            const double dx = (OGR_G_GetX(g, k + 1) - OGR_G_GetX(g, k)) * 111319 *
                              std::cos(OGR_G_GetY(g, k) * std::numbers::pi / 180);
            const double dy = (OGR_G_GetY(g, k + 1) - OGR_G_GetY(g, k)) * 110574;
            m += std::sqrt(dx * dx + dy * dy);
        }
        length.push_back(m);
    }
    GDALClose(ds);
    std::map<std::string, double> per_block;
    ds = GDALOpenEx(("/vsizip/" + faces.string()).c_str(), GDAL_OF_VECTOR, nullptr, nullptr, nullptr);
    ASSERT_NE(ds, nullptr);
    layer = GDALDatasetGetLayer(ds, 0);
    const int tract = OGR_FD_GetFieldIndex(OGR_L_GetLayerDefn(layer), "TRACTCE20");
    const int blk = OGR_FD_GetFieldIndex(OGR_L_GetLayerDefn(layer), "BLOCKCE20");
    for (OGRFeatureH f; (f = OGR_L_GetNextFeature(layer)) != nullptr; OGR_F_Destroy(f)) {
        ++per_block[std::string(OGR_F_GetFieldAsString(f, tract)) + OGR_F_GetFieldAsString(f, blk)];
    }
    GDALClose(ds);
    std::vector<double> faces_per_block;
    for (const auto& [b, count] : per_block) {
        faces_per_block.push_back(count);
    }

    const Result s = run("synth", (m_dir / "s").string() + " --target-vertices 300000");
    ASSERT_EQ(s.code, 0) << s.err;
    const auto dist = read_json(m_dir / "s" / "manifest.json")["distributions"];
    const std::vector<std::pair<std::string, std::vector<double>*>> kinds = {
        {"vertices_per_edge", &vertices}, {"edge_length_m", &length}, {"faces_per_block", &faces_per_block}};
    for (const auto& [name, values] : kinds) {
        double mean = 0;
        for (const double v : *values) {
            mean += v / double(values->size());
        }
        std::printf("%-18s %8s %10s %10s\n", name.c_str(), "", "Floyd", "synth");
        for (const int p : {10, 25, 50, 75, 90}) {
            char key[8]; // "p10" ... ("p" + std::to_string(p) trips GCC 12's -Wrestrict at -O3)
            std::snprintf(key, sizeof key, "p%d", p);
            const double ours = dist[name][key], theirs = quantile(*values, p);
            std::printf("%-18s %8s %10.1f %10.1f\n", "", key, theirs, ours);
            EXPECT_GE(ours, theirs / 2) << name << " p" << p;
            EXPECT_LE(ours, theirs * 2) << name << " p" << p;
        }
        const double ours = dist[name]["mean"];
        std::printf("%-18s %8s %10.1f %10.1f\n", "", "mean", mean, ours);
        EXPECT_GE(ours, mean / 2) << name << " mean";
        EXPECT_LE(ours, mean * 2) << name << " mean";
    }
}
