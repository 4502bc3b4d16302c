#pragma once
// Crack checks of CATP cuts, shared by the crack tests (tests/catp/test_cracks.cpp) and the
// hard-case suite (bench/catp/hard_cases.cpp): decode a cut exactly as the vertex shader does,
// weld by exact integer position, count border edges.
#include <cstddef>
#include <cstdint>
#include <random>
#include <unordered_map>

#include "catp/cut.h"
#include "catp/dataset.h"
#include "mesh/mesh.h"

namespace catpaq {

struct CutTopology {
    size_t triangles = 0;      // non-degenerate after welding
    size_t border_edges = 0;   // edges used by exactly one triangle
    size_t fragments = 0;
    int max_level = 0, min_level = 1 << 30;
};

// Decodes the cut R of `file` and counts border edges after welding vertices by their exact
// integer decoded position (identical integers <=> bit-identical positions on the GPU). `cache`
// keeps decoded nodes between calls. Throws std::runtime_error on a corrupt vertex.
CutTopology cut_topology(const CatpFile& file, const RefinedSet& refined,
                         std::unordered_map<uint64_t, DiamondFragments>& cache);

// A random conforming cut: each non-leaf diamond is refined with probability `p` (itself drawn
// in [0.2, 0.9]), or, in the spatial variant, when its centre lies within a random radius
// (lattice units) of a random diamond's centre — mixing levels.
RefinedSet random_cut(const CatpIndex& index, std::mt19937_64& rng, bool spatial);

// For open or non-manifold inputs: the border edges of a decoded cut that do not lie on the
// original mesh's border. An edge counts as on the border when its midpoint is within `tolerance`
// (world units) of an original border edge. A crack between fragments shows up here: it opens
// border edges along tetrahedron faces, away from the original border. For a closed original
// every border edge of the cut counts. Throws std::runtime_error on a corrupt
// vertex, as cut_topology does.
size_t border_edges_off_original_border(const CatpFile& file, const RefinedSet& refined, const Mesh& original,
                                        double tolerance, std::unordered_map<uint64_t, DiamondFragments>& cache);

}  // namespace catpaq
