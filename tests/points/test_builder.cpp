// The converter's invariants, checked on the dataset as a client reads it: every input point is
// in exactly one leaf (within the quantization bound), boxes are nested, errors are monotone and
// hold (every input point within its ancestors' error of one of their splats), parents' splats
// cover their children's; hard inputs work or are refused clearly.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <array>
#include <cstdio>
#include <map>
#include <tuple>
#include <unordered_map>

#include "common_codec/octahedral.h"
#include "points/builder.h"
#include "points/dataset.h"
#include "support.h"
// The converter's neighbour search is private to the points module; its exactness is tested here.
#include "../../points/src/estimate.h"
#include "../../points/src/grid_knn.h"

namespace catpaq {
namespace {

struct DecodedNode {
    uint64_t key;
    bool leaf;
    float error;
    PointNodeInfo info;
    DecodedPoints points;
};

std::vector<DecodedNode> decode_all(const PointDataset& dataset) {
    std::vector<DecodedNode> nodes(dataset.node_count());
    for (size_t i = 0; i < nodes.size(); ++i) {
        const ArchiveEntry& e = dataset.entries()[i];
        nodes[i].key = e.key;
        nodes[i].leaf = e.flags & kPointLeafFlag;
        nodes[i].error = e.error;
        nodes[i].info = dataset.meta().nodes[i];
        EXPECT_EQ(dataset.decode(i, nodes[i].points), "");
    }
    return nodes;
}

double random_in(uint64_t& state) { return test::random_unit(state); }

double distance(const float* a, const double* b) {
    double d2 = 0;
    for (int k = 0; k < 3; ++k) d2 += (double(a[k]) - b[k]) * (double(a[k]) - b[k]);
    return std::sqrt(d2);
}

bool is_ancestor(uint64_t ancestor, uint64_t key) {
    while (key > ancestor) key >>= 1;
    return key == ancestor;
}

// Checks every invariant of the dataset at `path` built from `cloud` (input coordinates);
// returns the number of leaves.
size_t check_dataset(const std::string& path, const PointCloud& cloud) {
    PointDataset dataset(path);
    const PointsMeta& meta = dataset.meta();
    std::vector<DecodedNode> nodes = decode_all(dataset);
    std::map<uint64_t, size_t> by_key;
    for (size_t i = 0; i < nodes.size(); ++i) by_key[nodes[i].key] = i;
    const size_t n = cloud.size();
    std::vector<std::array<double, 3>> local(n);  // input relative to the dataset's origin
    for (size_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) local[i][a] = cloud.positions[i][a] - meta.origin[a];

    // 1. Every input point is matched, one to one, with a leaf point within the leaf's bound.
    size_t leaf_points = 0;
    double cell = 0;
    for (const DecodedNode& node : nodes)
        if (node.leaf) {
            leaf_points += node.points.count;
            cell = std::max(cell, 2.0 * node.points.position_error);
        }
    EXPECT_EQ(leaf_points, n);
    cell = std::max(cell, 1e-9);
    struct Ref {
        size_t node, point;
    };
    auto cell_key = [cell](const double* p) {
        uint64_t h = 0;
        for (int a = 0; a < 3; ++a) h = h * 0x9e3779b97f4a7c15ULL + uint64_t(int64_t(std::floor(p[a] / cell)));
        return h;
    };
    std::unordered_multimap<uint64_t, Ref> grid;
    for (size_t k = 0; k < nodes.size(); ++k)
        if (nodes[k].leaf)
            for (size_t i = 0; i < nodes[k].points.count; ++i) {
                double p[3] = {nodes[k].points.positions[3 * i], nodes[k].points.positions[3 * i + 1],
                               nodes[k].points.positions[3 * i + 2]};
                grid.emplace(cell_key(p), Ref{k, i});
            }
    // Candidates of each input point: the leaf points within their leaf's bound. Points with the
    // fewest candidates choose first (each takes its nearest one still free), so two close input
    // points whose bounds overlap do not steal each other's match.
    std::vector<std::vector<std::pair<double, Ref>>> candidates(n);
    for (size_t i = 0; i < n; ++i) {
        const double* p = local[i].data();
        for (int dx = -1; dx <= 1; ++dx)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dz = -1; dz <= 1; ++dz) {
                    double q[3] = {p[0] + dx * cell, p[1] + dy * cell, p[2] + dz * cell};
                    auto range = grid.equal_range(cell_key(q));
                    for (auto it = range.first; it != range.second; ++it) {
                        const DecodedPoints& leaf = nodes[it->second.node].points;
                        double d = distance(&leaf.positions[3 * it->second.point], p);
                        if (d <= leaf.position_error) candidates[i].push_back({d, it->second});
                    }
                }
        // A cell can be visited twice when q lands in the same cell: keep each candidate once.
        std::sort(candidates[i].begin(), candidates[i].end(), [](const auto& a, const auto& b) {
            return a.first != b.first ? a.first < b.first
                                      : a.second.node != b.second.node ? a.second.node < b.second.node
                                                                       : a.second.point < b.second.point;
        });
        candidates[i].erase(std::unique(candidates[i].begin(), candidates[i].end(),
                                        [](const auto& a, const auto& b) {
                                            return a.second.node == b.second.node && a.second.point == b.second.point;
                                        }),
                            candidates[i].end());
    }
    std::vector<size_t> by_choice(n);
    for (size_t i = 0; i < n; ++i) by_choice[i] = i;
    std::stable_sort(by_choice.begin(), by_choice.end(),
                     [&](size_t a, size_t b) { return candidates[a].size() < candidates[b].size(); });
    std::vector<std::vector<uint8_t>> used(nodes.size());
    for (size_t k = 0; k < nodes.size(); ++k) used[k].assign(nodes[k].points.count, 0);
    std::vector<size_t> leaf_of(n, SIZE_MAX);
    double position_sum_in = 0, position_sum_out = 0;
    for (size_t i : by_choice) {
        for (const auto& [d, r] : candidates[i]) {
            if (used[r.node][r.point]) continue;
            used[r.node][r.point] = 1;
            leaf_of[i] = r.node;
            for (int a = 0; a < 3; ++a) position_sum_out += nodes[r.node].points.positions[3 * r.point + a];
            break;
        }
        EXPECT_NE(leaf_of[i], SIZE_MAX) << "input point " << i << " is in no leaf";
        if (leaf_of[i] == SIZE_MAX) return 0;
        for (int a = 0; a < 3; ++a) position_sum_in += local[i][a];
    }
    // The sums (a checksum of the leaf points) agree within the quantization.
    double max_leaf_error = 0;
    for (const DecodedNode& node : nodes)
        if (node.leaf) max_leaf_error = std::max(max_leaf_error, double(node.points.position_error));
    EXPECT_LE(std::fabs(position_sum_in - position_sum_out), 3 * double(n) * max_leaf_error + 1e-6);

