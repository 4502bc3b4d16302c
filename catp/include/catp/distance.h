#pragma once
// Distance from points to a triangle mesh (CGAL AABB tree; the only CGAL use in catp, kept in
// one translation unit). Used by `verify` and the error tests to measure Hausdorff-style errors.
#include <array>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

namespace catpaq {

class Progress;

// Squared distance from p to triangle (a, b, c) (closest point by Voronoi regions, Ericson 5.1.5;
// no CGAL): what the converter's error measures use, and the client's distance from the eye to a
// node's triangles.
double point_triangle_distance2(const std::array<double, 3>& p, const std::array<double, 3>& a,
                                const std::array<double, 3>& b, const std::array<double, 3>& c);

class SurfaceDistance {
public:
    // positions: xyz doubles; indices: 3 per triangle. Degenerate triangles are skipped.
    SurfaceDistance(const std::vector<std::array<double, 3>>& positions, const std::vector<uint32_t>& indices);
    ~SurfaceDistance();
    // Euclidean distance from p to the closest point of the surface. Thread-safe.
    double distance(const std::array<double, 3>& p) const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// Distance from points to a set of segments (the border edges of a mesh, for verify's crack
// check on open inputs). Zero-length segments are points.
class SegmentDistance {
public:
    explicit SegmentDistance(const std::vector<std::pair<std::array<double, 3>, std::array<double, 3>>>& segments);
    ~SegmentDistance();
    bool empty() const;
    // Distance from p to the closest segment; infinity when there are none. Thread-safe.
    double distance(const std::array<double, 3>& p) const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// Points on a mesh for distance measures: the vertices of non-degenerate triangles (strided to
// at most about count / 2), then uniform samples by area up to `count` in all. Zero-area
// triangles and isolated vertices are not surface and are never sampled. Deterministic (fixed
// seed), so two runs on the same mesh measure the same points.
std::vector<std::array<double, 3>> sample_surface(const std::vector<std::array<double, 3>>& positions,
                                                  const std::vector<uint32_t>& indices, size_t count);

struct DistanceStats {
    double max = 0, rms = 0;  // over the points, in the surface's units
};

// Distances from `points` to the surface `to` (in parallel): the largest and the root mean square.
// `progress`, if given, counts the points measured.
DistanceStats measure_distances(const SurfaceDistance& to, const std::vector<std::array<double, 3>>& points,
                                Progress* progress = nullptr);

}  // namespace catpaq
