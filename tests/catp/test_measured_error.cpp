// measured_simplification_error (the converter's own-error measure): its fast grid search with
// early exits must return exactly the maximum of the sample points' distances, computed here by
// brute force over every triangle: with an independent formula (equal up to rounding), and with
// the converter's own point_triangle_distance2 (equal bit for bit, as the output files depend on
// it).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "../../catp/src/fragment_build.h"
#include "catp/simplify.h"

using namespace catpaq;

namespace {

// Squared distance from p to triangle (a, b, c) by projection onto the plane when inside, else
// the closest of the three edges: independent of the implementation under test.
double segment_distance2(const Vec3d& p, const Vec3d& a, const Vec3d& b) {
    Vec3d ab = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, ap = {p[0] - a[0], p[1] - a[1], p[2] - a[2]};
    double len2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2];
    double t = len2 > 0 ? std::clamp((ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / len2, 0.0, 1.0) : 0.0;
    double d2 = 0;
    for (int i = 0; i < 3; ++i) d2 += (ap[i] - t * ab[i]) * (ap[i] - t * ab[i]);
    return d2;
}

double triangle_distance2(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    Vec3d u = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    Vec3d n = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    double nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
    double best = std::min({segment_distance2(p, a, b), segment_distance2(p, b, c), segment_distance2(p, c, a)});
    if (nn > 0) {
        double h = (n[0] * (p[0] - a[0]) + n[1] * (p[1] - a[1]) + n[2] * (p[2] - a[2])) / nn;
        Vec3d q = {p[0] - h * n[0], p[1] - h * n[1], p[2] - h * n[2]};
        auto side = [&](const Vec3d& x, const Vec3d& y) {
            Vec3d e = {y[0] - x[0], y[1] - x[1], y[2] - x[2]}, w = {q[0] - x[0], q[1] - x[1], q[2] - x[2]};
            Vec3d c2 = {e[1] * w[2] - e[2] * w[1], e[2] * w[0] - e[0] * w[2], e[0] * w[1] - e[1] * w[0]};
            return c2[0] * n[0] + c2[1] * n[1] + c2[2] * n[2];
        };
        if (side(a, b) >= 0 && side(b, c) >= 0 && side(c, a) >= 0) best = std::min(best, h * h * nn);
    }
    return best;
}

double mesh_distance(const Vec3d& p, const std::vector<Vec3d>& pos, const std::vector<uint32_t>& idx) {
    double best = 1e300;
    for (size_t i = 0; i + 2 < idx.size(); i += 3)
        best = std::min(best, triangle_distance2(p, pos[idx[i]], pos[idx[i + 1]], pos[idx[i + 2]]));
    return std::sqrt(best);
}

double mesh_distance_exact(const Vec3d& p, const std::vector<Vec3d>& pos, const std::vector<uint32_t>& idx) {
    double best = 1e300;
    for (size_t i = 0; i + 2 < idx.size(); i += 3)
        best = std::min(best, point_triangle_distance2(p, pos[idx[i]], pos[idx[i + 1]], pos[idx[i + 2]]));
    return std::sqrt(best);
}

// The same sample points as the converter: removed vertices and the simplified edges'
// midpoints; `distance` from a point to a mesh.
template <class Distance>
double brute_force_error(const WorkFragment& g, const std::vector<uint32_t>& s, Distance distance) {
    std::vector<uint8_t> kept(g.positions.size(), 0);
    for (uint32_t v : s) kept[v] = 1;
    double error = 0;
    for (size_t v = 0; v < g.positions.size(); ++v)
        if (!kept[v]) error = std::max(error, distance(g.positions[v], g.positions, s));
    for (size_t i = 0; i + 2 < s.size(); i += 3) {
        const Vec3d &a = g.positions[s[i]], &b = g.positions[s[i + 1]], &c = g.positions[s[i + 2]];
        Vec3d points[3] = {{(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2},
                           {(b[0] + c[0]) / 2, (b[1] + c[1]) / 2, (b[2] + c[2]) / 2},
                           {(a[0] + c[0]) / 2, (a[1] + c[1]) / 2, (a[2] + c[2]) / 2}};
        for (const Vec3d& p : points) error = std::max(error, distance(p, g.positions, g.indices));
    }
    return error;
}

double brute_force_error(const WorkFragment& g, const std::vector<uint32_t>& s) {
    return brute_force_error(g, s, mesh_distance);
}

double brute_force_error_exact(const WorkFragment& g, const std::vector<uint32_t>& s) {
    return brute_force_error(g, s, mesh_distance_exact);
}

// A noisy height field of n x n quads around (offset, offset, offset), in lattice-like units.
WorkFragment height_field(int n, double noise, uint64_t seed, double offset) {
    WorkFragment f;
    uint64_t state = seed * 0x9E3779B97F4A7C15ull + 1;
    auto random = [&] {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        return double(state >> 11) / double(1ull << 53) - 0.5;
    };
    for (int y = 0; y <= n; ++y)
        for (int x = 0; x <= n; ++x) {
            double h = 3.0 * std::sin(x * 0.3) * std::cos(y * 0.2) + noise * random();
            f.positions.push_back({offset + 10.0 * x, offset + 10.0 * y, offset + 10.0 * h});
        }
    for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
            uint32_t a = uint32_t(y * (n + 1) + x), b = a + 1, c = a + uint32_t(n + 1), d = c + 1;
            f.indices.insert(f.indices.end(), {a, b, d, a, d, c});
        }
    f.normals.assign(f.positions.size(), Vec3f{0, 0, 1});
    f.colors.assign(f.positions.size(), Rgb8{0, 0, 0});
    return f;
}

struct Random {
    uint64_t state;
    double operator()() {  // in [0, 1)
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        return double(state >> 11) / double(1ull << 53);
    }
    uint32_t below(uint32_t n) { return uint32_t((*this)() * n); }
};

// A scan-like surface with the awkward cases of real data: degenerate triangles (repeated and
// collinear corners), slivers, a far-away cluster (so the grid's cell count hits its cap and
// most cells are empty), and duplicate triangles.
WorkFragment awkward_surface(uint64_t seed) {
    WorkFragment f = height_field(12, 2.0, seed, 500000.0);
    Random random{seed};
    const uint32_t n = uint32_t(f.positions.size());
    for (int k = 0; k < 12; ++k) {
        const uint32_t a = random.below(n), b = random.below(n);
        f.indices.insert(f.indices.end(), {a, a, b});  // two equal corners
        const Vec3d &pa = f.positions[a], &pb = f.positions[b];
        f.positions.push_back({(pa[0] + pb[0]) / 2, (pa[1] + pb[1]) / 2, (pa[2] + pb[2]) / 2});
        f.indices.insert(f.indices.end(), {a, b, uint32_t(f.positions.size() - 1)});  // collinear
        f.positions.push_back({pa[0] + 1e-7, pa[1] + 30.0, pa[2] - 1e-7});
        f.indices.insert(f.indices.end(), {a, uint32_t(f.positions.size() - 1), a == 0 ? 1u : a - 1});  // sliver-ish
    }
    const size_t triangles = f.indices.size();
    for (size_t i = 0; i < triangles / 20; ++i) f.indices.push_back(f.indices[i]);  // duplicates
    // A small cluster far away.
    const uint32_t first = uint32_t(f.positions.size());
    for (int k = 0; k < 12; ++k)
        f.positions.push_back({520000.0 + 3 * random(), 530000.0 + 3 * random(), 540000.0 + 3 * random()});
    for (uint32_t k = 0; k + 2 < 12; ++k) f.indices.insert(f.indices.end(), {first + k, first + k + 1, first + k + 2});
    f.normals.assign(f.positions.size(), Vec3f{0, 0, 1});
    f.colors.assign(f.positions.size(), Rgb8{0, 0, 0});
    return f;
}

}  // namespace

