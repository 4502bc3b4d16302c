// The cut engine on synthetic DAGs (client/hierarchy.h build_synthetic_hierarchy): conforming
// cuts, budgets, monotonicity in the tolerance, convergence, frustum culling, asynchronous data,
// hysteresis and stale requests.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <set>

#include "client/cut_engine.h"
#include "client/hierarchy.h"
#include "test_core_support.h"

using namespace catpaq;
using catpaq::test::camera;
using catpaq::test::DelayedDelivery;
using catpaq::test::FakeResidency;

namespace {

constexpr double kSize = 1000.0;

Hierarchy terrain(uint64_t seed, int levels = 7, double keep = 0.9, double virtual_fraction = 0.1) {
    SyntheticHierarchySettings s;
    s.levels = levels;
    s.keep = keep;
    s.extra_parent = 0.35;
    s.virtual_fraction = virtual_fraction;
    s.size = kSize;
    s.seed = seed;
    return build_synthetic_hierarchy(s);
}

// A random camera above the terrain, looking at a random point of it.
ViewParams random_view(std::mt19937_64& rng, double tolerance = 1.5) {
    std::uniform_real_distribution<double> u(0, 1);
    std::array<double, 3> eye{u(rng) * kSize * 1.4 - kSize * 0.2, u(rng) * kSize * 1.4 - kSize * 0.2, 5 + u(rng) * kSize * 0.6};
    std::array<double, 3> target{u(rng) * kSize, u(rng) * kSize, 0};
    return camera(eye, target, tolerance);
}

// A smooth path: the eye flies along a curve at low height.
ViewParams path_view(int frame, int frames, double tolerance = 1.5) {
    double t = double(frame) / double(frames);
    double a = t * 2 * M_PI;
    std::array<double, 3> eye{kSize * (0.5 + 0.45 * std::cos(a)), kSize * (0.5 + 0.45 * std::sin(2 * a)), 20 + 150 * (1 + std::sin(3 * a))};
    std::array<double, 3> target{kSize * (0.5 + 0.3 * std::cos(a + 0.6)), kSize * (0.5 + 0.3 * std::sin(2 * a + 0.6)), 0};
    return camera(eye, target, tolerance);
}

std::set<uint32_t> refined_set(const CutEngine& engine) {
    auto v = engine.refined_nodes();
    return std::set<uint32_t>(v.begin(), v.end());
}

// Every drawn node has a refined parent or is a root; every refined node's parents are refined.
void expect_conforming(const Hierarchy& h, const CutEngine& engine, const Residency& residency) {
    ASSERT_EQ(engine.check(residency), "");
    for (uint32_t n : engine.refined_nodes())
        for (uint32_t p : h.node(n).parents) ASSERT_TRUE(engine.refined(p)) << "R is not closed under parents";
    for (uint32_t n : engine.drawn_nodes()) {
        ASSERT_FALSE(engine.refined(n));
        bool ok = h.node(n).parents.empty();
        for (uint32_t p : h.node(n).parents) ok |= engine.refined(p);
        ASSERT_TRUE(ok);
    }
}

}  // namespace

TEST(SyntheticHierarchy, IsAValidMonotoneDagWithSharedChildrenAndVirtualNodes) {
    Hierarchy h = terrain(7);
    EXPECT_EQ(h.check(), "");
    EXPECT_EQ(h.roots().size(), 1u);
    size_t shared = 0;
    for (const HierarchyNode& n : h.nodes()) shared += n.parents.size() > 1;
    EXPECT_GT(shared, h.size() / 10);
    EXPECT_GT(h.virtual_count(), 0u);
}

TEST(CutEngine, EveryCutIsConformingOverRandomCameraPaths) {
    for (uint64_t seed : {1, 2, 3}) {
        Hierarchy h = terrain(seed);
        PartDrawCounter counter(h);
        FakeResidency residency(h, true);
        CutEngine engine(h, counter);
        std::mt19937_64 rng(seed);
        for (int f = 0; f < 60; ++f) {
            ViewParams v = (f % 3 == 0) ? random_view(rng) : path_view(f, 60);
            engine.update(v, residency);
            expect_conforming(h, engine, residency);
            if (HasFatalFailure()) return;
        }
        EXPECT_GT(engine.last_frame().stats.refined_nodes, 10u);
    }
}

