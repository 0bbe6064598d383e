// scan_bench LEVEL_DIR EPS_M [ROUNDS [scalar|lanes|lanes4|hulls]]: the candidate scan of
// tigerlod-simplify (proximate_shortcuts) alone, on one thread, over the owned
// chains of every chain store of a level, at the tolerances tigerlod-simplify
// would use; with `scalar`, `lanes` or `hulls`, that kernel instead of the
// one tigerlod-simplify chooses. Prints the kernel, the fastest round's seconds, the shortcuts
// and runs found, and a hash of them, so two builds or two kernels of the scan
// can be compared for speed and for identical answers on the same stores.
#include "formats/chains/chain_store.hpp"
#include "simplification/candidates.hpp"
#include "simplification/simplifier.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using namespace tigerlod;
using namespace tigerlod::simplify;

int main(int argc, char** argv)
{
    if (argc < 3) {
        std::fprintf(stderr, "usage: scan_bench LEVEL_DIR EPS_M [ROUNDS [scalar|lanes|lanes4|hulls]]\n");
        return 2;
    }
    const double eps_m = std::atof(argv[2]);
    const int rounds = argc > 3 ? std::atoi(argv[3]) : 3;
    const std::string name = argc > 4 ? argv[4] : "fastest";
    const ScanKernel kernel = name == "scalar"   ? ScanKernel::scalar
                              : name == "lanes"  ? ScanKernel::lanes
                              : name == "lanes4" ? ScanKernel::lanes4
                              : name == "hulls"  ? ScanKernel::hulls
                                                 : ScanKernel::fastest;
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(argv[1])) {
        if (e.path().extension() == ".tlc") {
            files.push_back(e.path());
        }
    }
    std::sort(files.begin(), files.end());
    std::vector<chains::ChainStore> stores;
    std::vector<std::vector<double>> eps;
    for (const auto& f : files) {
        stores.push_back(chains::read(f));
        eps.push_back(chain_tolerances(stores.back(), eps_m, SimplifyOptions{}));
    }
    double best = 1e300;
    uint64_t shortcuts = 0, runs = 0, hash = 0;
    for (int r = 0; r < rounds; ++r) {
        shortcuts = runs = 0;
        hash = 1469598103934665603ULL;
        const auto t0 = std::chrono::steady_clock::now();
        for (size_t s = 0; s < stores.size(); ++s) {
            const auto& st = stores[s];
            for (size_t c = 0; c < st.chains.size(); ++c) {
                if (st.chains[c].flags & (chains::chain_halo | chains::chain_problem)) {
                    continue;
                }
                const auto cand =
                    proximate_shortcuts(st.chain_points(st.chains[c]), Tolerance(eps[s][c], Metric::l2), 0, kernel);
                shortcuts += cand.size();
                runs += cand.runs().size();
                for (const auto& run : cand.runs()) {
                    for (const uint32_t x : {run.from, run.lo, run.hi}) {
                        hash = (hash ^ x) * 1099511628211ULL;
                    }
                }
            }
        }
        best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }
    std::printf("{\"kernel\": \"%s\", \"seconds\": %.3f, \"shortcuts\": %llu, \"runs\": %llu, \"hash\": \"%016llx\"}\n",
                name == "fastest" ? (std::string("hulls or ") + fastest_scan_kernel()).c_str() : name.c_str(), best,
                static_cast<unsigned long long>(shortcuts), static_cast<unsigned long long>(runs),
                static_cast<unsigned long long>(hash));
    return 0;
}
