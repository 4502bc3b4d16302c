// The point format's CPU side: the hierarchy adapter on real datasets, decoding against
// points::PointDataset, the GPU packing against the decoded splats, bad input, and the generic
// cut engine on the point hierarchy.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>
#include <set>

#include "base/error.h"
#include "client/cut_engine.h"
#include "common_codec/octahedral.h"
#include "points/dataset.h"
#include "points_client/points_format.h"
#include "point_datasets.h"

using namespace catpaq;
using test::PointSet;

namespace {

std::vector<PointSet> hierarchy_sets() {
    PointSet balanced;
    PointSet midpoint;
    midpoint.model = PointSet::ScanLike;
    midpoint.split = PointSplitRule::Midpoint;
    midpoint.normals = false;
    midpoint.colors = false;
    midpoint.node_points = 2000;
    return {balanced, midpoint};
}

std::shared_ptr<const DecodedNode> decode_node(const PointsFormat& format, const PointDataset& file, uint32_t n) {
    const HierarchyNode& node = format.hierarchy().node(n);
    std::string error;
    const uint8_t* bytes = file.node_bytes(node.entry, &error);
    EXPECT_TRUE(bytes) << error;
    std::shared_ptr<const DecodedNode> out;
    EXPECT_EQ(format.decode(n, bytes, node.payload_bytes, out), "");
    return out;
}

}  // namespace

TEST(PointsHierarchy, MirrorsTheKdTreeWithMonotoneErrorsAndNestedBoxes) {
    for (const PointSet& set : hierarchy_sets()) {
        const std::string& path = test::points_dataset(set);
        PointDataset file(path);
        PointsFormat format(test::read_prefix(path));
        const Hierarchy& h = format.hierarchy();
        EXPECT_EQ(h.check(), "");
        ASSERT_EQ(h.size(), file.node_count());
        EXPECT_EQ(h.virtual_count(), 0u);
        ASSERT_EQ(h.roots().size(), 1u);
        EXPECT_EQ(h.node(h.roots()[0]).key, 1u);
        size_t leaves = 0;
        for (const HierarchyNode& n : h.nodes()) {
            const ArchiveEntry& e = file.entries()[n.entry];
            EXPECT_EQ(e.key, n.key);
            EXPECT_EQ(n.primitives, e.count);
            EXPECT_EQ(n.leaf, (e.flags & kPointLeafFlag) != 0);
            EXPECT_GE(n.error, double(e.error));
            EXPECT_GE(n.error, double(file.meta().nodes[n.entry].mean_radius));
            ASSERT_EQ(n.parts.size(), 1u);
            leaves += n.leaf;
            if (n.key == 1) {
                EXPECT_TRUE(n.parents.empty());
                EXPECT_EQ(n.parts[0].parent, kNoNode);
            } else {
                ASSERT_EQ(n.parents.size(), 1u);
                EXPECT_EQ(h.node(n.parents[0]).key, point_node_parent(n.key));
                EXPECT_EQ(n.parts[0].parent, n.parents[0]);
            }
            if (n.leaf) {
                EXPECT_TRUE(n.children.empty());
            } else {
                ASSERT_EQ(n.children.size(), 2u);
                std::set<uint64_t> keys{h.node(n.children[0]).key, h.node(n.children[1]).key};
                EXPECT_EQ(keys, (std::set<uint64_t>{2 * n.key, 2 * n.key + 1}));
            }
            for (uint32_t c : n.children) {
                EXPECT_GE(n.error, h.node(c).error) << "errors are monotone";
                EXPECT_TRUE(n.bounds.contains(h.node(c).bounds)) << "boxes nest";
            }
            // The world box holds the converter's box (splat balls, relative to the origin).
            const PointNodeInfo& info = file.meta().nodes[n.entry];
            for (int a = 0; a < 3; ++a) {
                EXPECT_LE(n.bounds.min[a], file.meta().origin[a] + info.box_min[a]);
                EXPECT_GE(n.bounds.max[a], file.meta().origin[a] + info.box_max[a]);
            }
        }
        EXPECT_GT(leaves, 10u);
        EXPECT_EQ(format.summary().primitive_noun, "points");
        EXPECT_FALSE(format.world_bounds().empty());
    }
}

