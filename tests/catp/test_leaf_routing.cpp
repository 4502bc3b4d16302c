// Leaf routing (catp/src/leaf_routing.h) must send every triangle to the same leaves as the
// converter's original search did, as far as the output can tell: a leaf counts when the exact
// clipper leaves a polygon of at least three corners in it (FragmentWelder::add_clipped ignores
// anything less). The reference is that original search (below: it walks the cubes the box
// touches and descends by explicit bisection, rejecting with separated()), filtered by the clip.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <vector>

#include "../../catp/src/clip.h"
#include "../../catp/src/fragment_build.h"
#include "../../catp/src/leaf_routing.h"

using namespace catpaq;

namespace {

using Triangle = std::array<Vec3d, 3>;

// The reference: every tetrahedron of `level` in block `within` that the points may overlap.
template <typename F>
void reference_search(const Vec3d* pts, int level, const BlockCube& within, F&& f) {
    int octave = level / 3;
    int32_t side = kLatticeSize >> octave;
    int32_t lo[3], hi[3];
    cube_range(pts, 3, side, lo, hi);
    int32_t per_block = int32_t(1) << (octave - within.octave);
    for (int i = 0; i < 3; ++i) {
        lo[i] = std::max(lo[i], within.index[i] * per_block);
        hi[i] = std::min(hi[i], within.index[i] * per_block + per_block - 1);
    }
    for (int32_t z = lo[2]; z <= hi[2]; ++z)
        for (int32_t y = lo[1]; y <= hi[1]; ++y)
            for (int32_t x = lo[0]; x <= hi[0]; ++x) {
                LatticePoint centre = {x * side + side / 2, y * side + side / 2, z * side + side / 2};
                DiamondInfo cube = diamond_info(DiamondId::from_centre(centre));
                std::vector<std::pair<Tetrahedron, int>> stack;
                for (int s = 0; s < 6; ++s) stack.push_back({diamond_tetrahedron(cube, s), 3 * octave});
                while (!stack.empty()) {
                    auto [t, l] = stack.back();
                    stack.pop_back();
                    if (separated(t, pts, 3)) continue;
                    if (l == level) {
                        f(t);
                        continue;
                    }
                    Tetrahedron a, b;
                    bisect(t, a, b);
                    stack.push_back({a, l + 1});
                    stack.push_back({b, l + 1});
                }
            }
}

// Onto the clipper's 2^-32 grid and into the root cube, as the converter's positions are.
Vec3d snapped(Vec3d p) {
    for (double& v : p) v = std::clamp(snap_to_grid(v), 0.0, double(kLatticeSize));
    return p;
}

Tetrahedron key_tetrahedron(const SlotKey& key) { return diamond_tetrahedron(diamond_info(DiamondId{key.diamond}), key.slot); }

// A random tetrahedron of `level`: a random cube of the level's octave, one of its six
// tetrahedra, then random children.
Tetrahedron random_leaf(int level, std::mt19937_64& rng) {
    int octave = level / 3;
    int32_t side = kLatticeSize >> octave;
    std::uniform_int_distribution<int32_t> cube(0, (kLatticeSize / side) - 1);
    LatticePoint centre = {cube(rng) * side + side / 2, cube(rng) * side + side / 2, cube(rng) * side + side / 2};
    Tetrahedron t = diamond_tetrahedron(diamond_info(DiamondId::from_centre(centre)), int(rng() % 6));
    for (int l = 3 * octave; l < level; ++l) {
        Tetrahedron c0, c1;
        bisect(t, c0, c1);
        t = rng() % 2 ? c1 : c0;
    }
    return t;
}

// A point of the tetrahedron by barycentric weights (normalised here).
Vec3d barycentric_point(const Tetrahedron& t, std::array<double, 4> w) {
    double sum = w[0] + w[1] + w[2] + w[3];
    Vec3d p{0, 0, 0};
    for (int k = 0; k < 4; ++k)
        for (int i = 0; i < 3; ++i) p[i] += w[k] / sum * t[k][i];
    return p;
}

double longest_edge(const Tetrahedron& t) {
    double best = 0;
    for (int a = 0; a < 4; ++a)
        for (int b = a + 1; b < 4; ++b) {
            double l = 0;
            for (int i = 0; i < 3; ++i) l += double(t[a][i] - t[b][i]) * double(t[a][i] - t[b][i]);
            best = std::max(best, std::sqrt(l));
        }
    return best;
}

// Triangles of the kinds where routing can go wrong, around a random leaf of `level`.
Triangle random_triangle(int level, std::mt19937_64& rng) {
    std::uniform_real_distribution<double> unit(0, 1);
    Tetrahedron t = random_leaf(level, rng);
    double size = longest_edge(t);
    const double nudges[] = {0, kSnapGrid, 1e-9, 1e-7, 1e-6, 1e-5, 1e-3, 0.1};
    auto nudge = [&] { return nudges[rng() % 8] * (rng() % 2 ? 1 : -1); };
    auto inside = [&] { return barycentric_point(t, {unit(rng), unit(rng), unit(rng), unit(rng)}); };
    Triangle tri;
    switch (rng() % 6) {
        case 0: {  // small, somewhere in the leaf (the common case: the fast path)
            Vec3d c = inside();
            double r = size * std::pow(10.0, -3.0 * unit(rng));
            for (Vec3d& p : tri)
                for (int i = 0; i < 3; ++i) p[i] = c[i] + r * (unit(rng) - 0.5);
            break;
        }
        case 1: {  // on or near a face plane of the leaf (bisection planes, cube faces, Kuhn planes)
            int f = int(rng() % 4);
            for (Vec3d& p : tri) {
                std::array<double, 4> w = {unit(rng), unit(rng), unit(rng), unit(rng)};
                w[f] = 0;
                p = barycentric_point(t, w);
                if (rng() % 2)
                    for (double& v : p) v += nudge();
            }
            break;
        }
        case 2: {  // corners at or next to the leaf's corners and edge midpoints
            for (Vec3d& p : tri) {
                int a = int(rng() % 4), b = int(rng() % 4);
                for (int i = 0; i < 3; ++i) p[i] = 0.5 * (t[a][i] + t[b][i]) + nudge();
            }
            break;
        }
        case 3: {  // near an axis-aligned lattice plane of the leaf's scale
            tri = {inside(), inside(), inside()};
            int axis = int(rng() % 3);
            double step = std::max(1.0, size / 4);
            double plane = std::round(tri[0][axis] / step) * step;
            for (Vec3d& p : tri)
                if (rng() % 3) p[axis] = plane + nudge();
            break;
        }
        case 4: {  // spanning several leaves
            Vec3d c = inside();
            for (Vec3d& p : tri)
                for (int i = 0; i < 3; ++i) p[i] = c[i] + 3 * size * (unit(rng) - 0.5);
            break;
        }
        default:  // anywhere in the leaf, large
            tri = {inside(), inside(), inside()};
    }
    for (Vec3d& p : tri) p = snapped(p);
    return tri;
}

// All descendants of t that are `depth` bisections below it.
std::vector<Tetrahedron> descendants(const Tetrahedron& t, int depth) {
    if (depth == 0) return {t};
    Tetrahedron c0, c1;
    bisect(t, c0, c1);
    std::vector<Tetrahedron> out = descendants(c0, depth - 1), more = descendants(c1, depth - 1);
    out.insert(out.end(), more.begin(), more.end());
    return out;
}

// The clip that decides the output: does the triangle leave at least three polygon corners in
// the tetrahedron?
bool reaches(const Triangle& tri, const SlotKey& key) {
    std::vector<ClipVertex> polygon;
    clip_triangle(tri, tetrahedron_clip_planes(key_tetrahedron(key), 0xf), polygon);
    return polygon.size() >= 3;
}

struct Counts {
    size_t triangles = 0, fast = 0, reached = 0;
};

// Compares the routing with the filtered general search for one triangle in one block.
void check_block(const Triangle& tri, int level, const BlockCube& block, Counts& counts) {
    std::set<SlotKey> general, routed;
    reference_search(tri.data(), level, block, [&](const Tetrahedron& t) { general.insert(slot_key(t)); });
    size_t calls = 0;
    for_each_leaf_slot(tri.data(), level, block, [&](SlotKey key) {
        routed.insert(key);
        ++calls;
    });
    ASSERT_EQ(calls, routed.size()) << "a leaf reported twice";
    SlotKey fast_key;
    bool fast = single_leaf(tri.data(), level, block, fast_key);
    counts.triangles++;
    counts.fast += fast;
    if (fast) {
        ASSERT_EQ(calls, 1u);
        ASSERT_TRUE(routed.count(fast_key));
    }
    // Leaves the reference does not report must not matter: the triangle does not reach them.
    for (const SlotKey& key : routed) {
        if (!general.count(key)) {
            ASSERT_FALSE(reaches(tri, key)) << "level " << level << ": the reference misses a leaf";
        }
    }
    for (const SlotKey& key : general) {
        if (!reaches(tri, key)) continue;
        counts.reached++;
        ASSERT_TRUE(routed.count(key)) << "level " << level << " block octave " << block.octave
                                       << ": leaf missed, triangle (" << tri[0][0] << " " << tri[0][1] << " "
                                       << tri[0][2] << ") (" << tri[1][0] << " " << tri[1][1] << " " << tri[1][2]
                                       << ") (" << tri[2][0] << " " << tri[2][1] << " " << tri[2][2] << ")";
    }
}

// Checks one triangle in every block of `block_octave` its box touches (as the converter bins
// it), and in a neighbouring block it does not touch (which it reaches no leaf of, and where the
// fast path must not answer).
void check_triangle(const Triangle& tri, int level, int block_octave, Counts& counts) {
    int32_t block_side = kLatticeSize >> block_octave, blocks = kLatticeSize / block_side;
    int32_t lo[3], hi[3];
    cube_range(tri.data(), 3, block_side, lo, hi);
    BlockCube block;
    block.octave = block_octave;
    for (block.index[2] = lo[2]; block.index[2] <= hi[2]; ++block.index[2])
        for (block.index[1] = lo[1]; block.index[1] <= hi[1]; ++block.index[1])
            for (block.index[0] = lo[0]; block.index[0] <= hi[0]; ++block.index[0]) {
                check_block(tri, level, block, counts);
                if (::testing::Test::HasFatalFailure()) return;
            }
    BlockCube other = block;
    for (int i = 0; i < 3; ++i) other.index[i] = lo[i];
    other.index[0] = hi[0] + 1 < blocks ? hi[0] + 1 : lo[0] - 1;
    if (other.index[0] < 0) return;
    size_t before = counts.fast;
    check_block(tri, level, other, counts);
    ASSERT_EQ(counts.fast, before) << "the fast path reported a leaf outside the block";
}

}  // namespace

