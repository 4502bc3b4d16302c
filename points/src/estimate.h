#pragma once
// Private to the points module: normals and splat radii of input points from their nearest
// neighbours (points/builder.h, step 3).
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include "mesh/mesh.h"

namespace catpaq::points_detail {

// Appends to `ids` the points, other than the leaf's [begin, end), inside the box [lo, hi].
using HaloFn = std::function<void(const float lo[3], const float hi[3], size_t begin, size_t end, std::vector<uint32_t>& ids)>;

// The min(k, all) points nearest to q among all the cloud's, nearest first, exact; returns how
// many. For the few points a leaf's halo leaves unsettled (outliers, whose neighbours are far).
using NearestFn = std::function<size_t(const float q[3], size_t k, uint32_t* index, float* distance2)>;

struct EstimateInput {
    const Vec3d* positions = nullptr;  // all points (relative to the origin), leaves contiguous
    const float* xyz = nullptr;        // the same as floats, 3 per point
    HaloFn halo;                       // the points around a leaf
    NearestFn nearest;                 // a search over the whole cloud
    float cloud_extent = 0;         // the cloud's largest side: a halo this wide holds every point
    size_t neighbours = 16;         // k of the normals' PCA
    size_t radius_neighbour = 6;    // a radius reaches this neighbour (PointsBuildSettings)
    bool orient_up = false;         // else outward from the origin (the bounds' centre)
};

// The eigenvector of the symmetric `cov` (its six distinct entries: xx, xy, xz, yy, yz, zz) with
// the smallest eigenvalue, and the three eigenvalues ascending: exactly the bits of Eigen's
// SelfAdjointEigenSolver::computeDirect (eigenvectors().col(0), eigenvalues()).
void smallest_eigenvector(const double cov[6], double vector[3], double values[3]);

// The same for a neighbourhood with a plane, faster: the smallest eigenvalue by Newton's method
// on the characteristic polynomial from 0 (below it, the cubic rises and is concave: the steps
// approach the root from below and never pass it), the other two from the polynomial's
// coefficients, the vector as Eigen finds it from the eigenvalue. Returns false, computing
// nothing, where the smallest eigenvalue is not well apart from the next (gap below a
// thousandth of the largest) or Newton's method has not settled within a few steps: then
// smallest_eigenvector's closed form is the one to use.
bool plane_eigenvector(const double cov[6], double vector[3], double values[3]);

// Estimates normals (when `normals` is not null) and radii (when `radii` is not null) of the
// points [begin, end), which are one leaf of the hierarchy: orientation is made consistent
// within the leaf. Writes normals[begin, end) and radii[begin, end). The neighbours are exact:
// those of the leaf and a halo of its surroundings, widened for the points that need more; the
// last few search the whole cloud (in.nearest).
void estimate_leaf(const EstimateInput& in, size_t begin, size_t end, Vec3f* normals, float* radii);

}  // namespace catpaq::points_detail
