// simplification/scan_lanes.ipp: the lanes kernel of the candidate scan,
// included by candidates.cpp once per instruction set, each time inside a
// namespace of its own and a `#pragma GCC target` for that set, after
// defining there: V (`lanes` doubles as a GCC vector), M (the masks their
// comparisons give, all bits set or none), `lanes`, and
//   int bits(M)     bit l set when lane l of the mask is,
//   V root(V)       the square root of each lane (correctly rounded, as
//                   std::sqrt),
//   V iota()        0, 1, ..., lanes - 1.
// So the kernels differ in their width only: every lane does the scalar
// scan's IEEE operations in the same order (no fused multiply-adds:
// -ffp-contract=off), and each finds what scan<> finds.
// No include guard: it is meant to be included more than once.

/// a where m is set, else b.
inline V select(M m, V a, V b) noexcept
{
    return m ? a : b; // a blend (each lane of m is all ones or all zeros)
}
/// `lanes` doubles from p on.
inline V load(const double* p) noexcept
{
    V v;
    std::memcpy(&v, p, sizeof v);
    return v;
}
/// x cross y, as Arc computes it: x.x y.y - x.y y.x. Swapping x and y gives
/// exactly its negation (the same two products, subtracted the other way).
inline V cross(V xx, V xy, V yx, V yy) noexcept
{
    return xx * yy - xy * yx;
}

/// Per lane of the group of starts j, j + 1, ...: how many ends it tests (0
/// where no start of [j, starts_hi) is), and the most of them.
inline double lane_steps(uint32_t j, uint32_t n, uint32_t starts_hi, uint32_t max_reach, V& steps) noexcept
{
    steps = V{};
    double longest = 0;
    for (int l = 0; l < lanes; ++l) {
        const uint32_t start = j + static_cast<uint32_t>(l);
        if (start + 2 < n && start < starts_hi) {
            const auto last = max_reach ? std::min<uint64_t>(n - 1, uint64_t{start} + max_reach) : n - 1;
            steps[l] = double(last - (start + 1));
            longest = std::max(longest, steps[l]);
        }
    }
    return longest;
}

