#pragma once
// The CATP converter: a mesh in, a CATP dataset (catp/format.h) out.
//
// 1. The model is placed in a power-of-two cube and mapped to the integer lattice.
// 2. Leaves follow the density (about `leaf_triangles` per tetrahedron, estimated from a sample
//    of the vertices): a sparse part stops at a coarser level than a dense one (the refined
//    diamonds are closed under parents, so the leaves tile the model as a cut of the hierarchy
//    does). The precision asked for sets the vertex layout, its barycentric grid, and a floor:
//    no leaf is coarser than the level whose quantization step, which bounds the finest
//    level's distance to the input, reaches the precision.
// 3. Leaves: the mesh is clipped by the leaf tetrahedra (catp/src/clip.h: canonical, exactly
//    snapped constructions decided by exact predicates).
// 4. Coarser diamonds, bottom-up: the fragments of a diamond's children are gathered and welded,
//    simplified to about half (vertices on the diamond's outer faces locked), then clipped by the
//    diamond's interior faces into one fragment per tetrahedron. Errors are made monotone.
// 5. Vertices are quantized to the 64-bit vertex with the face rule, fragments compressed, and the
//    archive written atomically.
//
// Out of core: the input is read as a stream (PLY files are never loaded whole), per-vertex data
// is paged, triangles are sorted into spatial blocks (tetrahedra of a "block level" chosen so the
// fullest block fits the memory budget) that are clipped one at a time, and each level's
// fragments live in memory only up to a share of the budget, the rest in anonymous scratch files
// next to the output. The output does not depend on the budget (tested: bit-identical files).
#include <cstdint>
#include <string>
#include <vector>

#include "catp/format.h"
#include "mesh/mesh.h"
#include "mesh/precision.h"

