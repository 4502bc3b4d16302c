#pragma once
// Private to the points module: normals and splat radii of input points from their nearest
// neighbours (points/builder.h, step 3).
#include <cstddef>
#include <cstdint>

#include "kdtree.h"
#include "mesh/mesh.h"

namespace catpaq::points_detail {

struct EstimateInput {
    const KdTree* tree = nullptr;      // over all points (float, relative to the origin)
    const Vec3d* positions = nullptr;  // the same points in double precision, in the tree's ids
    size_t neighbours = 16;         // k of the normals' PCA
    size_t radius_neighbour = 6;    // a radius reaches this neighbour (PointsBuildSettings)
    bool orient_up = false;         // else outward from the origin (the bounds' centre)
};

// Estimates normals (when `normals` is not null) and radii (when `radii` is not null) of the
// points [begin, end), which are one leaf of the hierarchy: orientation is made consistent
// within the leaf. Writes normals[begin, end) and radii[begin, end).
void estimate_leaf(const EstimateInput& in, size_t begin, size_t end, Vec3f* normals, float* radii);

}  // namespace catpaq::points_detail