TEST(MeasuredError, EqualsTheBruteForceMaximumOfTheSampleDistances) {
    for (uint64_t seed = 1; seed <= 4; ++seed) {
        for (double noise : {0.0, 0.5, 4.0}) {
            SCOPED_TRACE(testing::Message() << "seed " << seed << " noise " << noise);
            WorkFragment g = height_field(24, noise, seed, 300000.0 + 17.0 * double(seed));
            for (size_t target : {g.indices.size() / 6, g.indices.size() / 12}) {
                SimplifySettings settings;
                settings.target_triangles = target;
                SimplifyResult r = simplify_mesh(&g.positions[0][0], g.positions.size(), g.indices.data(),
                                                 g.indices.size(), nullptr, settings);
                ASSERT_LT(r.indices.size(), g.indices.size());
                double measured = measured_simplification_error(g, r.indices);
                double expected = brute_force_error(g, r.indices);
                // Both are the same maximum of the same points' distances; only the rounding of
                // the two point-triangle formulas may differ.
                EXPECT_NEAR(measured, expected, 1e-9 * std::max(1.0, expected));
                EXPECT_EQ(measured, brute_force_error_exact(g, r.indices));
                // Skipping the edges the simplification left unchanged (their midpoints lie on
                // the gathered surface) changes nothing.
                EXPECT_EQ(measured_simplification_error(g, r.indices, &r.sources), measured);
                if (noise > 0) {
                    EXPECT_GT(measured, 0.0);
                }
            }
        }
    }
}

