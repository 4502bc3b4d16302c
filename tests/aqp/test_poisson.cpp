// Poisson reconstruction of point clouds for AQP (aqp_reconstruct/poisson.h): a closed, oriented
// manifold close to the sampled surface, with normals given or estimated; bad input refused.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "aqp/clean.h"
#include "aqp_reconstruct/poisson.h"
#include "base/error.h"

using namespace catpaq;
using namespace catpaq::aqp;

namespace {

// `n` points uniformly on the sphere of radius `r` about `centre`, with outward normals.
void sample_sphere(size_t n, double r, const Vec3d& centre, std::vector<Vec3d>& points, std::vector<Vec3f>& normals) {
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> u(-1, 1), angle(0, 2 * M_PI);
    for (size_t i = 0; i < n; ++i) {
        const double z = u(rng), t = angle(rng), s = std::sqrt(1 - z * z);
        const Vec3d d{s * std::cos(t), s * std::sin(t), z};
        points.push_back({centre[0] + r * d[0], centre[1] + r * d[1], centre[2] + r * d[2]});
        normals.push_back({float(d[0]), float(d[1]), float(d[2])});
    }
}

// Signed volume of a closed mesh (positive when its triangles face outwards), about `o` (near the
// mesh, so that far offsets do not cancel).
double signed_volume(const Mesh& m, const Vec3d& o) {
    double v = 0;
    auto at = [&](uint32_t i) {
        const Vec3d& p = m.positions[i];
        return Vec3d{p[0] - o[0], p[1] - o[1], p[2] - o[2]};
    };
    for (size_t t = 0; t < m.triangle_count(); ++t) {
        const Vec3d a = at(m.indices[3 * t]), b = at(m.indices[3 * t + 1]), c = at(m.indices[3 * t + 2]);
        v += (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) + a[2] * (b[0] * c[1] - b[1] * c[0])) / 6;
    }
    return v;
}

void expect_closed_sphere(const Mesh& m, double r, const Vec3d& centre, double tolerance) {
    std::string why;
    EXPECT_TRUE(is_oriented_manifold(m, &why)) << why;
    Mesh copy = m;
    CleanReport clean;
    clean_to_manifold(copy, CleanOptions{}, &clean);
    EXPECT_EQ(clean.border_edges, 0u);
    EXPECT_EQ(clean.components, 1u);
    EXPECT_EQ(clean.genus, 0);
    double worst = 0;
    for (const Vec3d& p : m.positions)
        worst = std::max(worst, std::fabs(std::hypot(p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]) - r));
    EXPECT_LT(worst, tolerance);
    const double volume = signed_volume(m, centre), sphere = 4.0 / 3.0 * M_PI * r * r * r;
    EXPECT_NEAR(volume, sphere, 0.05 * sphere) << "faces outwards and encloses the sphere";
}

}  // namespace

TEST(Poisson, PointsWithNormalsBecomeAClosedOrientedSphere) {
    std::vector<Vec3d> points;
    std::vector<Vec3f> normals;
    sample_sphere(6000, 1.0, {0, 0, 0}, points, normals);
    PoissonReport report;
    const Mesh m = poisson_reconstruct(points, normals, PoissonOptions{}, &report);
    EXPECT_EQ(report.normals_estimated, 0u);
    EXPECT_GT(report.triangles, 1000u);
    expect_closed_sphere(m, 1.0, {0, 0, 0}, 0.02);
}

// Without normals they are estimated and oriented; a far offset keeps the result in place.
TEST(Poisson, NormalsAreEstimatedAndOrientedFarFromTheOrigin) {
    std::vector<Vec3d> points;
    std::vector<Vec3f> normals;
    const Vec3d centre{1e6, -2e6, 5e5};
    sample_sphere(6000, 1.0, centre, points, normals);
    PoissonReport report;
    const Mesh m = poisson_reconstruct(points, {}, PoissonOptions{}, &report);
    EXPECT_EQ(report.normals_estimated, 6000u);
    expect_closed_sphere(m, 1.0, centre, 0.03);
}

TEST(Poisson, TooFewOrNonFinitePointsAreRefusedWithAMessage) {
    std::vector<Vec3d> points;
    std::vector<Vec3f> normals;
    sample_sphere(10, 1.0, {0, 0, 0}, points, normals);
    try {
        poisson_reconstruct(points, normals, PoissonOptions{});
        FAIL() << "10 points accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("at least 16 points"), std::string::npos) << e.what();
    }
    sample_sphere(100, 1.0, {0, 0, 0}, points, normals);
    points[50][1] = NAN;
    try {
        poisson_reconstruct(points, normals, PoissonOptions{});
        FAIL() << "a NaN accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("not finite"), std::string::npos) << e.what();
    }
}

