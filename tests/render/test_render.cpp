// tigerlod-render as a user runs it: bad inputs get their message and exit
// code and leave nothing behind; over whole camera paths, in every mode, the
// reader never holds more than the budget and no chain is drawn twice in a
// frame; and views of the Floyd tree (../shared/data) and of the default demo
// tree (us-atlas, fetched by scripts/test into .cache/) match reference
// images within a tolerance. Each skips with its reason when its data is
// absent. TIGERLOD_UPDATE_RENDER_REFERENCE=1 rewrites the references.
#include "../support/run_tool.hpp"
#include "../support/synthetic_tree.hpp"
#include "core/digest.hpp"

#include <gdal.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <sstream>

namespace fs = std::filesystem;
using tigerlod::testing::slurp;

namespace {

const fs::path source_dir = TIGERLOD_SOURCE_DIR;
const fs::path bin_dir = TIGERLOD_BIN_DIR;
const fs::path floyd_edges = source_dir.parent_path() / "shared" / "data" / "tiger" / "tl_2020_51063_edges.zip";
const fs::path us_atlas = source_dir / ".cache" / "npm" / "us-atlas-3.0.1" / "counties-10m.json";
const fs::path reference_dir = source_dir / "tests" / "render" / "reference";

int run(const std::string& tool, const std::string& args, const fs::path& log)
{
    return tigerlod::testing::run_tool(bin_dir, tool, args, log);
}

fs::path temp_dir(const std::string& name)
{
    const fs::path d = fs::temp_directory_path() / ("tigerlod-render-" + name + "-" + std::to_string(::getpid()));
    fs::remove_all(d);
    fs::create_directories(d);
    return d;
}

struct Image {
    int width = 0, height = 0;
    std::vector<uint8_t> rgb;
};

Image read_png(const fs::path& p)
{
    GDALAllRegister();
    Image im;
    GDALDatasetH ds = GDALOpen(p.c_str(), GA_ReadOnly);
    if (ds == nullptr) {
        return im;
    }
    im.width = GDALGetRasterXSize(ds);
    im.height = GDALGetRasterYSize(ds);
    im.rgb.resize(size_t(im.width) * size_t(im.height) * 3);
    std::vector<uint8_t> band(size_t(im.width) * size_t(im.height));
    for (int b = 0; b < 3 && b < GDALGetRasterCount(ds); ++b) {
        if (GDALRasterIO(GDALGetRasterBand(ds, b + 1), GF_Read, 0, 0, im.width, im.height, band.data(), im.width,
                         im.height, GDT_Byte, 0, 0) == CE_None) {
            for (size_t i = 0; i < band.size(); ++i) {
                im.rgb[3 * i + size_t(b)] = band[i];
            }
        }
    }
    GDALClose(ds);
    return im;
}

void write_png(const fs::path& p, const Image& im)
{
    GDALDatasetH mem = GDALCreate(GDALGetDriverByName("MEM"), "", im.width, im.height, 3, GDT_Byte, nullptr);
    std::vector<uint8_t> band(size_t(im.width) * size_t(im.height));
    for (int b = 0; b < 3; ++b) {
        for (size_t i = 0; i < band.size(); ++i) {
            band[i] = im.rgb[3 * i + size_t(b)];
        }
        if (GDALRasterIO(GDALGetRasterBand(mem, b + 1), GF_Write, 0, 0, im.width, im.height, band.data(), im.width,
                         im.height, GDT_Byte, 0, 0) != CE_None) {
            ADD_FAILURE() << "cannot fill the image for " << p;
        }
    }
    GDALClose(GDALCreateCopy(GDALGetDriverByName("PNG"), p.c_str(), mem, FALSE, nullptr, nullptr, nullptr));
    GDALClose(mem);
    fs::remove(p.string() + ".aux.xml");
}

/// Compare `actual` with tests/render/reference/`name`: at most 0.5% of the
/// pixels may differ (a channel by more than 48), since another Mesa may
/// round a line's edge another way. On failure the actual image and a diff
/// (differing pixels red over a faded reference) are written beside the
/// test's build and named.
void expect_like_reference(const fs::path& actual, const std::string& name)
{
    const fs::path ref = reference_dir / name;
    if (std::getenv("TIGERLOD_UPDATE_RENDER_REFERENCE") != nullptr) {
        fs::create_directories(reference_dir);
        fs::copy_file(actual, ref, fs::copy_options::overwrite_existing);
        std::printf("reference %s rewritten\n", ref.c_str());
        return;
    }
    const Image a = read_png(actual), r = read_png(ref);
    ASSERT_GT(a.width, 0) << actual << " is not a readable PNG";
    ASSERT_GT(r.width, 0) << ref << " is missing: TIGERLOD_UPDATE_RENDER_REFERENCE=1 writes it";
    ASSERT_EQ(a.width, r.width);
    ASSERT_EQ(a.height, r.height);
    Image diff = r;
    size_t differ = 0, ink = 0;
    for (size_t i = 0; i < a.rgb.size() / 3; ++i) {
        bool d = false;
        for (size_t c = 0; c < 3; ++c) {
            d = d || std::abs(int(a.rgb[3 * i + c]) - int(r.rgb[3 * i + c])) > 48;
            diff.rgb[3 * i + c] = uint8_t(255 - (255 - r.rgb[3 * i + c]) / 4);
        }
        ink += r.rgb[3 * i] < 200 ? 1 : 0;
        if (d) {
            ++differ;
            diff.rgb[3 * i] = 255;
            diff.rgb[3 * i + 1] = 0;
            diff.rgb[3 * i + 2] = 0;
        }
    }
    EXPECT_GT(ink, a.rgb.size() / 3 / 1000) << name << ": the reference shows almost nothing";
    const double fraction = double(differ) / double(a.rgb.size() / 3);
    if (fraction > 0.005) {
        const fs::path out = bin_dir.parent_path() / "render-test-failures";
        fs::create_directories(out);
        fs::copy_file(actual, out / ("actual-" + name), fs::copy_options::overwrite_existing);
        write_png(out / ("diff-" + name), diff);
        ADD_FAILURE() << name << ": " << differ << " pixels differ (" << 100 * fraction
                      << "%, at most 0.5%); actual and diff images in " << out;
    }
}

nlohmann::json summary(const fs::path& out)
{
    return nlohmann::json::parse(slurp(out / "summary.json"));
}

/// Every out-of-core mode of a summary within its budget, with every CSV row too.
void expect_budget_and_once(const fs::path& out, uint64_t budget)
{
    const auto s = summary(out);
    ASSERT_EQ(s["modes"].size(), 3U);
    for (const auto& m : s["modes"]) {
        const std::string mode = m["mode"];
        EXPECT_EQ(m["duplicate_chains"], 0) << mode;
        EXPECT_EQ(m["errors"], 0) << mode;
        if (mode == "incore") {
            continue;
        }
        EXPECT_EQ(m["budget_bytes"], budget) << mode;
        EXPECT_TRUE(m["within_budget"].get<bool>()) << mode << ": peak " << m["peak_bytes"];
        EXPECT_LE(m["peak_bytes"].get<uint64_t>(), budget) << mode;
        EXPECT_LE(m["select_p95_ms"].get<double>(), m["select_max_ms"].get<double>()) << mode;
        // Whether the budget bound: it evicted, skipped or cut the prefetch list.
        EXPECT_EQ(m["budget_bound"].get<bool>(),
                  m["evictions"].get<uint64_t>() + m["skipped"].get<uint64_t>() + m["prefetch_cuts"].get<uint64_t>() >
                      0)
            << mode;
        if (mode == "ooc-noprefetch") {
            EXPECT_EQ(m["prefetch_cuts"], 0) << mode;
            EXPECT_EQ(m["prefetches"], 0) << mode;
        }
        std::istringstream csv(slurp(out / ("frames-" + mode + ".csv")));
        std::string line;
        std::getline(csv, line);
        EXPECT_EQ(line, "frame,ms,front_nodes,lods,chains,vertices,segments,resident_bytes,misses,bytes_read,complete,"
                        "select_ms,center_x,center_y,units_per_pixel");
        size_t rows = 0;
        for (; std::getline(csv, line); ++rows) {
            std::vector<std::string> f;
            std::istringstream cells(line);
            for (std::string c; std::getline(cells, c, ',');) {
                f.push_back(c);
            }
            ASSERT_EQ(f.size(), 15U) << line;
            EXPECT_GT(std::stod(f[14]), 0.0) << line; // the view's scale
            EXPECT_LE(std::stoull(f[7]), budget) << mode << " frame " << f[0];
            // Choosing the front is part of the frame's time.
            EXPECT_LE(std::stod(f[11]), std::stod(f[1])) << mode << " frame " << f[0];
        }
        EXPECT_EQ(rows, m["frames"].get<size_t>()) << mode;
    }
}

/// D/tree from a config: ingest, simplify (`simplify_args`), pack. Fails the test on any error.
void build_tree(const fs::path& d, const std::string& config, const std::string& simplify_args)
{
    const std::string s = d.string();
    ASSERT_EQ(run("ingest", config + " " + s + "/ingest", d / "log"), 0) << slurp(d / "log");
    ASSERT_EQ(run("simplify", simplify_args + " " + s + "/ingest " + s + "/simp", d / "log"), 0) << slurp(d / "log");
    ASSERT_EQ(run("pack", s + "/ingest " + s + "/simp " + s + "/tree", d / "log"), 0) << slurp(d / "log");
}

/// The views of a keyframe file (`keyframes`, one frame each after the first) drawn in core
/// at 640x360 into D/views: frames/incore-00000.png, -00001.png, ..., and overview.png.
void render_views(const fs::path& d, const std::string& keyframes)
{
    const std::string s = d.string();
    std::ofstream(d / "views.path") << keyframes;
    ASSERT_EQ(
        run("render",
            "--path " + s + "/views.path --mode incore --png-every 1 --size 640x360 " + s + "/tree " + s + "/views",
            d / "log"),
        0)
        << slurp(d / "log");
}

} // namespace

