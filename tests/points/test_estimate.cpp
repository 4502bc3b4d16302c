// points/src/estimate.h's smallest_eigenvector against the Eigen solver it stands in for: the
// same bits on covariances of planar, linear, isotropic and degenerate neighbourhoods.
#include <gtest/gtest.h>

#include <cstring>
#include <random>

#include <Eigen/Eigenvalues>

#include "../../points/src/estimate.h"

using namespace catpaq::points_detail;

namespace {

void expect_as_eigen(const double c[6]) {
    Eigen::Matrix3d m;
    m << c[0], c[1], c[2], c[1], c[3], c[4], c[2], c[4], c[5];
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
    solver.computeDirect(m);
    double vector[3], values[3];
    smallest_eigenvector(c, vector, values);
    const Eigen::Vector3d n = solver.eigenvectors().col(0), v = solver.eigenvalues();
    for (int a = 0; a < 3; ++a) {
        // Bit for bit (NaN included).
        EXPECT_EQ(std::memcmp(&vector[a], &n[a], 8), 0) << a << ": " << vector[a] << " " << n[a];
        EXPECT_EQ(std::memcmp(&values[a], &v[a], 8), 0) << a << ": " << values[a] << " " << v[a];
    }
}

// The covariance (xx, xy, xz, yy, yz, zz) of 16 points spread uniformly by `scales` along the
// columns of `axes`, around `centre` on every axis.
void random_covariance(std::mt19937_64& random, const double scales[3], const Eigen::Matrix3d& axes, double centre,
                       double c[6]) {
    std::uniform_real_distribution<double> uniform(-1, 1);
    double p[16][3], mean[3] = {0, 0, 0};
    for (auto& q : p) {
        const double u[3] = {uniform(random) * scales[0], uniform(random) * scales[1], uniform(random) * scales[2]};
        for (int a = 0; a < 3; ++a) {
            q[a] = centre + axes(a, 0) * u[0] + axes(a, 1) * u[1] + axes(a, 2) * u[2];
            mean[a] += q[a] / 16;
        }
    }
    for (int i = 0; i < 6; ++i) c[i] = 0;
    for (auto& q : p) {
        const double d[3] = {q[0] - mean[0], q[1] - mean[1], q[2] - mean[2]};
        c[0] += d[0] * d[0], c[1] += d[0] * d[1], c[2] += d[0] * d[2];
        c[3] += d[1] * d[1], c[4] += d[1] * d[2], c[5] += d[2] * d[2];
    }
}

}  // namespace

TEST(PointEstimate, SmallestEigenvectorHasEigensBits) {
    std::mt19937_64 random(7);
    std::uniform_real_distribution<double> uniform(-1, 1);
    for (int trial = 0; trial < 20000; ++trial) {
        // Points spread along three random axes by scales from planar to linear to isotropic.
        const int kind = trial % 5;
        const double scales[5][3] = {{1, 1, 1e-3}, {1, 1e-3, 1e-4}, {1, 1, 1}, {1, 0.5, 0.1}, {1, 1, 0}};
        Eigen::Matrix3d axes = Eigen::Matrix3d::NullaryExpr([&] { return uniform(random); });
        double c[6];
        random_covariance(random, scales[kind], axes, 100, c);
        expect_as_eigen(c);
        if (HasFailure()) return;
    }
    // Degenerate ones: zero, a multiple of the identity, diagonal with ties, a single axis.
    const double special[][6] = {{0, 0, 0, 0, 0, 0}, {2, 0, 0, 2, 0, 2}, {1, 0, 0, 1, 0, 0}, {0, 0, 0, 0, 0, 1},
                                 {1, 0, 0, 0, 0, 0}, {3, 0, 0, 1, 0, 1}, {1, 1, 1, 1, 1, 1}, {1e-300, 0, 0, 1e-300, 0, 0}};
    for (const auto& c : special) expect_as_eigen(c);
}

// The Newton path for neighbourhoods with a plane: where it answers, the vector is Eigen's line
// within 1e-6 rad (the 16-bit octahedral code's step is 1e-2; the two closed forms round
// differently, by about 2e-8 on these) and the eigenvalues Eigen's within 1e-9 of the largest; it answers on every
// neighbourhood with a clear plane, and declines linear and degenerate ones.
TEST(PointEstimate, PlaneEigenvectorAgreesWithEigenAndDeclinesWithoutAPlane) {
    std::mt19937_64 random(13);
    std::uniform_real_distribution<double> uniform(-1, 1);
    const double scales[6][3] = {{1, 1, 1e-3}, {1, 0.3, 1e-2}, {1, 1, 0}, {1, 0.5, 0.1}, {1, 1, 1}, {1, 1e-4, 1e-5}};
    size_t answered[6] = {0, 0, 0, 0, 0, 0};
    const int trials = 6000;
    for (int trial = 0; trial < trials; ++trial) {
        const int kind = trial % 6;
        // Orthonormal axes (a random rotation), so that the scales are the spread along them.
        Eigen::Matrix3d axes = Eigen::Matrix3d::NullaryExpr([&] { return uniform(random); }).householderQr().householderQ();
        double c[6];
        random_covariance(random, scales[kind], axes, 10, c);
        double v[3], l[3], ve[3], le[3];
        smallest_eigenvector(c, ve, le);
        if (!plane_eigenvector(c, v, l)) continue;
        ++answered[kind];
        const double dot = std::fabs(v[0] * ve[0] + v[1] * ve[1] + v[2] * ve[2]);
        ASSERT_LT(std::acos(std::min(dot, 1.0)), 1e-6) << "trial " << trial;
        ASSERT_NEAR(std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]), 1.0, 1e-12);
        for (int a = 0; a < 3; ++a) ASSERT_NEAR(l[a], le[a], 1e-9 * le[2]) << "trial " << trial << " value " << a;
    }
    const size_t per_kind = trials / 6;
    EXPECT_EQ(answered[0], per_kind);  // planes
    EXPECT_EQ(answered[1], per_kind);
    EXPECT_EQ(answered[2], per_kind);  // exact planes (a zero eigenvalue)
    EXPECT_GT(answered[3], per_kind * 9 / 10);
    // (16 random points spread alike on three axes still have a smallest spread, often well
    // apart: where the Newton path answers them, it agrees as above.)
    EXPECT_EQ(answered[5], 0u);            // lines
    double v[3], l[3];
    const double degenerate[][6] = {{0, 0, 0, 0, 0, 0}, {2, 0, 0, 2, 0, 2}, {1, 0, 0, 0, 0, 0}, {NAN, 0, 0, 1, 0, 1}};
    for (const auto& c : degenerate) EXPECT_FALSE(plane_eigenvector(c, v, l));
}