    size_t leaves = 0;
    for (size_t k = 0; k < nodes.size(); ++k) {
        const DecodedNode& node = nodes[k];
        leaves += node.leaf;
        // 2. Splat balls inside the node's box; boxes nested; errors monotone.
        for (size_t i = 0; i < node.points.count; ++i)
            for (int a = 0; a < 3; ++a) {
                EXPECT_GE(node.points.positions[3 * i + a] - node.points.radii[i], node.info.box_min[a]);
                EXPECT_LE(node.points.positions[3 * i + a] + node.points.radii[i], node.info.box_max[a]);
            }
        if (node.key != 1) {
            const DecodedNode& parent = nodes[by_key.at(point_node_parent(node.key))];
            EXPECT_GE(parent.error, node.error);
            for (int a = 0; a < 3; ++a) {
                EXPECT_LE(parent.info.box_min[a], node.info.box_min[a]);
                EXPECT_GE(parent.info.box_max[a], node.info.box_max[a]);
            }
            // 4. The parent's splats cover the child's: each child splat's ball lies in a parent's.
            for (size_t i = 0; i < node.points.count; ++i) {
                bool covered = false;
                for (size_t j = 0; j < parent.points.count && !covered; ++j) {
                    double c[3] = {node.points.positions[3 * i], node.points.positions[3 * i + 1], node.points.positions[3 * i + 2]};
                    covered = distance(&parent.points.positions[3 * j], c) + node.points.radii[i] <=
                              double(parent.points.radii[j]) * (1 + 1e-6);
                }
                EXPECT_TRUE(covered) << "node " << node.key << " splat " << i;
            }
        }
        // 3. The error holds: every input point of the subtree within `error` of a splat centre.
        for (size_t i = 0; i < n; ++i) {
            if (!is_ancestor(node.key, nodes[leaf_of[i]].key)) continue;
            double nearest = INFINITY;
            for (size_t j = 0; j < node.points.count; ++j) nearest = std::min(nearest, distance(&node.points.positions[3 * j], local[i].data()));
            EXPECT_LE(nearest, double(node.error) * (1 + 1e-6)) << "node " << node.key << " input " << i;
        }
    }
    return leaves;
}

PointsBuildSettings small_nodes() {
    PointsBuildSettings settings;
    settings.node_points = 512;
    settings.progress = false;
    return settings;
}

TEST(PointBuilder, EveryInvariantHoldsOnASphereWithTheMidpointSplit) {
    PointCloud cloud = test::sphere_cloud(12000);
    std::string path = test::scratch("sphere.cpq");
    PointsBuildSettings settings = small_nodes();
    settings.split = PointSplitRule::Midpoint;
    PointsBuildReport report = build_points(cloud, path, settings);
    EXPECT_TRUE(report.normals_estimated);
    EXPECT_TRUE(report.radii_estimated);
    EXPECT_LE(report.worst_error_to_radius, 0.25);
    EXPECT_GT(report.depth, 3);
    EXPECT_EQ(check_dataset(path, cloud), report.leaves);
}

TEST(PointBuilder, EveryInvariantHoldsWithTheBalancedSplit) {
    PointCloud cloud = test::sphere_cloud(12000, 1.0, {0, 0, 0}, 2);
    PointsBuildSettings settings = small_nodes();
    settings.split = PointSplitRule::Balanced;
    std::string path = test::scratch("balanced.cpq");
    PointsBuildReport report = build_points(cloud, path, settings);
    EXPECT_EQ(check_dataset(path, cloud), report.leaves);
    // Balanced leaves are at least a quarter full (midpoint leaves can be nearly empty).
    EXPECT_GE(report.min_leaf_points, settings.node_points / 4);
}

TEST(PointBuilder, EstimatedNormalsPointOutOfASphere) {
    PointCloud cloud = test::sphere_cloud(20000, 1.0, {0, 0, 0}, 3);
    std::string path = test::scratch("normals.cpq");
    build_points(cloud, path, small_nodes());
    PointDataset dataset(path);
    DecodedPoints out;
    size_t outward = 0, total = 0;
    for (size_t i = 0; i < dataset.node_count(); ++i) {
        ASSERT_EQ(dataset.decode(i, out), "");
        for (size_t k = 0; k < out.count; ++k) {
            float n[3];
            oct_decode(out.normals[k], n);
            const float* p = &out.positions[3 * k];
            float length = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
            outward += (n[0] * p[0] + n[1] * p[1] + n[2] * p[2]) / length > 0.9f;
            ++total;
        }
    }
    EXPECT_GT(double(outward) / double(total), 0.99);
}

TEST(PointBuilder, FarFromTheOriginKeepsPrecision) {
    // A 1 m sphere at (1e7, 2e7, -1e7): stored relative to the bounds' centre, every input point
    // is found within its leaf's quantization bound (millimetres would be lost in float).
    PointCloud cloud = test::sphere_cloud(8000, 1.0, {1e7, 2e7, -1e7}, 4);
    std::string path = test::scratch("far.cpq");
    PointsBuildReport report = build_points(cloud, path, small_nodes());
    PointDataset dataset(path);
    EXPECT_NEAR(dataset.meta().origin[0], 1e7, 1.0);
    EXPECT_EQ(check_dataset(path, cloud), report.leaves);
    EXPECT_LT(dataset.entries().back().error, 0.01);  // a leaf's bound: well under a centimetre
}

TEST(PointBuilder, DuplicatePointsWork) {
    PointCloud cloud;
    for (int copy = 0; copy < 400; ++copy)
        for (int k = 0; k < 5; ++k) cloud.positions.push_back({double(k), double(k * k), 0.5 * k});
    std::string path = test::scratch("duplicates.cpq");
    PointsBuildReport report = build_points(cloud, path, small_nodes());
    EXPECT_EQ(check_dataset(path, cloud), report.leaves);
}

TEST(PointBuilder, PointsOnAPlaneAndOnALineWork) {
    PointCloud plane, line;
    uint64_t state = 5;
    for (int i = 0; i < 3000; ++i) {
        plane.positions.push_back({test::random_unit(state), test::random_unit(state), 0.5});
        line.positions.push_back({2.0 * test::random_unit(state), 1.0, -3.0});
    }
    std::string plane_path = test::scratch("plane.cpq"), line_path = test::scratch("line.cpq");
    EXPECT_EQ(check_dataset(plane_path, plane), build_points(plane, plane_path, small_nodes()).leaves);
    EXPECT_EQ(check_dataset(line_path, line), build_points(line, line_path, small_nodes()).leaves);
}

// The k smallest squared distances from point q of xyz to all of them, by brute force (the same
// float arithmetic as the searches, so equal values compare equal).
std::vector<float> brute_nearest(const std::vector<float>& xyz, size_t q, size_t k) {
    std::vector<float> d2(xyz.size() / 3);
    for (size_t i = 0; i < d2.size(); ++i) {
        const float dx = xyz[3 * i] - xyz[3 * q], dy = xyz[3 * i + 1] - xyz[3 * q + 1], dz = xyz[3 * i + 2] - xyz[3 * q + 2];
        d2[i] = dx * dx + dy * dy + dz * dz;
    }
    std::sort(d2.begin(), d2.end());
    d2.resize(std::min(k, d2.size()));
    return d2;
}

// A plane's samples with a clump of duplicates and a few far outliers: what the grid handles
// worst (cells far from uniform) and what the leaf halo reaches last.
std::vector<float> awkward_cloud(size_t n, uint64_t seed) {
    std::vector<float> xyz;
    uint64_t state = seed;
    for (size_t i = 0; i < n; ++i) {
        xyz.push_back(float(test::random_unit(state)));
        xyz.push_back(float(test::random_unit(state)));
        xyz.push_back(float(0.01 * test::random_unit(state)));
    }
    for (int i = 0; i < 100; ++i) xyz.insert(xyz.end(), {0.5f, 0.5f, 0.005f});
    for (int i = 0; i < 5; ++i)
        for (int a = 0; a < 3; ++a) xyz.push_back(float(40 * test::random_unit(state) - 20));
    return xyz;
}

TEST(PointNeighbours, TheGridFindsWhatBruteForceFinds) {
    using points_detail::GridKnn;
    using points_detail::LocalKnn;
    const std::vector<float> xyz = awkward_cloud(3000, 9);
    const size_t n = xyz.size() / 3;
    for (double per_cell : {0.5, 2.0, 4.0, 16.0})
        for (size_t k : {1, 5, 16, 40}) {
            GridKnn grid;
            grid.build(xyz.data(), nullptr, n, per_cell);
            uint32_t index[GridKnn::kMaxK];
            float d2[GridKnn::kMaxK];
            for (size_t q = 0; q < n; q += 13) {
                const size_t found = grid.nearest(&xyz[3 * q], k, index, d2);
                EXPECT_EQ(std::vector<float>(d2, d2 + found), brute_nearest(xyz, q, k)) << "point " << q << " k " << k;
            }
            size_t visited = 0;
            grid.all_nearest(k, [](uint32_t id) { return id % 5 == 0; },
                             [&](uint32_t id, const float*, size_t found, const uint32_t* ids, const float* distance2) {
                                 ++visited;
                                 EXPECT_EQ(std::vector<float>(distance2, distance2 + found), brute_nearest(xyz, id, k)) << "point " << id;
                                 for (size_t j = 0; j < found; ++j) {
                                     const float dx = xyz[3 * ids[j]] - xyz[3 * id], dy = xyz[3 * ids[j] + 1] - xyz[3 * id + 1],
                                                 dz = xyz[3 * ids[j] + 2] - xyz[3 * id + 2];
                                     EXPECT_EQ(dx * dx + dy * dy + dz * dz, distance2[j]);
                                 }
                             });
            EXPECT_EQ(visited, (n + 4) / 5);
        }
    // The clump makes LocalKnn take its kd-tree; ids are mapped back.
    std::vector<uint32_t> ids(n);
    for (size_t i = 0; i < n; ++i) ids[i] = uint32_t(1000 + i);
    LocalKnn local;
    local.build(xyz.data(), ids.data(), n, 40.0);
    size_t visited = 0;
    local.all_nearest(16, [](uint32_t) { return true; },
                      [&](uint32_t id, const float*, size_t found, const uint32_t*, const float* distance2) {
                          ++visited;
                          EXPECT_EQ(std::vector<float>(distance2, distance2 + found), brute_nearest(xyz, id - 1000, 16));
                      });
    EXPECT_EQ(visited, n);
}

TEST(PointNeighbours, LeafEstimatesUseExactNeighboursAcrossLeavesAndForOutliers) {
    // Leaves of 256 points in x order; a leaf's halo is found by scanning the others. Radii are
    // the distance to the 6th neighbour, which brute force gives exactly.
    std::vector<float> xyz = awkward_cloud(4000, 11);
    const size_t n = xyz.size() / 3;
    std::vector<uint32_t> order(n);
    for (size_t i = 0; i < n; ++i) order[i] = uint32_t(i);
    std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return xyz[3 * a] < xyz[3 * b]; });
    std::vector<float> sorted(3 * n);
    std::vector<Vec3d> positions(n);
    for (size_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) {
            sorted[3 * i + a] = xyz[3 * order[i] + a];
            positions[i][a] = sorted[3 * i + a];
        }
    points_detail::EstimateInput in;
    in.positions = positions.data();
    in.xyz = sorted.data();
    in.cloud_extent = 40;
    in.halo = [&](const float lo[3], const float hi[3], size_t begin, size_t end, std::vector<uint32_t>& ids) {
        for (size_t i = 0; i < n; ++i) {
            if (i >= begin && i < end) continue;
            const float* p = &sorted[3 * i];
            if (p[0] >= lo[0] && p[0] <= hi[0] && p[1] >= lo[1] && p[1] <= hi[1] && p[2] >= lo[2] && p[2] <= hi[2])
                ids.push_back(uint32_t(i));
        }
    };
    in.nearest = [&](const float q[3], size_t k, uint32_t* index, float* distance2) {
        std::vector<std::pair<float, uint32_t>> all(n);
        for (size_t i = 0; i < n; ++i) {
            const float dx = sorted[3 * i] - q[0], dy = sorted[3 * i + 1] - q[1], dz = sorted[3 * i + 2] - q[2];
            all[i] = {dx * dx + dy * dy + dz * dz, uint32_t(i)};
        }
        std::sort(all.begin(), all.end());
        const size_t found = std::min(k, n);
        for (size_t j = 0; j < found; ++j) std::tie(distance2[j], index[j]) = all[j];
        return found;
    };
    std::vector<float> radii(n, -1);
    std::vector<Vec3f> normals(n);
    for (size_t begin = 0; begin < n; begin += 256)
        points_detail::estimate_leaf(in, begin, std::min(n, begin + 256), normals.data(), radii.data());
    for (size_t i = 0; i < n; ++i) {
        EXPECT_EQ(radii[i], std::sqrt(brute_nearest(sorted, i, 7).back())) << "point " << i;
        const float length = std::sqrt(normals[i][0] * normals[i][0] + normals[i][1] * normals[i][1] + normals[i][2] * normals[i][2]);
        EXPECT_NEAR(length, 1.0f, 1e-5f);
    }
}