TEST(CutEngine, BudgetsAreNeverExceededOverRandomCameraPaths) {
    Hierarchy h = terrain(11);
    PartDrawCounter counter(h);
    FakeResidency residency(h, false);
    DelayedDelivery delivery(residency, 2);
    CutBudgets budgets;
    budgets.max_primitives = 20000;
    budgets.max_gpu_bytes = 300000;
    budgets.max_cpu_bytes = 500000;
    budgets.max_new_requests = 7;
    budgets.max_outstanding_requests = 40;
    CutEngine engine(h, counter, budgets);
    std::mt19937_64 rng(5);
    uint64_t most = 0;
    size_t blocked = 0;
    for (int f = 0; f < 400; ++f) {
        ViewParams v = (f % 40 < 20) ? path_view(f, 400, 0.5) : random_view(rng, 0.5);
        const CutFrame& frame = engine.update(v, residency);
        const CutFrameStats& s = frame.stats;
        ASSERT_LE(s.primitives, budgets.max_primitives) << "frame " << f;
        ASSERT_LE(s.gpu_bytes, budgets.max_gpu_bytes) << "frame " << f;
        ASSERT_LE(s.cpu_bytes, budgets.max_cpu_bytes) << "frame " << f;
        ASSERT_LE(s.new_requests, budgets.max_new_requests) << "frame " << f;
        ASSERT_LE(frame.requests.size(), budgets.max_outstanding_requests) << "frame " << f;
        ASSERT_FALSE(s.over_budget);
        ASSERT_EQ(engine.check(residency), "");
        most = std::max(most, s.primitives);
        blocked += s.budget_blocked;
        delivery.frame(frame);
    }
    EXPECT_GT(most, budgets.max_primitives / 2) << "the budget was never approached: the test proves nothing";
    EXPECT_GT(blocked, 0u);
}

TEST(CutEngine, LoweredBudgetsAreMetByCoarseningTheLowestErrorNodes) {
    Hierarchy h = terrain(12);
    PartDrawCounter counter(h);
    FakeResidency residency(h, true);
    CutEngine engine(h, counter);
    ViewParams v = path_view(3, 10, 0.5);
    engine.update(v, residency);
    uint64_t full = engine.last_frame().stats.primitives;
    ASSERT_GT(full, 2000u);
    CutBudgets b;
    b.max_primitives = full / 3;
    engine.set_budgets(b);
    const CutFrame& f = engine.update(v, residency);
    EXPECT_LE(f.stats.primitives, b.max_primitives);
    EXPECT_GT(f.stats.coarsenings, 0u);
    EXPECT_EQ(engine.check(residency), "");
}

TEST(CutEngine, UnderABudgetTheCutFollowsTheViewAsIfBuiltFresh) {
    // Under a binding budget, a cut that flew along a path ends where a fresh engine would be
    // for the last view, up to the hysteresis band: old detail is traded for the new view's
    // larger errors (refinement by decreasing projected error, swaps with lower-error frontier
    // nodes).
    Hierarchy h = terrain(13);
    PartDrawCounter counter(h);
    FakeResidency residency(h, true);
    CutBudgets b;
    b.max_primitives = 15000;
    CutEngine flown(h, counter, b);
    uint32_t swaps = 0;
    for (int f = 0; f <= 40; ++f) {
        const CutFrame& frame = flown.update(path_view(f, 80, 0.25), residency);
        ASSERT_LE(frame.stats.primitives, b.max_primitives);
        if (f > 0) swaps += frame.stats.coarsenings;
    }
    ViewParams last = path_view(40, 80, 0.25);
    CutEngine fresh(h, counter, b);
    const CutFrame& ff = fresh.update(last, residency);
    const CutFrame& fl = flown.update(last, residency);
    EXPECT_GT(swaps, 0u);
    EXPECT_GT(ff.stats.primitives, b.max_primitives * 3 / 4) << "the budget does not bind";
    EXPECT_LE(fl.stats.certified_error_px, ff.stats.certified_error_px / last.hysteresis * 1.0001);
}