TEST(Render, BadInputsGetTheirMessageAndExitCodeAndLeaveNothing)
{
    const fs::path d = temp_dir("bad");
    tigerlod::testing::make_synthetic_tree(2).write(d / "tree");
    const std::string tree = (d / "tree").string(), out = (d / "out").string();
    struct Case {
        std::string what, args;
        int code;
        std::string message;
    };
    std::ofstream(d / "short.path") << "# lon lat m/px\n-80 37\n";
    std::ofstream(d / "lat.path") << "-80 37 10\n-80 97 10 5\n";
    std::ofstream(d / "word.path") << "-80 37 ten\n";
    std::ofstream(d / "empty.path") << "# nothing\n\n";
    const std::vector<Case> cases = {
        {"missing tree", (d / "none").string() + " " + out, 1, "skeleton.tls: cannot open"},
        {"path of two fields", "--path " + (d / "short.path").string() + " " + tree + " " + out, 1,
         "short.path:2: expected LON LAT METRES_PER_PIXEL [FRAMES], found 2 fields"},
        {"latitude out of range", "--path " + (d / "lat.path").string() + " " + tree + " " + out, 1,
         "lat.path:2: LON must be in -180..180 and LAT in -90..90"},
        {"not a number", "--path " + (d / "word.path").string() + " " + tree + " " + out, 1,
         "word.path:1: METRES_PER_PIXEL 'ten' is not a number"},
        {"no keyframes", "--path " + (d / "empty.path").string() + " " + tree + " " + out, 1, "no keyframes"},
        {"no such path file", "--path " + (d / "nope.path").string() + " " + tree + " " + out, 1,
         "cannot read the camera path"},
        {"budget below the skeleton", "--budget-mb 0.0001 " + tree + " " + out, 2, "does not hold the skeleton"},
        {"bad size", "--size 10x10 " + tree + " " + out, 2, "'--size' must be WIDTHxHEIGHT"},
        {"bad mode", "--mode fast " + tree + " " + out, 2, "--mode"},
    };
    for (const auto& c : cases) {
        EXPECT_EQ(run("render", c.args, d / "log"), c.code) << c.what << ": " << slurp(d / "log");
        EXPECT_NE(slurp(d / "log").find(c.message), std::string::npos) << c.what << ": " << slurp(d / "log");
        EXPECT_FALSE(fs::exists(out)) << c.what;
    }
    // A damaged tile: the payloads in it cannot be read; the run fails naming them.
    fs::copy(d / "tree", d / "damaged", fs::copy_options::recursive);
    for (const auto& f : fs::directory_iterator(d / "damaged" / "tiles")) {
        fs::resize_file(f.path(), fs::file_size(f.path()) / 2);
    }
    EXPECT_EQ(run("render", "--frames 4 --fps 0 " + (d / "damaged").string() + " " + out, d / "log"), 1)
        << slurp(d / "log");
    EXPECT_NE(slurp(d / "log").find("damaged or missing payloads"), std::string::npos) << slurp(d / "log");
    EXPECT_FALSE(fs::exists(out));
    fs::remove_all(d);
}

