#pragma once
// Stitched patch edges: how AQP patches drawn at different levels meet without cracks
// (semi-uniform adaptive patch tessellation, Dyken et al. 2009, as in seed paper 001 §5).
//
// Every patch edge is drawn at one level both patches sharing it agree on: the coarser of their
// two drawn levels (edge_levels). A level's edge samples are every other sample of the finer
// level's (levels nest exactly, and shared edge samples are bit-identical in both patches,
// docs/formats/aqp.md), so the finer patch can draw the coarse edge from its own samples: each
// of its samples on that edge is *snapped* to the nearest sample of the coarse edge (snap_sample),
// which collapses the grid's first row of cells onto the coarse edge: triangles that lose an
// edge become degenerate (they draw nothing and are left out of the drawn geometry), the others
// fan from the coarse edge samples to the second row. The patch's interior stays at its own
// level. Both patches then end on the same polyline through the same samples: no T-junction, no
// crack. One template grid per level serves every combination of edge levels: the vertex shader
// (shaders/aqp.vert) snaps with the same integer arithmetic as snap_sample.
#include <array>
#include <cstdint>
#include <vector>

#include "aqp/format.h"

namespace catpaq {

// The index of sample (i, j) of a patch of `size` samples per side snapped for edge levels
// `edge_level` (per edge 0..3, each <= level): a sample on edge e (0: j = 0, 1: i = size - 1,
// 2: j = size - 1, 3: i = 0) moves along the edge to the nearest multiple of 2^(level -
// edge_level[e]), ties towards the larger index; corners never move.
std::array<int, 2> snap_sample(int i, int j, int level, const std::array<int, 4>& edge_level);

// The level each edge of `patch` is drawn at when it is drawn at `level`: the coarser of its own
// and the neighbour's across that edge (`drawn_level(q)`: patch q's drawn level, or -1 when q is
// not drawn: then its own; also on the surface's border).
template <class DrawnLevel>
std::array<int, 4> edge_levels(const aqp::AqpMeta& meta, uint32_t patch, int level, DrawnLevel&& drawn_level) {
    std::array<int, 4> out{level, level, level, level};
    for (int e = 0; e < 4; ++e) {
        const aqp::PatchLink& link = meta.patches[patch].link[size_t(e)];
        if (link.patch >= meta.patches.size()) continue;
        const int other = drawn_level(link.patch);
        if (other >= 0 && other < level) out[size_t(e)] = other;
    }
    return out;
}

// The template grid of a level: two triangles per cell, split along (i, j)-(i+1, j+1), counter-
// clockwise seen from outside; vertex v is sample (v % size, v / size). What the renderer uploads
// once per level.
std::vector<uint32_t> grid_triangles(int level);

// The triangles of a patch drawn at `level` with edges at `edge_level`, as sample indices
// (j * size + i) after snapping, degenerate ones left out: the geometry the renderer draws.
std::vector<uint32_t> stitched_triangles(int level, const std::array<int, 4>& edge_level);

}  // namespace catpaq