TEST(PointsDecode, EqualsThePointDatasetsDecodedPoints) {
    PointSet set;
    const std::string& path = test::points_dataset(set);
    PointDataset file(path);
    PointsFormat format(test::read_prefix(path));
    const Hierarchy& h = format.hierarchy();
    // Decoding and packing alone, timed (the format's decode, as the fetcher's workers run it).
    std::vector<std::vector<uint8_t>> payloads(h.size());
    for (uint32_t n = 0; n < h.size(); ++n) {
        std::string error;
        const uint8_t* bytes = file.node_bytes(h.node(n).entry, &error);
        ASSERT_TRUE(bytes) << error;
        payloads[n].assign(bytes, bytes + h.node(n).payload_bytes);
    }
    size_t points = 0;
    double codec_seconds = 0, format_seconds = 0;
    for (int run = 0; run < 3; ++run) {  // the best of three: the machine is shared
        DecodedPoints scratch;
        auto start = std::chrono::steady_clock::now();
        for (uint32_t n = 0; n < h.size(); ++n) ASSERT_EQ(decode_point_node(payloads[n].data(), payloads[n].size(), scratch), "");
        const double codec = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        points = 0;
        start = std::chrono::steady_clock::now();
        for (uint32_t n = 0; n < h.size(); ++n) {
            std::shared_ptr<const DecodedNode> out;
            ASSERT_EQ(format.decode(n, payloads[n].data(), payloads[n].size(), out), "");
            points += points_node(*out).splats.count;
        }
        const double whole = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        codec_seconds = run ? std::min(codec_seconds, codec) : codec;
        format_seconds = run ? std::min(format_seconds, whole) : whole;
    }
    std::printf("client decode, one thread: %zu points; codec alone %.1f M points/s, decode + pack + data box %.1f M points/s\n",
                points, points / codec_seconds / 1e6, points / format_seconds / 1e6);
    for (uint32_t n = 0; n < h.size(); ++n) {
        std::shared_ptr<const DecodedNode> decoded = decode_node(format, file, n);
        ASSERT_TRUE(decoded);
        const PackedSplats& got = points_node(*decoded).splats;
        DecodedPoints want;
        ASSERT_EQ(file.decode(h.node(n).entry, want), "");
        ASSERT_EQ(got.count, want.count);
        EXPECT_EQ(got, pack_splats(want, file.meta().origin));
        EXPECT_EQ(decoded->part_primitives, std::vector<uint32_t>{uint32_t(got.count)});
        EXPECT_EQ(decoded->bytes.gpu, uint64_t(got.count) * got.stride);
        EXPECT_FALSE(decoded->data_bounds.empty());
        EXPECT_TRUE(h.node(n).bounds.contains(decoded->data_bounds));
    }
}

// A resident node keeps only its packed splats: 8 bytes a point on the CPU with colours, 6
// without (the decoded arrays beside them were 21 more).
TEST(PointsDecode, ClientKeepsAtMost8BytesPerPoint) {
    for (const PointSet& set : hierarchy_sets()) {
        const std::string& path = test::points_dataset(set);
        PointDataset file(path);
        PointsFormat format(test::read_prefix(path));
        uint64_t cpu = 0, points = 0;
        for (uint32_t n = 0; n < format.hierarchy().size(); ++n) {
            std::shared_ptr<const DecodedNode> decoded = decode_node(format, file, n);
            ASSERT_TRUE(decoded);
            cpu += decoded->bytes.cpu;
            points += decoded->part_primitives[0];
            EXPECT_EQ(decoded->bytes.cpu, decoded->bytes.gpu) << "node " << n;
        }
        std::printf("client CPU bytes per resident point: %.2f (%s)\n", double(cpu) / double(points),
                    set.colors ? "colours" : "no colours");
        EXPECT_LE(cpu, (set.colors ? 8u : 6u) * points);
    }
}

// data_distance is the distance to the nearest drawn splat ball: never more than the distance
// to a decoded splat ball (every packed splat covers its decoded one), and no less than it by
// more than the packing's growth of a radius.
TEST(PointsDistance, IsALowerBoundOfTheDecodedSplatsDistanceAndNearlyTight) {
    PointSet set;
    const std::string& path = test::points_dataset(set);
    PointDataset file(path);
    PointsFormat format(test::read_prefix(path));
    const Hierarchy& h = format.hierarchy();
    for (uint32_t n = 0; n < h.size(); n += 7) {
        std::shared_ptr<const DecodedNode> decoded = decode_node(format, file, n);
        DecodedPoints want;
        ASSERT_EQ(file.decode(h.node(n).entry, want), "");
        const PackedSplats& splats = points_node(*decoded).splats;
        for (const std::array<double, 3>& eye : {std::array<double, 3>{0, 0, 0}, std::array<double, 3>{2.5, -1.0, 0.5},
                                                 std::array<double, 3>{-0.3, 0.9, -3.0}}) {
            double exact = INFINITY;
            for (size_t i = 0; i < want.count; ++i) {
                double d2 = 0;
                for (int a = 0; a < 3; ++a) {
                    const double d = file.meta().origin[a] + double(want.positions[3 * i + a]) - eye[a];
                    d2 += d * d;
                }
                exact = std::min(exact, std::sqrt(d2) - double(want.radii[i]));
            }
            const std::optional<double> got = format.data_distance(n, *decoded, eye);
            ASSERT_TRUE(got);
            EXPECT_LE(*got, std::max(0.0, exact)) << "node " << n;
            EXPECT_GE(*got, exact - 2.0 * double(splats.max_radius) - 2.0 * double(splats.position_error)) << "node " << n;
        }
    }
}

