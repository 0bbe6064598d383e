// A polygon map built region by region gives what the whole build gives,
// also with each region built alone as a job and handed on as bytes.
#include "core/errors.hpp"
#include "stages/ingest/map_builder.hpp"
#include "stages/ingest/region_share.hpp"
#include "stages/ingest/regions.hpp"

#include <gtest/gtest.h>

#include <map>
#include <mutex>
#include <set>
#include <span>
#include <tuple>

using namespace tigerlod;
using namespace tigerlod::ingest;

namespace {

const Projection& proj()
{
    static const Projection p{ProjectionParams{}};
    return p;
}

/// Square tracts of 0.01 degree (about 1 km) from (-100, 40), each ring
/// through its four corners and the midpoints of its sides.
void square(RawMap& m, int x, int y, uint32_t unit)
{
    auto at = [&](int i, int j) { return LonLatE6{-100000000 + 5000 * (2 * x + i), 40000000 + 5000 * (2 * y + j)}; };
    std::vector<LonLatE6> r = {at(0, 0), at(1, 0), at(2, 0), at(2, 1), at(2, 2),
                               at(1, 2), at(0, 2), at(0, 1), at(0, 0)};
    m.add_polyline(r, unit, no_unit, 0, 0, {0, static_cast<int64_t>(unit)});
}

/// One state's file: columns [x0, x0 + 4) by rows [0, 4), two counties of
/// two columns each; every other tract has a given internal point.
RawMap state_part(int state, int x0, const std::string& county_of_first = "")
{
    RawMap m;
    m.kind = RawMap::Kind::polygon_rings;
    m.level_names = {"nation", "state", "county", "tract"};
    m.files = {"state" + std::to_string(state) + ".shp"};
    const std::string st = std::to_string(10 + state);
    for (int x = x0; x < x0 + 4; ++x) {
        for (int y = 0; y < 4; ++y) {
            std::string county = st + std::to_string((x - x0) / 2);
            if (!county_of_first.empty() && x == x0) {
                county = county_of_first;
            }
            RawUnit u;
            const auto id = static_cast<uint32_t>(m.units.size());
            u.codes = {"US", st, county, county + std::to_string(id)};
            if (id % 2 == 0) {
                u.intpt = LonLatE6{-100000000 + 10000 * x + 5000, 40000000 + 10000 * y + 5000};
            }
            u.weight = 1.0 + 0.01 * id;
            u.source = {0, id};
            m.units.push_back(u);
            square(m, x, y, id);
        }
    }
    m.points_read = m.coords.size();
    return m;
}

struct Out {
    BuildResult result;
    std::map<std::string, std::string> stores; // level/partition -> encoded
};

StoreSink collect(Out& o, std::mutex& m)
{
    return [&o, &m](const chains::ChainStore& s) {
        const std::lock_guard lock(m);
        o.stores[s.level_name + "/" + s.partition] = chains::encode(s);
    };
}

Out whole(const std::vector<RawMap>& parts, const BuildOptions& opt)
{
    RawMap raw;
    raw.kind = parts.front().kind;
    raw.level_names = parts.front().level_names;
    for (auto p : parts) {
        raw.append(std::move(p));
    }
    Out o;
    std::mutex m;
    o.result = build_map(std::move(raw), proj(), opt, collect(o, m));
    return o;
}

Out by_regions(const std::vector<RawMap>& parts, const BuildOptions& opt)
{
    std::vector<PartSummary> summaries;
    for (const auto& p : parts) {
        summaries.push_back(summarize_part(p));
    }
    Out o;
    std::mutex m;
    o.result = build_by_regions(
        summaries, [&](size_t i) { return parts.at(i); }, parts.front().level_names, proj(), opt, collect(o, m));
    return o;
}

void expect_same(const Out& a, const Out& b)
{
    ASSERT_EQ(a.stores.size(), b.stores.size());
    for (const auto& [name, bytes] : a.stores) {
        ASSERT_TRUE(b.stores.count(name)) << name;
        EXPECT_EQ(bytes, b.stores.at(name)) << name;
    }
    EXPECT_EQ(a.result.problems, b.result.problems);
    ASSERT_EQ(a.result.samples.size(), b.result.samples.size());
    for (size_t i = 0; i < a.result.samples.size(); ++i) {
        const auto& x = a.result.samples[i];
        const auto& y = b.result.samples[i];
        EXPECT_EQ(std::tie(x.kind, x.lon_deg, x.lat_deg, x.where), std::tie(y.kind, y.lon_deg, y.lat_deg, y.where));
    }
    EXPECT_EQ(a.result.input_vertices, b.result.input_vertices);
    EXPECT_EQ(a.result.unique_vertices, b.result.unique_vertices);
    EXPECT_EQ(a.result.edges, b.result.edges);
    ASSERT_EQ(a.result.levels.size(), b.result.levels.size());
    for (size_t L = 0; L < a.result.levels.size(); ++L) {
        const auto& x = a.result.levels[L];
        const auto& y = b.result.levels[L];
        EXPECT_EQ(std::tie(x.name, x.units, x.chains, x.rings, x.vertices, x.junctions, x.partitions, x.halo_chains,
                           x.constraint_points, x.computed_internal_points),
                  std::tie(y.name, y.units, y.chains, y.rings, y.vertices, y.junctions, y.partitions, y.halo_chains,
                           y.constraint_points, y.computed_internal_points))
            << x.name;
    }
}

bool built_by_regions(const BuildResult& r)
{
    for (const auto& [phase, s] : r.seconds) {
        if (phase == "coarse_levels") {
            return true;
        }
    }
    return false;
}

} // namespace

