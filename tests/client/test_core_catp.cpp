// The cut engine on a real CATP dataset (a sphere built with build_catp): the hierarchy built from
// the index, and every cut the engine produces — fed by the real fetcher and caches — decodes to
// a closed surface (welded by exact integer position, no border edges).
#include <gtest/gtest.h>

#include <set>

#include "catp/cut.h"
#include "catp/dataset.h"
#include "catp_client/catp_format.h"
#include "client/cache.h"
#include "client/cut_engine.h"
#include "client/fetcher.h"
#include "client/hierarchy.h"
#include "crack_check.h"
#include "test_core_support.h"

using namespace catpaq;

namespace {

RefinedSet as_refined_set(const Hierarchy& h, const CutEngine& engine) {
    RefinedSet r;
    for (uint32_t n : engine.refined_nodes()) r.refine(DiamondId{h.node(n).key});
    return r;
}

// The slots the engine draws: for each drawn node, the parts whose creating parent is refined.
std::set<std::pair<uint64_t, int>> engine_slots(const Hierarchy& h, const CutEngine& engine) {
    std::set<std::pair<uint64_t, int>> out;
    for (uint32_t n : engine.drawn_nodes())
        for (const HierarchyPart& p : h.node(n).parts)
            if (p.parent == kNoNode || engine.refined(p.parent)) out.insert({h.node(n).key, int(p.id)});
    return out;
}

std::set<std::pair<uint64_t, int>> reference_slots(const CatpIndex& index, const RefinedSet& r) {
    std::set<std::pair<uint64_t, int>> out;
    for (const DrawnSlot& d : drawn_slots(index, r)) out.insert({d.entry->key, d.slot});
    return out;
}

// Bounds of the model and a camera orbiting it.
struct Orbit {
    double centre[3], radius;
    explicit Orbit(const CatpIndex& index) {
        const CatpMeta& m = index.meta();
        radius = 0;
        for (int i = 0; i < 3; ++i) {
            centre[i] = 0.5 * (m.bounds_min[i] + m.bounds_max[i]);
            radius = std::max(radius, 0.5 * (m.bounds_max[i] - m.bounds_min[i]));
        }
    }
    ViewParams view(int frame, int frames, double tolerance) const {
        double t = double(frame) / double(frames);
        double a = t * 2 * M_PI;
        double d = radius * (1.15 + 2.5 * (0.5 + 0.5 * std::cos(3 * a)));  // close to far
        std::array<double, 3> eye{centre[0] + d * std::cos(a), centre[1] + d * std::sin(a), centre[2] + 0.4 * d * std::sin(2 * a)};
        std::array<double, 3> target{centre[0] + 0.3 * radius * std::cos(5 * a), centre[1], centre[2]};
        return test::camera(eye, target, tolerance, 50);
    }
};

}  // namespace

TEST(CatpHierarchy, EveryEntryIsANodeAndMissingParentsAreVirtualUpToTheRoot) {
    CatpFile file(test::sphere_dataset());
    const CatpIndex& index = file.index();
    Hierarchy h = build_catp_hierarchy(index);
    EXPECT_EQ(h.check(), "");
    EXPECT_EQ(h.data_count(), index.entries().size());
    ASSERT_EQ(h.roots().size(), 1u);
    EXPECT_EQ(h.node(h.roots()[0]).key, root_diamond().bits);
    for (const HierarchyNode& n : h.nodes()) {
        DiamondId id{n.key};
        const ArchiveEntry* e = index.find(id);
        EXPECT_EQ(n.has_data, e != nullptr);
        if (e) {
            EXPECT_EQ(n.payload_bytes, e->size);
            EXPECT_EQ(n.payload_offset, e->offset);
            EXPECT_EQ(n.primitives, e->count);
            EXPECT_GE(n.error, double(e->error));
            EXPECT_EQ(n.parts.size(), size_t(__builtin_popcount(e->flags & 0xff)));
        } else {
            EXPECT_TRUE(n.parts.empty());
            EXPECT_FALSE(n.children.empty()) << "a virtual node exists only as somebody's parent";
        }
        // Parents are exactly the diamond's parents, all present.
        std::set<uint64_t> expected, got;
        for (DiamondId p : diamond_parents(id)) expected.insert(p.bits);
        for (uint32_t p : n.parents) got.insert(h.node(p).key);
        EXPECT_EQ(got, expected);
        // The box of a diamond with data holds all its existing tetrahedra (lattice to world);
        // a virtual node's is the union of its children's (checked by h.check()).
        DiamondInfo info = diamond_info(id);
        uint8_t mask = n.has_data ? existing_slots(info) : 0;
        for (int s = 0; s < info.ring_size; ++s) {
            if (!(mask & (1 << s))) continue;
            for (const LatticePoint& p : diamond_tetrahedron(info, s)) {
                double l[3] = {double(p[0]), double(p[1]), double(p[2])}, w[3];
                index.lattice_to_world(l, w);
                for (int i = 0; i < 3; ++i) {
                    EXPECT_LE(n.bounds.min[i], w[i]);
                    EXPECT_GE(n.bounds.max[i], w[i]);
                }
            }
        }
        for (const HierarchyPart& p : n.parts)
            if (p.parent != kNoNode) {
                EXPECT_EQ(h.node(p.parent).key, slot_parent(info, p.id).bits);
            }
    }
    EXPECT_GT(h.virtual_count(), 0u) << "the sphere leaves diamonds without geometry inside";
}

