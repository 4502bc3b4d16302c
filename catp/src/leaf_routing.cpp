#include "leaf_routing.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>

namespace catpaq {

namespace {

int64_t len2(const LatticePoint& a, const LatticePoint& b) {
    int64_t s = 0;
    for (int i = 0; i < 3; ++i) s += int64_t(a[i] - b[i]) * (a[i] - b[i]);
    return s;
}

// ----------------------------------------------------------------------------------------------
// The fast path's geometry. A cube of octave k is cut into 6 tetrahedra (Kuhn) around its spine
// from B (the corner with even index coordinates, in units of the side) to A (odd ones), as
// lattice.h describes, and those are bisected 0 to 2 times down to the leaves of level 3k + r.
//
// Local coordinates u_i = (p_i - B_i) * (A_i > B_i ? 1 : -1) run from 0 at B to `side` at A.
// Reflecting the axes so maps every cube's tetrahedra onto the same shapes (longest-edge
// bisection commutes with reflections), so one set of leaf shapes in u serves every cube; only
// the leaves' keys depend on the cube, through its parity pattern (index mod 2 per axis).
// In u, slot s of the cube diamond is the region of one ordering of (u0, u1, u2): the ring
// {P0, Q2, P1, Q0, P2, Q1} (P_i: A with coordinate i from B; Q_i: B with coordinate i from A)
// steps one axis at a time from B to A through ring[s + 1], ring[s].

// The spine corners of cube `index` (octave side `side`): A_i = 2t (mod 4t) with t = side / 2.
void cube_spine(const int32_t index[3], int32_t side, LatticePoint& a, LatticePoint& b) {
    for (int i = 0; i < 3; ++i) {
        int32_t lo = index[i] * side;
        bool odd = index[i] & 1;
        a[i] = odd ? lo : lo + side;
        b[i] = odd ? lo + side : lo;
    }
}

// Tetrahedron `slot` of the cube diamond, with the corners in diamond_tetrahedron's order.
Tetrahedron cube_tetrahedron(const int32_t index[3], int32_t side, int slot) {
    LatticePoint a, b;
    cube_spine(index, side, a, b);
    auto P = [&](int i) { LatticePoint p = a; p[i] = b[i]; return p; };
    auto Q = [&](int i) { LatticePoint q = b; q[i] = a[i]; return q; };
    const LatticePoint ring[6] = {P(0), Q(2), P(1), Q(0), P(2), Q(1)};
    return {a, b, ring[slot], ring[(slot + 1) % 6]};
}

// The descendant of cube tetrahedron `slot` that `path` leads to: its bits, highest first, pick
// bisect()'s child 0 or 1 at each of the `bisections` steps.
Tetrahedron cube_leaf(const int32_t index[3], int32_t side, int slot, int bisections, int path) {
    Tetrahedron t = cube_tetrahedron(index, side, slot);
    for (int k = bisections - 1; k >= 0; --k) {
        Tetrahedron c0, c1;
        bisect(t, c0, c1);
        t = (path >> k) & 1 ? c1 : c0;
    }
    return t;
}

// The slot of the cube tetrahedron that contains local point u (one of them if u is on an inner
// face): 0: u2 >= u1 >= u0, 1: u2 >= u0 >= u1, 2: u0 >= u2 >= u1, 3: u0 >= u1 >= u2,
// 4: u1 >= u0 >= u2, 5: u1 >= u2 >= u0.
int kuhn_slot(const double u[3]) {
    if (u[2] >= u[1]) {
        if (u[1] >= u[0]) return 0;
        return u[2] >= u[0] ? 1 : 2;
    }
    if (u[0] >= u[1]) return 3;
    return u[0] >= u[2] ? 4 : 5;
}

// Margin of the strict inside test, relative to the normal's L1 norm: about 1e-6 lattice units.
// Input positions are on the 2^-32 grid, so local coordinates are exact and a plane value's
// rounding error is below 4 * 2^-53 * |n|_1 * 2^20 (5e-10 |n|_1): a value above the margin is
// truly positive.
constexpr double kPlaneMargin = 1e-6;

// A face of a leaf shape, in local coordinates: inside is n.u > d * side / 2 (n, d small integers).
struct Halfspace {
    double n[3], d, margin;
};

struct LeafShape {
    Halfspace faces[4];
    double lo[3], hi[3];  // bounding box, in units of side / 2
};

// A leaf's key, relative to its cube.
struct LeafEntry {
    int8_t centre[3];  // the diamond's centre: the cube's lowest corner + centre * side / 2
    uint8_t slot;
};

// Everything the routing looks up, made once. Leaves are numbered slot * 2^bisections + path.
// Computing slot_key() for every triangle instead cost 2% of the converter's CPU time (perf,
// 1M scan), and with explicit bisection and plane tests in lattice coordinates instead of these
// precomputed shapes, routing alone took 2.5x as long on the 1M scan.
struct RoutingTables {
    std::array<std::array<LeafShape, 24>, 3> shapes;               // [bisections][leaf]
    std::array<std::array<std::array<LeafEntry, 24>, 8>, 3> keys;  // [bisections][parity][leaf]
};

// The faces of tetrahedron t of cube `index`, in local coordinates with unit side / 2.
LeafShape local_shape(const Tetrahedron& t, const int32_t index[3], int32_t side) {
    LatticePoint a, b;
    cube_spine(index, side, a, b);
    int64_t u[4][3];
    for (int k = 0; k < 4; ++k)
        for (int i = 0; i < 3; ++i) {
            int64_t v = (a[i] > b[i] ? 1 : -1) * int64_t(t[k][i] - b[i]);
            assert(v % (side / 2) == 0);
            u[k][i] = v / (side / 2);
        }
    LeafShape shape;
    for (int i = 0; i < 3; ++i) {
        shape.lo[i] = double(std::min({u[0][i], u[1][i], u[2][i], u[3][i]}));
        shape.hi[i] = double(std::max({u[0][i], u[1][i], u[2][i], u[3][i]}));
    }
    for (int f = 0; f < 4; ++f) {
        const int64_t *p = u[(f + 1) % 4], *q = u[(f + 2) % 4], *r = u[(f + 3) % 4], *o = u[f];
        int64_t e1[3], e2[3], n[3];
        for (int i = 0; i < 3; ++i) {
            e1[i] = q[i] - p[i];
            e2[i] = r[i] - p[i];
        }
        n[0] = e1[1] * e2[2] - e1[2] * e2[1];
        n[1] = e1[2] * e2[0] - e1[0] * e2[2];
        n[2] = e1[0] * e2[1] - e1[1] * e2[0];
        int64_t d = n[0] * p[0] + n[1] * p[1] + n[2] * p[2];
        int64_t side_of_o = n[0] * o[0] + n[1] * o[1] + n[2] * o[2] - d;
        assert(side_of_o != 0);
        int64_t sign = side_of_o > 0 ? 1 : -1;  // inside is the opposite corner's side
        Halfspace& h = shape.faces[f];
        for (int i = 0; i < 3; ++i) h.n[i] = double(sign * n[i]);
        h.d = double(sign * d);
        h.margin = kPlaneMargin * (std::fabs(h.n[0]) + std::fabs(h.n[1]) + std::fabs(h.n[2]));
    }
    return shape;
}

[[maybe_unused]] bool same_shape(const LeafShape& a, const LeafShape& b) {
    for (int f = 0; f < 4; ++f)
        for (int i = 0; i < 4; ++i)
            if ((i < 3 ? a.faces[f].n[i] : a.faces[f].d) != (i < 3 ? b.faces[f].n[i] : b.faces[f].d)) return false;
    for (int i = 0; i < 3; ++i)
        if (a.lo[i] != b.lo[i] || a.hi[i] != b.hi[i]) return false;
    return true;
}

// Made on the 8 cubes of octave 1, one per parity pattern, with the general slot_key(). The
// keys' offsets hold for every cube of the same parity at every octave: moving by two cubes or
// scaling by two keeps the residues that orient the spines (lattice.h).
RoutingTables make_routing_tables() {
    RoutingTables tables{};
    const int32_t side = kLatticeSize / 2;
    for (int bisections = 0; bisections < 3; ++bisections)
        for (int parity = 0; parity < 8; ++parity) {
            const int32_t index[3] = {parity & 1, (parity >> 1) & 1, (parity >> 2) & 1};
            for (int slot = 0; slot < 6; ++slot)
                for (int path = 0; path < (1 << bisections); ++path) {
                    const int leaf = (slot << bisections) + path;
                    Tetrahedron t = cube_leaf(index, side, slot, bisections, path);
                    LeafShape shape = local_shape(t, index, side);
                    if (parity == 0) tables.shapes[bisections][leaf] = shape;
                    assert(same_shape(shape, tables.shapes[bisections][leaf]));  // the reflection argument
                    SlotKey key = slot_key(t);
                    LatticePoint c = DiamondId{key.diamond}.centre();
                    LeafEntry& e = tables.keys[bisections][parity][leaf];
                    for (int i = 0; i < 3; ++i) {
                        int32_t offset = c[i] - index[i] * side;
                        assert(offset % (side / 2) == 0 && offset >= 0 && offset <= side);
                        e.centre[i] = int8_t(offset / (side / 2));
                    }
                    e.slot = uint8_t(key.slot);
                }
        }
    return tables;
}

const RoutingTables& routing_tables() {
    static const RoutingTables tables = make_routing_tables();
    return tables;
}

// A cube of the leaves' octave and a triangle in its local coordinates.
struct LocalTriangle {
    int32_t index[3];
    int32_t side;
    double half_side;
    double u[3][3];  // exact: the corners are on the 2^-32 grid, within 2^21 of the cube
    LocalTriangle(const Vec3d tri[3], const int32_t cube[3], int32_t cube_side)
        : side(cube_side), half_side(double(cube_side / 2)) {
        for (int i = 0; i < 3; ++i) {
            index[i] = cube[i];
            bool odd = cube[i] & 1;
            double b = double(cube[i] * side + (odd ? side : 0));
            for (int k = 0; k < 3; ++k) u[k][i] = odd ? b - tri[k][i] : tri[k][i] - b;
        }
    }
    int parity() const { return (index[0] & 1) | (index[1] & 1) << 1 | (index[2] & 1) << 2; }
    // The key of a leaf of this cube.
    SlotKey key(const LeafEntry& e) const {
        LatticePoint centre;
        for (int i = 0; i < 3; ++i) centre[i] = index[i] * side + e.centre[i] * (side / 2);
        return {DiamondId::from_centre(centre).bits, e.slot};
    }
};

// True if all three points are strictly inside the shape (with the margin: floating-point error
// can only make it answer false). The first point first: it rejects the wrong candidates.
bool strictly_inside(const LeafShape& shape, const LocalTriangle& t) {
    for (int k = 0; k < 3; ++k)
        for (const Halfspace& h : shape.faces)
            if (!(h.n[0] * t.u[k][0] + h.n[1] * t.u[k][1] + h.n[2] * t.u[k][2] - h.d * t.half_side > h.margin))
                return false;
    return true;
}

// Conservative rejection, as separated() does it in lattice coordinates: true if the triangle's
// box misses the shape's or all three points are strictly outside one face (with margins, so
// floating-point error can only keep a tetrahedron that the exact clipper then rejects).
bool separated_local(const LeafShape& shape, const LocalTriangle& t) {
    for (int i = 0; i < 3; ++i) {
        double mn = std::min({t.u[0][i], t.u[1][i], t.u[2][i]}), mx = std::max({t.u[0][i], t.u[1][i], t.u[2][i]});
        if (mx < shape.lo[i] * t.half_side - 1e-6 || mn > shape.hi[i] * t.half_side + 1e-6) return true;
    }
    for (const Halfspace& h : shape.faces) {
        bool all_out = true;
        for (int k = 0; k < 3 && all_out; ++k)
            all_out = h.n[0] * t.u[k][0] + h.n[1] * t.u[k][1] + h.n[2] * t.u[k][2] - h.d * t.half_side < -h.margin;
        if (all_out) return true;
    }
    return false;
}

// Reports the leaves under node `node` (at `depth` bisections below the cube) that the triangle
// may overlap, pruning subtrees it cannot reach.
void descend_cube(const RoutingTables& tables, int bisections, int depth, int node, const LocalTriangle& t, SlotSink sink) {
    if (separated_local(tables.shapes[depth][node], t)) return;
    if (depth == bisections) {
        sink(t.key(tables.keys[bisections][t.parity()][node]));
        return;
    }
    descend_cube(tables, bisections, depth + 1, 2 * node, t, sink);
    descend_cube(tables, bisections, depth + 1, 2 * node + 1, t, sink);
}

}  // namespace

// ----------------------------------------------------------------------------------------------
// Tetrahedra in lattice coordinates (also used to choose the leaf level and to bin triangles).

void bisect(const Tetrahedron& t, Tetrahedron& c0, Tetrahedron& c1) {
    int a = 0, b = 1;
    int64_t best = -1;
    for (int i = 0; i < 4; ++i)
        for (int j = i + 1; j < 4; ++j) {
            int64_t l = len2(t[i], t[j]);
            if (l > best) { best = l; a = i; b = j; }
        }
    LatticePoint m;
    for (int k = 0; k < 3; ++k) m[k] = (t[a][k] + t[b][k]) / 2;
    c0 = t;
    c0[b] = m;
    c1 = t;
    c1[a] = m;
}

namespace {

// The plane of face f of a tetrahedron (the face opposite corner f), oriented so that the
// opposite corner is on its positive side, with the margin of the conservative tests: about
// 1e-6 lattice units, relative to the normal's L1 norm.
struct FacePlane {
    double n[3];
    LatticePoint a;
    double margin;
    FacePlane(const Tetrahedron& t, int f) : a(t[(f + 1) % 4]) {
        const LatticePoint& o = t[size_t(f)];
        const std::array<double, 3> normal = face_normal(t, f);
        std::copy(normal.begin(), normal.end(), n);
        const double so = n[0] * (o[0] - a[0]) + n[1] * (o[1] - a[1]) + n[2] * (o[2] - a[2]);
        if (!(so > 0))
            for (double& x : n) x = -x;
        margin = 1e-6 * (std::fabs(n[0]) + std::fabs(n[1]) + std::fabs(n[2]));
    }
    // Positive inside (the opposite corner's side).
    double inside(const Vec3d& p) const { return n[0] * (p[0] - a[0]) + n[1] * (p[1] - a[1]) + n[2] * (p[2] - a[2]); }
};

}  // namespace

bool separated(const Tetrahedron& t, const Vec3d* pts, int count) {
    double min[3], max[3];
    for (int i = 0; i < 3; ++i) {
        min[i] = max[i] = pts[0][i];
        for (int k = 1; k < count; ++k) {
            min[i] = std::min(min[i], pts[k][i]);
            max[i] = std::max(max[i], pts[k][i]);
        }
    }
    // Axis-aligned boxes first: cheap and rejects most candidates.
    for (int i = 0; i < 3; ++i) {
        int32_t tmin = std::min({t[0][i], t[1][i], t[2][i], t[3][i]}), tmax = std::max({t[0][i], t[1][i], t[2][i], t[3][i]});
        if (max[i] < tmin - 1e-6 || min[i] > tmax + 1e-6) return true;
    }
    for (int f = 0; f < 4; ++f) {
        const FacePlane plane(t, f);
        bool all_out = true;
        for (int k = 0; k < count && all_out; ++k) all_out = plane.inside(pts[k]) < -plane.margin;
        if (all_out) return true;
    }
    return false;
}

bool strictly_inside(const Tetrahedron& t, const Vec3d* pts, int count) {
    for (int f = 0; f < 4; ++f) {
        const FacePlane plane(t, f);
        for (int k = 0; k < count; ++k)
            if (!(plane.inside(pts[k]) > plane.margin)) return false;
    }
    return true;
}

void cube_range(const Vec3d* pts, int count, int32_t side, int32_t lo[3], int32_t hi[3]) {
    for (int i = 0; i < 3; ++i) {
        double mn = pts[0][i], mx = pts[0][i];
        for (int k = 1; k < count; ++k) {
            mn = std::min(mn, pts[k][i]);
            mx = std::max(mx, pts[k][i]);
        }
        lo[i] = std::max(0, int32_t(std::ceil(mn / side)) - 1);
        hi[i] = std::min((kLatticeSize / side) - 1, int32_t(std::floor(mx / side)));
    }
}

SlotKey slot_key(const Tetrahedron& t) {
    DiamondId id;
    int slot;
    bool ok = tetrahedron_diamond(t, id, slot);
    (void)ok;
    assert(ok);
    return {id.bits, slot};
}

// ----------------------------------------------------------------------------------------------
// Routing.

bool single_leaf(const Vec3d tri[3], int level, const BlockCube& within, SlotKey& key) {
    const int octave = level / 3, bisections = level % 3;
    assert(within.octave <= octave);
    const int32_t side = kLatticeSize >> octave, cubes = int32_t(1) << octave;
    // The cube of the first corner: one containing it (if it is on a cube face, the strict
    // test below fails whichever is taken).
    int32_t index[3];
    for (int i = 0; i < 3; ++i) {
        double q = tri[0][i] / side;  // exact: side is a power of two
        if (!(q >= 0 && q < cubes)) return false;
        index[i] = int32_t(q);
        if ((index[i] >> (octave - within.octave)) != within.index[i]) return false;  // another block's
    }
    const LocalTriangle t(tri, index, side);
    const RoutingTables& tables = routing_tables();
    const int first = kuhn_slot(t.u[0]) << bisections;
    for (int leaf = first; leaf < first + (1 << bisections); ++leaf)
        if (strictly_inside(tables.shapes[bisections][leaf], t)) {
            key = t.key(tables.keys[bisections][t.parity()][leaf]);
            return true;
        }
    return false;
}

void for_each_leaf_slot(const Vec3d tri[3], int level, const BlockCube& within, SlotSink sink) {
    SlotKey key;
    if (single_leaf(tri, level, within, key)) {
        sink(key);
        return;
    }
    search_leaf_slots(tri, level, within, sink);
}

void search_leaf_slots(const Vec3d tri[3], int level, const BlockCube& within, SlotSink sink) {
    // The cubes of the leaves' octave that the box touches, in the block.
    const int octave = level / 3, bisections = level % 3;
    const int32_t side = kLatticeSize >> octave;
    int32_t lo[3], hi[3];
    cube_range(tri, 3, side, lo, hi);
    const int32_t per_block = int32_t(1) << (octave - within.octave);
    for (int i = 0; i < 3; ++i) {
        lo[i] = std::max(lo[i], within.index[i] * per_block);
        hi[i] = std::min(hi[i], within.index[i] * per_block + per_block - 1);
    }
    const RoutingTables& tables = routing_tables();
    int32_t index[3];
    for (index[2] = lo[2]; index[2] <= hi[2]; ++index[2])
        for (index[1] = lo[1]; index[1] <= hi[1]; ++index[1])
            for (index[0] = lo[0]; index[0] <= hi[0]; ++index[0]) {
                const LocalTriangle t(tri, index, side);
                for (int slot = 0; slot < 6; ++slot) descend_cube(tables, bisections, 0, slot, t, sink);
            }
}


// ----------------------------------------------------------------------------------------------
// Grouping by leaf.

namespace {

size_t slot_key_hash(const SlotKey& k) {
    const uint64_t h = (k.diamond ^ uint64_t(k.slot) << 61) * 0x9E3779B97F4A7C15ull;
    return size_t(h ^ (h >> 29));
}

}  // namespace

void LeafGroups::build(const std::vector<std::vector<LeafHit>>& parts) {
    keys_.clear();
    table_.assign(256, 0);
    last_ = UINT32_MAX;
    leaf_of_hit_.clear();
    fill_.clear();
    for (const std::vector<LeafHit>& part : parts)
        for (const LeafHit& h : part) {
            const uint32_t leaf = number(h.key);
            if (leaf == fill_.size()) fill_.push_back(0);
            ++fill_[leaf];
            leaf_of_hit_.push_back(leaf);
        }
    start_.assign(keys_.size() + 1, 0);
    for (size_t g = 0; g < keys_.size(); ++g) {
        start_[g + 1] = start_[g] + fill_[g];
        fill_[g] = uint32_t(start_[g]);
    }
    // A stable scatter: each group keeps the hits' order.
    entries_.resize(leaf_of_hit_.size());
    size_t i = 0;
    for (const std::vector<LeafHit>& part : parts)
        for (const LeafHit& h : part) entries_[fill_[leaf_of_hit_[i++]]++] = {h.triangle, h.whole};
}

uint32_t LeafGroups::number(const SlotKey& key) {
    if (last_ != UINT32_MAX && keys_[last_] == key) return last_;
    if (2 * (keys_.size() + 1) > table_.size()) rehash(2 * table_.size());
    const size_t mask = table_.size() - 1;
    size_t h = slot_key_hash(key) & mask;
    while (table_[h] != 0 && !(keys_[table_[h] - 1] == key)) h = (h + 1) & mask;
    if (table_[h] == 0) {
        keys_.push_back(key);
        table_[h] = uint32_t(keys_.size());
    }
    return last_ = table_[h] - 1;
}

void LeafGroups::rehash(size_t capacity) {
    table_.assign(capacity, 0);
    for (uint32_t n = 0; n < keys_.size(); ++n) {
        size_t h = slot_key_hash(keys_[n]) & (capacity - 1);
        while (table_[h] != 0) h = (h + 1) & (capacity - 1);
        table_[h] = n + 1;
    }
}

}  // namespace catpaq
