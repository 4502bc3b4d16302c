#pragma once
// Out-of-core reduction of a PLY mesh too large for the AQP converter's memory (which works in
// core, aqp/build.h): the mesh is simplified block by block, from scratch files, to a mesh that
// fits, and the converter takes it from there.
//
// 1. The vertices go to a scratch file (positions, normals, colours: 40 bytes each); the faces,
//    fan-triangulated, to another.
// 2. The triangles are sorted by the block of a regular grid that holds their centroid (a
//    counting sort between scratch files). A vertex used by triangles of two blocks is a seam
//    vertex.
// 3. Round 1, both cores: each block is simplified by half-edge collapse (catp/simplify.h: the
//    CATP converter's simplifier, quadric error, topology kept, no folds) to its share of the
//    target, its seam vertices locked, so neighbouring blocks still meet.
// 4. Round 2, in memory: the same on round 1's result with the grid shifted by half a block, so
//    that round 1's seams lie inside blocks and are simplified too.
// After each block's simplification, vertices with three triangles are removed and slivers
// flipped (edges towards Delaunay where that moves the surface little): the AQP domain's
// flattening failed on what quadric simplification leaves there.
// Every output vertex is an input vertex: its position, normal and colour are the input's.
// The scratch files are anonymous (temp_file.h), next to the output; the kernel's page cache, not
// the process, holds them.
//
// 5. The distance of every input vertex of some triangle to the result is measured (CGAL's AABB
//    tree, catp/distance.h, both cores): the report's `vertex_distance` is the largest. The
//    converter adds it to every node's error (AqpBuildOptions::input_error), so that errors
//    stand against the input file (measured at the input's vertices, not a bound on every
//    surface point; verify --mesh measures the dataset against the input file both ways).
#include <cstdint>
#include <string>

#include "mesh/mesh.h"

namespace catpaq::aqp {

struct ReduceOptions {
    uint64_t target_triangles = 0;  // about this many triangles out (> 0)
    uint64_t memory_budget = 0;     // refuse at once when the estimate exceeds it (0: no limit)
    std::string scratch_near;       // scratch files go in this path's directory
    unsigned threads = 0;           // 0: all cores
    uint64_t block_triangles = 0;   // round 1's triangles per block (0: from the budget; tests set it)
    bool progress = true;           // named phases on a terminal
};

struct ReduceReport {
    uint64_t input_vertices = 0, input_triangles = 0;  // triangles after fan triangulation
    uint64_t round1_triangles = 0;                     // after round 1
    uint64_t vertices = 0, triangles = 0;              // out
    uint32_t blocks = 0;                               // occupied blocks of round 1
    uint64_t largest_block = 0;                        // triangles of round 1's largest block
    double vertex_distance = 0;                        // the largest from an input vertex to the result
    uint64_t memory_estimate = 0;                      // what the check against the budget used
    uint64_t scratch_bytes = 0;                        // written to scratch files
    double seconds = 0;
};

// The reduction's peak resident memory for a file of this many vertices, a target of
// `target_triangles` and a budget (which sets the blocks' size: their work takes at most half
// of it; 0: no budget). The scratch files' pages are not counted: the page cache holds them.
uint64_t reduce_memory_estimate(uint64_t input_vertices, uint64_t target_triangles, uint64_t budget);

// Reduces the PLY file at `path` (read once, through PlyStream). Throws Error on bad input (as
// PlyStream does), on a file without triangles, and when the estimate exceeds the budget.
Mesh reduce_ply_out_of_core(const std::string& path, const ReduceOptions& options, ReduceReport* report = nullptr);

}  // namespace catpaq::aqp