TEST(Render, SyntheticTreeWithinTheBudgetInEveryModeAndPath)
{
    const fs::path d = temp_dir("synthetic");
    tigerlod::testing::make_synthetic_tree(3).write(d / "tree");
    // 1 MiB: a fraction of the tree's payloads, so the streamer evicts.
    const uint64_t budget = 1 << 20;
    for (const std::string path : {"zoom", "pan", "jumpy"}) {
        const fs::path out = d / path;
        ASSERT_EQ(run("render",
                      "--path " + path + " --frames 40 --fps 0 --budget-mb 1 --size 320x200 " + (d / "tree").string() +
                          " " + out.string(),
                      d / "log"),
                  0)
            << slurp(d / "log");
        expect_budget_and_once(out, budget);
        EXPECT_TRUE(fs::exists(out / "overview.png"));
        EXPECT_TRUE(fs::exists(out / "zoom.png"));
    }
    fs::remove_all(d);
}

TEST(Render, ModeNoneDrawsThePreviewsAloneAndNamesTheTree)
{
    // The workflow's render job after every new tree: the two previews, no
    // renderer along the path; the summary names the tree's manifest.
    const fs::path d = temp_dir("none");
    tigerlod::testing::make_synthetic_tree(2).write(d / "tree");
    std::ofstream(d / "tree" / "manifest.json") << "{\"tree\": 1}\n";
    const fs::path out = d / "out";
    ASSERT_EQ(run("render", "--mode none --size 320x200 " + (d / "tree").string() + " " + out.string(), d / "log"), 0)
        << slurp(d / "log");
    EXPECT_TRUE(fs::exists(out / "overview.png"));
    EXPECT_TRUE(fs::exists(out / "zoom.png"));
    for (const auto& e : fs::directory_iterator(out)) {
        EXPECT_FALSE(e.path().filename().string().starts_with("frames-")) << e.path();
    }
    const auto summary = nlohmann::json::parse(slurp(out / "summary.json"));
    EXPECT_TRUE(summary["modes"].empty());
    EXPECT_EQ(summary["tree_manifest_sha256"], tigerlod::sha256_file(d / "tree" / "manifest.json"));
    fs::remove_all(d);
}