TEST(Regions, ThreeStatesGiveTheWholeBuildsStoresAndReport)
{
    // Three states side by side, and a fourth apart (an island): the nation's
    // outline runs through three regions, the state borders are between two.
    // A repeated point in state 11 is found once, by the region that owns it.
    std::vector<RawMap> parts = {state_part(0, 0), state_part(1, 4), state_part(2, 8), state_part(3, 20)};
    {
        RawMap& p = parts[1];
        p.coords.insert(p.coords.begin() + 1, p.coords[1]); // a repeated point in the first ring
        for (size_t i = 1; i < p.offsets.size(); ++i) {
            ++p.offsets[i];
        }
        ++p.points_read;
    }
    for (double halo : {1000.0, 0.0, 3000.0}) {
        for (unsigned threads : {1U, 2U}) {
            BuildOptions opt;
            opt.halo_m = halo;
            opt.threads = threads;
            opt.max_problem_samples = 5;
            const Out w = whole(parts, opt);
            const Out r = by_regions(parts, opt);
            EXPECT_FALSE(built_by_regions(w.result));
            EXPECT_TRUE(built_by_regions(r.result));
            expect_same(w, r);
            EXPECT_EQ(r.result.problems.at("duplicate_points"), 1U);
            EXPECT_EQ(r.result.levels.at(1).units, 4U);
            EXPECT_EQ(r.result.levels.at(3).units, 64U);
            EXPECT_EQ(r.stores.size(),
                      1U + 1U + 4U + 8U); // nation, state, a county store per state, a tract store per county
        }
    }
}

TEST(Regions, HalosReachIntoTheNeighbouringRegion)
{
    std::vector<RawMap> parts = {state_part(0, 0), state_part(1, 4)};
    BuildOptions opt;
    opt.halo_m = 1000;
    const Out r = by_regions(parts, opt);
    expect_same(whole(parts, opt), r);
    // The tract store of the first state's east county holds tracts of the
    // second state as halo.
    const std::string& bytes = r.stores.at("tract/101");
    const chains::ChainStore s =
        chains::decode(std::as_bytes(std::span<const char>(bytes.data(), bytes.size())), "tract/101");
    bool other_state = false;
    for (const auto& c : s.chains) {
        if ((c.flags & chains::chain_halo) != 0) {
            other_state =
                other_state || s.strings[c.left].rfind("11", 0) == 0 || s.strings[c.right].rfind("11", 0) == 0;
        }
    }
    EXPECT_TRUE(other_state);
}

TEST(Regions, OneRegionIsBuiltWhole)
{
    std::vector<RawMap> parts = {state_part(0, 0)};
    const Out r = by_regions(parts, BuildOptions{});
    EXPECT_FALSE(built_by_regions(r.result));
    expect_same(whole(parts, BuildOptions{}), r);
}

TEST(Regions, ACountyUnderTwoStatesIsAnInputError)
{
    // The first column of state 11 claims county "100", a county of state 10.
    std::vector<RawMap> parts = {state_part(0, 0), state_part(1, 4, "100")};
    try {
        by_regions(parts, BuildOptions{});
        FAIL() << "expected an input error";
    } catch (const input_error& e) {
        EXPECT_NE(
            std::string(e.what()).find("level 'county' does not nest in level 'state': its unit 100 lies in state 10"),
            std::string::npos)
            << e.what();
    }
}

namespace {

/// Each region built alone, as the workflow's jobs build them: parts read
/// back from their bytes (and only the region's own and near ones), shares
/// handed on as bytes, the regions in reverse order; then the finish.
Out by_region_jobs(const std::vector<RawMap>& parts, const BuildOptions& opt)
{
    std::vector<PartSummary> summaries;
    std::vector<std::string> bytes;
    for (const auto& p : parts) {
        summaries.push_back(summarize_part(p));
        bytes.push_back(encode_raw(p));
    }
    const RegionPlan plan = plan_regions(summaries, parts.front().level_names, proj(), opt);
    EXPECT_FALSE(plan.whole);
    Out o;
    std::mutex m;
    std::vector<RegionShare> shares(plan.regions.size());
    for (size_t r = plan.regions.size(); r-- > 0;) {
        const auto& region = plan.regions[r];
        std::set<size_t> allowed(region.parts.begin(), region.parts.end());
        allowed.insert(region.near.begin(), region.near.end());
        const std::function<RawMap(size_t)> load = [&](size_t i) {
            EXPECT_TRUE(allowed.count(i)) << "region " << r << " read part " << i << ", not in its plan";
            return decode_raw(std::as_bytes(std::span(bytes[i].data(), bytes[i].size())), "part");
        };
        RegionJobShare job;
        job.share = build_planned_region(plan, r, load, proj(), opt, collect(o, m));
        const std::string encoded = encode_share(job);
        RegionJobShare back = decode_share(std::as_bytes(std::span(encoded.data(), encoded.size())), "share");
        EXPECT_EQ(encode_share(back), encoded);
        shares[r] = std::move(back.share);
    }
    o.result = finish_planned(plan, std::move(shares), proj(), opt, collect(o, m));
    return o;
}

} // namespace