// View boxes: every node with geometry has one per slot with geometry (its own tetrahedra), a
// node without has those holding descendants' geometry, and each box of a non-root lies in a
// box of the parent that created it, the property that lets the engine reach every node that
// needs refinement (h.check() tests the nesting; here it must fail when broken).
TEST(CatpHierarchy, ViewBoxesAreTheTetrahedraHoldingGeometryAndNest) {
    CatpFile file(test::sphere_dataset());
    const CatpIndex& index = file.index();
    Hierarchy h = build_catp_hierarchy(index);
    ASSERT_TRUE(h.has_view_boxes());
    size_t tighter = 0, with_data = 0;
    for (const HierarchyNode& n : h.nodes()) {
        if (n.has_data) {
            ++with_data;
            EXPECT_GE(n.view_boxes.size(), size_t(__builtin_popcount(n.flags & 0xff)));
        }
        if (n.view_boxes.empty()) continue;  // a virtual node whose children's tetrahedra have other creators
        Aabb own;
        for (const Aabb& b : n.view_boxes) own.extend(b);
        double v_own = 1, v_all = 1;
        for (int i = 0; i < 3; ++i) {
            v_own *= own.max[i] - own.min[i];
            v_all *= n.bounds.max[i] - n.bounds.min[i];
        }
        tighter += v_own < 0.9 * v_all;
    }
    std::printf("%zu of %zu nodes have view boxes tighter than their bounds\n", tighter, h.size());
    EXPECT_GT(tighter, with_data / 4) << "descendants reach out of most diamonds' own tetrahedra";
    // Breaking the nesting is caught.
    for (uint32_t i = 0; i < h.size(); ++i) {
        if (h.node(i).parents.empty()) continue;
        Hierarchy broken = h;
        Aabb far;
        far.extend(std::array<double, 3>{1e9, 1e9, 1e9});
        broken.mutable_node(i).view_boxes.push_back(far);
        broken.mutable_node(i).bounds.extend(far);
        EXPECT_NE(broken.check(), "");
        break;
    }
}

