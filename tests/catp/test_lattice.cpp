// The implicit diamond hierarchy (catp/lattice.h) against explicit longest-edge bisection of the
// six Kuhn tetrahedra of the root cube.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <set>

#include "catp/lattice.h"

using namespace catpaq;

namespace {

std::vector<Tetrahedron> root_tetrahedra() {
    const int32_t S = kLatticeSize;
    std::vector<Tetrahedron> out;
    int perm[3] = {0, 1, 2};
    do {
        LatticePoint p0{0, 0, 0}, p1 = p0, p2, p3{S, S, S};
        p1[perm[0]] = S;
        p2 = p1;
        p2[perm[1]] = S;
        out.push_back({p0, p3, p1, p2});
    } while (std::next_permutation(perm, perm + 3));
    return out;
}

int64_t len2(const LatticePoint& a, const LatticePoint& b) {
    int64_t s = 0;
    for (int i = 0; i < 3; ++i) s += int64_t(a[i] - b[i]) * (a[i] - b[i]);
    return s;
}

// Explicit longest-edge bisection: returns the two children, or false if the edge is not unique.
bool bisect(const Tetrahedron& t, std::array<Tetrahedron, 2>& out) {
    int a = 0, b = 1;
    int64_t best = -1;
    int count = 0;
    for (int i = 0; i < 4; ++i)
        for (int j = i + 1; j < 4; ++j) {
            int64_t l = len2(t[i], t[j]);
            if (l > best) { best = l; a = i; b = j; count = 1; }
            else if (l == best) ++count;
        }
    if (count != 1) return false;
    LatticePoint m;
    for (int k = 0; k < 3; ++k) m[k] = (t[a][k] + t[b][k]) / 2;
    out[0] = t;
    out[0][b] = m;
    out[1] = t;
    out[1][a] = m;
    return true;
}

std::set<LatticePoint> as_set(const Tetrahedron& t) { return {t.begin(), t.end()}; }

}  // namespace

TEST(Lattice, RootDiamondHoldsTheSixKuhnTetrahedra) {
    DiamondInfo root = diamond_info(root_diamond());
    EXPECT_EQ(root.level, 0);
    EXPECT_EQ(root.cls, DiamondClass::Cube);
    EXPECT_EQ(existing_slots(root), 0x3f);
    EXPECT_TRUE(diamond_parents(root.id).empty());
    std::set<std::set<LatticePoint>> expected, got;
    for (auto& t : root_tetrahedra()) expected.insert(as_set(t));
    for (int s = 0; s < 6; ++s) got.insert(as_set(diamond_tetrahedron(root, s)));
    EXPECT_EQ(expected, got);
}

