#pragma once
/// @file nation.hpp
/// A synthetic nation for tigerlod-synth: a planar map in TIGER/Line's
/// terms (edges between nodes, faces with a state > county > tract > block
/// group > block hierarchy), built so that it is planar on TIGER's 1e-6
/// degree lattice by construction, deterministic for a seed, and any
/// county's part computable on its own.
///
/// Construction (README.md beside this file has the figures):
/// - A lattice of (W+1) x (H+1) nodes, rows and columns of varying width
///   (some a twentieth of the rest: near-parallel borders metres apart), each
///   node moved by a seeded jitter; every cell is a convex quadrilateral
///   (checked exactly) and one face.
/// - Each lattice edge is a polyline from one node to the next whose inner
///   vertices lie strictly inside the convex quadrilateral (A, h_R, B, h_L),
///   h the point 0.6 of the way from the edge's middle to a side cell's
///   centre. Those quadrilaterals lie in the triangles (A, B, centre) that
///   fan each convex cell, so two edges' quadrilaterals share at most a
///   node, and every vertex is tested against its quadrilateral with exact
///   integer predicates after rounding: no two edges meet but at a node.
///   Each polyline is monotone along AB, so it does not meet itself.
/// - Inside a cell, away from every edge's quadrilateral: a dangling road
///   from a corner toward the centre (a face on both sides), a lake ring
///   around the centre, and an island ring inside the lake, their radii in
///   disjoint ranges.
/// - Units grow from seeds over the cells by a shortest-path race with
///   random costs, each level inside its parent: connected, irregular.
///
/// Coordinates are integers in millionths of a degree (lon, lat), TIGER's
/// published precision; differences stay below 2^31, so every predicate
/// is exact in 64-bit integers.

#include <cstdint>
#include <string>
#include <vector>

namespace tigerlod::synth {

/// A point in millionths of a degree.
struct Pt {
    int64_t x = 0, y = 0; ///< lon x 1e6, lat x 1e6
    friend bool operator==(const Pt&, const Pt&) = default;
};

/// Twice the signed area of abc: > 0 when c is left of ab. Exact for
/// coordinate differences below 2^31.
inline int64_t orient(Pt a, Pt b, Pt c)
{
    return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
}

/// sin(2 pi x), x in turns, from + and * alone (the odd Taylor polynomial
/// to degree 11 on a quarter turn, error below 1e-7): the same bits on
/// every machine, where libm's sin is chosen by processor.
double sin_turns(double x);
/// cos(2 pi x), likewise.
inline double cos_turns(double x)
{
    return sin_turns(x + 0.25);
}

/// What to generate.
struct SynthOptions {
    uint64_t seed = 1;
    int states = 2;
    int counties_per_state = 4;
    int64_t target_vertices = 1'000'000; ///< over every EDGES file, each edge counted once
    double cell_m = 400;                 ///< the lattice's spacing on the ground
    double lon0 = -98, lat0 = 39;        ///< the nation's centre, degrees
};

/// The levels, coarsest first.
enum Level : int { state = 0, county, tract, block_group, block, level_count };
inline constexpr const char* level_names[level_count] = {"state", "county", "tract", "block_group", "block"};

/// One unit of a level: its parent (in the level before) and its code
/// within the parent (STATEFP20, COUNTYFP20, TRACTCE20, BLKGRPCE20,
/// BLOCKCE20).
struct Unit {
    uint32_t parent = 0;
    std::string code;
    uint32_t cells = 0;
};

/// An edge as TIGER EDGES holds it.
struct Edge {
    int64_t tlid = 0, tfidl = 0, tfidr = 0; ///< 0: no face on that side (outside the nation)
    int64_t tnidf = 0, tnidt = 0;
    const char* mtfcc = "";
    std::vector<Pt> points;
};

/// A face as TIGER FACES holds it (its polygon: outer ring, then holes).
struct Face {
    int64_t tfid = 0;
    uint32_t block = 0; ///< the unit of the block level
    bool water = false;
    Pt intpt;
    std::vector<std::vector<Pt>> rings;
};

/// The plan of the whole nation: the lattice and the units per level.
/// Everything else (geometry) is a function of it and the seed.
class Nation {
  public:
    explicit Nation(const SynthOptions& options);

