#pragma once
// Routing triangles to the leaf tetrahedra of the hierarchy they may overlap (private to the
// catp module): the converter sends every input triangle to those leaves, and the exact clipper
// then cuts it into each of them. Extra leaves only cost clipping time (the clipper rejects
// them); a missed leaf would lose geometry.
//
// Leaves of level 3k + r (r = 0..2) tile the cubes of octave k, each cube in 6 tetrahedra
// bisected r times. The routing works in one cube's local coordinates, where every cube looks
// the same, with leaf shapes and keys precomputed once:
// - the fast path locates the leaf containing the triangle's first corner (the cube by integer
//   division, the cube's tetrahedron by ordering the local coordinates, then at most 4
//   candidates) and, if the whole triangle is strictly inside it, reports that leaf alone.
//   That is 91.5% of the triangles of a 1M-triangle scan at leaf level 10 (a leaf holds about
//   2000 triangles; the others cross or touch a leaf face);
// - the others walk the cubes the triangle's box touches and descend each cube's tetrahedra,
//   pruning with a conservative separation test (as the converter did for every triangle).
// Routing alone on the 1M scan (leaf level 10): 12.7x faster than the general search for every
// triangle (0.59 s -> 0.047 s of CPU time for 1M triangles).
#include <cstdint>
#include <type_traits>
#include <vector>

#include "catp/lattice.h"
#include "mesh/mesh.h"
#include "spill.h"

namespace catpaq {

// A block: one cube of the lattice at octave `octave` (side 2^20 >> octave), by integer index.
struct BlockCube {
    int octave = 0;
    int32_t index[3] = {0, 0, 0};
    uint64_t key() const { return uint64_t(index[0]) | (uint64_t(index[1]) << 21) | (uint64_t(index[2]) << 42); }
    static BlockCube from_key(int octave, uint64_t key) {
        BlockCube b;
        b.octave = octave;
        for (int i = 0; i < 3; ++i) b.index[i] = int32_t((key >> (21 * i)) & 0x1fffff);
        return b;
    }
};

// Longest-edge bisection of a tetrahedron given by its corners: c0 keeps the first corner of the
// longest edge, c1 the second; the edge's midpoint replaces the other one.
void bisect(const Tetrahedron& t, Tetrahedron& c0, Tetrahedron& c1);

// Conservative rejection: true if all points are strictly outside one face (with a margin, so
// floating-point error can only make it keep a tetrahedron that the exact clipper then rejects).
bool separated(const Tetrahedron& t, const Vec3d* pts, int count);

// Conservative acceptance: true if all points are strictly inside every face (with the same
// margin, so floating-point error can only make it answer false).
bool strictly_inside(const Tetrahedron& t, const Vec3d* pts, int count);

// Index range of the cubes of side `side` that the points' bounding box may touch. ceil - 1, not
// floor: geometry exactly on a cube boundary plane belongs to both cubes (a triangle lying in that
// plane is kept by exactly one of them, by the coplanar rule).
void cube_range(const Vec3d* pts, int count, int32_t side, int32_t lo[3], int32_t hi[3]);

// The key of a tetrahedron of the hierarchy, its diamond and slot, from its corners (general:
// finds the diamond from the longest edge, about 0.2 us).
SlotKey slot_key(const Tetrahedron& t);

// The fast path alone: if the triangle lies strictly inside one tetrahedron of `level` inside
// the block cube `within`, sets `key` to it and returns true. False means "unknown" (the
// triangle crosses or touches a face of that tetrahedron, or floating-point error could hide
// that it does).
bool single_leaf(const Vec3d tri[3], int level, const BlockCube& within, SlotKey& key);

// Where the routing sends the keys: a reference to any callable taking a SlotKey (no allocation,
// and the routing code stays out of the header). The callable must outlive the call.
class SlotSink {
public:
    template <typename F>
        requires(!std::is_same_v<std::remove_cvref_t<F>, SlotSink>)
    SlotSink(F&& f)  // NOLINT: implicit, so a lambda can be passed directly
        : object_(const_cast<void*>(static_cast<const void*>(&f))),
          call_([](void* object, SlotKey key) { (*static_cast<std::remove_reference_t<F>*>(object))(key); }) {}
    void operator()(SlotKey key) const { call_(object_, key); }

private:
    void* object_;
    void (*call_)(void*, SlotKey);
};

// Calls sink(key) for every tetrahedron of `level` inside the block cube `within` (its octave at
// most level / 3) that the triangle may overlap, each once: the fast path's one leaf, or the
// leaves the conservative search keeps.
void for_each_leaf_slot(const Vec3d tri[3], int level, const BlockCube& within, SlotSink sink);

// for_each_leaf_slot's general search alone: for a triangle that single_leaf has already failed
// to place (the converter tries single_leaf first; trying it again cost 1% of the leaf phase).
void search_leaf_slots(const Vec3d tri[3], int level, const BlockCube& within, SlotSink sink);

// A leaf tetrahedron that routing sends a triangle (numbered by the caller: a block's record)
// to. whole: the triangle lies strictly inside the leaf (single_leaf), so clipping would keep it
// as it is: it is added without the clipper.
struct LeafHit {
    SlotKey key;
    uint32_t triangle;
    bool whole;
};

// Routed triangles grouped by leaf, each leaf's hits in triangle (input) order: the order in
// which its fragment must receive them, since the fragment's vertex and triangle order follow
// it. The leaves come in order of first appearance.
//
// A counting sort on leaves numbered as they appear. The hits arrive nearly grouped already
// (consecutive triangles mostly go to the same leaf), so numbering them costs little more than
// one pass: tbb::parallel_sort of the hits by (key, triangle) took 14% of the converter's leaf
// phase (perf, 10M scan) and this a tenth of that (weld_bench: route column).
class LeafGroups {
public:
    struct Entry {
        uint32_t triangle;
        bool whole;
    };

    // Groups the hits: the concatenation of `parts`, in triangle order. Keeps the memory for
    // the next call (fresh memory costs page faults).
    void build(const std::vector<std::vector<LeafHit>>& parts);

    size_t size() const { return keys_.size(); }
    const SlotKey& key(size_t g) const { return keys_[g]; }
    const Entry* begin(size_t g) const { return entries_.data() + start_[g]; }
    const Entry* end(size_t g) const { return entries_.data() + start_[g + 1]; }

private:
    uint32_t number(const SlotKey& key);  // the leaf's number: the next one when it is new
    void rehash(size_t capacity);         // a power of two

    std::vector<SlotKey> keys_;    // by leaf number
    std::vector<uint32_t> table_;  // open addressing: leaf number + 1, 0 = empty
    uint32_t last_ = UINT32_MAX;   // the previous hit's leaf
    std::vector<uint32_t> leaf_of_hit_, fill_;
    std::vector<size_t> start_;    // group g: entries_[start_[g], start_[g + 1])
    std::vector<Entry> entries_;
};

}  // namespace catpaq
