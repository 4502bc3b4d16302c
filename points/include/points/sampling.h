#pragma once
// Deterministic point clouds for tests and benchmarks: points sampled uniformly at random on a
// mesh's surface (area-weighted triangles, uniform barycentric positions), as a scanner's
// irregular sampling of a surface is, unlike a mesh's regular vertices.
#include <cstddef>
#include <cstdint>

#include "mesh/mesh.h"
#include "points/point_cloud.h"

namespace catpaq {

// `count` points on `mesh` (which must have triangles of positive total area). Normals (the
// triangles' interpolated vertex normals, or their face normals) and colours (interpolated)
// are kept when `with_normals` / `with_colors` and the mesh has them. Same arguments, same
// points on every machine (splitmix64).
PointCloud sample_surface(const Mesh& mesh, size_t count, uint64_t seed, bool with_normals, bool with_colors);

}  // namespace catpaq