    int width() const noexcept { return m_w; }  ///< cells
    int height() const noexcept { return m_h; } ///< cells
    const std::vector<Unit>& units(Level l) const noexcept { return m_units[l]; }
    /// The unit of `level` that cell (i, j) belongs to.
    uint32_t unit_of(int i, int j, Level level) const;
    /// The cells of each county, in (j, i) order.
    const std::vector<std::vector<uint32_t>>& county_cells() const noexcept { return m_county_cells; }

    /// A county's EDGES and FACES. Edges: every lattice edge bounding one of
    /// its cells (an edge on its border also goes to the neighbour's file,
    /// with the same TLID), and the dangles and rings inside its cells, in a
    /// fixed order. Faces: every face of its cells.
    struct CountyParts {
        std::vector<Edge> edges;
        std::vector<Face> faces;
    };
    CountyParts county_parts(uint32_t county) const;

    /// The county a face of county_faces() lies in.
    uint32_t county_of_face(int64_t tfid) const { return m_cell_unit[county][size_t((tfid - 1) / 3)]; }

    /// Node (i, j) of the lattice.
    Pt node(int i, int j) const;

  private:
    struct CellShape;
    CellShape cell_shape(int i, int j) const;
    using Polyline = std::vector<Pt>;
    /// The cells on the left and right of a lattice edge, and whether they exist.
    struct EdgeSides {
        int li = 0, lj = 0, ri = 0, rj = 0;
        bool has_l = false, has_r = false;
    };
    EdgeSides edge_sides(bool vertical, int i, int j) const;
    void lattice_edge(bool vertical, int i, int j, Polyline pts, std::vector<Edge>& out) const;
    Polyline lattice_polyline(bool vertical, int i, int j) const;
    /// The dangles and rings of cell (i, j) into `edges`, its faces into
    /// `faces`; `sides` its lattice polylines (bottom, right, top, left, each
    /// from the lower node). In steps: the frame, the dangles, the lake, the faces.
    void cell_inner(int i, int j, const Polyline* sides[4], std::vector<Edge>& edges, std::vector<Face>& faces) const;
    struct CellFrame;
    /// A cell's lake and island rings (empty where it has none), and the
    /// radius of the disc they lie in.
    struct Lake {
        std::vector<Pt> lake, island;
        double radius = 0;
    };
    CellFrame cell_frame(int i, int j) const;
    std::vector<std::vector<Pt>> cell_dangles(int i, int j, const CellFrame& f, std::vector<Edge>& edges) const;
    Lake cell_lake(const CellFrame& f) const;
    void cell_faces(int i, int j, const CellFrame& f, const Polyline* sides[4],
                    const std::vector<std::vector<Pt>>& dangles, const Lake& lake, std::vector<Face>& faces) const;
    void grow(Level level, int grain);

    SynthOptions m_opt;
    int m_w = 0, m_h = 0;
    std::vector<int64_t> m_col_x, m_row_y; ///< cumulative positions of the lattice lines
    int64_t m_jitter_x = 0, m_jitter_y = 0;
    std::vector<uint32_t> m_cell_unit[level_count];
    std::vector<Unit> m_units[level_count];
    std::vector<std::vector<uint32_t>> m_county_cells;
    std::vector<float> m_rugged; ///< per cell: how wiggly its edges are, a smooth field in [0, 1]
};                               // class Nation

/// The ids of everything a Nation writes, unique over the nation.
int64_t lattice_tlid(const Nation& n, bool vertical, int i, int j, int part);

} // namespace tigerlod::synth