TEST(Regions, EachRegionAsAJobOfItsOwnGivesTheWholeBuild)
{
    std::vector<RawMap> parts = {state_part(0, 0), state_part(1, 4), state_part(2, 8), state_part(3, 20)};
    for (double halo : {1000.0, 3000.0}) {
        BuildOptions opt;
        opt.halo_m = halo;
        opt.max_problem_samples = 5;
        const Out w = whole(parts, opt);
        const Out j = by_region_jobs(parts, opt);
        expect_same(w, j);
        EXPECT_TRUE(built_by_regions(j.result));
    }
    // The island state is near no other: its job reads its own part alone.
    BuildOptions opt;
    std::vector<PartSummary> summaries;
    for (const auto& p : parts) {
        summaries.push_back(summarize_part(p));
    }
    const RegionPlan plan = plan_regions(summaries, parts.front().level_names, proj(), opt);
    ASSERT_EQ(plan.regions.size(), 4U);
    EXPECT_TRUE(plan.regions[3].near.empty());
    EXPECT_EQ(plan.regions[1].near, (std::vector<size_t>{0, 2}));
}

TEST(Regions, APartAndAShareKeepTheirBytesAndRefuseTruncation)
{
    const RawMap part = state_part(1, 4);
    const std::string bytes = encode_raw(part);
    const RawMap back = decode_raw(std::as_bytes(std::span(bytes.data(), bytes.size())), "p");
    EXPECT_EQ(encode_raw(back), bytes);
    EXPECT_EQ(back.coords, part.coords);
    EXPECT_EQ(back.units.size(), part.units.size());
    for (size_t n : {size_t{0}, size_t{7}, size_t{8}, bytes.size() / 2, bytes.size() - 1}) {
        EXPECT_THROW(decode_raw(std::as_bytes(std::span(bytes.data(), n)), "p"), format_error) << n;
    }
    const std::string longer = bytes + "x";
    EXPECT_THROW(decode_raw(std::as_bytes(std::span(longer.data(), longer.size())), "p"), format_error);

    std::vector<RawMap> parts = {state_part(0, 0), state_part(1, 4)};
    std::vector<PartSummary> summaries;
    for (const auto& p : parts) {
        summaries.push_back(summarize_part(p));
    }
    const BuildOptions opt;
    const RegionPlan plan = plan_regions(summaries, parts.front().level_names, proj(), opt);
    RegionJobShare job;
    job.job = "r-10";
    job.stores = {"county/10"};
    job.store_bytes = {12};
    job.store_mtimes = {-34};
    job.share = build_planned_region(
        plan, 0, [&](size_t i) { return parts.at(i); }, proj(), opt, [](const chains::ChainStore&) {});
    ASSERT_FALSE(job.share.coarse.edges.empty());
    const std::string share = encode_share(job);
    const RegionJobShare head = decode_share_head(std::as_bytes(std::span(share.data(), share.size())), "s");
    EXPECT_EQ(head.job, "r-10");
    EXPECT_EQ(head.store_mtimes, std::vector<int64_t>{-34});
    for (size_t n : {size_t{0}, size_t{9}, share.size() / 2, share.size() - 1}) {
        EXPECT_THROW(decode_share(std::as_bytes(std::span(share.data(), n)), "s"), format_error) << n;
    }
}

TEST(Regions, ACountyUnderTwoStatesIsAnInputErrorOfTheFinishToo)
{
    // As ACountyUnderTwoStatesIsAnInputError, with the regions built apart:
    // two jobs both wrote the tract store of county 100, and the finish names it.
    std::vector<std::string> a{"county/10", "tract/100"}, b{"county/11", "tract/100"};
    RegionPlan plan;
    plan.level = 1;
    try {
        check_each_store_once(plan, {a, b}, {"nation", "state", "county", "tract"});
        FAIL() << "expected an input error";
    } catch (const input_error& e) {
        EXPECT_NE(std::string(e.what()).find("level 'tract': partition '100' has units under two codes of level "
                                             "'state' in different files"),
                  std::string::npos)
            << e.what();
    }
}
