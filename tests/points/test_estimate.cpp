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

}  // namespace

TEST(PointEstimate, SmallestEigenvectorHasEigensBits) {
    std::mt19937_64 random(7);
    std::uniform_real_distribution<double> uniform(-1, 1);
    for (int trial = 0; trial < 20000; ++trial) {
        // Points spread along three random axes by scales from planar to linear to isotropic.
        const int kind = trial % 5;
        const double scales[5][3] = {{1, 1, 1e-3}, {1, 1e-3, 1e-4}, {1, 1, 1}, {1, 0.5, 0.1}, {1, 1, 0}};
        Eigen::Matrix3d axes = Eigen::Matrix3d::NullaryExpr([&] { return uniform(random); });
        double p[16][3], mean[3] = {0, 0, 0};
        for (auto& q : p) {
            const double u[3] = {uniform(random) * scales[kind][0], uniform(random) * scales[kind][1],
                                 uniform(random) * scales[kind][2]};
            for (int a = 0; a < 3; ++a) {
                q[a] = 100 + axes(a, 0) * u[0] + axes(a, 1) * u[1] + axes(a, 2) * u[2];
                mean[a] += q[a] / 16;
            }
        }
        double c[6] = {0, 0, 0, 0, 0, 0};
        for (auto& q : p) {
            const double d[3] = {q[0] - mean[0], q[1] - mean[1], q[2] - mean[2]};
            c[0] += d[0] * d[0], c[1] += d[0] * d[1], c[2] += d[0] * d[2];
            c[3] += d[1] * d[1], c[4] += d[1] * d[2], c[5] += d[2] * d[2];
        }
        expect_as_eigen(c);
        if (HasFailure()) return;
    }
    // Degenerate ones: zero, a multiple of the identity, diagonal with ties, a single axis.
    const double special[][6] = {{0, 0, 0, 0, 0, 0}, {2, 0, 0, 2, 0, 2}, {1, 0, 0, 1, 0, 0}, {0, 0, 0, 0, 0, 1},
                                 {1, 0, 0, 0, 0, 0}, {3, 0, 0, 1, 0, 1}, {1, 1, 1, 1, 1, 1}, {1e-300, 0, 0, 1e-300, 0, 0}};
    for (const auto& c : special) expect_as_eigen(c);
}
