// check_parameterization (aqp/domain.h): orientation and total area of every surface triangle's
// image, the points' validity and the map's distortion.
#include <algorithm>
#include <cmath>

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "aqp/domain.h"
#include "vec3.h"
#include "base/error.h"

namespace catpaq::aqp {
namespace {

constexpr double kSqrt3Over4 = 0.43301270189221932338;  // area of the unit equilateral triangle


bool point_valid(const DomainPoint& p, size_t triangles) {
    if (p.triangle >= triangles) return false;
    double sum = 0;
    for (double b : p.bary) {
        if (!(b >= 0) || !(b <= 1)) return false;
        sum += b;
    }
    return std::fabs(sum - 1) <= 1e-9;
}

// Singular values (s1 >= s2) of the 2x2 matrix [a b; c d].
void singular_values(double a, double b, double c, double d, double& s1, double& s2) {
    double e = (a + d) / 2, f = (a - d) / 2, g = (c + b) / 2, h = (c - b) / 2;
    double q = std::sqrt(e * e + h * h), r = std::sqrt(f * f + g * g);
    s1 = q + r;
    s2 = std::fabs(q - r);
}

}  // namespace

bool ParamCheck::bijective() const {
    return flipped == 0 && degenerate == 0 && unfold_failures == 0 && wrapped == 0 && bad_points == 0 && base_vertices_off_corner == 0 &&
           std::fabs(image_area - domain_area) <= 1e-6 * domain_area;
}

std::string ParamCheck::describe() const {
    return strprintf("%zu triangles: %zu flipped, %zu degenerate, %zu without a shared chart, %zu wrapped, %zu bad points, %zu base "
                     "vertices off their corner, image area %.9g of %.9g; angle distortion mean %.3f p99 %.3g max %.3g, area "
                     "distortion mean %.3f p99 %.3g max %.3g",
                     triangles, flipped, degenerate, unfold_failures, wrapped, bad_points, base_vertices_off_corner, image_area,
                     domain_area, angle_distortion_mean, angle_distortion_p99, angle_distortion_max, area_distortion_mean,
                     area_distortion_p99, area_distortion_max);
}

ParamCheck check_parameterization(const Mesh& surface, const Parameterization& param) {
    ParamCheck c;
    const BaseDomain& d = param.domain;
    c.triangles = surface.triangle_count();
    c.domain_area = double(d.triangle_count()) * kSqrt3Over4;
    if (param.points.size() != surface.vertex_count()) {
        c.bad_points = surface.vertex_count();
        return c;
    }
    for (const DomainPoint& p : param.points) c.bad_points += !point_valid(p, d.triangle_count());
    for (uint32_t b = 0; b < d.vertex_count(); ++b) {
        const DomainPoint& p = param.points[d.vertex_source[b]];
        bool at_corner = false;
        for (int i = 0; i < 3; ++i) at_corner |= p.bary[i] == 1.0 && d.triangles[p.triangle][i] == b;
        c.base_vertices_off_corner += !at_corner;
    }
    if (c.bad_points) return c;

    // Each triangle is measured on its own, in parallel; the sums and counts are then taken in
    // triangle order, so the figures do not depend on the threads. (Sequential, this was half a
    // second of the 1M scan's conversion on one core.)
    std::vector<double> triangle_area(c.triangles);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, c.triangles, 4096), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t t = r.begin(); t < r.end(); ++t) {
            const uint32_t* tri = &surface.indices[3 * t];
            Vec3d u = sub(surface.positions[tri[1]], surface.positions[tri[0]]);
            Vec3d v = sub(surface.positions[tri[2]], surface.positions[tri[0]]);
            triangle_area[t] = 0.5 * std::sqrt(std::max(0.0, dot(u, u) * dot(v, v) - dot(u, v) * dot(u, v)));
        }
    });
    double surface_area = 0;
    for (double a : triangle_area) surface_area += a;
    // Domain lengths scaled so that the domain's area is the surface's.
    const double scale = surface_area > 0 ? std::sqrt(surface_area / c.domain_area) : 1.0;
    struct Measured {
        double angle, areal, area;
        uint32_t triangle;
        bool operator<(const Measured& o) const { return triangle < o.triangle; }
    };
    struct Image {
        double image = 0;
        bool unfolded = false, wraps = false, measured = false;
        Measured m;
    };
    std::vector<Image> images(c.triangles);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, c.triangles, 1024), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t t = r.begin(); t < r.end(); ++t) {
            const uint32_t* tri = &surface.indices[3 * t];
            Image& im = images[t];
            Vec2 x[3];
            if (!triangle_image(param, tri, x)) continue;
            im.unfolded = true;
            for (Vec2& p : x) p = lattice_to_plane(p);
            im.wraps = !triangle_image_area(param, tri, im.image);
            const double image = im.image;
            // The affine map from the surface triangle (in an orthonormal frame of its plane) to
            // its image: J = D E^-1 with E, D the edge vectors of each.
            Vec3d e1 = sub(surface.positions[tri[1]], surface.positions[tri[0]]);
            Vec3d e2 = sub(surface.positions[tri[2]], surface.positions[tri[0]]);
            double l1 = std::sqrt(dot(e1, e1));
            if (!(l1 > 0) || !(image > 0)) continue;
            double ex = dot(e2, e1) / l1, ey2 = dot(e2, e2) - ex * ex;
            if (!(ey2 > 0)) continue;
            double ey = std::sqrt(ey2);
            const double area = 0.5 * l1 * ey;
            // E = [l1 ex; 0 ey], E^-1 = [1/l1  -ex/(l1 ey); 0  1/ey].
            double d11 = scale * (x[1][0] - x[0][0]), d21 = scale * (x[1][1] - x[0][1]);
            double d12 = scale * (x[2][0] - x[0][0]), d22 = scale * (x[2][1] - x[0][1]);
            double j11 = d11 / l1, j21 = d21 / l1;
            double j12 = -d11 * ex / (l1 * ey) + d12 / ey, j22 = -d21 * ex / (l1 * ey) + d22 / ey;
            double s1, s2;
            singular_values(j11, j12, j21, j22, s1, s2);
            if (!(s2 > 0)) continue;
            const double angle = s1 / s2, areal = s1 * s2;
            im.m = {angle, std::max(areal, 1 / areal), area, uint32_t(t)};
            im.measured = true;
        }
    });
    double weight = 0;
    std::vector<Measured> measured;
    measured.reserve(c.triangles);
    for (size_t t = 0; t < c.triangles; ++t) {
        const Image& im = images[t];
        if (!im.unfolded) {
            ++c.unfold_failures;
            continue;
        }
        c.image_area += im.image;
        if (im.image < 0) ++c.flipped;
        if (im.image == 0) ++c.degenerate;
        if (im.wraps) ++c.wrapped;
        if (im.image <= 0 || im.wraps) c.bad_vertices.insert(c.bad_vertices.end(), &surface.indices[3 * t], &surface.indices[3 * t + 3]);
        if (!im.measured) continue;
        const Measured& m = im.m;
        c.angle_distortion_mean += m.angle * m.area;
        c.area_distortion_mean += m.areal * m.area;
        weight += m.area;
        c.angle_distortion_max = std::max(c.angle_distortion_max, m.angle);
        c.area_distortion_max = std::max(c.area_distortion_max, m.areal);
        measured.push_back(m);
    }
    if (weight > 0) {
        c.angle_distortion_mean /= weight;
        c.area_distortion_mean /= weight;
    }
    // Sorted by the value, ties by triangle (a total order: the same result on any threads).
    auto percentile99 = [&](auto key) {
        tbb::parallel_sort(measured.begin(), measured.end(), [&](const Measured& a, const Measured& b) {
            return key(a) != key(b) ? key(a) < key(b) : a.triangle < b.triangle;
        });
        double seen = 0;
        for (const Measured& m : measured)
            if ((seen += m.area) >= 0.99 * weight) return key(m);
        return measured.empty() ? 0.0 : key(measured.back());
    };
    c.area_distortion_p99 = percentile99([](const Measured& m) { return m.areal; });
    c.angle_distortion_p99 = percentile99([](const Measured& m) { return m.angle; });
    for (size_t i = measured.size(); i-- > 0 && c.worst_triangles.size() < 16;) c.worst_triangles.push_back(measured[i].triangle);
    return c;
}

}  // namespace catpaq::aqp