TEST(CutEngine, LoweringTheToleranceNeverCoarsensAndNeverIncreasesTheCertifiedError) {
    Hierarchy h = terrain(21, 7, 1.0, 0.1);
    PartDrawCounter counter(h);
    FakeResidency residency(h, true);
    CutEngine engine(h, counter);
    std::array<double, 3> eye{200, 300, 60}, target{600, 500, 0};
    uint64_t last_primitives = 0;
    double last_error = 1e300;
    std::set<uint32_t> last_refined;
    for (double tol = 64; tol >= 0.25; tol /= 2) {
        ViewParams v = camera(eye, target, tol);
        engine.update(v, residency);
        const CutFrame& f = engine.update(v, residency);  // converged: nothing left to do
        EXPECT_EQ(f.stats.refinements + f.stats.coarsenings, 0u);
        std::set<uint32_t> r = refined_set(engine);
        EXPECT_TRUE(std::includes(r.begin(), r.end(), last_refined.begin(), last_refined.end())) << "tolerance " << tol;
        EXPECT_GE(f.stats.primitives, last_primitives) << "tolerance " << tol;
        EXPECT_LE(f.stats.certified_error_px, last_error) << "tolerance " << tol;
        for (uint32_t n : engine.drawn_nodes())
            if (!h.node(n).leaf && h.node(n).has_data) {
                EXPECT_LE(engine.projected_error(n), tol) << "an unrefined node above the tolerance";
            }
        last_primitives = f.stats.primitives;
        last_error = f.stats.certified_error_px;
        last_refined = r;
    }
    EXPECT_GT(last_refined.size(), 100u);
}

TEST(CutEngine, ConvergesToTheFullResolutionCutWithTinyToleranceAndUnlimitedBudgets) {
    Hierarchy h = terrain(31, 6, 0.8, 0.15);
    PartDrawCounter counter(h);
    FakeResidency residency(h, true);
    CutEngine engine(h, counter);
    // Close to the terrain, looking along it with a wide field of view, frustum off so that
    // every node counts.
    ViewParams v = camera({500, 500, 5}, {900, 900, 0}, 1e-9, 120);
    v.use_frustum = false;
    const CutFrame& f = engine.update(v, residency);
    // Expected: every non-leaf node with data refined, plus the virtual ancestors they need;
    // virtual nodes draw nothing and are never refined for their own sake.
    std::set<uint32_t> expected;
    std::vector<uint32_t> stack;
    for (const HierarchyNode& n : h.nodes())
        if (!n.leaf && n.has_data) stack.push_back(n.index);
    while (!stack.empty()) {
        uint32_t n = stack.back();
        stack.pop_back();
        if (!expected.insert(n).second) continue;
        for (uint32_t p : h.node(n).parents) stack.push_back(p);
    }
    EXPECT_EQ(refined_set(engine), expected);
    uint64_t leaf_primitives = 0;
    for (const HierarchyNode& n : h.nodes()) {
        if (n.leaf && n.has_data) {
            EXPECT_TRUE(engine.drawn(n.index)) << "leaf " << n.index;
            for (const HierarchyPart& p : n.parts) leaf_primitives += p.primitives;
        }
    }
    EXPECT_EQ(f.stats.primitives, leaf_primitives);
    EXPECT_EQ(f.requests.size(), 0u);
}