TEST(Render, FloydTreeMatchesItsReferencesWithinTheBudget)
{
    if (!fs::exists(floyd_edges)) {
        GTEST_SKIP() << "needs ../shared/data/tiger (Floyd County TIGER/Line 2020): " << floyd_edges;
    }
    const fs::path d = temp_dir("floyd");
    const std::string s = d.string();
    ASSERT_NO_FATAL_FAILURE(build_tree(d, (source_dir / "configs" / "floyd.yaml").string(), "--tolerances 1,4,16,64"));
    // Whole paths in every mode, under a budget that holds a third of the tree.
    for (const std::string path : {"zoom", "jumpy"}) {
        ASSERT_EQ(run("render",
                      "--path " + path + " --frames 60 --fps 0 --budget-mb 0.6 --size 640x360 " + s + "/tree " + s +
                          "/" + path,
                      d / "log"),
                  0)
            << slurp(d / "log");
        expect_budget_and_once(d / path, uint64_t(0.6 * 1024 * 1024));
    }
    // Two keyframes: the county, and a close view of blocks along the river.
    ASSERT_NO_FATAL_FAILURE(render_views(d, "-80.36 36.93 60\n-80.355 36.955 4 1\n"));
    expect_like_reference(d / "views" / "frames" / "incore-00000.png", "floyd-county.png");
    expect_like_reference(d / "views" / "frames" / "incore-00001.png", "floyd-blocks.png");
    expect_like_reference(d / "views" / "overview.png", "floyd-overview.png");
    fs::remove_all(d);
}

TEST(Render, DemoTreeMatchesItsReferences)
{
    if (!fs::exists(us_atlas)) {
        GTEST_SKIP() << "needs " << us_atlas << " (scripts/test fetches it: scripts/fetch-npm us-atlas@3.0.1)";
    }
    const fs::path d = temp_dir("demo");
    const std::string config = (source_dir / "configs" / "demo.yaml").string();
    ASSERT_NO_FATAL_FAILURE(build_tree(d, config, "--config " + config));
    // The lower 48, and Virginia's counties.
    ASSERT_NO_FATAL_FAILURE(render_views(d, "-97 38.5 4500\n-79 37.8 700 1\n"));
    expect_like_reference(d / "views" / "frames" / "incore-00000.png", "demo-conus.png");
    expect_like_reference(d / "views" / "frames" / "incore-00001.png", "demo-virginia.png");
    fs::remove_all(d);
}