TEST(Lattice, ImplicitDiamondsMatchExplicitLongestEdgeBisectionForTwelveLevels) {
    std::vector<Tetrahedron> generation = root_tetrahedra();
    for (int level = 0; level < 12; ++level) {
        // Every tetrahedron has a unique longest edge and belongs to a diamond of this level.
        std::map<DiamondId, std::set<int>> slots_seen;
        std::map<std::set<LatticePoint>, int> faces;
        std::vector<Tetrahedron> next;
        for (const Tetrahedron& t : generation) {
            DiamondId id;
            int slot;
            ASSERT_TRUE(tetrahedron_diamond(t, id, slot)) << "level " << level;
            DiamondInfo d = diamond_info(id);
            ASSERT_EQ(d.level, level);
            ASSERT_EQ(as_set(diamond_tetrahedron(d, slot)), as_set(t));
            slots_seen[id].insert(slot);
            for (int skip = 0; skip < 4; ++skip) {
                std::set<LatticePoint> face;
                for (int k = 0; k < 4; ++k)
                    if (k != skip) face.insert(t[k]);
                faces[face]++;
            }
            std::array<Tetrahedron, 2> explicit_children;
            ASSERT_TRUE(bisect(t, explicit_children));
            std::array<Tetrahedron, 2> implicit_children = split_tetrahedron(d, slot);
            std::set<std::set<LatticePoint>> e{as_set(explicit_children[0]), as_set(explicit_children[1])};
            std::set<std::set<LatticePoint>> i{as_set(implicit_children[0]), as_set(implicit_children[1])};
            ASSERT_EQ(e, i);
            std::vector<DiamondId> children = diamond_children(id);
            for (const Tetrahedron& child : explicit_children) {
                DiamondId cid;
                int cslot;
                ASSERT_TRUE(tetrahedron_diamond(child, cid, cslot))
                    << "level " << level << " child " << child[0][0] << "," << child[0][1] << "," << child[0][2] << " "
                    << child[1][0] << "," << child[1][1] << "," << child[1][2] << " " << child[2][0] << ","
                    << child[2][1] << "," << child[2][2] << " " << child[3][0] << "," << child[3][1] << ","
                    << child[3][2];
                ASSERT_NE(std::find(children.begin(), children.end(), cid), children.end());
                // The child tetrahedron is created by refining exactly this diamond.
                ASSERT_EQ(slot_parent(diamond_info(cid), cslot), id);
                std::vector<DiamondId> parents = diamond_parents(cid);
                ASSERT_NE(std::find(parents.begin(), parents.end(), id), parents.end());
                next.push_back(child);
            }
        }
        // Uniform refinement is conforming: interior faces are shared by exactly two tetrahedra,
        // faces on the root cube boundary belong to one.
        for (auto& [face, count] : faces) {
            bool on_boundary = false;
            for (int axis = 0; axis < 3 && !on_boundary; ++axis) {
                bool all_lo = true, all_hi = true;
                for (auto& p : face) {
                    all_lo &= p[axis] == 0;
                    all_hi &= p[axis] == kLatticeSize;
                }
                on_boundary = all_lo || all_hi;
            }
            ASSERT_EQ(count, on_boundary ? 1 : 2);
        }
        // Each diamond of the level has exactly its existing slots, and its children list holds
        // exactly the diamonds its tetrahedra split into.
        for (auto& [id, slots] : slots_seen) {
            DiamondInfo d = diamond_info(id);
            uint8_t mask = 0;
            for (int s : slots) mask |= uint8_t(1 << s);
            ASSERT_EQ(mask, existing_slots(d)) << "level " << level;
            std::set<DiamondId> from_splits;
            for (int s : slots)
                for (const Tetrahedron& child : split_tetrahedron(d, s)) {
                    DiamondId cid;
                    int cslot;
                    ASSERT_TRUE(tetrahedron_diamond(child, cid, cslot));
                    from_splits.insert(cid);
                }
            std::vector<DiamondId> listed = diamond_children(id);
            ASSERT_EQ(from_splits, std::set<DiamondId>(listed.begin(), listed.end()));
        }
        generation = std::move(next);
    }
}

TEST(Lattice, DiamondIdRoundTripsItsCentre) {
    LatticePoint c{12345, kLatticeSize - 1, 1};
    EXPECT_EQ(DiamondId::from_centre(c).centre(), c);
}

TEST(Lattice, DiamondClassesHaveTheirTetrahedronCounts) {
    // An interior diamond of each class: 6, 4 and 8 tetrahedra.
    const int32_t t = 1 << 10, q = 4 * t * 8;  // away from the boundary
    DiamondInfo cube = diamond_info(DiamondId::from_centre({q + t, q + t, q + t}));
    DiamondInfo face = diamond_info(DiamondId::from_centre({q + t, q + t, q}));
    DiamondInfo edge = diamond_info(DiamondId::from_centre({q + t, q, q}));
    EXPECT_EQ(cube.cls, DiamondClass::Cube);
    EXPECT_EQ(existing_slots(cube), 0x3f);
    EXPECT_EQ(face.cls, DiamondClass::Face);
    EXPECT_EQ(existing_slots(face), 0x0f);
    EXPECT_EQ(edge.cls, DiamondClass::Edge);
    EXPECT_EQ(existing_slots(edge), 0xff);
    EXPECT_EQ(diamond_parents(cube.id).size(), 3u);
    EXPECT_EQ(diamond_parents(face.id).size(), 2u);
    EXPECT_EQ(diamond_parents(edge.id).size(), 4u);
    EXPECT_EQ(diamond_children(cube.id).size(), 6u);
    EXPECT_EQ(diamond_children(face.id).size(), 4u);
    EXPECT_EQ(diamond_children(edge.id).size(), 8u);
}