TEST(CutEngine, NodesOutsideTheFrustumRequestNothingAndAreNotRefinedForTheirOwnSake) {
    Hierarchy h = terrain(41);
    PartDrawCounter counter(h);
    {
        // Looking away from the terrain: nothing requested, nothing refined.
        FakeResidency residency(h, false);
        CutEngine engine(h, counter);
        ViewParams away = camera({500, 500, 50}, {500, 500, 5000});
        for (int f = 0; f < 5; ++f) {
            const CutFrame& frame = engine.update(away, residency);
            EXPECT_EQ(frame.requests.size(), 0u);
            EXPECT_EQ(frame.stats.refined_nodes, 0u);
        }
    }
    // Looking at one corner: data arrives, and every refined node is either seen or an
    // ancestor needed by a seen refined node; every request is on behalf of a seen node.
    FakeResidency residency(h, false);
    DelayedDelivery delivery(residency, 1);
    CutEngine engine(h, counter);
    ViewParams corner = camera({100, 100, 150}, {100, 100, 0}, 1.0, 40);
    for (int f = 0; f < 40; ++f) {
        const CutFrame& frame = engine.update(corner, residency);
        for (const CutRequest& r : frame.requests) EXPECT_GT(r.priority, 0.0);
        delivery.frame(frame);
    }
    std::set<uint32_t> needed;
    std::vector<uint32_t> stack;
    for (uint32_t n : engine.refined_nodes())
        if (corner.may_see(h.node(n).bounds)) stack.push_back(n);
    while (!stack.empty()) {
        uint32_t n = stack.back();
        stack.pop_back();
        if (!needed.insert(n).second) continue;
        for (uint32_t p : h.node(n).parents) stack.push_back(p);
    }
    size_t unseen = 0;
    for (uint32_t n : engine.refined_nodes()) {
        EXPECT_TRUE(needed.count(n)) << "node " << n << " refined outside the frustum for its own sake";
        unseen += !corner.may_see(h.node(n).bounds);
    }
    EXPECT_GT(engine.refined_nodes().size(), 20u);
    // Nothing about the far corner was ever loaded.
    for (const HierarchyNode& n : h.nodes())
        if (n.level >= 3 && n.bounds.min[0] > 700 && n.bounds.min[1] > 700) {
            EXPECT_FALSE(residency.resident(n.index));
        }
}

TEST(CutEngine, UpdateNeverWaitsAndRefinesOnlyOnceDataHasArrived) {
    Hierarchy h = terrain(51);
    PartDrawCounter counter(h);
    FakeResidency residency(h, false);
    const int delay = 4;
    DelayedDelivery delivery(residency, delay);
    CutEngine engine(h, counter);
    int first_refinement = -1;
    for (int f = 0; f < 120; ++f) {
        ViewParams v = path_view(f, 240, 1.0);
        const CutFrame& frame = engine.update(v, residency);
        // Every drawn node with data is resident, except a root still loading (a hole).
        for (uint32_t n : engine.drawn_nodes()) {
            if (!h.node(n).has_data || residency.resident(n)) continue;
            EXPECT_TRUE(h.node(n).parents.empty()) << "frame " << f << ": refined before its children arrived";
        }
        if (frame.stats.refinements > 0 && first_refinement < 0) first_refinement = f;
        if (f < delay) {
            EXPECT_EQ(frame.stats.refined_nodes, 0u);  // nothing arrived yet
        }
        delivery.frame(frame);
    }
    // The root and its children (requested at once, the root first) arrive after `delay` frames.
    EXPECT_GE(first_refinement, delay);
    EXPECT_GT(engine.refined_nodes().size(), 20u);
    EXPECT_GT(delivery.delivered(), 20u);
}

// Skipping levels: from a cold start, with data arriving a few frames after each request, the
// engine converges to the same cut as without skipping (the cut depends on projected errors
// only), fetching fewer nodes (nodes the cut refines are not fetched when their descendants can
// be drawn at once), and every drawn node with data is still resident (no holes).
TEST(CutEngine, SkippingLevelsConvergesToTheSameCutFetchingLess) {
    Hierarchy h = terrain(61, 8);
    PartDrawCounter counter(h);
    std::mt19937_64 rng(3);
    size_t views = 0, fewer = 0;
    for (int trial = 0; trial < 12; ++trial) {
        ViewParams v = random_view(rng, 1.0);
        std::set<uint32_t> cut[2];
        size_t fetched[2];
        for (int mode = 0; mode < 2; ++mode) {
            v.skip_factor = mode == 0 ? 0.0 : 8.0;
            FakeResidency residency(h, false);
            DelayedDelivery delivery(residency, 2);
            CutEngine engine(h, counter);
            for (int f = 0; f < 400; ++f) {
                const CutFrame& frame = engine.update(v, residency);
                for (uint32_t n : engine.drawn_nodes())
                    if (h.node(n).has_data && !residency.resident(n)) {
                        EXPECT_TRUE(h.node(n).parents.empty()) << "a hole below the root";
                    }
                delivery.frame(frame);
                if (frame.requests.empty() && frame.stats.refinements == 0 && f > 3) break;
            }
            EXPECT_EQ(engine.check(residency), "");
            cut[mode] = refined_set(engine);
            fetched[mode] = residency.count();
        }
        EXPECT_EQ(cut[0], cut[1]) << "trial " << trial;
        EXPECT_LE(fetched[1], fetched[0]) << "trial " << trial;
        std::printf("view %d: %zu refined, fetched %zu nodes, skipping %zu\n", trial, cut[0].size(), fetched[0], fetched[1]);
        views++;
        fewer += fetched[1] < fetched[0];
    }
    EXPECT_GE(fewer, views / 2) << "skipping saves fetches on most views";
}

