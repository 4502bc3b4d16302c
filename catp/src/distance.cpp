// The only translation unit of catp that includes CGAL.
#include "catp/distance.h"

#include <cmath>

#include <CGAL/AABB_segment_primitive.h>
#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>

namespace catpaq {

namespace {
using Kernel = CGAL::Simple_cartesian<double>;
using Point = Kernel::Point_3;
using Triangle = Kernel::Triangle_3;
using Iterator = std::vector<Triangle>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<Kernel, Iterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<Kernel, Primitive>>;
using Segment = Kernel::Segment_3;
using SegmentIterator = std::vector<Segment>::const_iterator;
using SegmentTree = CGAL::AABB_tree<CGAL::AABB_traits<Kernel, CGAL::AABB_segment_primitive<Kernel, SegmentIterator>>>;
}  // namespace

struct SurfaceDistance::Impl {
    std::vector<Triangle> triangles;
    Tree tree;
};

SurfaceDistance::SurfaceDistance(const std::vector<std::array<double, 3>>& positions, const std::vector<uint32_t>& indices)
    : impl_(new Impl) {
    for (size_t i = 0; i + 2 < indices.size(); i += 3) {
        const auto &a = positions[indices[i]], &b = positions[indices[i + 1]], &c = positions[indices[i + 2]];
        Triangle t(Point(a[0], a[1], a[2]), Point(b[0], b[1], b[2]), Point(c[0], c[1], c[2]));
        if (!t.is_degenerate()) impl_->triangles.push_back(t);
    }
    impl_->tree.insert(impl_->triangles.begin(), impl_->triangles.end());
    impl_->tree.accelerate_distance_queries();
}

SurfaceDistance::~SurfaceDistance() = default;

double SurfaceDistance::distance(const std::array<double, 3>& p) const {
    if (impl_->triangles.empty()) return INFINITY;
    return std::sqrt(CGAL::to_double(impl_->tree.squared_distance(Point(p[0], p[1], p[2]))));
}

struct SegmentDistance::Impl {
    std::vector<Segment> segments;
    std::vector<Point> points;  // zero-length segments
    SegmentTree tree;
};

SegmentDistance::SegmentDistance(const std::vector<std::pair<std::array<double, 3>, std::array<double, 3>>>& segments)
    : impl_(new Impl) {
    for (const auto& [a, b] : segments) {
        Point pa(a[0], a[1], a[2]), pb(b[0], b[1], b[2]);
        if (pa == pb) impl_->points.push_back(pa);
        else impl_->segments.push_back(Segment(pa, pb));
    }
    impl_->tree.insert(impl_->segments.begin(), impl_->segments.end());
    if (!impl_->segments.empty()) impl_->tree.accelerate_distance_queries();
}

SegmentDistance::~SegmentDistance() = default;

bool SegmentDistance::empty() const { return impl_->segments.empty() && impl_->points.empty(); }

double SegmentDistance::distance(const std::array<double, 3>& p) const {
    Point q(p[0], p[1], p[2]);
    double best = INFINITY;
    if (!impl_->segments.empty()) best = CGAL::to_double(impl_->tree.squared_distance(q));
    for (const Point& x : impl_->points) best = std::min(best, CGAL::to_double(CGAL::squared_distance(q, x)));
    return std::sqrt(best);
}

}  // namespace catpaq
