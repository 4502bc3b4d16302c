// The generated hard cases (mesh/generators.h: points on lattice planes, offsets of 1e7, a
// 1e-4 wide model, needles, near-degenerate and degenerate triangles, non-manifold edges, holes,
// flat sheets): each either converts with every property the other tests prove (verify's
// invariants, a closed input welding closed, an open one's border only on the input's border,
// bounds that hold), or is refused with a message. Never a crash.
#include <gtest/gtest.h>

#include <map>
#include <set>

#include "aqp/clean.h"
#include "aqp/dataset.h"
#include "aqp/verify.h"
#include "base/error.h"
#include "catp/distance.h"
#include "mesh/generators.h"
#include "support.h"

using namespace catpaq;
using namespace catpaq::aqp;

namespace {

// The input's border edges as segments (after cleaning: what the converter maps).
std::vector<std::pair<Vec3d, Vec3d>> border_segments(const Mesh& mesh) {
    std::vector<std::pair<Vec3d, Vec3d>> out;
    std::map<std::pair<uint32_t, uint32_t>, int> uses;
    for (size_t t = 0; t < mesh.triangle_count(); ++t)
        for (int k = 0; k < 3; ++k) {
            uint32_t a = mesh.indices[3 * t + k], b = mesh.indices[3 * t + (k + 1) % 3];
            ++uses[{std::min(a, b), std::max(a, b)}];
        }
    for (auto [edge, n] : uses)
        if (n == 1) out.push_back({mesh.positions[edge.first], mesh.positions[edge.second]});
    return out;
}

// The closed surface of a voxel set: every voxel face not shared with another voxel, as
// `split` x `split` squares of two outward triangles each (vertices repeated; cleaning welds them).
Mesh voxel_surface(const std::vector<std::array<int, 3>>& voxels, int split) {
    std::set<std::array<int, 3>> filled(voxels.begin(), voxels.end());
    Mesh m;
    for (const auto& v : voxels)
        for (int axis = 0; axis < 3; ++axis)
            for (int side : {-1, 1}) {
                std::array<int, 3> next = v;
                next[axis] += side;
                if (filled.count(next)) continue;
                // Each small square's corners, counter-clockwise seen from outside.
                const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
                for (int s1 = 0; s1 < split; ++s1)
                    for (int s2 = 0; s2 < split; ++s2) {
                        std::array<Vec3d, 4> c;
                        for (int k = 0; k < 4; ++k) {
                            Vec3d q{double(v[0]), double(v[1]), double(v[2])};
                            q[axis] += side > 0 ? 1 : 0;
                            q[a1] += double(s1 + (k == 1 || k == 2)) / split;
                            q[a2] += double(s2 + (k == 2 || k == 3)) / split;
                            c[k] = q;
                        }
                        if (side < 0) std::swap(c[1], c[3]);
                        const uint32_t base = uint32_t(m.positions.size());
                        m.positions.insert(m.positions.end(), c.begin(), c.end());
                        m.indices.insert(m.indices.end(), {base, base + 1, base + 2, base, base + 2, base + 3});
                    }
            }
    return m;
}

class AqpHardCase : public ::testing::TestWithParam<HardCase> {};

}  // namespace

TEST_P(AqpHardCase, ConvertsWithEveryPropertyOrIsRefusedWithAMessage) {
    const HardCase c = GetParam();
    const Mesh input = make_hard_case(c);
    aqp::test::Built b;
    try {
        b = aqp::test::build(input, hard_case_name(c));
    } catch (const Error& e) {
        EXPECT_GT(std::string(e.what()).size(), 10u) << hard_case_name(c) << " refused without a message";
        GTEST_SKIP() << "refused: " << e.what();
    }
    AqpDataset d(b.path);
    AqpVerifyReport r = verify_aqp(d);
    EXPECT_TRUE(r.ok()) << (r.problems.empty() ? "" : r.problems[0]);
    EXPECT_EQ(b.report.location_misses, 0u);
    const Mesh clean = clean_to_manifold(input, {}).mesh;
    const std::vector<std::pair<Vec3d, Vec3d>> border = border_segments(clean);
    const int k = d.finest_level();
    const Mesh finest = aqp_level_mesh(d, k);
    const size_t open = count_edges(finest.indices).border;
    if (border.empty()) {
        EXPECT_EQ(open, 0u) << "a closed input gave border edges: a crack";
    } else {
        // Every border edge of the output runs along the input's border, within the bound.
        SegmentDistance to_border(border);
        double bound = 0;
        for (uint32_t p = 0; p < d.patch_count(); ++p) bound = std::max(bound, double(d.entry(p, k).error));
        std::map<std::pair<uint32_t, uint32_t>, int> uses;
        for (size_t t = 0; t < finest.triangle_count(); ++t)
            for (int e = 0; e < 3; ++e) {
                uint32_t a = finest.indices[3 * t + e], z = finest.indices[3 * t + (e + 1) % 3];
                ++uses[{std::min(a, z), std::max(a, z)}];
            }
        for (auto [edge, n] : uses) {
            if (n != 1) continue;
            const Vec3d& a = finest.positions[edge.first];
            const Vec3d& z = finest.positions[edge.second];
            const Vec3d mid{(a[0] + z[0]) / 2, (a[1] + z[1]) / 2, (a[2] + z[2]) / 2};
            ASSERT_LE(to_border.distance(mid), bound * (1 + 1e-6)) << "a border edge away from the input's border";
        }
    }
    aqp::test::expect_bounds_hold(clean, b.path, /*not_vacuous=*/false);
}

INSTANTIATE_TEST_SUITE_P(AllHardCases, AqpHardCase, ::testing::ValuesIn(kAllHardCases),
                         [](const ::testing::TestParamInfo<HardCase>& info) { return std::string(hard_case_name(info.param)); });

TEST(AqpHardCases, HighGenusConvertsWithItsPropertiesOrIsRefusedWithAMessage) {
    // A 9 x 9 voxel slab with 16 holes, its faces split 4 x 4 (9600 triangles): genus 16.
    std::vector<std::array<int, 3>> voxels;
    for (int x = 0; x < 9; ++x)
        for (int y = 0; y < 9; ++y)
            if (x % 2 == 0 || y % 2 == 0) voxels.push_back({x, y, 0});
    const Mesh slab = voxel_surface(voxels, 4);
    CleanReport clean;
    clean_to_manifold(slab, {}, &clean);
    ASSERT_EQ(clean.genus, 16);
    // Measured: the default (50) and 30 stop at 306 base triangles (refused: "handles"), 400
    // converts, 600 folds around the tunnels (refused: "domain triangles").
    for (size_t domain : {size_t(0), size_t(400), size_t(600)}) {
        AqpBuildOptions options;
        options.domain_triangles = domain;
        try {
            aqp::test::Built b = aqp::test::build(slab, "genus16_" + std::to_string(domain), options);
            AqpDataset d(b.path);
            EXPECT_TRUE(verify_aqp(d).ok());
            EXPECT_EQ(count_edges(aqp_level_mesh(d, d.finest_level()).indices).border, 0u);
            aqp::test::expect_bounds_hold(clean_to_manifold(slab, {}).mesh, b.path, false);
        } catch (const Error& e) {
            // Too few base triangles for 16 handles, or folds: the message says so.
            const std::string what = e.what();
            EXPECT_TRUE(what.find("handles") != std::string::npos || what.find("domain triangles") != std::string::npos) << what;
        }
    }
}