TEST(PointsPacking, PackedSplatsCoverTheDecodedOnesIn8BytesOr6WithoutColour) {
    for (const PointSet& set : hierarchy_sets()) {
        const std::string& path = test::points_dataset(set);
        PointDataset file(path);
        PointsFormat format(test::read_prefix(path));
        double worst_error_to_radius = 0, worst_normal_degrees = 0;
        int worst_color = 0;
        for (uint32_t n = 0; n < format.hierarchy().size(); ++n) {
            std::shared_ptr<const DecodedNode> decoded = decode_node(format, file, n);
            const PointsNode& node = points_node(*decoded);
            DecodedPoints d;
            ASSERT_EQ(file.decode(format.hierarchy().node(n).entry, d), "");
            const PackedSplats& s = node.splats;
            ASSERT_EQ(s.stride, (d.flags & kPointHasColors) ? 8u : 6u) << "6 bytes without colours";
            ASSERT_EQ(s.halves.size(), s.stride / 2 * d.count);
            float min_radius = INFINITY;
            for (size_t i = 0; i < d.count; ++i) {
                const UnpackedSplat u = unpack_splat(s, i);
                double moved2 = 0;
                for (int a = 0; a < 3; ++a) {
                    const double world = s.origin[a] + double(u.position[a]);
                    const double want = file.meta().origin[a] + double(d.positions[3 * i + a]);
                    moved2 += (world - want) * (world - want);
                }
                const double moved = std::sqrt(moved2);
                EXPECT_LE(moved, s.position_error * 1.0001 + 1e-12);
                // The packed splat covers the decoded one (the shader's exp2 may be a few ulps low).
                EXPECT_GE(double(u.radius) * (1 + 5e-6), double(d.radii[i]) + moved) << "node " << n << " splat " << i;
                min_radius = std::min(min_radius, d.radii[i]);
                if (d.flags & kPointHasNormals) {
                    float want[3];
                    oct_decode(d.normals[i], want);
                    double dot = want[0] * u.normal[0] + want[1] * u.normal[1] + want[2] * u.normal[2];
                    worst_normal_degrees = std::max(worst_normal_degrees, std::acos(std::min(1.0, dot)) * 180 / M_PI);
                }
                if (d.flags & kPointHasColors)
                    for (int k = 0; k < 3; ++k) worst_color = std::max(worst_color, std::abs(int(u.color[k]) - int(d.colors[3 * i + k])));
            }
            worst_error_to_radius = std::max(worst_error_to_radius, double(s.position_error) / min_radius);
        }
        std::printf("GPU packing: %u bytes per point; worst position error / smallest radius %.3f; worst normal %.2f deg; "
                    "worst colour step %d\n",
                    set.colors ? kSplatBytesWithColor : kSplatBytesWithoutColor, worst_error_to_radius, worst_normal_degrees, worst_color);
        EXPECT_LT(worst_error_to_radius, 0.5) << "the node grid is fine next to the splats";
        EXPECT_LT(worst_normal_degrees, 4.0);
        EXPECT_LE(worst_color, 5);
    }
}

TEST(PointsDecode, RefusesCorruptAndMisplacedNodesWithAnError) {
    PointSet set;
    const std::string& path = test::points_dataset(set);
    PointDataset file(path);
    PointsFormat format(test::read_prefix(path));
    const Hierarchy& h = format.hierarchy();
    const HierarchyNode& root = h.node(h.roots()[0]);
    std::string error;
    const uint8_t* bytes = file.node_bytes(root.entry, &error);
    ASSERT_TRUE(bytes);
    std::vector<uint8_t> copy(bytes, bytes + root.payload_bytes);
    std::shared_ptr<const DecodedNode> out;
    for (size_t cut : {size_t(0), size_t(7), copy.size() / 2, copy.size() - 1})
        EXPECT_NE(format.decode(root.index, copy.data(), cut, out), "") << "truncated at " << cut;
    for (size_t at = 0; at < copy.size(); at += 97) {
        std::vector<uint8_t> bad = copy;
        bad[at] ^= 0x5a;
        EXPECT_NE(format.decode(root.index, bad.data(), bad.size(), out), "") << "byte " << at;
    }
    EXPECT_FALSE(out);
    // A valid node given as another node whose count differs.
    const uint32_t child = root.children[0];
    if (h.node(child).primitives != root.primitives) {
        std::string problem = format.decode(child, copy.data(), copy.size(), out);
        EXPECT_NE(problem.find("the index says"), std::string::npos) << problem;
    }
}

