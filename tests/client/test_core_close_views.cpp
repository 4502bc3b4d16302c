// Close views: the certified error stays an honest, finite bound when the eye comes close to a
// node or enters its box (it was error * k / near: 18,000 px with the eye inside a node's box),
// and uses where a node's data really is, when the residency knows it. And the frame statistics
// say what kept the error above the tolerance.
#include <gtest/gtest.h>

#include <cmath>

#include "client/cut_engine.h"
#include "client/hierarchy.h"
#include "test_core_support.h"

using namespace catpaq;
using catpaq::test::camera;

namespace {

// One root with data over [0,10]^3 (error 0.1) and two leaf children halving it along x.
Hierarchy cube(double root_error = 0.1, double leaf_error = 0.01) {
    Hierarchy h;
    Aabb box;
    box.extend(std::array<double, 3>{0, 0, 0});
    box.extend(std::array<double, 3>{10, 10, 10});
    uint32_t root = h.add_node(1, 0, root_error, box, true);
    h.mutable_node(root).parts.push_back({kNoNode, 0, 100});
    for (int i = 0; i < 2; ++i) {
        Aabb half;
        half.extend(std::array<double, 3>{5.0 * i, 0, 0});
        half.extend(std::array<double, 3>{5.0 * i + 5, 10, 10});
        uint32_t c = h.add_node(2 + i, 1, leaf_error, half, true);
        h.add_parent(c, root);
        h.mutable_node(c).parts.push_back({root, 0, 100});
    }
    h.finalize();
    return h;
}

// Everything resident; optionally the data of every node lies in `data` (a box) at `distance`
// from any eye the test uses.
class KnownDataResidency : public Residency {
public:
    bool resident(uint32_t) const override { return true; }
    NodeBytes bytes(uint32_t) const override { return {16, 16}; }
    const Aabb* data_bounds(uint32_t) const override { return data.empty() ? nullptr : &data; }
    double data_distance(uint32_t, const std::array<double, 3>&) const override { return distance; }
    Aabb data;
    double distance = 0;
};

}  // namespace

TEST(ProjectedError, IsTheAngleTheErrorCanSpanInPixelsAndStaysFinite) {
    const double k = 500;
    // Far away it is the familiar error * k / d (to first order) and never below it.
    EXPECT_NEAR(projected_error_px(0.01, 100, k), 0.01 * k / 100, 1e-9);
    EXPECT_GE(projected_error_px(0.5, 1, k), 0.5 * k / 1);
    EXPECT_DOUBLE_EQ(projected_error_px(0.5, 1, k), k * std::asin(0.5));
    // Within `error` of the eye the deviation can cover the whole view: k * pi, not infinity.
    EXPECT_DOUBLE_EQ(projected_error_px(0.5, 0.5, k), k * M_PI);
    EXPECT_DOUBLE_EQ(projected_error_px(0.5, 0, k), k * M_PI);
    EXPECT_EQ(projected_error_px(0, 0, k), 0);
    // Monotone: nearer is never smaller.
    for (double d = 0.51; d < 10; d *= 1.3) EXPECT_GE(projected_error_px(0.5, d, k), projected_error_px(0.5, d * 1.3, k));
}

TEST(CutEngine, TheEyeInsideANodesBoxGivesABoundedCertifiedError) {
    Hierarchy h = cube();
    PartDrawCounter counter(h);
    CutEngine engine(h, counter);
    KnownDataResidency residency;  // knows nothing of the data: the hierarchy's boxes count
    ViewParams v = camera({2, 5, 5}, {9, 5, 5}, 1.5);  // inside the root's box and a leaf's
    v.near = 1e-6;
    for (int i = 0; i < 5; ++i) engine.update(v, residency);
    const CutFrameStats& s = engine.last_frame().stats;
    EXPECT_LE(s.certified_error_px, v.k() * M_PI * (1 + 1e-12));
    EXPECT_GT(s.certified_error_px, 100);  // the leaf's data may be at the eye: nothing better is known
    EXPECT_GT(s.leaves_over_tolerance, 0u) << "the finest level is what stops refinement";
}

TEST(CutEngine, WhereTheDataIsKnownTheCertifiedErrorUsesItsDistance) {
    Hierarchy h = cube();
    PartDrawCounter counter(h);
    CutEngine engine(h, counter);
    KnownDataResidency residency;
    // The geometry is a slab at x in [9, 10]: the eye at x = 2 is 7 away from it (though inside
    // every box of the hierarchy), and the distance to the triangles says 7 too.
    residency.data.extend(std::array<double, 3>{9, 0, 0});
    residency.data.extend(std::array<double, 3>{10, 10, 10});
    residency.distance = 7;
    ViewParams v = camera({2, 5, 5}, {9, 5, 5}, 1.5);
    for (int i = 0; i < 5; ++i) engine.update(v, residency);
    const CutFrameStats& s = engine.last_frame().stats;
    EXPECT_NEAR(s.certified_error_px, v.k() * std::asin(0.01 / 7), 1e-9);
    EXPECT_LT(s.certified_error_px, 1.5);
    EXPECT_EQ(s.leaves_over_tolerance, 0u);
}

TEST(CutEngine, ABudgetThatRefusesARefinementIsNamed) {
    Hierarchy h = cube();
    PartDrawCounter counter(h);
    CutBudgets budgets;
    budgets.max_primitives = 150;  // the root (100) fits, its two leaves (200) do not
    CutEngine engine(h, counter, budgets);
    KnownDataResidency residency;
    ViewParams v = camera({5, 5, 30}, {5, 5, 5}, 0.5);
    for (int i = 0; i < 5; ++i) engine.update(v, residency);
    const CutFrameStats& s = engine.last_frame().stats;
    EXPECT_GT(s.certified_error_px, 0.5);
    EXPECT_GT(s.budget_blocked, 0u);
    EXPECT_EQ(s.budgets_binding, kPrimitiveBudget);
    EXPECT_EQ(s.leaves_over_tolerance, 0u);
}