TEST(CutEngine, HysteresisPreventsThrashingWhenTheCameraOscillatesSlightly) {
    Hierarchy h = terrain(61, 7, 1.0, 0.05);
    PartDrawCounter counter(h);
    FakeResidency residency(h, true);
    // Operations after convergence while the eye oscillates by 1% of its distance.
    auto run = [&](bool budgeted, bool hysteresis, size_t* refined = nullptr, uint64_t* primitives = nullptr) {
        CutBudgets b;
        if (budgeted) b.max_primitives = 22000;
        CutEngine engine(h, counter, b);
        uint32_t ops = 0;
        for (int f = 0; f < 130; ++f) {
            double wobble = 0.01 * std::sin(f * 0.7);
            std::array<double, 3> eye{300 * (1 + wobble), 250 * (1 + wobble), 80 * (1 + wobble)};
            ViewParams v = camera(eye, {600, 600, 0}, 1.0);
            if (!hysteresis) {
                v.hysteresis = 1.0;
                v.frustum_margin = 0.0;
            }
            const CutFrame& frame = engine.update(v, residency);
            if (f >= 30) ops += frame.stats.refinements + frame.stats.coarsenings;  // after full periods
        }
        if (refined) *refined = engine.refined_nodes().size();
        if (primitives) *primitives = engine.last_frame().stats.primitives;
        return ops;
    };
    for (bool budgeted : {false, true}) {
        SCOPED_TRACE(budgeted ? "with a binding budget" : "without a budget");
        size_t refined = 0;
        uint64_t primitives = 0;
        EXPECT_EQ(run(budgeted, true, &refined, &primitives), 0u);
        EXPECT_GT(refined, 50u);
        if (budgeted) {
            EXPECT_LE(primitives, 22000u);
            EXPECT_GT(primitives, 20000u);
        }
        // The same oscillation without hysteresis flips nodes: the test sits on real thresholds.
        EXPECT_GT(run(budgeted, false), 20u);
    }
}

TEST(CutEngine, RequestsAreOrderedByPriorityAndStaleOnesAreReportedCancelled) {
    Hierarchy h = terrain(71);
    PartDrawCounter counter(h);
    FakeResidency residency(h, false);
    residency.set(h.roots()[0], true);
    CutBudgets b;
    b.max_new_requests = 1000;
    CutEngine engine(h, counter, b);
    ViewParams look = camera({500, 500, 300}, {500, 500, 0}, 0.5, 90);
    const CutFrame& f1 = engine.update(look, residency);
    ASSERT_GT(f1.requests.size(), 0u);
    for (size_t i = 1; i < f1.requests.size(); ++i) {
        const CutRequest& a = f1.requests[i - 1];
        const CutRequest& c = f1.requests[i];
        bool ordered = a.reason < c.reason || (a.reason == c.reason && (a.priority > c.priority ||
                                                                         (a.priority == c.priority && a.level <= c.level)));
        EXPECT_TRUE(ordered) << i;
    }
    std::set<uint64_t> asked;
    for (const CutRequest& r : f1.requests) asked.insert(r.key);
    // Same view: the same requests again, nothing new, nothing cancelled.
    const CutFrame& f2 = engine.update(look, residency);
    EXPECT_EQ(f2.stats.new_requests, 0u);
    EXPECT_EQ(f2.cancelled.size(), 0u);
    EXPECT_EQ(f2.requests.size(), asked.size());
    // Looking away: every earlier request is cancelled.
    const CutFrame& f3 = engine.update(camera({500, 500, 300}, {500, 500, 5000}), residency);
    EXPECT_EQ(f3.requests.size(), 0u);
    std::set<uint64_t> cancelled;
    for (const CutRequest& c : f3.cancelled) cancelled.insert(c.key);
    EXPECT_EQ(cancelled, asked);
}