// The grid's float filters, fallbacks and exact ring search against arbitrary "simplifications"
// (random triangles over the gathered vertices, some far from the surface) of meshes with
// degenerate, sliver and duplicate triangles: still exactly the brute-force maximum, bit for bit.
// The meshes grow and shrink, so the per-thread grid memory is reused at every size.
TEST(MeasuredError, ExactOnAwkwardMeshesAndArbitrarySimplifications) {
    for (uint64_t seed = 1; seed <= 5; ++seed) {
        SCOPED_TRACE(testing::Message() << "seed " << seed);
        WorkFragment g = awkward_surface(seed);
        Random random{seed * 7919};
        const uint32_t n = uint32_t(g.positions.size()) - 12;  // not the far cluster
        for (size_t triangles : {size_t(1), size_t(5), g.indices.size() / 3 / 4, g.indices.size() / 3 / 2}) {
            std::vector<uint32_t> s;
            // Mostly a subset of the gathered triangles (points on the surface), plus random
            // triangles across the main surface (points off it, raising the maximum query after
            // query).
            for (size_t t = 0; t < triangles; ++t) {
                if (t % 4 == 3) {
                    s.insert(s.end(), {random.below(n), random.below(n), random.below(n)});
                } else {
                    const size_t k = 3 * random.below(uint32_t(g.indices.size() / 3));
                    s.insert(s.end(), {g.indices[k], g.indices[k + 1], g.indices[k + 2]});
                }
            }
            // The far cluster kept as it is (its vertices removed, their exact searches would
            // sweep the whole grid).
            s.insert(s.end(), g.indices.end() - 30, g.indices.end());
            EXPECT_EQ(measured_simplification_error(g, s), brute_force_error_exact(g, s)) << triangles << " triangles";
        }
    }
}

TEST(MeasuredError, NothingRemovedIsZero) {
    WorkFragment g = height_field(8, 1.0, 7, 1000.0);
    EXPECT_EQ(measured_simplification_error(g, g.indices), 0.0);
}

// lost_geometry_reach: the converter's bound for a node that draws nothing rests on every piece
// of its geometry reaching an outer face of the diamond (the surface then goes on into a
// neighbour); a piece alone inside must be reported, and the diameter must cover the geometry.
TEST(LostGeometryReach, APieceAloneInsideIsNotAnchoredAndOneOnAnOuterFaceIs) {
    const DiamondInfo d = diamond_info(root_diamond());
    const Tetrahedron t = diamond_tetrahedron(d, 0);
    auto point = [](const LatticePoint& p, const LatticePoint& q, double wp) {
        return Vec3d{wp * p[0] + (1 - wp) * q[0], wp * p[1] + (1 - wp) * q[1], wp * p[2] + (1 - wp) * q[2]};
    };
    Vec3d centre{0, 0, 0};
    for (const LatticePoint& c : t)
        for (int a = 0; a < 3; ++a) centre[a] += 0.25 * c[a];
    const Vec3d near_centre = point(t[0], LatticePoint{int32_t(centre[0]), int32_t(centre[1]), int32_t(centre[2])}, 0.25);
    const Vec3d on_face = point(t[0], t[2], 0.5);  // the middle of edge (A, ring 0): on outer face (A, r0, r1)

    WorkFragment alone;
    alone.positions = {centre, near_centre, point(t[1], LatticePoint{int32_t(centre[0]), int32_t(centre[1]), int32_t(centre[2])}, 0.25)};
    alone.indices = {0, 1, 2};
    std::array<const WorkFragment*, 8> slots{};
    slots[0] = &alone;
    EXPECT_FALSE(lost_geometry_reach(d, slots).anchored);

    WorkFragment reaching = alone;
    reaching.positions[2] = on_face;
    slots[0] = &reaching;
    LostGeometryReach reach = lost_geometry_reach(d, slots);
    EXPECT_TRUE(reach.anchored);
    double d2 = 0;
    for (int a = 0; a < 3; ++a) d2 += (on_face[a] - centre[a]) * (on_face[a] - centre[a]);
    EXPECT_GE(reach.diameter, std::sqrt(d2));

    // Both in one node: a lone piece (apart from the other) still has nothing near it.
    WorkFragment apart = alone;
    for (Vec3d& v : apart.positions)
        for (double& c : v) c *= 0.5;  // towards B, the origin: no position shared
    slots[1] = &apart;
    EXPECT_FALSE(lost_geometry_reach(d, slots).anchored);
}
