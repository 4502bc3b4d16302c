#pragma once
// Checks of AQP datasets for tests, benches and (later) `catpaq verify`: the invariants the
// converter guarantees, and the surface a level draws.
#include <cstddef>
#include <string>
#include <vector>

#include "aqp/dataset.h"
#include "mesh/mesh.h"

namespace catpaq::aqp {

struct AqpVerifyReport {
    size_t nodes = 0;
    size_t corrupt_nodes = 0;             // checksum or decoding failures
    size_t shared_sample_mismatches = 0;  // a sample on a shared edge or corner that differs between patches
    size_t nesting_mismatches = 0;        // a level's sample that is not its finer level's sample
    size_t monotonicity_violations = 0;   // a node's bound below its finer level's
    size_t extent_violations = 0;         // a local coordinate beyond its patch's extent in the metadata
    std::vector<std::string> problems;    // the first few, in words
    bool ok() const {
        return corrupt_nodes + shared_sample_mismatches + nesting_mismatches + monotonicity_violations + extent_violations == 0;
    }
};

// Decodes every node and checks: shared edges and corners carry the same position, normal and
// colour in every patch at every level (edges matched through the metadata's links, in their
// orientation), each level is every other sample of the next, the bounds are monotone, local
// coordinates stay within the patch extents.
AqpVerifyReport verify_aqp(const AqpDataset& dataset);

// Every patch at `level`, triangulated as a renderer draws it (each grid cell split along its
// (i, j)-(i+1, j+1) diagonal), with world positions. With `weld`, samples at the same
// quantization grid position become one vertex and triangles left with a repeated vertex are
// dropped: a closed input gives a closed mesh exactly when no crack opened. Normals and colours
// are decoded too.
Mesh aqp_level_mesh(const AqpDataset& dataset, int level, bool weld = true);

}  // namespace catpaq::aqp
