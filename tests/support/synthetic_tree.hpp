#pragma once
// A synthetic Data Tree for the reader tests and the fuzzers' seeds: a
// quadtree of nodes over a square, each with random chains inside its box
// (some sharing endpoints, some closed), and LODs that keep every 2^k-th
// interior vertex. Built with the datatree encoders only, written as a tree
// folder: one tile for the root, one per child subtree of the root.

#include "core/digest.hpp"
#include "core/fs.hpp"
#include "formats/datatree/datatree.hpp"

#include <filesystem>
#include <random>
#include <string>
#include <vector>

namespace tigerlod::testing {

struct SyntheticTree {
    datatree::Skeleton skeleton;
    std::vector<std::string> tiles;                        // bytes, parallel to skeleton.tiles
    std::vector<std::vector<datatree::Geometry>> geometry; // [node][lod]
    std::vector<datatree::ChainTable> tables;
    std::vector<std::vector<std::string>> payloads; // [node][0 table, 1 + lod]

    void write(const std::filesystem::path& dir) const
    {
        std::filesystem::create_directories(dir / "tiles");
        for (size_t t = 0; t < tiles.size(); ++t) {
            write_file_atomic(dir / skeleton.tiles[t].file, tiles[t]);
        }
        write_file_atomic(dir / "skeleton.tls", datatree::encode_skeleton(skeleton));
    }
};

/// `depth` levels below the root; the root box is [0, size]^2 grid units.
inline SyntheticTree make_synthetic_tree(uint32_t depth, int32_t size = 1 << 20, uint32_t seed = 1, uint32_t nlods = 3)
{
    SyntheticTree t;
    auto& sk = t.skeleton;
    sk.projection[7] = 0.01; // grid_m
    for (uint32_t l = 0; l <= depth; ++l) {
        sk.level_names.push_back("level" + std::to_string(l));
    }
    for (uint32_t k = 0; k < nlods; ++k) {
        sk.lod_eps_m.push_back(k == 0 ? 0.0 : 10.0 * (1 << (2 * k)));
    }
    std::mt19937 rng(seed); // 32-bit results, taken as uint32_t below
    // Nodes breadth-first: a queue of (box, level).
    struct Pending {
        datatree::Box box;
        uint32_t level, parent;
        std::string code;
    };
    std::vector<Pending> todo{{{0, 0, size, size}, 0, datatree::no_node, ""}};
    for (size_t i = 0; i < todo.size(); ++i) {
        const Pending p = todo[i];
        datatree::Node n;
        n.parent = p.parent;
        n.level = p.level;
        n.code = 0;
        if (!p.code.empty()) {
            n.code = static_cast<uint32_t>(sk.strings.size());
            sk.strings.push_back(p.code);
        }
        if (p.level < depth) {
            n.first_child = static_cast<uint32_t>(todo.size());
            n.child_count = 4;
            const int32_t mx = p.box.min_x + (p.box.max_x - p.box.min_x) / 2;
            const int32_t my = p.box.min_y + (p.box.max_y - p.box.min_y) / 2;
            const datatree::Box q[4] = {{p.box.min_x, p.box.min_y, mx, my},
                                        {mx, p.box.min_y, p.box.max_x, my},
                                        {p.box.min_x, my, mx, p.box.max_y},
                                        {mx, my, p.box.max_x, p.box.max_y}};
            for (int c = 0; c < 4; ++c) {
                todo.push_back({q[c], p.level + 1, static_cast<uint32_t>(i), p.code + char('a' + c)});
            }
        }
        // Chains: random walks inside the box.
        const int32_t w = p.box.max_x - p.box.min_x, h = p.box.max_y - p.box.min_y;
        std::uniform_int_distribution<int32_t> ux(p.box.min_x, p.box.max_x), uy(p.box.min_y, p.box.max_y);
        std::uniform_int_distribution<int32_t> step(-std::max(1, w / 64), std::max(1, w / 64));
        const auto nchains = static_cast<uint32_t>(3 + rng() % 4);
        datatree::Geometry g0;
        datatree::ChainTable table;
        table.strings = {"", "u1", "u2", "S1400"};
        GridPoint last{ux(rng), uy(rng)};
        for (uint32_t c = 0; c < nchains; ++c) {
            std::vector<GridPoint> pts;
            const bool closed = c % 3 == 2;
            const GridPoint start = (c % 2 == 1) ? last : GridPoint{ux(rng), uy(rng)};
            pts.push_back(start);
            const auto m = static_cast<uint32_t>(10 + rng() % 60);
            for (uint32_t k = 0; k < m; ++k) {
                GridPoint q{pts.back().x + step(rng), pts.back().y + step(rng)};
                q.x = std::clamp(q.x, p.box.min_x, p.box.min_x + w);
                q.y = std::clamp(q.y, p.box.min_y, p.box.min_y + h);
                pts.push_back(q);
            }
            if (closed) {
                pts.push_back(start);
            }
            last = pts.back();
            g0.add_chain(pts);
            table.chains.push_back({1000 * i + c, 1, 2, 3, closed ? 1U : 0U});
        }
        n.chains = nchains;
        n.box = p.box;
        std::vector<datatree::Geometry> lods{g0};
        for (uint32_t k = 1; k < nlods; ++k) {
            datatree::Geometry g;
            const size_t keep = size_t{1} << k;
            for (size_t c = 0; c < g0.chain_count(); ++c) {
                const auto src = g0.chain(c);
                std::vector<GridPoint> pts{src.front()};
                for (size_t v = 1; v + 1 < src.size(); ++v) {
                    if (v % keep == 0) {
                        pts.push_back(src[v]);
                    }
                }
                pts.push_back(src.back());
                g.add_chain(pts);
            }
            lods.push_back(std::move(g));
        }
        std::vector<std::string> pl{datatree::encode_table(table)};
        for (uint32_t k = 0; k < nlods; ++k) {
            datatree::LodInfo li;
            li.error_m = 0.5 * k * k * sk.lod_eps_m[1 % nlods];
            li.vertices = lods[k].points.size();
            n.lods.push_back(li);
            pl.push_back(datatree::encode_geometry(lods[k], {p.box.min_x, p.box.min_y}));
        }
        sk.nodes.push_back(n);
        t.geometry.push_back(std::move(lods));
        t.tables.push_back(std::move(table));
        t.payloads.push_back(std::move(pl));
    }
    // Tiles: the root alone, then each child subtree of the root.
    std::vector<std::vector<uint32_t>> members(1 + (depth > 0 ? 4 : 0));
    members[0].push_back(0);
    for (uint32_t i = 1; i < sk.nodes.size(); ++i) {
        uint32_t top = i;
        while (sk.nodes[top].parent != 0) {
            top = sk.nodes[top].parent;
        }
        members[top].push_back(i);
    }
    for (uint32_t tile = 0; tile < members.size(); ++tile) {
        std::string bytes = datatree::tile_header(0);
        auto place = [&](const std::string& pl) {
            datatree::PayloadRef r{tile, bytes.size(), static_cast<uint32_t>(pl.size()),
                                   crc32(std::as_bytes(std::span(pl.data(), pl.size())))};
            bytes += pl;
            return r;
        };
        for (uint32_t n : members[tile]) {
            sk.nodes[n].table = place(t.payloads[n][0]);
            for (uint32_t k = 0; k < nlods; ++k) {
                sk.nodes[n].lods[k].payload = place(t.payloads[n][1 + k]);
            }
        }
        const std::string head = datatree::tile_header(bytes.size());
        std::copy(head.begin(), head.end(), bytes.begin());
        sk.tiles.push_back({"tiles/t" + std::to_string(tile) + ".tlt", bytes.size()});
        t.tiles.push_back(std::move(bytes));
    }
    return t;
}

} // namespace tigerlod::testing
