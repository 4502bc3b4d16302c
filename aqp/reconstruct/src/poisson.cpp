// Poisson surface reconstruction through CGAL (aqp_reconstruct/poisson.h). All the CGAL of the
// AQP side is in this file, so that only it pays CGAL's compile time.
#include "aqp_reconstruct/poisson.h"

#include <chrono>
#include <cmath>
#include <unordered_map>
#include <utility>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/IO/facets_in_complex_2_to_triangle_mesh.h>
#include <CGAL/Implicit_surface_3.h>
#include <CGAL/Poisson_reconstruction_function.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_default_triangulation_3.h>
#include <CGAL/compute_average_spacing.h>
#include <CGAL/jet_estimate_normals.h>
#include <CGAL/make_surface_mesh.h>
#include <CGAL/mst_orient_normals.h>
#include <CGAL/property_map.h>

#include "base/error.h"

namespace catpaq::aqp {

namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Vector = Kernel::Vector_3;
using PointWithNormal = std::pair<Point, Vector>;
using PointMap = CGAL::First_of_pair_property_map<PointWithNormal>;
using NormalMap = CGAL::Second_of_pair_property_map<PointWithNormal>;

// Normals by a jet fit over the k nearest neighbours, then oriented consistently along a
// minimum spanning tree (Hoppe et al. 1992); points the tree cannot reach are dropped.
size_t estimate_and_orient_normals(std::vector<PointWithNormal>& points, size_t k) {
    CGAL::jet_estimate_normals<CGAL::Sequential_tag>(
        points, unsigned(k), CGAL::parameters::point_map(PointMap()).normal_map(NormalMap()));
    auto unoriented = CGAL::mst_orient_normals(points, unsigned(k),
                                               CGAL::parameters::point_map(PointMap()).normal_map(NormalMap()));
    const size_t dropped = size_t(std::distance(unoriented, points.end()));
    points.erase(unoriented, points.end());
    return dropped;
}

// The implicit function's zero set meshed as a closed manifold (Manifold_tag), copied into a
// Mesh: vertices in the mesher's order, triangles oriented outwards (CGAL orients the facet
// with the largest z towards +z and propagates).
Mesh mesh_zero_set(CGAL::Poisson_reconstruction_function<Kernel>& function, double spacing,
                   const PoissonOptions& o) {
    using Triangulation = CGAL::Surface_mesher::Surface_mesh_default_triangulation_3_generator<Kernel>::Type;
    using Complex = CGAL::Surface_mesh_complex_2_in_triangulation_3<Triangulation>;
    using Surface = CGAL::Implicit_surface_3<Kernel, CGAL::Poisson_reconstruction_function<Kernel>>;
    const Point inner = function.get_inner_point();
    const Kernel::Sphere_3 bounding = function.bounding_sphere();
    const double radius = std::sqrt(CGAL::to_double(bounding.squared_radius()));
    const double sphere_radius = 5.0 * radius;
    const double dichotomy_error = o.distance * spacing / 1000.0;
    Surface surface(function, Kernel::Sphere_3(inner, sphere_radius * sphere_radius), dichotomy_error / sphere_radius);
    CGAL::Surface_mesh_default_criteria_3<Triangulation> criteria(o.min_angle, o.radius * spacing, o.distance * spacing);
    Triangulation triangulation;
    Complex complex(triangulation);
    CGAL::make_surface_mesh(complex, surface, criteria, CGAL::Manifold_tag());
    if (triangulation.number_of_vertices() == 0 || complex.number_of_facets() == 0)
        fail("Poisson reconstruction: the surface mesher found no surface (are the normals oriented outwards?)");
    CGAL::Surface_mesh<Point> sm;
    CGAL::facets_in_complex_2_to_triangle_mesh(complex, sm);
    Mesh mesh;
    std::unordered_map<uint32_t, uint32_t> index;
    for (auto v : sm.vertices()) {
        index[uint32_t(v)] = uint32_t(mesh.positions.size());
        const Point& p = sm.point(v);
        mesh.positions.push_back({p.x(), p.y(), p.z()});
    }
    for (auto f : sm.faces())
        for (auto v : CGAL::vertices_around_face(sm.halfedge(f), sm)) mesh.indices.push_back(index.at(uint32_t(v)));
    return mesh;
}

}  // namespace

uint64_t poisson_memory_estimate(uint64_t points) { return points * 5200 + (uint64_t(24) << 20); }

Mesh poisson_reconstruct(const std::vector<Vec3d>& positions, const std::vector<Vec3f>& normals,
                         const PoissonOptions& o, PoissonReport* report) {
    const auto start = std::chrono::steady_clock::now();
    if (positions.size() < 16)
        fail("Poisson reconstruction needs at least 16 points; the input has %zu", positions.size());
    if (!normals.empty() && normals.size() != positions.size())
        fail("Poisson reconstruction: %zu normals for %zu points", normals.size(), positions.size());
    PoissonReport r;
    r.input_points = positions.size();
    std::vector<PointWithNormal> points;
    points.reserve(positions.size());
    for (size_t i = 0; i < positions.size(); ++i) {
        const Vec3d& p = positions[i];
        if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
            fail("Poisson reconstruction: point %zu is not finite", i);
        const Vector n = normals.empty() ? Vector(0, 0, 0) : Vector(normals[i][0], normals[i][1], normals[i][2]);
        points.push_back({Point(p[0], p[1], p[2]), n});
    }
    if (normals.empty()) {
        r.normals_estimated = points.size();
        r.unoriented_dropped = estimate_and_orient_normals(points, o.normal_neighbours);
        if (points.size() < 16) fail("Poisson reconstruction: too few points kept an oriented normal");
    }
    r.average_spacing = CGAL::compute_average_spacing<CGAL::Sequential_tag>(points, 6, CGAL::parameters::point_map(PointMap()));
    if (!(r.average_spacing > 0)) fail("Poisson reconstruction: the points have no spacing (all coincide?)");
    CGAL::Poisson_reconstruction_function<Kernel> function(points.begin(), points.end(), PointMap(), NormalMap());
    if (!function.compute_implicit_function())
        fail("Poisson reconstruction: the solver did not converge (check that the normals are consistent)");
    Mesh mesh = mesh_zero_set(function, r.average_spacing, o);
    r.vertices = mesh.positions.size();
    r.triangles = mesh.indices.size() / 3;
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (report) *report = r;
    return mesh;
}

}  // namespace catpaq::aqp