namespace catpaq {

// The finest level's largest distance from the input the converter guarantees: Precision
// (mesh/precision.h), in model units or mean input edges.

// Vertex layouts to choose from (common_codec/packed_vertex.h).
enum class LayoutChoice : uint8_t {
    Auto,        // without colours Position48; with colours Rgb24 if its grid reaches the
                 // precision at the leaf level the density chooses, else Rgb18, else deeper
    Rgb24,       // full colour; the leaves go deeper when the precision needs it
    Rgb18,
    Position48,  // drops the input's colours
};
bool parse_layout_choice(const std::string& text, LayoutChoice& out);

struct CatpBuildSettings {
    size_t leaf_triangles = 2000;  // target triangles per leaf tetrahedron
    int leaf_level = -1;           // force a leaf level (-1: choose from the density and precision)
    Precision precision;
    LayoutChoice layout = LayoutChoice::Auto;
    UpAxis up = UpAxis::PosY;      // stored for viewers
    unsigned threads = 0;          // 0: all cores
    bool progress = true;          // progress bar on a terminal
    // Working memory the build may use, in bytes (0: default_memory_budget()). It covers the
    // converter's data and worker threads, not the process's code and libraries (`catpaq convert
    // --memory` subtracts those, so there the budget bounds the whole process).
    uint64_t memory_budget = 0;
    // true: the model's centre at the lattice cube's centre, where the planes of every level meet
    // (the hard cases are built to put geometry on those planes); false, the default: a flat
    // model's centre is shifted off the middle plane across its thin axis (builder.cpp,
    // kThinAxisShift), so that a flat noisy scan does not lie along a face of the diamonds of
    // every level. Other models are centred either way.
    bool centred_placement = false;
};

// Working memory the converter reserves per worker thread, and needs at least beyond that.
// Measured, not derived: a thread keeps the simplifier's and the error grid's arrays from
// diamond to diamond (up to 12 and 8 MiB), but the largest diamond of a level sets its working
// set (65k gathered triangles on the 10M scan: the simplifier's block alone is 16 MiB), a thread
// waiting inside one diamond's parallel steps may take up parts of another (TBB work stealing)
// with arrays of their own, and glibc keeps each thread arena's freed blocks resident. The
// per-thread part of the peak reached about 34 MiB on the 10M scan. The fixed part holds the
// input reader's 4 MiB window and the levels' indexes. (bench/catp/memory_budget_bench sweeps
// budgets and thread counts and checks the peak the kernel measured.)
constexpr uint64_t kMemoryPerThread = uint64_t(40) << 20;
constexpr uint64_t kMinimumDataMemory = uint64_t(8) << 20;
// The smallest budget for `threads` workers (0: as many as cores): kMinimumDataMemory plus
// kMemoryPerThread per thread, for at least two threads.
uint64_t minimum_memory_budget(unsigned threads = 0);
// Half the machine's physical memory.
uint64_t default_memory_budget();

struct CatpLevelStats {
    int level = 0;
    size_t diamonds = 0, fragments = 0, triangles = 0, vertices = 0;
    uint64_t bytes = 0;
    double max_error = 0;  // world units
    // Diamonds whose geometry is all thinner than the level's quantization step: they draw
    // nothing. A level where every diamond draws nothing shows nothing at all, and no error
    // bound can hold for it.
    size_t empty_diamonds = 0;
};

struct CatpBuildReport {
    size_t input_vertices = 0, input_triangles = 0;
    int leaf_level = 0;            // the deepest leaves'
    int coarsest_leaf_level = 0;   // the coarsest leaves' (leaves follow the density)
    int density_leaf_level = 0;    // where the density is even: the mean tetrahedron there holds
                                   // about leaf_triangles
    VertexLayout layout;
    double mean_edge = 0;          // world units
    double precision = 0;          // asked for, world units
    double leaf_step = 0;          // the coarsest leaves' quantization step (<= precision), world units
    std::vector<std::string> warnings;  // for the user: what was not as asked
    size_t nodes = 0;
    uint64_t file_bytes = 0;
    double seconds = 0;
    // Wall time of the phases: reading the vertices (with normals, placement and level choice),
    // binning the triangles into blocks, clipping the leaves, encoding the leaf nodes,
    // coarsening (with node encoding), and finishing the file.
    double seconds_read = 0, seconds_bin = 0, seconds_clip = 0, seconds_leaf_nodes = 0, seconds_coarsen = 0,
           seconds_write = 0;
    bool compact_bins = false;  // triangles binned as vertex indices, the vertices kept in memory
    uint64_t peak_rss = 0;
    uint64_t memory_budget = 0;
    uint64_t bytes_spilled = 0;  // scratch bytes written to disk (0 when everything fitted)
    int block_level = 0;         // level of the spatial blocks the leaves were built in
    size_t blocks = 0;
    // Leaves coarser than the blocks (a sparse part's, when the budget asked for small
    // blocks): each gathered its triangles from the blocks they were binned in.
    size_t leaves_across_blocks = 0;
    double diagonal = 0;                 // world units
    std::vector<CatpLevelStats> levels;  // coarse to fine
    // Thin geometry lost at the finest level: pieces of input triangles that have no area once
    // their corners are quantized (thinner than the grid step), so that no level draws them.
    // The stored bounds include their distance to what is drawn (lost_error, world units); where
    // that exceeds twice the quantization step (lost_beyond_step: more than the grid's own noise;
    // a 1M scan loses 31k slivers, all within 1.05 steps of what is drawn), convert warns.
    // What the input file holds that a dataset cannot (texture coordinates, materials, face
    // colours, ...): one sentence per kind, for convert to warn about.
    std::vector<std::string> dropped_input;
    size_t lost_triangles = 0;
    double lost_area = 0;  // world units squared
    double lost_error = 0;
    bool lost_beyond_step = false;
};

// Converts `mesh` (validated: finite, indices in range) into a dataset at `output_path`.
// Throws Error with a clear message for inputs it refuses (no triangles, zero extent).
CatpBuildReport build_catp(const Mesh& mesh, const std::string& output_path, const CatpBuildSettings& settings);

// Converts a mesh file: PLY is streamed (memory bounded by the budget, not by the input size);
// OBJ, OFF and STL are read whole first. Throws Error on bad input, naming the file.
CatpBuildReport build_catp_file(const std::string& input_path, const std::string& output_path,
                                const CatpBuildSettings& settings);

}  // namespace catpaq
