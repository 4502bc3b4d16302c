#pragma once
// The regular conformal tetrahedral hierarchy, addressed implicitly.
//
// Space is the root cube [0, 2^kLatticeBits]^3 in integer lattice coordinates, split into six
// tetrahedra around its main diagonal (Kuhn) and refined by longest-edge bisection. A *diamond*
// is the set of tetrahedra that share a longest edge (the *spine*); it is identified by the
// lattice coordinates of the spine midpoint (its *centre*), so parents, children, spine, ring
// and tetrahedra are all computed from the centre, never stored.
//
// Let t be the largest power of two dividing all three centre coordinates, and k the number of
// coordinates that are odd multiples of t:
//   k = 3  cube diamond: the centre of a cube of side 2t; spine = a main diagonal; 6 tetrahedra
//   k = 2  face diamond: the centre of a square of side 2t; spine = a face diagonal; 4 tetrahedra
//   k = 1  edge diamond: the midpoint of an axis edge of length 2t; spine = that edge; 8 tetrahedra
// Level = 3 * octave + (3 - k), octave = kLatticeBits - 1 - log2(t): the root cube diamond is
// level 0, and the spines get shorter at every level (2t*sqrt3 > 2t*sqrt2 > 2t > t*sqrt3 ...).
// The spine runs from A = c + d to B = c - d, where d_i = +-t on the odd coordinates (0 on the
// others) with the sign chosen so that A_i = 2t (mod 4t): every sub-cube's diagonal passes
// through the centre of its parent cube, which is what longest-edge bisection of the Kuhn cube
// produces (tests/catp/test_lattice.cpp checks this against explicit bisection).
//
// Near the root cube's boundary diamonds are partial: only tetrahedra inside the cube exist.
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "common_codec/barycentric.h"

namespace catpaq {

constexpr int kLatticeBits = 20;  // lattice coordinates are 0 .. 2^20 (21 bits each in a DiamondId)
constexpr int32_t kLatticeSize = int32_t(1) << kLatticeBits;
constexpr int kMaxLevel = 3 * (kLatticeBits - 1) + 2;  // edge diamonds with t = 1
static_assert(kLatticeSize <= (1 << 22), "barycentric decode needs lattice coordinates below 2^22");

// A diamond, by the lattice coordinates of its centre packed into 63 bits (21 per axis, which holds 0 .. 2^20 inclusive).
struct DiamondId {
    uint64_t bits = 0;

    static DiamondId from_centre(const LatticePoint& c) {
        return DiamondId{uint64_t(uint32_t(c[0])) | (uint64_t(uint32_t(c[1])) << 21) | (uint64_t(uint32_t(c[2])) << 42)};
    }
    LatticePoint centre() const {
        return {int32_t(bits & 0x1fffff), int32_t((bits >> 21) & 0x1fffff), int32_t((bits >> 42) & 0x1fffff)};
    }
    bool operator==(const DiamondId& o) const { return bits == o.bits; }
    bool operator!=(const DiamondId& o) const { return bits != o.bits; }
    bool operator<(const DiamondId& o) const { return bits < o.bits; }
};

struct DiamondIdHash {
    size_t operator()(DiamondId id) const { return size_t(id.bits * 0x9E3779B97F4A7C15ull >> 1); }
};

enum class DiamondClass : uint8_t { Cube = 0, Face = 1, Edge = 2 };

// A tetrahedron as its four corners: spine endpoints A, B, then two consecutive ring vertices.
using Tetrahedron = std::array<LatticePoint, 4>;

struct DiamondInfo {
    DiamondId id;
    LatticePoint centre;
    int32_t scale = 0;  // t
    int level = 0;
    DiamondClass cls = DiamondClass::Cube;
    LatticePoint spine_a, spine_b;
    // Cyclic ring of 6 / 4 / 8 vertices (some may be outside the cube). A fixed array, so that
    // diamond_info() never allocates: it is called on hot paths of the converter and the client.
    std::array<LatticePoint, 8> ring{};
    int ring_size = 0;
};

DiamondId root_diamond();
bool is_valid_diamond_centre(const LatticePoint& c);  // inside the cube, not a corner of the grid
bool inside_root_cube(const LatticePoint& p);

DiamondInfo diamond_info(DiamondId id);
int diamond_level(DiamondId id);

// Tetrahedron `slot` of the diamond: (A, B, ring[slot], ring[slot + 1 mod n]). The slot exists if
// all four corners lie inside the root cube. Slots are numbered 0 .. ring size - 1 (< 8).
Tetrahedron diamond_tetrahedron(const DiamondInfo& d, int slot);
bool tetrahedron_exists(const Tetrahedron& t);
// The normal of face f of t (the face opposite corner f: corners f+1, f+2, f+3 mod 4), not
// normalized: (t[f+2] - t[f+1]) x (t[f+3] - t[f+1]) in double. Its sign follows the corners'
// order, not the side the tetrahedron is on.
std::array<double, 3> face_normal(const Tetrahedron& t, int f);
// Bit mask of the slots that exist.
uint8_t existing_slots(const DiamondInfo& d);

// Parents (diamonds whose refinement creates this diamond's tetrahedra) and children (diamonds
// created by refining this one), restricted to the root cube. Order is deterministic.
std::vector<DiamondId> diamond_parents(DiamondId id);
std::vector<DiamondId> diamond_children(DiamondId id);

// The parent diamond whose refinement creates tetrahedron `slot`: the ring vertex of the slot
// that is a parent centre. Undefined for the root.
DiamondId slot_parent(const DiamondInfo& d, int slot);

// The two tetrahedra a tetrahedron of diamond d splits into when d is refined:
// (A, c, r0, r1) and (c, B, r0, r1).
std::array<Tetrahedron, 2> split_tetrahedron(const DiamondInfo& d, int slot);

// The diamond a tetrahedron belongs to: the one whose spine is the tetrahedron's longest edge.
// Also returns the slot. Returns false if the tetrahedron is not one of the hierarchy.
bool tetrahedron_diamond(const Tetrahedron& t, DiamondId& id, int& slot);

// Canonical (lexicographically sorted) corners, used as the key of a tetrahedron and for
// barycentric quantization.
Tetrahedron canonical_tetrahedron(const Tetrahedron& t);

}  // namespace catpaq
