#pragma once
// The inverse of the parameterization: from a domain point to the surface point it maps to (the
// surface triangle whose image holds the point, and barycentric coordinates in it), and the
// surface's attributes interpolated there. Used to resample patches.
//
// Each base triangle keeps the images (in its chart) of the surface triangles overlapping it
// (develop_image in aqp/domain.h) in a uniform grid of buckets. A query tests the images of the
// point's bucket and takes the one holding it; when rounding leaves a point a hair outside every
// image (on an edge between two), it takes the one it is least outside of, clamped onto it, and
// counts a miss when that is more than 1e-9 (in barycentric terms) outside.
#include <array>
#include <atomic>
#include <cstdint>
#include <vector>

#include "aqp/domain.h"
#include "mesh/mesh.h"

namespace catpaq::aqp {

struct SurfacePoint {
    uint32_t triangle = 0;
    std::array<double, 3> bary{1, 0, 0};
};

struct SurfaceSample {
    Vec3d position{};
    Vec3f normal{0, 0, 1};  // unit
    Rgb8 color{0, 0, 0};
};

class SurfaceMap {
public:
    // A surface triangle's image in a base triangle's chart (lattice coordinates).
    struct Image {
        uint32_t triangle;
        float box[4];    // x0 y0 x1 y1, rounded outwards
        double x[3][2];  // corners
    };

    // `surface` must have normals (compute_vertex_normals otherwise) and outlive the map.
    // Builds the buckets in parallel.
    SurfaceMap(const Mesh& surface, const Parameterization& param);

    // Thread-safe.
    SurfacePoint locate(const DomainPoint& x) const;
    SurfaceSample sample(const DomainPoint& x) const;
    SurfaceSample interpolate(const SurfacePoint& s) const;

    // Queries whose point was farther than the tolerance from every candidate image.
    size_t misses() const { return misses_.load(); }
    // The images overlapping base triangle `base`, in its chart.
    const std::vector<Image>& images(uint32_t base) const { return buckets_[base].images; }

private:
    struct Buckets {
        int size = 1;                 // size x size cells over [0,1]^2
        std::vector<uint32_t> start;  // size * size + 1 offsets into `items`
        std::vector<uint32_t> items;  // indices into `images`
        std::vector<Image> images;
    };
    const Mesh& surface_;
    const Parameterization& param_;
    std::vector<Buckets> buckets_;  // per base triangle
    mutable std::atomic<size_t> misses_{0};
};

}  // namespace catpaq::aqp