TEST(PointBuilder, OutliersFarFromTheSurfaceWork) {
    PointCloud cloud;
    const std::vector<float> xyz = awkward_cloud(5000, 13);
    for (size_t i = 0; i < xyz.size(); i += 3) cloud.positions.push_back({xyz[i], xyz[i + 1], xyz[i + 2]});
    std::string path = test::scratch("outliers.cpq");
    PointsBuildReport report = build_points(cloud, path, small_nodes());
    EXPECT_EQ(check_dataset(path, cloud), report.leaves);
}

TEST(PointBuilder, OnePointWorksWithARadiusAndIsRefusedWithout) {
    PointCloud one;
    one.positions.push_back({1, 2, 3});
    std::string path = test::scratch("one.cpq");
    EXPECT_TRUE(test::fails_with([&] { build_points(one, path, small_nodes()); }, {"coincide", "radii"}));
    one.radii.push_back(0.5f);
    PointsBuildReport report = build_points(one, path, small_nodes());
    EXPECT_EQ(report.nodes, 1u);
    EXPECT_EQ(check_dataset(path, one), 1u);
    PointCloud same;
    for (int i = 0; i < 100; ++i) same.positions.push_back({4, 4, 4});
    EXPECT_TRUE(test::fails_with([&] { build_points(same, path, small_nodes()); }, {"all 100 points coincide"}));
}

