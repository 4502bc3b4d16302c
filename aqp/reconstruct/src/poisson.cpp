// Poisson surface reconstruction through CGAL (aqp_reconstruct/poisson.h). All the CGAL of the
// AQP side is in this file, so that only it pays CGAL's compile time.
#include "aqp_reconstruct/poisson.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <optional>
#include <unordered_map>
#include <utility>

#include <Eigen/Eigenvalues>

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

// The Poisson function as the surface mesher sees it, counting its evaluations. The mesher's work
// follows the area of the zero set: about 100 evaluations per input point on closed scans and
// spheres, 430 on a cloud whose density varies a hundredfold (its average spacing is the dense
// part's). Open clouds are refused before meshing (poisson_reconstruct: their zero set runs out
// to the mesher's bounding sphere, five times the points' radius); this bounds whatever else
// makes the zero set much larger than the points: past `limit` evaluations the mesher is stopped
// (by an exception, the only way out of CGAL's refinement loop) and the reconstruction refused.
struct CountedFunction {
    struct Exhausted {};
    const CGAL::Poisson_reconstruction_function<Kernel>* function;
    uint64_t* evaluations;
    uint64_t limit;
    Kernel::FT operator()(const Point& p) const {
        if (++*evaluations > limit) throw Exhausted{};
        return (*function)(p);
    }
};

