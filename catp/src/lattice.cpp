#include "catp/lattice.h"

#include <algorithm>
#include <cassert>

namespace catpaq {

namespace {

int32_t lowest_power_of_two(const LatticePoint& c) {
    uint32_t bits = uint32_t(c[0]) | uint32_t(c[1]) | uint32_t(c[2]);
    return bits == 0 ? 0 : int32_t(bits & (~bits + 1));
}

bool is_odd_multiple(int32_t v, int32_t t) { return (v / t) % 2 != 0; }

int log2_exact(int32_t t) {
    int s = 0;
    while ((int32_t(1) << s) < t) ++s;
    return s;
}

// The neighbour of v (an odd multiple of t) at distance t that is congruent to `residue` mod 4t.
int32_t step_to_residue(int32_t v, int32_t t, int32_t residue) {
    return ((v + t) % (4 * t) == residue) ? v + t : v - t;
}

LatticePoint add(const LatticePoint& a, int32_t dx, int32_t dy, int32_t dz) { return {a[0] + dx, a[1] + dy, a[2] + dz}; }

}  // namespace

bool inside_root_cube(const LatticePoint& p) {
    for (int i = 0; i < 3; ++i)
        if (p[i] < 0 || p[i] > kLatticeSize) return false;
    return true;
}

bool is_valid_diamond_centre(const LatticePoint& c) {
    if (!inside_root_cube(c)) return false;
    int32_t t = lowest_power_of_two(c);
    return t != 0 && t <= kLatticeSize / 2;
}

DiamondId root_diamond() { return DiamondId::from_centre({kLatticeSize / 2, kLatticeSize / 2, kLatticeSize / 2}); }

int diamond_level(DiamondId id) {
    LatticePoint c = id.centre();
    int32_t t = lowest_power_of_two(c);
    int k = 0;
    for (int i = 0; i < 3; ++i) k += is_odd_multiple(c[i], t);
    int octave = kLatticeBits - 1 - log2_exact(t);
    return 3 * octave + (3 - k);
}

DiamondInfo diamond_info(DiamondId id) {
    DiamondInfo d;
    d.id = id;
    d.centre = id.centre();
    assert(is_valid_diamond_centre(d.centre));
    const LatticePoint& c = d.centre;
    int32_t t = d.scale = lowest_power_of_two(c);
    bool odd[3];
    int k = 0;
    for (int i = 0; i < 3; ++i) k += (odd[i] = is_odd_multiple(c[i], t));
    d.level = 3 * (kLatticeBits - 1 - log2_exact(t)) + (3 - k);
    d.cls = DiamondClass(3 - k);
    d.spine_a = d.spine_b = c;
    for (int i = 0; i < 3; ++i) {
        if (!odd[i]) continue;
        d.spine_a[i] = step_to_residue(c[i], t, 2 * t);
        d.spine_b[i] = 2 * c[i] - d.spine_a[i];
    }
    const LatticePoint& A = d.spine_a;
    const LatticePoint& B = d.spine_b;
    if (d.cls == DiamondClass::Cube) {
        // P_i: A with coordinate i from B; Q_i: B with coordinate i from A. Each consecutive pair
        // is joined by a cube edge; the Q_i are the parents (edge diamonds of scale 2t).
        auto P = [&](int i) { LatticePoint p = A; p[i] = B[i]; return p; };
        auto Q = [&](int i) { LatticePoint q = B; q[i] = A[i]; return q; };
        d.ring = {P(0), Q(2), P(1), Q(0), P(2), Q(1)};
        d.ring_size = 6;
    } else if (d.cls == DiamondClass::Face) {
        int i = -1, j = -1, e = -1;
        for (int a = 0; a < 3; ++a) {
            if (odd[a]) (i < 0 ? i : j) = a;
            else e = a;
        }
        LatticePoint s1 = c, s2 = c, up = c, down = c;
        s1[i] = A[i]; s1[j] = B[j];
        s2[i] = B[i]; s2[j] = A[j];
        up[e] += t;
        down[e] -= t;
        d.ring = {s1, up, s2, down};  // the parents (cube centres) are at odd positions
        d.ring_size = 4;
    } else {
        int i = odd[0] ? 0 : (odd[1] ? 1 : 2);
        int j = (i + 1) % 3, l = (i + 2) % 3;
        if (j > l) std::swap(j, l);
        const int steps[8][2] = {{1, 0}, {1, 1}, {0, 1}, {-1, 1}, {-1, 0}, {-1, -1}, {0, -1}, {1, -1}};
        for (auto& s : steps) {
            LatticePoint r = c;
            r[j] += s[0] * t;
            r[l] += s[1] * t;
            d.ring[d.ring_size++] = r;  // the parents (face centres) are at even positions
        }
    }
    return d;
}

Tetrahedron diamond_tetrahedron(const DiamondInfo& d, int slot) {
    int n = d.ring_size;
    return {d.spine_a, d.spine_b, d.ring[slot], d.ring[(slot + 1) % n]};
}

std::array<double, 3> face_normal(const Tetrahedron& t, int f) {
    const LatticePoint &a = t[size_t((f + 1) % 4)], &b = t[size_t((f + 2) % 4)], &c = t[size_t((f + 3) % 4)];
    double u[3], v[3];
    for (int k = 0; k < 3; ++k) {
        u[k] = double(b[k] - a[k]);
        v[k] = double(c[k] - a[k]);
    }
    return {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
}

bool tetrahedron_exists(const Tetrahedron& t) {
    for (const LatticePoint& p : t)
        if (!inside_root_cube(p)) return false;
    return true;
}

uint8_t existing_slots(const DiamondInfo& d) {
    uint8_t mask = 0;
    for (int s = 0; s < d.ring_size; ++s)
        if (tetrahedron_exists(diamond_tetrahedron(d, s))) mask |= uint8_t(1 << s);
    return mask;
}

std::vector<DiamondId> diamond_parents(DiamondId id) {
    DiamondInfo d = diamond_info(id);
    std::vector<DiamondId> out;
    const LatticePoint& c = d.centre;
    int32_t t = d.scale;
    if (d.cls == DiamondClass::Cube) {
        if (t >= kLatticeSize / 2) return out;  // the root
        for (int i = 0; i < 3; ++i) {
            LatticePoint p;
            for (int j = 0; j < 3; ++j) p[j] = step_to_residue(c[j], t, j == i ? 2 * t : 0);
            out.push_back(DiamondId::from_centre(p));
        }
    } else {
        for (size_t r = d.cls == DiamondClass::Face ? 1 : 0; r < size_t(d.ring_size); r += 2)
            if (inside_root_cube(d.ring[r])) out.push_back(DiamondId::from_centre(d.ring[r]));
    }
    return out;
}

std::vector<DiamondId> diamond_children(DiamondId id) {
    DiamondInfo d = diamond_info(id);
    std::vector<DiamondId> out;
    const LatticePoint& c = d.centre;
    int32_t t = d.scale;
    auto push = [&](const LatticePoint& p) {
        if (inside_root_cube(p)) out.push_back(DiamondId::from_centre(p));
    };
    if (d.cls == DiamondClass::Cube || d.cls == DiamondClass::Face) {
        for (int i = 0; i < 3; ++i) {
            if (d.cls == DiamondClass::Face && !is_odd_multiple(c[i], t)) continue;
            LatticePoint lo = c, hi = c;
            lo[i] -= t;
            hi[i] += t;
            push(lo);
            push(hi);
        }
    } else if (t >= 2) {
        int32_t h = t / 2;
        for (int s = 0; s < 8; ++s) push(add(c, (s & 1) ? h : -h, (s & 2) ? h : -h, (s & 4) ? h : -h));
    }
    return out;
}

DiamondId slot_parent(const DiamondInfo& d, int slot) {
    int n = d.ring_size;
    int first_parent_parity = d.cls == DiamondClass::Edge ? 0 : 1;
    int r = (slot % 2 == first_parent_parity) ? slot : (slot + 1) % n;
    return DiamondId::from_centre(d.ring[r]);
}

std::array<Tetrahedron, 2> split_tetrahedron(const DiamondInfo& d, int slot) {
    Tetrahedron t = diamond_tetrahedron(d, slot);
    return {Tetrahedron{t[0], d.centre, t[2], t[3]}, Tetrahedron{d.centre, t[1], t[2], t[3]}};
}

static int64_t squared_distance(const LatticePoint& a, const LatticePoint& b) {
    int64_t s = 0;
    for (int i = 0; i < 3; ++i) s += int64_t(a[i] - b[i]) * (a[i] - b[i]);
    return s;
}

bool tetrahedron_diamond(const Tetrahedron& t, DiamondId& id, int& slot) {
    int best_a = -1, best_b = -1;
    int64_t best = -1;
    bool unique = true;
    for (int a = 0; a < 4; ++a) {
        for (int b = a + 1; b < 4; ++b) {
            int64_t l = squared_distance(t[a], t[b]);
            if (l > best) { best = l; best_a = a; best_b = b; unique = true; }
            else if (l == best) unique = false;
        }
    }
    if (!unique) return false;
    LatticePoint c;
    for (int i = 0; i < 3; ++i) {
        int32_t s = t[best_a][i] + t[best_b][i];
        if (s % 2) return false;
        c[i] = s / 2;
    }
    if (!is_valid_diamond_centre(c)) return false;
    DiamondInfo d = diamond_info(DiamondId::from_centre(c));
    bool spine_matches = (d.spine_a == t[best_a] && d.spine_b == t[best_b]) ||
                         (d.spine_a == t[best_b] && d.spine_b == t[best_a]);
    if (!spine_matches) return false;
    LatticePoint others[2];
    int k = 0;
    for (int a = 0; a < 4; ++a)
        if (a != best_a && a != best_b) others[k++] = t[a];
    int n = d.ring_size;
    for (int s = 0; s < n; ++s) {
        const LatticePoint& r0 = d.ring[s];
        const LatticePoint& r1 = d.ring[(s + 1) % n];
        if ((r0 == others[0] && r1 == others[1]) || (r0 == others[1] && r1 == others[0])) {
            id = d.id;
            slot = s;
            return true;
        }
    }
    return false;
}

Tetrahedron canonical_tetrahedron(const Tetrahedron& t) {
    Tetrahedron c = t;
    std::sort(c.begin(), c.end());
    return c;
}

}  // namespace catpaq