TEST(PointBuilder, OutputIsTheSameOnOneThreadAndOnAll) {
    // Subtrees are built in parallel and nodes reach the archive in any order: the file must not
    // depend on it.
    PointCloud cloud = test::sphere_cloud(6000, 1.0, {0, 0, 0}, 6);
    PointsBuildSettings settings = small_nodes();
    std::string all = test::scratch("threads_all.cpq"), one = test::scratch("threads_one.cpq");
    build_points(cloud, all, settings);
    settings.threads = 1;
    build_points(cloud, one, settings);
    EXPECT_EQ(read_file(all), read_file(one));
}

// The leaves' estimated radii cover the surface they sample: on uniformly random samples of a
// square, the discs of the decoded leaf splats leave at most 1e-3 of its interior uncovered (the
// radii before, sqrt(pi d_16^2 / 15), left 2.5e-2: the client drew them 1.4x as large).
TEST(PointBuilder, EstimatedRadiiCoverUniformlyRandomSamplesOfAPlane) {
    PointCloud cloud;
    uint64_t state = 5;
    const size_t count = 40000;
    for (size_t i = 0; i < count; ++i)
        cloud.positions.push_back({random_in(state), random_in(state), 0.0});
    const std::string path = test::scratch("plane_radii.cpq");
    PointsBuildSettings settings = small_nodes();
    settings.node_points = 2048;
    build_points(cloud, path, settings);
    PointDataset dataset(path);
    // Leaf discs on a grid of cells of 0.01 (about 2 spacings), to find the discs near a probe.
    const int cells = 100;
    std::vector<std::vector<std::array<float, 3>>> grid(size_t(cells) * cells);
    for (const DecodedNode& node : decode_all(dataset)) {
        if (!node.leaf) continue;
        for (size_t i = 0; i < node.points.count; ++i) {
            const float* p = &node.points.positions[3 * i];
            const double x = p[0] + dataset.meta().origin[0], y = p[1] + dataset.meta().origin[1];
            const int cx = std::clamp(int(x * cells), 0, cells - 1), cy = std::clamp(int(y * cells), 0, cells - 1);
            grid[size_t(cy) * cells + cx].push_back({float(x), float(y), node.points.radii[i]});
        }
    }
    size_t probes = 0, uncovered = 0;
    for (size_t probe = 0; probe < 200000; ++probe) {
        const double x = 0.05 + 0.9 * random_in(state), y = 0.05 + 0.9 * random_in(state);
        const int cx = int(x * cells), cy = int(y * cells);
        bool covered = false;
        for (int dy = -2; dy <= 2 && !covered; ++dy)
            for (int dx = -2; dx <= 2 && !covered; ++dx)
                for (const auto& disc : grid[size_t(cy + dy) * cells + cx + dx])
                    if ((disc[0] - x) * (disc[0] - x) + (disc[1] - y) * (disc[1] - y) < double(disc[2]) * disc[2]) {
                        covered = true;
                        break;
                    }
        ++probes;
        uncovered += !covered;
    }
    std::printf("uniform plane, %zu points: %zu of %zu probes uncovered by the leaf discs\n", count, uncovered, probes);
    EXPECT_LE(double(uncovered), 1e-3 * double(probes));
}