/// scan<> for L2 on `lanes` consecutive starts at once, one per lane, every
/// lane doing the scalar scan's arithmetic (no fused multiply-adds), so
/// both find the same shortcuts (tests compare them; so does scan_bench's
/// hash, on the tract set at 1 to 64 m): the wedge's narrowing, the choice
/// of its edges and the tests of each end become selects on masks instead
/// of branches. Lane l starts at j + l and tests end j + l + 2 + t at step
/// t; a group runs until its longest lane ends (5% more lane steps than the
/// scalar scan's on the tract set with four lanes: consecutive starts reach
/// about as far).
/// Exact in doubles because every coordinate difference is under 2^26 (the
/// caller checks): squared lengths are integers below 2^53.
/// `ran_out`, if given, gets the starts whose scan reached the last vertex
/// of `pts` with the wedge still open (not stopped by `max_reach`): where
/// `pts` is a window of a longer chain, those may have shortcuts beyond it.
void scan_lanes(std::span<const GridPoint> pts, const Tolerance& tol, uint32_t max_reach, int128 reps2,
                uint32_t starts_lo, uint32_t starts_hi, Candidates& out, std::vector<uint32_t>* ran_out = nullptr)
{
    const auto n = static_cast<uint32_t>(pts.size());
    // The points as doubles, padded so that lanes past the end read copies of the last point.
    std::vector<double> xs(n + 2 * lanes), ys(n + 2 * lanes);
    for (uint32_t i = 0; i < n + 2 * lanes; ++i) {
        const GridPoint p = pts[std::min(i, n - 1)];
        xs[i] = p.x;
        ys[i] = p.y;
    }
    const double reps2_d = double(reps2);
    const WedgeConstants wc(reps2);
    const double r_eps = wc.r_eps, cos_s = wc.cos_s, sin_s = wc.sin_s, deep2 = wc.deep2;
    const double eps_cos = r_eps * cos_s, eps_sin = r_eps * sin_s; // scan<>'s products
    // Per lane, the runs it closed in this group, and its unsure ends' test.
    std::vector<Candidates::Run> closed[lanes];
    std::vector<UnsureEnds> unsure(lanes, UnsureEnds(tol, r_eps, r_eps)); // L2: the ball is the disc
    for (uint32_t j = starts_lo; j + 2 < n && j < starts_hi; j += lanes) {
        for (int l = 0; l < lanes; ++l) {
            unsure[l].reset(j + static_cast<uint32_t>(l));
        }
        V steps; // per lane, how many ends it tests (0: no start there)
        const double longest = lane_steps(j, n, starts_hi, max_reach, steps);
        const V ax = load(&xs[j]), ay = load(&ys[j]);
        V wax{}, way{}, wbx{}, wby{}; // the wedge's arc, from WA counter-clockwise to WB
        M open = ~M{};                // no arc yet
        M alive = steps > 0;          // ends left to test, and the wedge not empty
        // The largest squared distance of an intermediate vertex from the
        // start; infinite once a constraint was left out of the wedge (no
        // end is then sure without the exact test, as in scan<>).
        V far2{};
        V k = iota() + double(j + 2);
        // Per lane, its run: hi the last end found (-2 for none yet), lo[l] its first.
        V hi = V{} - 2;
        uint32_t lo[lanes] = {};
        // Steps go in blocks: first what each step needs that does not
        // depend on the wedge (the constraint's arc, through a square root),
        // for the whole block, then the wedge's narrowing step by step. So
        // the roots' latency overlaps, where one step at a time waits on each.
        struct Step {
            V oax, oay, obx, oby; // the constraint's arc OA -> OB (arc_around)
            M narrow;             // the constraint narrows the wedge
            V far;                // its squared distance, or infinity where it was left out
            V bx, by, len2;       // end k, from the start
        };
        Step block[block_steps];
        bool more = true;
        M ended{}; // lanes that tested their last end with the wedge open
        for (double t0 = 0; more && t0 < longest; t0 += block_steps) {
            const int count = static_cast<int>(std::min<double>(block_steps, longest - t0));
            for (int i = 0; i < count; ++i) {
                Step& st = block[i];
                const auto at = static_cast<size_t>(j + 1 + static_cast<uint32_t>(t0) + static_cast<uint32_t>(i));
                const V qx = load(&xs[at]) - ax, qy = load(&ys[at]) - ay;
                const V r2 = qx * qx + qy * qy;
                const V d = r2 - reps2_d;
                const V c = root(select(d < 0, -d, d));
                const M constrained = r2 > reps2_d;
                const V sin_w = eps_cos + c * sin_s, cos_w = c * cos_s - eps_sin;
                const M too_wide = cos_w <= 1e-6 * (c + r_eps);
                st.far = select(constrained & too_wide, V{} + HUGE_VAL, r2);
                st.narrow = constrained & ~too_wide;
                st.oax = qx * cos_w + qy * sin_w;
                st.oay = qy * cos_w - qx * sin_w;
                st.obx = qx * cos_w - qy * sin_w;
                st.oby = qy * cos_w + qx * sin_w;
                st.bx = load(&xs[at + 1]) - ax;
                st.by = load(&ys[at + 1]) - ay;
                st.len2 = st.bx * st.bx + st.by * st.by;
            }
            for (int i = 0; i < count; ++i, k += 1) {
                const Step& st = block[i];
                const M before = alive;
                alive &= V{} + (t0 + i) < steps;
                ended |= before & ~alive; // tested every end, the wedge open
                if (bits(alive) == 0) {
                    more = false;
                    break;
                }
                // Vertex k - 1 becomes an intermediate vertex: narrow the
                // wedge (Arc::intersect): each edge of the wedge stays if the
                // arc holds it, else the arc's if the wedge holds that, else
                // the intersection is empty.
                far2 = select(far2 < st.far, st.far, far2);
                const M narrow = st.narrow;
                const V oa_wa = cross(st.oax, st.oay, wax, way), wa_ob = cross(wax, way, st.obx, st.oby);
                const V oa_wb = cross(st.oax, st.oay, wbx, wby), wb_ob = cross(wbx, wby, st.obx, st.oby);
                const M o_holds_wa = (oa_wa >= 0) & (wa_ob >= 0);
                const M holds_oa = (oa_wa <= 0) & (oa_wb >= 0); // wa x oa >= 0, oa x wb >= 0
                const M o_holds_wb = (oa_wb >= 0) & (wb_ob >= 0);
                const M holds_ob = (wa_ob >= 0) & (wb_ob <= 0); // wa x ob >= 0, ob x wb >= 0
                const M empty = ~open & ((~o_holds_wa & ~holds_oa) | (~o_holds_wb & ~holds_ob));
                const M take_a = narrow & (open | ~o_holds_wa), take_b = narrow & (open | ~o_holds_wb);
                alive &= ~(narrow & empty);
                wax = select(take_a, st.oax, wax);
                way = select(take_a, st.oay, way);
                wbx = select(take_b, st.obx, wbx);
                wby = select(take_b, st.oby, wby);
                open &= ~narrow;
                // End k: in the wedge, and surely or exactly proximate. An
                // end equal to the start (len2 = 0) is never sure, and the
                // exact branch leaves it out, as scan<> does.
                const V c1 = cross(wax, way, st.bx, st.by), c2 = cross(st.bx, st.by, wbx, wby);
                const M tested = alive & (open | ((c1 >= 0) & (c2 >= 0)));
                const M deep = open | ((c1 > 0) & (c2 > 0) & (c1 * c1 >= deep2 * (wax * wax + way * way) * st.len2) &
                                       (c2 * c2 >= deep2 * (wbx * wbx + wby * wby) * st.len2));
                M found = tested & (far2 * (1 + 1e-12) < st.len2) & deep;
                if (const int left = bits(tested & ~found)) {
                    // Deep in a complete wedge (far2 is infinite once a
                    // constraint was left out of it).
                    const int deep_complete = bits(deep & (far2 < HUGE_VAL));
                    for (int l = 0; l < lanes; ++l) {
                        const uint32_t start = j + static_cast<uint32_t>(l), end = static_cast<uint32_t>(k[l]);
                        if ((left >> l & 1) != 0 && pts[end] != pts[start] &&
                            unsure[l].proximate(pts, end, (deep_complete >> l & 1) != 0)) {
                            found[l] = ~int64_t{0};
                        }
                    }
                }
                // A found end extends its lane's run, or opens one (after a gap: the old one goes out).
                if (const int opened = bits(found & (hi + 1 != k))) {
                    for (int l = 0; l < lanes; ++l) {
                        if ((opened >> l & 1) != 0) {
                            if (hi[l] >= 0) {
                                closed[l].push_back(
                                    {j + static_cast<uint32_t>(l), lo[l], static_cast<uint32_t>(hi[l])});
                            }
                            lo[l] = static_cast<uint32_t>(k[l]);
                        }
                    }
                }
                hi = select(found, k, hi);
            }
        }
        if (ran_out) {
            ended |= alive; // the longest lanes, open to the end
            for (int l = 0; l < lanes; ++l) {
                const uint32_t start = j + static_cast<uint32_t>(l);
                if (ended[l] != 0 && (max_reach == 0 || uint64_t{start} + max_reach >= n - 1)) {
                    ran_out->push_back(start);
                }
            }
        }
        for (int l = 0; l < lanes; ++l) {
            for (const auto& r : closed[l]) {
                out.add_run(r.from, r.lo, r.hi);
            }
            closed[l].clear();
            if (hi[l] >= 0) {
                out.add_run(j + static_cast<uint32_t>(l), lo[l], static_cast<uint32_t>(hi[l]));
            }
        }
    }
}
