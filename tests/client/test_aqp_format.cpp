// AQP behind the format seam, CPU side: the hierarchy adapter's invariants on real datasets,
// decoding against the coarser level (equal to aqp::AqpDataset's samples; a missing or wrong
// parent is an error, never a wrong decode), and crack-free stitched geometry for random
// per-patch levels and views.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <limits>
#include <optional>
#include <cmath>
#include <map>
#include <random>
#include <set>

#include "aqp_client/stitch.h"
#include "aqp_support.h"
#include "base/error.h"
#include "client/cut_engine.h"

using namespace catpaq;
using test::AqpModel;

namespace {

const AqpModel kModels[] = {AqpModel::Sphere, AqpModel::Torus, AqpModel::Bunny};

TEST(AqpHierarchy, TilesFormATreeWithMonotoneErrorsAndBoxesHoldingTheSamples) {
    for (AqpModel m : kModels) {
        const std::string& path = test::aqp_dataset_path(m);
        test::OpenedAqp o = test::open_aqp(path);
        aqp::AqpDataset dataset(path);
        const aqp::AqpMeta& meta = dataset.meta();
        const Hierarchy& h = o.format->hierarchy();
        const size_t patches = dataset.patch_count();
        SCOPED_TRACE(test::aqp_model_name(m));
        size_t nodes = 0;
        for (int l = 0; l <= dataset.finest_level(); ++l) nodes += meta.tile_count(l);
        EXPECT_EQ(h.check(), "");
        EXPECT_EQ(h.size(), nodes);
        EXPECT_LT(h.size(), patches * size_t(dataset.finest_level() + 1)) << "coarse levels are tiles of several patches";
        EXPECT_EQ(h.roots().size(), meta.tile_count(0));
        EXPECT_EQ(h.virtual_count(), 0u);
        EXPECT_TRUE(h.decodes_against_parents());
        std::vector<size_t> patches_per_level(size_t(dataset.finest_level()) + 1, 0);
        for (uint32_t i = 0; i < h.size(); ++i) {
            const HierarchyNode& n = h.node(i);
            const uint32_t tile = aqp::aqp_key_tile(n.key);
            const int level = aqp::aqp_key_level(n.key);
            ASSERT_LT(tile, meta.tile_count(level));
            const uint32_t first = meta.first_patch(tile, level), count = meta.tile_patches(tile, level);
            patches_per_level[size_t(level)] += count;
            EXPECT_EQ(n.level, level);
            EXPECT_EQ(n.error, double(dataset.entry(first, level).error));  // the stored bounds are monotone already
            ASSERT_EQ(n.parts.size(), 1u);
            EXPECT_EQ(n.primitives, count * (uint32_t(2) << (2 * level)));
            if (level == 0) {
                EXPECT_TRUE(n.parents.empty());
                EXPECT_EQ(n.decode_parent, kNoNode);
            } else {
                // The one parent: the tile one level down holding every patch of this one.
                ASSERT_EQ(n.parents.size(), 1u);
                const HierarchyNode& parent = h.node(n.parents[0]);
                EXPECT_EQ(parent.level, level - 1);
                const uint32_t pfirst = meta.first_patch(aqp::aqp_key_tile(parent.key), level - 1);
                EXPECT_LE(pfirst, first);
                EXPECT_LE(first + count, pfirst + meta.tile_patches(aqp::aqp_key_tile(parent.key), level - 1));
                EXPECT_EQ(n.decode_parent, n.parents[0]);
                EXPECT_EQ(n.parts[0].parent, n.parents[0]);
                EXPECT_GE(parent.error, n.error);
            }
            EXPECT_EQ(n.leaf, level == dataset.finest_level());
        }
        for (size_t c : patches_per_level) EXPECT_EQ(c, patches) << "every patch in one tile per level";
        // Boxes hold the decoded samples (world) of every level of a sample of patches.
        for (uint32_t p = 0; p < patches; p += 7) {
            const std::vector<aqp::PatchGrid> grids = dataset.decode_levels(p, dataset.finest_level());
            for (const aqp::PatchGrid& g : grids) {
                const Aabb& box = h.node(test::patch_node(o, p, g.level)).bounds;
                for (size_t s = 0; s < g.position.size(); ++s) {
                    Aabb point;
                    point.extend(dataset.world_position(g, s));
                    ASSERT_TRUE(box.contains(point)) << "patch " << p << " level " << g.level;
                }
            }
        }
    }
}

TEST(AqpDecode, DecodingTilesThroughTheTreeGivesTheDatasetsSamples) {
    for (AqpModel m : {AqpModel::Sphere, AqpModel::Bunny}) {
        const std::string& path = test::aqp_dataset_path(m);
        test::OpenedAqp o = test::open_aqp(path);
        aqp::AqpDataset dataset(path);
        const Hierarchy& h = o.format->hierarchy();
        const std::vector<std::shared_ptr<const DecodedNode>> decoded = test::decode_all(o);
        for (uint32_t i = 0; i < h.size(); ++i) {
            const std::shared_ptr<const DecodedNode>& out = decoded[i];
            ASSERT_TRUE(out);
            const int level = aqp::aqp_key_level(h.node(i).key);
            const uint32_t tile = aqp::aqp_key_tile(h.node(i).key);
            const std::vector<aqp::PatchGrid>& grids = aqp_grids(*out);
            ASSERT_EQ(grids.size(), dataset.meta().tile_patches(tile, level));
            EXPECT_EQ(out->part_primitives, std::vector<uint32_t>{h.node(i).primitives});
            EXPECT_TRUE(h.node(i).bounds.contains(out->data_bounds));
            EXPECT_FALSE(out->data_bounds.empty());
            EXPECT_EQ(out->bytes.gpu, grids.size() * aqp_gpu_bytes(level, dataset.meta().has_colors()));
        }
        for (uint32_t p = 0; p < dataset.patch_count(); p += 5) {
            const std::vector<aqp::PatchGrid> expected = dataset.decode_levels(p, dataset.finest_level());
            for (int l = 0; l <= dataset.finest_level(); ++l) {
                const aqp::PatchGrid& g = test::patch_grid(*decoded[test::patch_node(o, p, l)], p);
                EXPECT_EQ(g.level, l);
                EXPECT_EQ(g.position, expected[size_t(l)].position) << "patch " << p << " level " << l;
                EXPECT_EQ(g.normal, expected[size_t(l)].normal);
                EXPECT_EQ(g.color, expected[size_t(l)].color);
            }
        }
    }
}

TEST(AqpDecode, AFinerLevelWithoutItsParentOrWithAnotherIsAClearError) {
    test::OpenedAqp o = test::open_aqp(test::aqp_dataset_path(AqpModel::Sphere));
    const aqp::AqpMeta& meta = o.format->meta();
    const uint32_t last = uint32_t(meta.patches.size() - 1);
    // A level whose coarser level has several tiles (so that one does not hold patch `last`).
    int level = 2;
    while (level <= int(meta.patch_level) && meta.tile_count(level - 1) < 2) ++level;
    ASSERT_LE(level, int(meta.patch_level));
    const uint32_t p0l0 = test::patch_node(o, 0, 0), p0l1 = test::patch_node(o, 0, 1);
    const uint32_t mine = test::patch_node(o, last, level), other_tile = test::patch_node(o, 0, level - 1);
    const uint32_t two_down = test::patch_node(o, last, level - 2);
    ASSERT_NE(o.format->hierarchy().node(mine).parents[0], other_tile);
    std::shared_ptr<const DecodedNode> out;
    // Without a parent.
    std::string problem = o.format->decode(p0l1, o.node_bytes(p0l1), o.node_size(p0l1), out);
    EXPECT_NE(problem.find("difference from level 0, which was not given"), std::string::npos) << problem;
    EXPECT_FALSE(out);
    // The tile one level down that does not hold its patches, or its own patches two levels down.
    for (uint32_t wrong : {other_tile, two_down}) {
        std::shared_ptr<const DecodedNode> parent = test::decode_chain(o, wrong);
        problem = o.format->decode_with_parent(mine, *parent, o.node_bytes(mine), o.node_size(mine), out);
        EXPECT_NE(problem.find("not the tile holding its patches one level down"), std::string::npos) << problem;
        EXPECT_FALSE(out);
    }
    std::shared_ptr<const DecodedNode> own = test::decode_chain(o, p0l0);
    // Damaged bytes: an error, not a crash.
    std::vector<uint8_t> bytes(o.node_bytes(p0l1), o.node_bytes(p0l1) + o.node_size(p0l1));
    for (size_t i = 40; i < bytes.size(); i += 17) bytes[i] ^= 0x5a;
    problem = o.format->decode_with_parent(p0l1, *own, bytes.data(), bytes.size(), out);
    EXPECT_NE(problem, "");
    problem = o.format->decode_with_parent(p0l1, *own, bytes.data(), 10, out);
    EXPECT_NE(problem, "");
    // The seam's default for formats that decode alone, and the session's guard: the fetcher's
    // decoder only calls decode_with_parent when the request carries the parent.
    EXPECT_TRUE(o.format->decode(p0l0, o.node_bytes(p0l0), o.node_size(p0l0), out).empty());
}

TEST(AqpDecode, ThroughputOfTheTree) {
    test::OpenedAqp o = test::open_aqp(test::aqp_dataset_path(AqpModel::Bunny));
    const Hierarchy& h = o.format->hierarchy();
    const int k = int(o.format->meta().patch_level);
    const auto start = std::chrono::steady_clock::now();
    uint64_t bytes = 0, samples = 0;
    const std::vector<std::shared_ptr<const DecodedNode>> decoded = test::decode_all(o);
    for (uint32_t i = 0; i < h.size(); ++i) {
        bytes += o.node_size(i);
        for (const aqp::PatchGrid& g : aqp_grids(*decoded[i])) samples += g.position.size();
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::printf("bunny: decoded %zu patches x %d levels in %zu tiles, %.2f MB compressed, %.2f M samples in %.3f s: %.1f MB/s, "
                "%.1f M samples/s, %.2f bytes per sample compressed, %.1f GPU bytes per sample\n",
                o.format->meta().patches.size(), k + 1, h.size(), bytes / 1e6, samples / 1e6, seconds, bytes / 1e6 / seconds,
                samples / 1e6 / seconds, double(bytes) / double(samples),
                double(aqp_gpu_bytes(k, o.format->meta().has_colors())) / double(((1 << k) + 1) * ((1 << k) + 1)));
    EXPECT_GT(samples, 0u);
}

// The cut engine with level skipping on (skip_factor 8, the session's default) over the AQP
// hierarchy: every node it asks for has its decode parent resident, so the session can always
// decode it. The control: the same hierarchy without decode parents skips, and then asks for
// nodes whose parent is not resident.
size_t requests_without_resident_parent(const Hierarchy& h, const std::array<double, 3>& eye,
                                        const std::array<double, 3>& target) {
    PartDrawCounter counter(h);
    ResidencyTable residency(h);
    CutEngine engine(h, counter);
    ViewParams view = ViewParams::look_at(eye, target, {0, 0, 1}, 0.8, 640, 480, 0.01, 100);
    view.tolerance_px = 0.5;
    view.skip_factor = 8;
    size_t orphans = 0;
    for (int frame = 0; frame < 200; ++frame) {
        const CutFrame& f = engine.update(view, residency);
        EXPECT_EQ(engine.check(residency), "");
        if (f.requests.empty()) break;
        // Up to 8 arrive per frame; the parent (the chain's level below) decides decodability.
        size_t arrived = 0;
        for (const CutRequest& r : f.requests) {
            const uint32_t parent = h.node(r.node).parents.empty() ? kNoNode : h.node(r.node).parents[0];
            if (parent != kNoNode && !residency.resident(parent)) ++orphans;
            if (arrived++ < 8) residency.set_resident(r.node, NodeBytes{64, 64});
        }
    }
    return orphans;
}

TEST(AqpHierarchy, TheCutEngineNeverAsksForALevelWhoseParentIsNotResidentEvenWhenSkipping) {
    for (bool untiled : {false, true}) {
        test::OpenedAqp o = test::open_aqp(test::aqp_dataset_path(AqpModel::Bunny, untiled));
        const Hierarchy& h = o.format->hierarchy();
        const Aabb b = o.format->world_bounds();
        const std::array<double, 3> target{(b.min[0] + b.max[0]) / 2, (b.min[1] + b.max[1]) / 2, (b.min[2] + b.max[2]) / 2};
        const std::array<double, 3> eye{target[0] + 0.9 * (b.max[0] - b.min[0]), target[1] + 0.2, target[2] + 0.3};
        EXPECT_EQ(requests_without_resident_parent(h, eye, target), 0u) << (untiled ? "untiled" : "tiled");
        if (!untiled) continue;
        // The control (on patch chains, where skipping is plain): without decode parents the
        // engine skips levels.
        Hierarchy skippable = h;
        for (uint32_t i = 0; i < skippable.size(); ++i) skippable.mutable_node(i).decode_parent = kNoNode;
        skippable.finalize();
        ASSERT_FALSE(skippable.decodes_against_parents());
        EXPECT_GT(requests_without_resident_parent(skippable, eye, target), 0u) << "without decode parents the engine skips levels";
    }
}

TEST(AqpHierarchy, ADecodeParentThatIsNotAParentIsRejected) {
    test::OpenedAqp o = test::open_aqp(test::aqp_dataset_path(AqpModel::Sphere));
    Hierarchy h = o.format->hierarchy();
    const int k = int(o.format->meta().patch_level);
    const uint32_t node = test::patch_node(o, 0, k), other = test::patch_node(o, 0, k - 2);
    h.mutable_node(node).decode_parent = other;
    try {
        h.finalize();
        ADD_FAILURE() << "a decode parent that is not a parent was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("decodes against a node that is not a parent"), std::string::npos) << e.what();
    }
}

// ---- stitching ------------------------------------------------------------------------------

// Twice the signed area of triangle (a, b, c) of sample indices in the (i, j) plane.
long signed_area2(uint32_t a, uint32_t b, uint32_t c, int size) {
    const long ai = long(a % size), aj = long(a / size), bi = long(b % size), bj = long(b / size), ci = long(c % size),
               cj = long(c / size);
    return (bi - ai) * (cj - aj) - (ci - ai) * (bj - aj);
}

TEST(AqpStitch, StitchedTemplatesTileThePatchWithoutFolds) {
    for (int level = 0; level <= 5; ++level) {
        const int size = (1 << level) + 1;
        const long full = 2L * (size - 1) * (size - 1);
        for (int e0 = 0; e0 <= level; ++e0)
            for (int e1 = 0; e1 <= level; ++e1)
                for (int e2 = 0; e2 <= level; e2 += std::max(1, level / 2))
                    for (int e3 = 0; e3 <= level; e3 += std::max(1, level / 3)) {
                        const std::array<int, 4> edges{e0, e1, e2, e3};
                        const std::vector<uint32_t> t = stitched_triangles(level, edges);
                        long area = 0;
                        std::map<std::pair<uint32_t, uint32_t>, int> directed;
                        for (size_t i = 0; i < t.size(); i += 3) {
                            const long a = signed_area2(t[i], t[i + 1], t[i + 2], size);
                            ASSERT_GT(a, 0) << "level " << level << " edges " << e0 << e1 << e2 << e3;
                            area += a;
                            for (int k = 0; k < 3; ++k) directed[{t[i + size_t(k)], t[i + size_t(k + 1) % 3]}]++;
                        }
                        // Covers the square exactly once (positive triangles summing to its area).
                        ASSERT_EQ(area, full);
                        // The boundary is the coarse edges: a boundary half-edge joins samples
                        // 2^(level - e) apart on edge e.
                        for (const auto& [he, count] : directed) {
                            ASSERT_EQ(count, 1);
                            if (directed.count({he.second, he.first})) continue;
                            const int ai = int(he.first % size), aj = int(he.first / size), bi = int(he.second % size),
                                      bj = int(he.second / size);
                            const int e = aj == 0 && bj == 0 ? 0 : ai == size - 1 && bi == size - 1 ? 1 : aj == size - 1 && bj == size - 1 ? 2 : 3;
                            ASSERT_EQ(std::abs(bi - ai) + std::abs(bj - aj), 1 << (level - edges[size_t(e)]));
                        }
                    }
    }
    // Uniform edges: the template grid itself.
    EXPECT_EQ(stitched_triangles(3, {3, 3, 3, 3}), grid_triangles(3));
}

// Edges (by welded position) used by one triangle only, that are not on the surface's border.
struct CrackCount {
    size_t triangles = 0, border_edges = 0, cracks = 0;
};
CrackCount count_cracks(const DrawnGeometry& g, const std::set<std::array<double, 3>>& surface_border) {
    std::map<std::array<double, 3>, uint32_t> weld;
    std::vector<uint32_t> id(g.mesh.positions.size());
    for (size_t v = 0; v < id.size(); ++v) id[v] = weld.emplace(g.mesh.positions[v], uint32_t(weld.size())).first->second;
    std::vector<std::array<double, 3>> position(weld.size());
    for (const auto& [p, i] : weld) position[i] = p;
    std::map<std::pair<uint32_t, uint32_t>, int> edges;
    CrackCount c;
    for (size_t t = 0; t + 2 < g.mesh.indices.size(); t += 3) {
        ++c.triangles;
        for (int k = 0; k < 3; ++k) {
            uint32_t a = id[g.mesh.indices[t + size_t(k)]], b = id[g.mesh.indices[t + size_t(k + 1) % 3]];
            if (a == b) continue;  // flattened by quantization
            edges[{std::min(a, b), std::max(a, b)}]++;
        }
    }
    for (const auto& [e, count] : edges) {
        if (count != 1) continue;
        ++c.border_edges;
        if (!surface_border.count(position[e.first]) || !surface_border.count(position[e.second])) ++c.cracks;
    }
    return c;
}

// Positions (in `g`'s frame) of the samples on patch edges without a neighbour, at every level.
std::set<std::array<double, 3>> surface_border_positions(const test::OpenedAqp& o, const aqp::AqpDataset& d,
                                                         const std::array<double, 3>& eye) {
    std::set<std::array<double, 3>> out;
    const aqp::AqpMeta& meta = d.meta();
    for (uint32_t p = 0; p < meta.patches.size(); ++p) {
        bool border = false;
        for (const aqp::PatchLink& l : meta.patches[p].link) border |= l.patch >= meta.patches.size();
        if (!border) continue;
        // The finest level's edge samples hold every coarser level's.
        const uint32_t node = test::patch_node(o, p, d.finest_level());
        std::shared_ptr<const DecodedNode> decoded = test::single_patch_node(*test::decode_chain(o, node), p);
        const DrawnGeometry g = o.format->drawn_geometry({{node, decoded.get(), 0}}, eye);
        const int size = aqp_grids(*decoded)[0].size;
        for (int e = 0; e < 4; ++e) {
            if (meta.patches[p].link[size_t(e)].patch < meta.patches.size()) continue;
            for (int t = 0; t < size; ++t) {
                const int i = e == 0 ? t : e == 1 ? size - 1 : e == 2 ? t : 0;
                const int j = e == 0 ? 0 : e == 1 ? t : e == 2 ? size - 1 : t;
                out.insert(g.mesh.positions[size_t(j * size + i)]);
            }
        }
    }
    return out;
}

void expect_random_cuts_are_crack_free(AqpModel m) {
    const std::string& path = test::aqp_dataset_path(m);
    test::OpenedAqp o = test::open_aqp(path);
    aqp::AqpDataset dataset(path);
    const size_t patches = dataset.patch_count();
    const int k = dataset.finest_level();
    // Every level of every patch, decoded once, each patch level as a node of its own: any
    // per-patch levels, not only those of a cut of tiles.
    const std::vector<std::shared_ptr<const DecodedNode>> tiles = test::decode_all(o);
    std::vector<std::vector<std::shared_ptr<const DecodedNode>>> decoded(patches);
    for (uint32_t p = 0; p < patches; ++p)
        for (int l = 0; l <= k; ++l) decoded[p].push_back(test::single_patch_node(*tiles[test::patch_node(o, p, l)], p));
    const Aabb bounds = o.format->world_bounds();
    std::mt19937_64 rng(uint64_t(m) * 7919 + 1);
    size_t unstitched_cracks = 0;
    for (int trial = 0; trial < 12; ++trial) {
        // A random view (the frame's anchor moves with it) and random per-patch levels: uniform,
        // or spatially coherent around a random focus, as view-dependent cuts are.
        std::array<double, 3> eye;
        for (int a = 0; a < 3; ++a)
            eye[size_t(a)] = bounds.min[size_t(a)] + (bounds.max[size_t(a)] - bounds.min[size_t(a)]) *
                                                         std::uniform_real_distribution<double>(-1.0, 2.0)(rng);
        const std::set<std::array<double, 3>> border = surface_border_positions(o, dataset, eye);
        const uint32_t focus = uint32_t(rng() % patches);
        const Aabb fbox = aqp_patch_box(dataset.meta(), focus);
        std::vector<DecodedPart> parts;
        std::set<int> levels;
        for (uint32_t p = 0; p < patches; ++p) {
            int level = int(rng() % uint64_t(k + 1));
            if (trial % 2 == 1) {  // finer near the focus
                const Aabb box = aqp_patch_box(dataset.meta(), p);
                double d = 0;
                for (int a = 0; a < 3; ++a) d = std::max(d, std::abs((box.min[size_t(a)] + box.max[size_t(a)]) - (fbox.min[size_t(a)] + fbox.max[size_t(a)])) / 2);
                const double diag = bounds.max[0] - bounds.min[0];
                level = std::clamp(k - int(d / diag * 2.0 * k), 0, k);
            }
            levels.insert(level);
            parts.push_back({test::patch_node(o, p, level), decoded[p][size_t(level)].get(), 0});
        }
        const DrawnGeometry g = o.format->drawn_geometry(parts, eye);
        const CrackCount c = count_cracks(g, border);
        std::printf("%s trial %d: %zu levels, %zu triangles, %zu border edges, %zu cracks\n", test::aqp_model_name(m), trial,
                    levels.size(), c.triangles, c.border_edges, c.cracks);
        EXPECT_GT(levels.size(), 1u);
        EXPECT_EQ(c.cracks, 0u) << test::aqp_model_name(m) << " trial " << trial;
        if (dataset.meta().border_edges == 0) {  // a closed surface (the bunny's holes are filled by cleaning)
            EXPECT_EQ(c.border_edges, 0u);
        }
        // The negative control: each patch alone (its edges at its own level) cracks.
        DrawnGeometry apart;
        apart.origin = g.origin;
        for (const DecodedPart& part : parts) {
            const DrawnGeometry one = o.format->drawn_geometry({part}, eye);
            EXPECT_EQ(one.origin, g.origin);
            const uint32_t base = uint32_t(apart.mesh.positions.size());
            apart.mesh.positions.insert(apart.mesh.positions.end(), one.mesh.positions.begin(), one.mesh.positions.end());
            for (uint32_t v : one.mesh.indices) apart.mesh.indices.push_back(base + v);
        }
        unstitched_cracks += count_cracks(apart, border).cracks;
    }
    EXPECT_GT(unstitched_cracks, 0u) << "the detector finds the cracks of unstitched patches";
}

TEST(AqpStitch, RandomMixedLevelsOfAClosedSphereAreCrackFree) { expect_random_cuts_are_crack_free(AqpModel::Sphere); }
TEST(AqpStitch, RandomMixedLevelsOfAClosedTorusAreCrackFree) { expect_random_cuts_are_crack_free(AqpModel::Torus); }
TEST(AqpStitch, RandomMixedLevelsOfTheBunnyCrackNowhereButOnItsBorder) { expect_random_cuts_are_crack_free(AqpModel::Bunny); }

double point_triangle_distance(const std::array<double, 3>& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    // Dense sampling of the triangle, independent of the format's exact formula: an upper bound
    // of the distance, above it by at most a 64th of the triangle's size.
    double best = std::numeric_limits<double>::infinity();
    const int n = 64;
    for (int i = 0; i <= n; ++i)
        for (int j = 0; i + j <= n; ++j) {
            const double u = double(i) / n, v = double(j) / n, w = 1 - u - v;
            double d2 = 0;
            for (int k = 0; k < 3; ++k) {
                const double x = w * a[size_t(k)] + u * b[size_t(k)] + v * c[size_t(k)] - p[size_t(k)];
                d2 += x * x;
            }
            best = std::min(best, std::sqrt(d2));
        }
    return best;
}

// data_distance is a lower bound of the distance to what the patch draws, stitched to coarser
// neighbours or not (the cut engine's projected errors rely on it), and not far below it.
TEST(AqpFormat, DataDistanceBoundsTheDistanceToTheStitchedTrianglesFromBelow) {
    test::OpenedAqp o = test::open_aqp(test::aqp_dataset_path(AqpModel::Torus));
    const aqp::AqpMeta& meta = o.format->meta();
    const int k = int(meta.patch_level);
    const Aabb bounds = o.format->world_bounds();
    std::mt19937_64 rng(5);
    size_t close = 0;
    for (int trial = 0; trial < 60; ++trial) {
        const uint32_t p = uint32_t(rng() % meta.patches.size());
        const int level = 1 + int(rng() % uint64_t(k));
        std::vector<std::shared_ptr<const DecodedNode>> keep;
        std::vector<DecodedPart> parts;
        auto add = [&](uint32_t patch, int l) {
            const uint32_t node = test::patch_node(o, patch, l);
            keep.push_back(test::single_patch_node(*test::decode_chain(o, node), patch));
            parts.push_back({node, keep.back().get(), 0});
        };
        add(p, level);  // first: its vertices come first in the drawn geometry
        for (const aqp::PatchLink& link : meta.patches[p].link)
            if (link.patch < meta.patches.size()) add(link.patch, int(rng() % uint64_t(level + 1)));
        // An eye near the patch (inside its box sometimes) or anywhere around the model.
        const Aabb box = aqp_patch_box(meta, p);
        std::array<double, 3> eye;
        for (int a = 0; a < 3; ++a) {
            const Aabb& around = trial % 2 ? box : bounds;
            const double lo = around.min[size_t(a)], hi = around.max[size_t(a)];
            eye[size_t(a)] = lo + (hi - lo) * std::uniform_real_distribution<double>(-0.3, 1.3)(rng);
        }
        const DrawnGeometry g = o.format->drawn_geometry(parts, eye);
        const uint32_t own = uint32_t(aqp_grids(*keep[0])[0].position.size());
        double drawn = std::numeric_limits<double>::infinity();
        auto world = [&](uint32_t v) {
            const Vec3d& q = g.mesh.positions[v];
            return Vec3d{g.origin[0] + q[0], g.origin[1] + q[1], g.origin[2] + q[2]};
        };
        for (size_t t = 0; t + 2 < g.mesh.indices.size(); t += 3) {
            const uint32_t a = g.mesh.indices[t], b = g.mesh.indices[t + 1], c = g.mesh.indices[t + 2];
            if (a >= own || b >= own || c >= own) continue;  // a neighbour's
            drawn = std::min(drawn, point_triangle_distance(eye, world(a), world(b), world(c)));
        }
        const std::optional<double> bound = o.format->data_distance(parts[0].node, *keep[0], eye);
        ASSERT_TRUE(bound.has_value());
        const double slack = 1e-9 * (1 + drawn) + meta.step;  // float positions
        EXPECT_LE(*bound, drawn + slack) << "patch " << p << " level " << level << " trial " << trial;
        close += *bound >= 0.5 * drawn;
    }
    EXPECT_GT(close, 30u) << "the bound is mostly within a factor 2";
}

TEST(AqpFormat, OpeningRejectsBadMetadataAndIndexWithAClearError) {
    const std::string& path = test::aqp_dataset_path(AqpModel::Sphere);
    std::vector<uint8_t> file = test::read_file_bytes(path);
    DatasetPrefix prefix = DatasetPrefix::parse(file.data(), file.size(), path);
    DatasetPrefix bad_meta = prefix;
    bad_meta.meta[0] = 'X';
    EXPECT_THROW(AqpFormat{bad_meta}, Error);
    DatasetPrefix short_index = prefix;
    short_index.entries.pop_back();
    try {
        AqpFormat f(short_index);
        ADD_FAILURE() << "an index missing a node was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
    AqpFormat ok(prefix);
    EXPECT_EQ(ok.summary().lines.size(), 7u);
    EXPECT_FALSE(ok.world_bounds().empty());
}

}  // namespace