// Every leaf of every cube of several octaves and all parity patterns: a small triangle at its
// centroid takes the fast path and gets the key the general slot_key() computes.
TEST(LeafRouting, FastPathFindsEveryLeafOfEveryCubeParityWithItsKey) {
    for (int level = 0; level <= 14; ++level) {
        int octave = level / 3;
        int32_t side = kLatticeSize >> octave;
        int32_t cubes = std::min(4, kLatticeSize / side);
        BlockCube root;  // octave 0: the whole lattice
        for (int32_t z = 0; z < cubes; ++z)
            for (int32_t y = 0; y < cubes; ++y)
                for (int32_t x = 0; x < cubes; ++x) {
                    LatticePoint centre = {x * side + side / 2, y * side + side / 2, z * side + side / 2};
                    DiamondInfo cube = diamond_info(DiamondId::from_centre(centre));
                    for (int s = 0; s < 6; ++s)
                        for (const Tetrahedron& leaf : descendants(diamond_tetrahedron(cube, s), level - 3 * octave)) {
                            Vec3d c = barycentric_point(leaf, {1, 1, 1, 1});
                            Triangle tri;
                            for (int k = 0; k < 3; ++k)
                                for (int i = 0; i < 3; ++i) tri[k][i] = c[i] + (i == k ? 1e-3 : 0.0);
                            for (Vec3d& p : tri) p = snapped(p);
                            SlotKey key;
                            ASSERT_TRUE(single_leaf(tri.data(), level, root, key)) << "level " << level;
                            SlotKey expected = slot_key(leaf);
                            ASSERT_EQ(key.diamond, expected.diamond) << "level " << level;
                            ASSERT_EQ(key.slot, expected.slot) << "level " << level;
                        }
                }
    }
}

// Random triangles of the hard kinds (small, on and near leaf faces and lattice planes, at
// corners, spanning several leaves) at many leaf and block levels: the routing reaches the same
// leaves as the reference search, so the converter's output cannot change.
TEST(LeafRouting, HardTrianglesReachTheSameLeavesAsTheReferenceSearch) {
    std::mt19937_64 rng(7);
    Counts total;
    for (int level : {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 20, 31, 45, 55, 56}) {
        for (int n = 0; n < 1500; ++n) {
            Triangle tri = random_triangle(level, rng);
            int block_octave = int(rng() % (level / 3 + 1));
            check_triangle(tri, level, block_octave, total);
            if (HasFatalFailure()) return;
        }
    }
    // Both paths are exercised (seed 7: 13500 fast of 83687 checks), and the triangles do reach
    // leaves (250454 reached leaves).
    EXPECT_GT(total.fast, total.triangles / 10);
    EXPECT_GT(total.fast, 0u);
    EXPECT_LT(total.fast, total.triangles);
    EXPECT_GT(total.reached, total.triangles);
}
