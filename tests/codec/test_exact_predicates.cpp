#include <gtest/gtest.h>

#include "common_codec/exact_predicates.h"

using namespace catpaq;

TEST(ExactPredicates, OrientationSignsAreExactForNearlyCoplanarPoints) {
    double a[3] = {0, 0, 0}, b[3] = {1, 0, 0}, c[3] = {0, 1, 0};
    double above[3] = {0.3, 0.3, 1e-300}, on[3] = {0.3, 0.3, 0.0}, below[3] = {0.3, 0.3, -1e-300};
    EXPECT_EQ(orient3d(a, b, c, above), 1);
    EXPECT_EQ(orient3d(a, b, c, on), 0);
    EXPECT_EQ(orient3d(a, b, c, below), -1);
}

TEST(ExactPredicates, PointOnADiagonalPlaneFarFromTheOriginIsCoplanar) {
    // The plane x = y through lattice points around 2^21; floating-point evaluation of the
    // determinant would round, the exact predicate must return 0.
    double a[3] = {2097152, 2097152, 0}, b[3] = {2097153, 2097153, 5}, c[3] = {0, 0, 7};
    double p[3] = {1048576.125, 1048576.125, 3.3};
    EXPECT_EQ(orient3d(a, b, c, p), 0);
    double q[3] = {1048576.125, 1048576.1250000002, 3.3};
    EXPECT_NE(orient3d(a, b, c, q), 0);
}

TEST(ExactPredicates, Orient2dOnCoordinatePlanes) {
    double a[3] = {0, 0, 5}, b[3] = {1, 0, 6}, c[3] = {0, 1, 7};
    EXPECT_EQ(orient2d(a, b, c, 0, 1), 1);
    EXPECT_EQ(orient2d(a, c, b, 0, 1), -1);
}
