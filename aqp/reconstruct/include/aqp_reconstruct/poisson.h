#pragma once
// Surfaces from point clouds for AQP (AQP maps closed, scan-like surfaces; seed 001 reconstructs a
// two-manifold from the scan first): CGAL's Poisson surface reconstruction (Kazhdan et al.
// 2006, Poisson_surface_reconstruction_3), meshed by CGAL's surface mesher as a closed manifold.
// The only CGAL translation unit of the AQP side: the converter itself stays CGAL-free.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "mesh/mesh.h"

namespace catpaq::aqp {

struct PoissonOptions {
    // Mesh size relative to the points' average spacing (their 6 nearest neighbours): the
    // surface mesher's Delaunay balls are at most `radius` spacings and its facets' centres at
    // most `distance` spacings from the implicit surface (CGAL's defaults: 30 and 0.375; a
    // smaller distance follows the points more closely, with more triangles). 1.5 spacings keeps
    // about the points' resolution: 8000 points on a unit sphere gave 3552 vertices (at 3: 891;
    // at CGAL's default 30: 586, too coarse for a scan), in 2.4 s against 1.4 s.
    double radius = 1.5;
    double distance = 0.25;
    double min_angle = 20.0;  // degrees, smallest facet angle the mesher aims for
    size_t normal_neighbours = 18;  // k of the jet fit and the orientation's minimum spanning tree
    // The surface mesher may evaluate the implicit function this many times per point (plus
    // 2^20) before the reconstruction is refused as not closed (poisson_reconstruct).
    uint64_t evaluations_per_point = 2000;
};

struct PoissonReport {
    size_t input_points = 0;
    size_t normals_estimated = 0;   // 0 when the input had normals
    size_t repeated_dropped = 0;    // points at the position of an earlier one (left out)
    size_t unoriented_dropped = 0;  // points whose normal could not be oriented (left out)
    double average_spacing = 0;
    uint64_t evaluations = 0;  // of the implicit function by the surface mesher
    size_t vertices = 0, triangles = 0;
    double seconds = 0;
};

// Peak resident memory of converting a cloud of `points` to AQP through the reconstruction (the
// cloud, the reconstruction and the AQP build of its surface), from measurements rounded up
// (`catpaq convert --format aqp`, maximum resident size by /usr/bin/time or wait4). It depends
// on how the points lie as much as on their count (the mesher's triangles follow the average
// spacing): gen_mesh scans' vertices, 89 MiB for 22k points and 169 MiB for 60k; random samples
// of a scan (sample_surface), 123 MiB for 21k. 5200 bytes a point and 24 MiB.
uint64_t poisson_memory_estimate(uint64_t points);

// Reconstructs a closed surface from `positions` with `normals` (unit, pointing out; empty: they
// are estimated by jet fitting and oriented along a minimum spanning tree of the neighbour
// graph). Throws Error when there are too few points (fewer than 16), when the positions are not
// finite, or when the solver or the mesher fails (a message that says so, and what to try).
Mesh poisson_reconstruct(const std::vector<Vec3d>& positions, const std::vector<Vec3f>& normals,
                         const PoissonOptions& options, PoissonReport* report = nullptr);

}  // namespace catpaq::aqp