// Nodes fetched by parts: a refinement waits only for the parts it makes drawn (those its node
// creates in each child), so a cold start on a still view converges to the same cut as with
// whole nodes, and every part it fetched is drawn by that cut or was on the way (its creating
// parent is refined); no part of an unrefined parent is ever fetched.
TEST(CutEngine, FetchingPartsConvergesToTheSameCutFetchingOnlyPartsOfRefinedParents) {
    SyntheticHierarchySettings s;
    s.levels = 7;
    s.keep = 0.9;
    s.extra_parent = 0.35;
    s.virtual_fraction = 0.1;
    s.size = kSize;
    s.seed = 73;
    Hierarchy whole_h = build_synthetic_hierarchy(s);
    s.fetch_parts = true;
    Hierarchy parts_h = build_synthetic_hierarchy(s);
    PartDrawCounter whole_counter(whole_h), parts_counter(parts_h);
    std::mt19937_64 rng(5);
    size_t views = 0, fewer = 0;
    for (int trial = 0; trial < 10; ++trial) {
        ViewParams v = random_view(rng, 1.0);
        v.skip_factor = trial % 2 ? 8.0 : 0.0;

        FakeResidency whole(whole_h, false);
        DelayedDelivery delivery(whole, 1);
        CutEngine whole_engine(whole_h, whole_counter);
        for (int f = 0; f < 400; ++f) {
            const CutFrame& frame = whole_engine.update(v, whole);
            delivery.frame(frame);
            if (frame.requests.empty() && frame.stats.refinements == 0 && f > 3) break;
        }
        uint64_t whole_bytes = 0;
        for (uint32_t n = 0; n < whole_h.size(); ++n)
            if (whole_h.node(n).has_data && whole.resident(n)) whole_bytes += whole_h.node(n).payload_bytes;

        ResidencyTable parts(parts_h);
        CutEngine parts_engine(parts_h, parts_counter);
        for (int f = 0; f < 400; ++f) {
            const CutFrame& frame = parts_engine.update(v, parts);
            ASSERT_EQ(parts_engine.check(parts), "");
            for (const CutRequest& r : frame.requests) {
                const HierarchyNode& n = parts_h.node(r.node);
                ASSERT_TRUE(n.fetch_parts);
                bool any = false;
                for (size_t i = 0; i < n.parts.size(); ++i) {
                    if (n.parts[i].parent != r.parent) continue;
                    const uint64_t p = n.parts[i].primitives;
                    parts.set_part_resident(r.node, i, NodeBytes{16 * p, 20 * p});
                    any = true;
                }
                EXPECT_TRUE(any) << "a request names parts that exist";
            }
            if (frame.requests.empty() && frame.stats.refinements == 0 && f > 3) break;
        }
        EXPECT_EQ(refined_set(parts_engine), refined_set(whole_engine)) << "trial " << trial;
        uint64_t parts_bytes = 0;
        for (uint32_t n = 0; n < parts_h.size(); ++n) {
            const HierarchyNode& node = parts_h.node(n);
            for (size_t i = 0; i < node.parts.size(); ++i) {
                if (!parts.part_resident(n, i)) continue;
                parts_bytes += node.parts[i].size;
                const uint32_t parent = node.parts[i].parent;
                EXPECT_TRUE(parent == kNoNode || parts_engine.refined(parent))
                    << "trial " << trial << ": a part fetched for a parent that is not refined";
            }
        }
        for (uint32_t n : parts_engine.drawn_nodes())
            for (size_t i = 0; i < parts_h.node(n).parts.size(); ++i) {
                const uint32_t parent = parts_h.node(n).parts[i].parent;
                if (parent == kNoNode || parts_engine.refined(parent)) {
                    EXPECT_TRUE(parts.part_resident(n, i)) << "trial " << trial << ": a drawn part is not resident";
                }
            }
        EXPECT_LE(parts_bytes, whole_bytes) << "trial " << trial;
        std::printf("view %d: fetched %llu bytes by parts, %llu whole\n", trial, (unsigned long long)parts_bytes,
                    (unsigned long long)whole_bytes);
        views++;
        fewer += parts_bytes < whole_bytes;
    }
    EXPECT_GE(fewer, views / 2) << "parts save bytes on most views";
}
