#pragma once
// Input cleaning for AQP: any triangle soup in, a consistently oriented two-manifold out (with or
// without border), or an Error saying why it cannot be made one.
//
// The steps, in order (each counted in CleanReport):
// 1. weld vertices at exactly the same position (bit-equal coordinates; -0 and +0 are equal),
//    then the ends of edges shorter than 1e-9 of the diagonal (rings of vertices a few ulps
//    apart, as a pole computed with sin(pi)); the first vertex of a group keeps its normal and
//    colour;
// 2. remove degenerate triangles: a repeated corner after welding, or three exactly collinear
//    corners (exact predicates: zero area, not "small");
// 3. remove duplicate triangles: the same three vertices as an earlier triangle, in either
//    orientation;
// 4. split non-manifold edges and vertices: along an edge used by more than two triangles the
//    first triangle stays joined to the first later one that runs the edge the other way (else
//    to the second), the others are cut loose there; then every vertex gets one copy per fan of
//    triangles joined through its edges (a bowtie vertex becomes two). Two boxes sharing an edge
//    become two closed boxes; a third sheet on a hinge becomes a separate sheet. Rounds repeat
//    while an edge still has more than two triangles; after a few, such triangles are removed;
// 5. orient every connected component consistently, keeping the orientation most of its input
//    triangles had; a non-orientable component (a Moebius strip) is refused;
// 6. drop tiny components: those whose area is below `min_component_area_fraction` of the total;
// 7. drop vertices no triangle uses.
// Cost: O(n log n) time and O(n) memory in the input size; a pure function (thread-safe).
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "mesh/mesh.h"

namespace catpaq::aqp {

struct CleanOptions {
    // Components with less than this share of the total surface area are dropped (they would
    // each need base domain triangles of their own and show as specks).
    double min_component_area_fraction = 1e-3;
};

struct CleanReport {
    size_t input_vertices = 0, input_triangles = 0;
    size_t welded_vertices = 0;           // merged into an earlier vertex at the same position, or
                                          // joined to one by an edge under 1e-9 of the diagonal
    size_t degenerate_triangles = 0;      // repeated corner or exactly collinear corners
    size_t duplicate_triangles = 0;       // same vertices as an earlier triangle
    size_t nonmanifold_edges = 0;         // edges with three or more triangles (first round)
    size_t nonmanifold_vertices = 0;      // vertices whose triangles form several fans (first round)
    size_t split_vertices = 0;            // vertex copies made to separate fans
    size_t nonmanifold_triangles_removed = 0;  // still on a non-manifold edge after the split rounds
    size_t flipped_triangles = 0;         // reversed to orient their component consistently
    size_t dropped_components = 0, dropped_component_triangles = 0;
    size_t unreferenced_vertices = 0;     // used by no remaining triangle
    // The result.
    size_t vertices = 0, triangles = 0;
    size_t components = 0;
    size_t border_edges = 0, border_loops = 0;
    int genus = 0;  // summed over components: (2 - V + E - F - loops) / 2 each

    // One line per non-zero count, for `convert` to show ("welded 12 vertices at equal positions").
    std::vector<std::string> summary() const;
};

// The cleaned mesh and, for every output vertex, the input vertex its attributes come from.
struct CleanMesh {
    Mesh mesh;
    std::vector<uint32_t> source_vertex;
};

// Cleans `input` as described above. Throws Error (naming the problem) when the input fails
// validate_mesh (non-finite coordinates, bad indices), has no triangles, nothing is left after
// cleaning, or a component is not orientable.
CleanMesh clean_to_manifold(const Mesh& input, const CleanOptions& options, CleanReport* report = nullptr);

// True if every edge has one or two triangles, every vertex's triangles form a single fan, and
// every edge with two triangles is run in opposite directions by them (consistent orientation).
// `why`, if given, receives the first problem found.
bool is_oriented_manifold(const Mesh& mesh, std::string* why = nullptr);

}  // namespace catpaq::aqp
