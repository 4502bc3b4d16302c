#pragma once
// Distance from points to a triangle mesh (CGAL AABB tree; the only CGAL use in catp, kept in
// one translation unit). Used by `verify` and the error tests to measure Hausdorff-style errors.
#include <array>
#include <cstdint>
#include <memory>
#include <vector>

namespace catpaq {

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

}  // namespace catpaq