TEST(CatpCut, EveryEngineCutFedByTheFetcherIsConformingAndCrackFree) {
    CatpFile file(test::sphere_dataset());
    const CatpIndex& index = file.index();
    std::unique_ptr<CatpFormat> format = test::open_catp_format(test::sphere_dataset());
    const Hierarchy& h = format->hierarchy();
    const uint64_t cache_budget = 6u << 20;
    NodeStore store(h, cache_budget, 1u << 20);
    CutBudgets budgets;
    budgets.max_cpu_bytes = cache_budget / 2;
    budgets.max_primitives = 30000;
    budgets.max_new_requests = 24;
    CutEngine engine(h, store.counter(), budgets);
    FetcherSettings fetcher_settings;
    fetcher_settings.decode = format_decoder(*format);
    Fetcher fetcher(std::make_unique<LocalFileSource>(test::sphere_dataset()), fetcher_settings);
    Orbit orbit(index);
    std::unordered_map<uint64_t, DiamondFragments> decoded;
    size_t checked = 0, mixed = 0;
    std::vector<FetchedNode> arrived;
    for (int f = 0; f < 90; ++f) {
        ViewParams v = orbit.view(f, 90, 1.0);
        arrived.clear();
        fetcher.poll(arrived);
        for (FetchedNode& n : arrived) {
            ASSERT_TRUE(n.ok) << n.error;
            store.add(n.node, n.decoded, n.compressed);
        }
        const CutFrame& frame = engine.update(v, store);
        store.pin(engine.pinned());
        std::vector<FetchRequest> wanted;
        for (const CutRequest& r : frame.requests) wanted.push_back(FetchRequest::of(h.node(r.node)));
        fetcher.request(wanted);

        ASSERT_EQ(engine.check(store), "");
        ASSERT_LE(frame.stats.primitives, budgets.max_primitives);
        ASSERT_LE(frame.stats.cpu_bytes, budgets.max_cpu_bytes);
        ASSERT_LE(store.decoded_cache().bytes(), cache_budget) << "memory must stay flat";
        RefinedSet r = as_refined_set(h, engine);
        ASSERT_EQ(r.size(), engine.refined_nodes().size()) << "R is not closed under parents";
        ASSERT_EQ(engine_slots(h, engine), reference_slots(index, r));
        if (frame.stats.holes == 0) {
            // Primitives are exact once everything drawn is resident.
            uint64_t triangles = 0;
            for (const DrawnSlot& d : drawn_slots(index, r)) {
                auto decoded = store.decoded(h.find(d.entry->key));
                ASSERT_TRUE(decoded) << "a drawn node is not resident";
                triangles += catp_fragments(*decoded).slots[d.slot].triangle_count();
            }
            EXPECT_EQ(frame.stats.primitives, triangles);
            if (f % 3 == 0) {
                test::CutTopology topo = test::cut_topology(file, r, decoded);
                EXPECT_EQ(topo.border_edges, 0u) << "frame " << f << ": " << topo.fragments << " fragments, levels "
                                                 << topo.min_level << ".." << topo.max_level;
                checked++;
                mixed += topo.max_level > topo.min_level;
            }
        }
        // A frame of the test waits for the fetcher, so the run is deterministic.
        for (int i = 0; i < 20000 && !fetcher.idle(); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    EXPECT_GT(checked, 20u);
    EXPECT_GT(mixed, 10u) << "the cuts should mix levels";
    EXPECT_GT(fetcher.stats().delivered, 50u);
    EXPECT_EQ(fetcher.stats().checksum_failures, 0u);
}

TEST(CatpCut, TinyToleranceConvergesToTheFinestCutWhichIsCrackFree) {
    CatpFile file(test::sphere_dataset());
    const CatpIndex& index = file.index();
    std::unique_ptr<CatpFormat> format = test::open_catp_format(test::sphere_dataset());
    const Hierarchy& h = format->hierarchy();
    NodeStore store(h, uint64_t(1) << 32);
    for (const HierarchyNode& n : h.nodes())
        if (n.has_data) store.add(n.index, test::decode_catp_node(*format, file, n.index));
    CutEngine engine(h, store.counter());
    Orbit orbit(index);
    ViewParams v = orbit.view(0, 1, 1e-9);
    v.use_frustum = false;
    const CutFrame& f = engine.update(v, store);
    RefinedSet all;
    for (const ArchiveEntry& e : index.entries())
        if (!(e.flags & kCatpLeafFlag)) all.refine(DiamondId{e.key});
    RefinedSet got = as_refined_set(h, engine);
    // Every diamond is refined but those whose tetrahedra hold no geometry, in them or below
    // (no view box: refining them draws nothing new): the cut draws what the finest cut draws.
    for (uint64_t id : all.ids()) {
        if (!got.ids().count(id)) {
            EXPECT_TRUE(h.node(h.find(id)).view_boxes.empty()) << id;
        }
    }
    for (uint64_t id : got.ids()) EXPECT_TRUE(all.ids().count(id) || !h.node(h.find(id)).has_data) << id;
    EXPECT_EQ(engine_slots(h, engine), reference_slots(index, all));
    std::unordered_map<uint64_t, DiamondFragments> decoded;
    test::CutTopology topo = test::cut_topology(file, got, decoded);
    EXPECT_EQ(topo.border_edges, 0u);
    EXPECT_EQ(f.stats.primitives, topo.triangles);
    EXPECT_EQ(f.stats.holes, 0u);
}

TEST(CatpCut, LoweringTheToleranceOnlyRefinesDrawsMoreAndLowersTheCertifiedError) {
    CatpFile file(test::sphere_dataset());
    const CatpIndex& index = file.index();
    std::unique_ptr<CatpFormat> format = test::open_catp_format(test::sphere_dataset());
    const Hierarchy& h = format->hierarchy();
    NodeStore store(h, uint64_t(1) << 32);
    for (const HierarchyNode& n : h.nodes())
        if (n.has_data) store.add(n.index, test::decode_catp_node(*format, file, n.index));
    CutEngine engine(h, store.counter());
    Orbit orbit(index);
    std::set<uint32_t> last;
    double last_error = 1e300;
    uint64_t last_primitives = 0;
    std::unordered_map<uint64_t, DiamondFragments> decoded;
    for (double tol = 32; tol >= 0.5; tol /= 2) {
        ViewParams v = orbit.view(1, 8, tol);
        const CutFrame& f = engine.update(v, store);
        std::vector<uint32_t> rv = engine.refined_nodes();
        std::set<uint32_t> r(rv.begin(), rv.end());
        EXPECT_TRUE(std::includes(r.begin(), r.end(), last.begin(), last.end()));
        EXPECT_LE(f.stats.certified_error_px, last_error);
        EXPECT_GE(f.stats.primitives, last_primitives) << "tolerance " << tol;
        last_primitives = f.stats.primitives;
        test::CutTopology topo = test::cut_topology(file, as_refined_set(h, engine), decoded);
        EXPECT_EQ(topo.border_edges, 0u) << "tolerance " << tol;
        last = r;
        last_error = f.stats.certified_error_px;
    }
    EXPECT_GT(last.size(), 10u);
}