TEST(PointBuilder, BadCloudsAndSettingsAreRefused) {
    PointCloud cloud = test::sphere_cloud(100);
    cloud.positions[7][2] = INFINITY;
    std::string path = test::scratch("bad.cpq");
    EXPECT_TRUE(test::fails_with([&] { build_points(cloud, path, small_nodes()); }, {"point 7", "non-finite"}));
    EXPECT_TRUE(test::fails_with([&] { build_points(PointCloud{}, path, small_nodes()); }, {"no points"}));
    PointsBuildSettings settings = small_nodes();
    settings.node_points = 3;
    EXPECT_TRUE(test::fails_with([&] { build_points(test::sphere_cloud(100), path, settings); }, {"node size"}));
    settings = small_nodes();
    settings.radius_neighbour = 0;
    EXPECT_TRUE(test::fails_with([&] { build_points(test::sphere_cloud(100), path, settings); }, {"radius neighbour"}));
    const std::string nowhere = test::scratch("missing_dir/out.cpq");
    EXPECT_TRUE(test::fails_with([&] { build_points(test::sphere_cloud(100), nowhere, small_nodes()); }, {"missing_dir"}));
    std::filesystem::create_directories(test::scratch("a_directory"));
    const std::string directory = test::scratch("a_directory");
    EXPECT_TRUE(test::fails_with([&] { build_points(test::sphere_cloud(100), directory, small_nodes()); }, {"a_directory"}));
}