// The reconstruction works on the cloud moved to the origin and scaled to a unit box: the same
// sphere converts at any size and offset. (A sphere 2e-3 wide at 1e6 failed CGAL's mesher before.)
TEST(Poisson, SpheresOfAnySizeAndOffsetBecomeClosedSpheres) {
    const struct {
        double radius;
        Vec3d centre;
    } cases[] = {{1e-3, {1e6, 1e6, 1e6}},
                 {1e-12, {0, 0, 0}},
                 {1e15, {0, 0, 0}},
                 {1e25, {-3e25, 0, 0}},
                 {1.0, {1e7, -1e7, 0}}};
    for (const auto& c : cases) {
        SCOPED_TRACE(testing::Message() << "radius " << c.radius << " at " << c.centre[0]);
        std::vector<Vec3d> points;
        std::vector<Vec3f> normals;
        sample_sphere(6000, c.radius, c.centre, points, normals);
        PoissonReport report;
        const Mesh m = poisson_reconstruct(points, {}, PoissonOptions{}, &report);
        expect_closed_sphere(m, c.radius, c.centre, 0.04 * c.radius);
        EXPECT_NEAR(report.average_spacing / c.radius, 0.03, 0.02) << "reported in the input's units";
    }
}

// An open surface's zero set does not close around the points: refused at once with a message
// (it ran for minutes and gigabytes in the surface mesher before), at any scale.
TEST(Poisson, AnOpenSheetIsRefusedAsNotClosed) {
    for (double scale : {1.0, 1e-20, 1e19}) {
        std::mt19937_64 rng(7);
        std::uniform_real_distribution<double> u(0, 1);
        std::vector<Vec3d> points;
        for (int i = 0; i < 3000; ++i) {
            const double x = u(rng), y = u(rng);
            points.push_back({scale * x, scale * y, scale * 0.1 * (x * x + y)});
        }
        try {
            poisson_reconstruct(points, {}, PoissonOptions{});
            FAIL() << "an open sheet accepted at scale " << scale;
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("do not enclose a volume"), std::string::npos) << e.what();
        }
    }
}

// Repeated points are left out (CGAL's jet fit crashed on a cloud of a few distinct positions);
// too few distinct points, and points on one plane, are refused with a message that says so.
TEST(Poisson, RepeatedPointsAreDroppedAndFlatOrFewPointsRefused) {
    std::vector<Vec3d> points;
    std::vector<Vec3f> normals;
    sample_sphere(3000, 1.0, {0, 0, 0}, points, normals);
    const size_t distinct = points.size();
    for (size_t i = 0; i < distinct; i += 2) points.push_back(points[i]);
    PoissonReport report;
    const Mesh m = poisson_reconstruct(points, {}, PoissonOptions{}, &report);
    EXPECT_EQ(report.repeated_dropped, (distinct + 1) / 2);
    expect_closed_sphere(m, 1.0, {0, 0, 0}, 0.03);

    auto refused = [](const std::vector<Vec3d>& cloud, const char* why) {
        try {
            poisson_reconstruct(cloud, {}, PoissonOptions{});
            ADD_FAILURE() << "accepted; expected: " << why;
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
        }
    };
    std::vector<Vec3d> few;
    for (int i = 0; i < 3000; ++i) few.push_back({1e7 + double(i % 4), 0, double(i % 3)});
    refused(few, "at least 16 distinct points");
    std::vector<Vec3d> plane, line;
    std::mt19937_64 rng(9);
    std::uniform_real_distribution<double> u(0, 1);
    for (int i = 0; i < 3000; ++i) {
        const double x = u(rng), y = u(rng);
        plane.push_back({x, y, 2.0});
        line.push_back({x, 2 * x, 3 * x});
    }
    refused(plane, "lie on one plane");
    refused(line, "lie on one plane (or line)");
}

// The surface mesher's evaluations of the implicit function are bounded (about 100 a point on a
// closed surface): past the limit the reconstruction is refused with a message, not left to run.
TEST(Poisson, TheMeshersWorkIsBounded) {
    std::vector<Vec3d> points;
    std::vector<Vec3f> normals;
    sample_sphere(12000, 1.0, {0, 0, 0}, points, normals);
    PoissonOptions options;
    options.evaluations_per_point = 0;  // the limit is then the fixed 2^20, below this sphere's needs
    try {
        poisson_reconstruct(points, normals, options);
        FAIL() << "the mesher ran past its limit";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("far larger than they are"), std::string::npos) << e.what();
    }
    PoissonReport report;
    poisson_reconstruct(points, normals, PoissonOptions{}, &report);
    EXPECT_GT(report.evaluations, uint64_t(1) << 20) << "the refusal above proves nothing";
    EXPECT_LT(report.evaluations, 200 * points.size());
}
