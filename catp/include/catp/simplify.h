#pragma once
// Boundary-preserving mesh simplification by half-edge collapse, for building the coarser
// levels of the diamond hierarchy: the converter welds the fragments of a diamond's children and
// simplifies them to about half the triangles while every vertex on the diamond's outer boundary
// stays exactly where it is, so fragments of neighbouring diamonds at any mix of levels still meet
// without cracks.
//
// Why our own and not meshoptimizer's: the meshoptimizer that Debian ships (0.18) can only lock
// the topological border, not an arbitrary set of vertices, and vertices on a diamond's faces are
// not always topological borders.
//
// Method. Every collapse removes one vertex u by moving it onto an adjacent vertex v (half-edge
// collapse), so the output references a subset of the input vertices and no position is ever
// changed. Cost = Garland-Heckbert quadric error: every vertex carries the area-weighted sum of
// the squared-distance quadrics of its triangles' planes (plus, on a topological border, of
// planes through each border edge perpendicular to its triangle), accumulated as vertices merge;
// the cost of u -> v is (Q_u + Q_v)(v) divided by the accumulated weight (area), i.e. a mean
// squared distance, and its square root is the error in object units.
// Collapses are performed in passes: candidates (the two cheapest allowed targets of each
// removable vertex) are sorted by cost, and the cheapest ones are performed while each vertex
// takes part in at most one collapse per pass; the error allowed in a pass follows the costs of
// the pass's candidates, so the error limit rises gradually. The pass schedule does not depend on
// the target, so a smaller target runs the same collapses as a larger one and then some more: the
// reported error is monotone in the target.
//
// A collapse is rejected when it would turn a triangle's normal by more than about 78 degrees,
// make a triangle face more than about 73 degrees away from the input surface its corners stand
// for (the sum of the input normals merged into them: this stops folds that build up over several
// collapses), make a triangle of zero area, violate the link condition (create a non-manifold edge
// or a duplicate triangle), or remove the last triangle of a vertex. Topology is preserved: closed
// surfaces stay closed, borders stay borders, components never vanish.
//
// The error is a mean, not a bound: removed vertices lie up to about twice the reported error
// from the output surface (measured on noisy spheres; tests/catp/test_simplify.cpp asserts 3x).
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

namespace catpaq {

struct SimplifySettings {
    // Stop as soon as the output has at most this many triangles. 0 simplifies as far as the
    // constraints and max_error allow.
    size_t target_triangles = 0;
    // Never perform a collapse whose error (see SimplifyResult::error) exceeds this, in object
    // units. Simplification stops early, above the target, when no cheaper collapse is left.
    // Negative or NaN: only free collapses (error 0, e.g. inside flat regions).
    double max_error = std::numeric_limits<double>::infinity();
    // true: vertices on the topological border (edges used by one triangle) are never removed.
    // false: a border vertex may only slide along the border, i.e. collapse onto one of its two
    // border neighbours along a border edge; the border's shape is kept by its edge quadrics.
    bool lock_topological_border = false;
    // Never create an edge longer than this (object units): keeps the triangles of a simplified
    // mesh within a size, where density matters more than adaptivity (the AQP converter's
    // out-of-core reduction, aqp/reduce.h). Infinity, the default, never rejects anything.
    double max_edge_length = std::numeric_limits<double>::infinity();
};

struct SimplifyResult {
    // Triangles (3 indices each) referencing the input vertices; winding as in the input.
    // Surviving triangles keep their input order.
    std::vector<uint32_t> indices;
    // For each output triangle, the input triangle it was (index into the input's triangles):
    // the same corners in the same order, each either unchanged or replaced by the vertex it
    // collapsed onto.
    std::vector<uint32_t> sources;
    // Largest error of any collapse performed: the square root of its quadric cost, a distance in
    // object units (about the rms distance of the removed region's planes to the kept vertex).
    // 0 when nothing was collapsed.
    double error = 0;
};

// Simplifies the triangle mesh (positions: x, y, z per vertex; indices: 3 per triangle) towards
// settings.target_triangles.
//
// - indices must be < vertex_count and index_count a multiple of 3 (std::invalid_argument
//   otherwise); index_count must be below 2^32. positions must be finite.
// - locked: null or vertex_count bytes; nonzero = this vertex is never removed (other vertices
//   may still collapse onto it). Vertices on non-manifold edges (used by more than two triangles
//   or twice in the same direction) and vertices whose triangle fan is not one disk or one
//   half-disk are locked too.
// - Triangles with a repeated index are dropped, and of duplicated triangles (same three vertices
//   in either winding) only the first is kept, before anything else; so the output may be smaller
//   than the input even when the target is not below it. Triangles of zero area with three
//   distinct vertices are kept (dropping them would open holes); a vertex of one is only removed
//   by a collapse that removes that triangle too. Isolated vertices are ignored.
// - Empty input gives empty output.
// - The result is deterministic: the same input gives the same output on every run (and every
//   machine, given IEEE double arithmetic without FMA contraction, as the project builds): no
//   address, hash or thread order is involved.
// - Reentrant and thread-safe: no global state; concurrent calls on different (or the same
//   read-only) inputs are fine. Memory: about 200 bytes per referenced vertex plus 12 per index,
//   in one block per call (a vertex buffer much larger than the mesh is compacted first).
// - Speed: about 5M input triangles/s on one core for 5k-20k triangles (bench/catp/simplify_bench).
SimplifyResult simplify_mesh(const double* positions, size_t vertex_count, const uint32_t* indices,
                             size_t index_count, const uint8_t* locked,
                             const SimplifySettings& settings);

}  // namespace catpaq