TEST(PointBuilder, ConvertsAFileAndReportsWhatItDropped) {
    std::string xyz = test::write_text("file.xyz", [] {
        std::string text;
        uint64_t state = 8;
        for (int i = 0; i < 2000; ++i)
            text += std::to_string(test::random_unit(state)) + " " + std::to_string(test::random_unit(state)) + " 0 7\n";
        return text;
    }());
    std::string path = test::scratch("file.cpq");
    PointsBuildReport report = build_points_file(xyz, path, small_nodes());
    EXPECT_EQ(report.input_points, 2000u);
    ASSERT_EQ(report.dropped_input.size(), 1u);
    EXPECT_NE(report.dropped_input[0].find("intensity"), std::string::npos);
    PointDataset dataset(path);
    EXPECT_EQ(dataset.meta().input_points, 2000u);
}

TEST(PointDataset, RefusesOtherKindsAndReportsCorruptNodes) {
    std::string path = test::scratch("corrupt.cpq");
    build_points(test::sphere_cloud(3000), path, small_nodes());
    std::string bytes = read_file(path);
    PointDataset good(path);
    const ArchiveEntry& last = good.entries().back();
    bytes[last.offset + last.size / 2] ^= 0x40;
    std::string bad_path = test::write_text("corrupt_node.cpq", bytes);
    PointDataset bad(bad_path);
    DecodedPoints out;
    std::string problem = bad.decode(good.entries().size() - 1, out);
    EXPECT_NE(problem.find("checksum"), std::string::npos) << problem;

    ArchiveWriter writer(test::scratch("catp_kind.cpq"), ArchiveKind::Catp);
    writer.finish({});
    EXPECT_TRUE(test::fails_with([&] { PointDataset other(test::scratch("catp_kind.cpq")); }, {"catp", "not a point dataset"}));
}

}  // namespace
}  // namespace catpaq
