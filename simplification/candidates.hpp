#pragma once
/// @file candidates.hpp
/// Step 0 and Step 3 of the paper on the CPU, exactly: the proximate
/// shortcuts of a chain, and the point constraints that cull them.

#include "core/geometry.hpp"
#include "core/metric.hpp"

#include <cstdint>
#include <span>
#include <vector>

namespace tigerlod::simplify {

/// One shortcut v_from -> v_to (to > from + 1) of a chain.
struct Shortcut {
    uint32_t from = 0, to = 0;
    friend bool operator==(const Shortcut&, const Shortcut&) = default;
};

/// The proximate shortcuts of a chain, as runs of consecutive ends: most
/// starts reach every vertex from from + 2 up to the last one within eps
/// (one run for 88% of the tract set's starts), so a run stands for dozens
/// of shortcuts (77.7 M shortcuts in 2.2 M runs on the tract level at 16 m).
/// Each shortcut has an id, numbered by (from, to): the states the
/// simplifier keeps per shortcut are indexed by it.
class Candidates {
  public:
    struct Run {
        uint32_t from = 0, lo = 0, hi = 0; ///< shortcuts from -> lo, ..., from -> hi
    };

    /// Appends shortcut from -> to; calls come in (from, to) order.
    void add(uint32_t from, uint32_t to) { add_run(from, to, to); }
    /// Appends shortcuts from -> lo, ..., from -> hi; calls come in (from, to) order.
    void add_run(uint32_t from, uint32_t lo, uint32_t hi)
    {
        if (!m_runs.empty() && m_runs.back().from == from && m_runs.back().hi + 1 == lo) {
            m_runs.back().hi = hi;
        } else {
            m_runs.push_back({from, lo, hi});
        }
    }
    /// Appends the runs of `later` (not finished), whose starts all follow this one's.
    void append(const Candidates& later);
    /// The shortcuts of the runs so far, finished or not, counted without
    /// the 32 bits of an id: a chain can have more (a coast of millions of
    /// vertices at kilometres), which finish() refuses.
    uint64_t count() const noexcept;
    /// Ends the list for a chain of `n` vertices; add() may not follow.
    /// Throws std::length_error if count() passes max_ids: the ids would wrap.
    void finish(uint32_t n);
    /// The most shortcuts a chain's ids can number.
    static constexpr uint64_t max_ids = UINT32_MAX;

    /// Shortcuts in all.
    uint32_t size() const noexcept { return m_base.empty() ? 0 : m_base.back(); }
    bool empty() const noexcept { return size() == 0; }
    std::span<const Run> runs() const noexcept { return m_runs; }
    /// The runs from vertex v.
    std::span<const Run> runs_from(uint32_t v) const noexcept
    {
        return m_run_first.empty()
                   ? std::span<const Run>{}
                   : std::span<const Run>(m_runs).subspan(m_run_first[v], m_run_first[v + 1] - m_run_first[v]);
    }
    /// Id of the first shortcut of run `r` (an index into runs()); the run's
    /// shortcut to k has id run_id(r) + k - lo. run_id(runs().size()) == size().
    uint32_t run_id(size_t r) const noexcept { return m_base[r]; }
    /// Index in runs() of the first run from v.
    uint32_t first_run(uint32_t v) const noexcept { return m_run_first.empty() ? 0 : m_run_first[v]; }
    /// The ids of the shortcuts from v: [first_id(v), first_id(v + 1)).
    uint32_t first_id(uint32_t v) const noexcept { return m_run_first.empty() ? 0 : m_base[m_run_first[v]]; }
    /// The shortcut with id `id` (< size()).
    Shortcut at(uint32_t id) const noexcept;
    /// Every shortcut, in id order.
    std::vector<Shortcut> list() const;

  private:
    std::vector<Run> m_runs;
    /// Per vertex, its first run: n + 1 entries once finished with shortcuts, else none.
    std::vector<uint32_t> m_run_first;
    /// Per run, the id of its first shortcut, and the count in all: runs + 1 entries.
    std::vector<uint32_t> m_base;
}; // class Candidates

/// Every proximate shortcut of `pts`: each original vertex strictly between
/// the ends lies within `tol` of the segment (the segment, not its line, so
/// chains that turn back are handled). Shortcuts with equal ends (a ring's
/// closure) are left out, and so are those reaching more than `max_reach`
/// vertices ahead (0: no cap).
///
/// O(n * w) for w the reach of a shortcut: for each start, the directions in
/// which a segment can pass within eps of every vertex seen so far form a
/// wedge that only narrows; the scan stops when it is empty, and the exact
/// test runs only for ends near the wedge's edges or beyond the farthest
/// intermediate vertex.
Candidates proximate_shortcuts(std::span<const GridPoint> pts, const Tolerance& tol, uint32_t max_reach);

/// Which code proximate_shortcuts runs. `fastest`, for L2: the hull scan
/// where the tolerance is coarse for the chain's spacing and every
/// coordinate difference of the chain is under 2^31 (hull_scan.hpp: blocks
/// of ends decided at once), else, where the differences are under 2^26,
/// several starts at once on x86-64 processors (`lanes`: eight with
/// AVX-512F, four with AVX2; `lanes4`: four, with AVX2); the scalar scan
/// elsewhere. `scalar`, `lanes`, `lanes4` and `hulls` run that scan
/// wherever it can (the scalar one elsewhere), so tests and benchmarks can
/// compare: all give the same shortcuts, each exactly (`scalar` and the
/// lanes with the same IEEE operations in the same order, `hulls` by its
/// own proofs).
enum class ScanKernel { fastest, scalar, lanes, lanes4, hulls };
/// What `fastest` runs on this processor where the hull scan does not pay
/// (hull_scan_pays): "avx512", "avx2" or "scalar".
const char* fastest_scan_kernel() noexcept;
Candidates proximate_shortcuts(std::span<const GridPoint> pts, const Tolerance& tol, uint32_t max_reach,
                               ScanKernel kernel);

/// The shortcuts from the starts in [first, last) only, not finished: each
/// start's scan depends on no other, so the pieces of a long chain can run on
/// threads of their own, and appended in order (Candidates::append) and
/// finished they are proximate_shortcuts' result, byte for byte.
///
/// With `end_sample` R > 0, a chain the hull scan takes (`fastest`, the
/// tolerance coarse for its spacing) has its shortcuts start and end only
/// at the vertices a greedy fit within eps / R keeps (hull_scan.hpp,
/// greedy_fit_vertices): a subset of its proximate shortcuts that holds the
/// original edges, so every rule tests them as before and the output keeps
/// every guarantee, with a few vertices more than the minimum where the
/// fewest-vertex path would have turned between the fit's vertices
/// (simplification/README.md, "Ends at a greedy fit's vertices").
Candidates proximate_shortcuts_from(std::span<const GridPoint> pts, const Tolerance& tol, uint32_t max_reach,
                                    uint32_t first, uint32_t last, ScanKernel kernel = ScanKernel::fastest,
                                    uint32_t end_sample = 0);

/// Point constraints (Algorithm 5.2, exact): the ids of the shortcuts whose
/// region between them and the original subchain holds one of `points`
/// (inside, or on the shortcut other than at its ends: a junction at a
/// shortcut's end is on both sides), in increasing order. The region's even-odd
/// test is accumulated along the subchain, so each (start, point) pair costs
/// O(reach).
std::vector<uint32_t> cull_by_points(std::span<const GridPoint> pts, const Candidates& cand,
                                     std::span<const GridPoint> points);

} // namespace tigerlod::simplify