// The implicit function's zero set meshed as a closed manifold (Manifold_tag), copied into a
// Mesh: vertices in the mesher's order, triangles oriented outwards (CGAL orients the facet
// with the largest z towards +z and propagates). None when the mesher used up `limit`
// evaluations.
std::optional<Mesh> mesh_zero_set(const CGAL::Poisson_reconstruction_function<Kernel>& function, double spacing,
                                    const PoissonOptions& o, uint64_t limit, uint64_t* evaluations) {
    using Triangulation = CGAL::Surface_mesher::Surface_mesh_default_triangulation_3_generator<Kernel>::Type;
    using Complex = CGAL::Surface_mesh_complex_2_in_triangulation_3<Triangulation>;
    using Surface = CGAL::Implicit_surface_3<Kernel, CountedFunction>;
    const Point inner = function.get_inner_point();
    const Kernel::Sphere_3 bounding = function.bounding_sphere();
    const double radius = std::sqrt(CGAL::to_double(bounding.squared_radius()));
    const double sphere_radius = 5.0 * radius;
    const double dichotomy_error = o.distance * spacing / 1000.0;
    Surface surface(CountedFunction{&function, evaluations, limit},
                    Kernel::Sphere_3(inner, sphere_radius * sphere_radius), dichotomy_error / sphere_radius);
    CGAL::Surface_mesh_default_criteria_3<Triangulation> criteria(o.min_angle, o.radius * spacing, o.distance * spacing);
    Triangulation triangulation;
    Complex complex(triangulation);
    try {
        CGAL::make_surface_mesh(complex, surface, criteria, CGAL::Manifold_tag());
    } catch (const CountedFunction::Exhausted&) {
        return std::nullopt;
    }
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
    // CGAL works on the points moved to the origin and scaled to a unit box (the mesh is mapped
    // back), where its tolerances hold: a sphere 2e-3 wide a million units from the origin failed
    // the mesher's own assertion ("a facet is not in conflict with its refinement point").
    Bounds box;
    for (size_t i = 0; i < positions.size(); ++i) {
        const Vec3d& p = positions[i];
        if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
            fail("Poisson reconstruction: point %zu is not finite", i);
        box.add(p);
    }
    Vec3d centre;
    double extent = 0;
    for (int a = 0; a < 3; ++a) {
        centre[a] = 0.5 * box.min[a] + 0.5 * box.max[a];
        extent = std::max(extent, box.max[a] - box.min[a]);
    }
    if (!(extent > 0) || !std::isfinite(extent))
        fail("Poisson reconstruction: the points have no extent (all coincide), or one too large for doubles");
    const double scale = 1.0 / extent;
    std::vector<PointWithNormal> points;
    points.reserve(positions.size());
    for (size_t i = 0; i < positions.size(); ++i) {
        const Vec3d& p = positions[i];
        const Vector n = normals.empty() ? Vector(0, 0, 0) : Vector(normals[i][0], normals[i][1], normals[i][2]);
        points.push_back({Point((p[0] - centre[0]) * scale, (p[1] - centre[1]) * scale, (p[2] - centre[2]) * scale), n});
    }
    // Repeated positions (a cloud merged from overlapping scans, or coordinates written with too
    // few digits) leave a point no neighbourhood to fit: CGAL's jet fit crashed on them. The first
    // of each is kept.
    {
        std::vector<uint32_t> order(points.size());
        for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
        auto key = [&](uint32_t i) {
            const Point& p = points[i].first;
            return std::array<double, 3>{p.x(), p.y(), p.z()};
        };
        std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return key(a) < key(b); });
        std::vector<uint8_t> repeated(points.size(), 0);
        for (size_t k = 1; k < order.size(); ++k) repeated[order[k]] = key(order[k]) == key(order[k - 1]);
        size_t kept = 0;
        for (size_t i = 0; i < points.size(); ++i)
            if (!repeated[i]) points[kept++] = points[i];
        r.repeated_dropped = points.size() - kept;
        points.resize(kept);
        if (points.size() < 16)
            fail("Poisson reconstruction needs at least 16 distinct points; the input has %zu (of %zu points)",
                 points.size(), positions.size());
    }
    // Points on one plane (or line) enclose no volume, and CGAL's triangulation stops on a failed
    // precondition: refused here with a message that says why. Flat: the spread across the
    // points' thinnest direction is below 1e-9 of the unit box they were scaled to.
    {
        Eigen::Vector3d mean = Eigen::Vector3d::Zero();
        for (const PointWithNormal& p : points) mean += Eigen::Vector3d(p.first.x(), p.first.y(), p.first.z());
        mean /= double(points.size());
        Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
        for (const PointWithNormal& p : points) {
            const Eigen::Vector3d d = Eigen::Vector3d(p.first.x(), p.first.y(), p.first.z()) - mean;
            covariance += d * d.transpose();
        }
        covariance /= double(points.size());
        const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(covariance, Eigen::EigenvaluesOnly);
        if (!(std::sqrt(std::max(0.0, solver.eigenvalues()[0])) > 1e-9))
            fail("Poisson reconstruction: the %zu points lie on one plane (or line) and enclose no volume: AQP needs a "
                 "closed surface; convert them with --format points",
                 points.size());
    }
    if (normals.empty()) {
        r.normals_estimated = points.size();
        r.unoriented_dropped = estimate_and_orient_normals(points, o.normal_neighbours);
        if (points.size() < 16) fail("Poisson reconstruction: too few points kept an oriented normal");
    }
    const double spacing =
        CGAL::compute_average_spacing<CGAL::Sequential_tag>(points, 6, CGAL::parameters::point_map(PointMap()));
    if (!(spacing > 0)) fail("Poisson reconstruction: the points have no spacing (all coincide?)");
    r.average_spacing = spacing * extent;
    CGAL::Poisson_reconstruction_function<Kernel> function(points.begin(), points.end(), PointMap(), NormalMap());
    if (!function.compute_implicit_function())
        fail("Poisson reconstruction: the solver did not converge (check that the normals are consistent)");
    // A closed surface has the points inside it and the outside (positive) all around them: the
    // function on a sphere of 1.5 times the points' radius is positive. An open one (a terrain,
    // a facade) leaves a function near zero far from the points, whose zero set the mesher
    // chased out to its bounding sphere: a 3000-point height field ran for over five minutes,
    // growing past a gigabyte, before this test refused it in a second.
    const Kernel::Sphere_3 around = function.bounding_sphere();
    const double around_radius = 1.5 * std::sqrt(CGAL::to_double(around.squared_radius()));
    constexpr int kSphereSamples = 2048;
    for (int k = 0; k < kSphereSamples; ++k) {
        // Fibonacci sphere: evenly spread directions.
        const double z = 1.0 - (2.0 * k + 1.0) / kSphereSamples, ring = std::sqrt(std::max(0.0, 1.0 - z * z));
        const double angle = 2.399963229728653 * k;
        const Point q(around.center().x() + around_radius * ring * std::cos(angle),
                      around.center().y() + around_radius * ring * std::sin(angle),
                      around.center().z() + around_radius * z);
        if (!(CGAL::to_double(function(q)) > 0))
            fail("Poisson reconstruction: the %zu points do not enclose a volume (the implicit surface reaches past "
                 "1.5 times their radius): they do not sample a closed surface (a terrain, a facade, a scan with "
                 "large holes or normals that point inwards). AQP needs a closed surface: convert the points with "
                 "--format points, or a mesh of them with --format catp",
                 points.size());
    }
    uint64_t evaluations = 0;
    const uint64_t limit = o.evaluations_per_point * uint64_t(points.size()) + (uint64_t(1) << 20);
    std::optional<Mesh> meshed = mesh_zero_set(function, spacing, o, limit, &evaluations);
    if (!meshed)
        fail("Poisson reconstruction: the surface of the %zu points is far larger than they are (the mesher stopped "
             "after %llu evaluations of the implicit function): the points do not sample a closed surface (a "
             "terrain, a facade, a scan with large holes). AQP needs a closed surface: convert the points with "
             "--format points, or a mesh of them with --format catp",
             points.size(), (unsigned long long)evaluations);
    Mesh mesh = std::move(*meshed);
    for (Vec3d& p : mesh.positions)
        for (int a = 0; a < 3; ++a) p[a] = centre[a] + p[a] * extent;
    r.evaluations = evaluations;
    r.vertices = mesh.positions.size();
    r.triangles = mesh.indices.size() / 3;
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (report) *report = r;
    return mesh;
}

}  // namespace catpaq::aqp