TEST(PointsFormatOpen, RefusesMetadataThatDisagreesWithTheIndex) {
    PointSet set;
    DatasetPrefix prefix = test::read_prefix(test::points_dataset(set));
    {
        DatasetPrefix bad = prefix;
        bad.entries.pop_back();
        EXPECT_THROW(PointsFormat{bad}, Error);
    }
    {
        DatasetPrefix bad = prefix;
        bad.entries.back().level += 1;
        EXPECT_THROW(PointsFormat{bad}, Error);
    }
    {
        DatasetPrefix bad = prefix;
        bad.meta.resize(bad.meta.size() / 2);
        EXPECT_THROW(PointsFormat{bad}, Error);
    }
    {
        DatasetPrefix bad = prefix;
        bad.header.kind = ArchiveKind::Catp;
        EXPECT_THROW(PointsFormat{bad}, Error);
    }
    // Dropping one leaf of a pair leaves an inner node with one child (version 1 metadata, which
    // lists keys: version 2 cannot express such a tree and its writer refuses it).
    {
        DatasetPrefix bad = prefix;
        PointsMeta meta;
        ASSERT_EQ(decode_points_meta(bad.meta.data(), bad.meta.size(), meta), "");
        for (size_t i = bad.entries.size(); i-- > 0;)
            if (bad.entries[i].flags & kPointLeafFlag) {
                bad.entries.erase(bad.entries.begin() + long(i));
                meta.nodes.erase(meta.nodes.begin() + long(i));
                break;
            }
        EXPECT_THROW(encode_points_meta(meta), Error);
        bad.meta = encode_points_meta(meta, 1);
        try {
            PointsFormat format(bad);
            ADD_FAILURE() << "opened";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("lacks a child"), std::string::npos) << e.what();
        }
    }
}

// The generic cut engine on the kd-tree: drawn nodes are resident, replace each other (every leaf
// has exactly one drawn node on its path to the root), and a node is refined only once both
// children are resident; streaming the requests converges to the tolerance.
TEST(PointsCut, DrawnNodesAreResidentAndPartitionTheTree) {
    PointSet set;
    const std::string& path = test::points_dataset(set);
    PointsFormat format(test::read_prefix(path));
    const Hierarchy& h = format.hierarchy();
    for (double skip : {0.0, 8.0}) {  // every level fetched, or levels skipped as the session does
        PartDrawCounter counter(h);
        ResidencyTable residency(h, 8.0);
        CutEngine engine(h, counter);
        for (double distance : {6.0, 2.5, 1.6}) {
            ViewParams view =
                ViewParams::look_at({0, -distance, 0.5}, {0, 0, 0}, {0, 0, 1}, 45 * M_PI / 180, 320, 240, 0.01, 100);
            view.tolerance_px = 1.0;
            view.skip_factor = skip;
            bool converged = false;
            for (int frame = 0; frame < 200 && !converged; ++frame) {
                const CutFrame& f = engine.update(view, residency);
                ASSERT_EQ(engine.check(residency), "");
                for (uint32_t n : f.drawn)
                    EXPECT_TRUE(residency.resident(n) || (frame == 0 && n == h.roots()[0])) << "drawn node not resident";
                for (uint32_t n : engine.refined_nodes())
                    for (uint32_t c : h.node(n).children)
                        EXPECT_TRUE(residency.resident(c) || engine.refined(c)) << "refined over a missing child";
                // Every leaf has exactly one drawn node among itself and its ancestors.
                for (const HierarchyNode& leaf : h.nodes()) {
                    if (!leaf.leaf) continue;
                    int drawn = 0;
                    for (uint32_t n = leaf.index;; n = h.node(n).parents[0]) {
                        drawn += engine.drawn(n);
                        if (h.node(n).parents.empty()) break;
                    }
                    EXPECT_EQ(drawn, 1) << "leaf " << leaf.key;
                }
                converged = f.requests.empty() && f.stats.holes == 0;
                for (const CutRequest& r : f.requests)
                    residency.set_resident(r.node, NodeBytes{8ull * h.node(r.node).primitives, 0});
            }
            EXPECT_TRUE(converged) << "distance " << distance;
            EXPECT_GT(engine.last_frame().drawn.size(), distance < 2 ? 8u : 1u) << "the close views refine";
            EXPECT_TRUE(engine.last_frame().stats.certified_error_px <= view.tolerance_px ||
                        engine.last_frame().stats.leaves_over_tolerance > 0);
        }
    }
}
