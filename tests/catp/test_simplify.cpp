// catp/simplify.h: half-edge collapse simplification with locked vertices. Each test states the
// property it checks in its name; the meshes are built here (icospheres, noisy spheres, height
// fields, patches with holes, non-manifold fans).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <set>
#include <stdexcept>
#include <utility>
#include <vector>

#include "catp/simplify.h"

using namespace catpaq;

namespace {

using V3 = std::array<double, 3>;

struct TestMesh {
    std::vector<V3> positions;
    std::vector<uint32_t> indices;
    size_t triangles() const { return indices.size() / 3; }
};

V3 sub(const V3& a, const V3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
V3 cross(const V3& a, const V3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
double norm(const V3& a) { return std::sqrt(dot(a, a)); }

uint64_t hash64(uint64_t x) {
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
}
double unit_random(uint64_t key) { return double(hash64(key) >> 11) / double(1ull << 53); }  // [0, 1)

// Icosphere with `levels` midpoint subdivisions (20 * 4^levels triangles), radius 1 plus
// `noise` * (uniform [-1, 1]) per vertex, outward winding.
TestMesh icosphere(int levels, double noise = 0, uint64_t seed = 1) {
    TestMesh m;
    const double t = (1 + std::sqrt(5.0)) / 2;
    m.positions = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                   {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
    m.indices = {0, 11, 5, 0, 5, 1, 0, 1, 7, 0, 7, 10, 0, 10, 11, 1, 5, 9, 5, 11, 4, 11, 10, 2, 10, 7, 6, 7, 1, 8,
                 3, 9, 4, 3, 4, 2, 3, 2, 6, 3, 6, 8, 3, 8, 9, 4, 9, 5, 2, 4, 11, 6, 2, 10, 8, 6, 7, 9, 8, 1};
    for (V3& p : m.positions) {
        const double l = norm(p);
        p = {p[0] / l, p[1] / l, p[2] / l};
    }
    for (int level = 0; level < levels; ++level) {
        std::map<std::pair<uint32_t, uint32_t>, uint32_t> mid;
        auto midpoint = [&](uint32_t a, uint32_t b) {
            const auto key = std::minmax(a, b);
            auto it = mid.find(key);
            if (it != mid.end()) return it->second;
            V3 p = {m.positions[a][0] + m.positions[b][0], m.positions[a][1] + m.positions[b][1],
                    m.positions[a][2] + m.positions[b][2]};
            const double l = norm(p);
            m.positions.push_back({p[0] / l, p[1] / l, p[2] / l});
            const uint32_t id = uint32_t(m.positions.size() - 1);
            mid.emplace(key, id);
            return id;
        };
        std::vector<uint32_t> next;
        for (size_t i = 0; i < m.indices.size(); i += 3) {
            const uint32_t a = m.indices[i], b = m.indices[i + 1], c = m.indices[i + 2];
            const uint32_t ab = midpoint(a, b), bc = midpoint(b, c), ca = midpoint(c, a);
            next.insert(next.end(), {a, ab, ca, b, bc, ab, c, ca, bc, ab, bc, ca});
        }
        m.indices = std::move(next);
    }
    if (noise > 0)
        for (size_t v = 0; v < m.positions.size(); ++v) {
            const double r = 1 + noise * (2 * unit_random(seed * 1000003 + v) - 1);
            for (double& c : m.positions[v]) c *= r;
        }
    return m;
}

// Height field z = f(x, y) on an n x n grid over [0, 1]^2, upward winding. Cells for which
// `hole(i, j)` is true are left out.
template <class F, class H>
TestMesh grid(int n, F f, H hole) {
    TestMesh m;
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) {
            const double x = double(i) / n, y = double(j) / n;
            m.positions.push_back({x, y, f(x, y)});
        }
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            if (hole(i, j)) continue;
            const uint32_t a = uint32_t(j * (n + 1) + i), b = a + 1, c = a + uint32_t(n + 1), d = c + 1;
            if ((i + j) % 2) {
                m.indices.insert(m.indices.end(), {a, b, d, a, d, c});
            } else {
                m.indices.insert(m.indices.end(), {a, b, c, b, d, c});
            }
        }
    return m;
}
template <class F>
TestMesh grid(int n, F f) {
    return grid(n, f, [](int, int) { return false; });
}

SimplifyResult run(const TestMesh& m, size_t target, const std::vector<uint8_t>* locked = nullptr,
                   double max_error = INFINITY, bool lock_border = false) {
    SimplifySettings s;
    s.target_triangles = target;
    s.max_error = max_error;
    s.lock_topological_border = lock_border;
    return simplify_mesh(m.positions.empty() ? nullptr : m.positions[0].data(), m.positions.size(), m.indices.data(),
                         m.indices.size(), locked ? locked->data() : nullptr, s);
}

// Undirected edge -> number of triangles using it.
std::map<std::pair<uint32_t, uint32_t>, int> edge_use(const std::vector<uint32_t>& idx) {
    std::map<std::pair<uint32_t, uint32_t>, int> use;
    for (size_t t = 0; t < idx.size(); t += 3)
        for (int j = 0; j < 3; ++j) ++use[std::minmax(idx[t + j], idx[t + (j + 1) % 3])];
    return use;
}

// Directed border edges (a, b): edges of a triangle whose reverse is in no triangle.
std::set<std::pair<uint32_t, uint32_t>> border_edges(const std::vector<uint32_t>& idx) {
    std::set<std::pair<uint32_t, uint32_t>> directed, border;
    for (size_t t = 0; t < idx.size(); t += 3)
        for (int j = 0; j < 3; ++j) directed.insert({idx[t + j], idx[t + (j + 1) % 3]});
    for (const auto& e : directed)
        if (!directed.count({e.second, e.first})) border.insert(e);
    return border;
}

std::set<uint32_t> referenced(const std::vector<uint32_t>& idx) { return {idx.begin(), idx.end()}; }

// Checks a closed, consistently oriented, edge-manifold surface (every directed edge once and
// its reverse once); returns the Euler characteristic V - E + F.
long euler_closed_manifold(const std::vector<uint32_t>& idx, bool& ok) {
    std::map<std::pair<uint32_t, uint32_t>, int> directed;
    for (size_t t = 0; t < idx.size(); t += 3)
        for (int j = 0; j < 3; ++j) ++directed[{idx[t + j], idx[t + (j + 1) % 3]}];
    ok = true;
    for (const auto& [e, n] : directed)
        if (n != 1 || directed.count({e.second, e.first}) == 0) ok = false;
    return long(referenced(idx).size()) - long(directed.size() / 2) + long(idx.size() / 3);
}

// Number of triangles that repeat an index, have (near) zero area, or repeat another triangle's
// vertex set.
size_t bad_triangles(const TestMesh& m, const std::vector<uint32_t>& idx) {
    size_t bad = 0;
    std::set<std::array<uint32_t, 3>> seen;
    for (size_t t = 0; t < idx.size(); t += 3) {
        std::array<uint32_t, 3> k = {idx[t], idx[t + 1], idx[t + 2]};
        const V3 n = cross(sub(m.positions[k[1]], m.positions[k[0]]), sub(m.positions[k[2]], m.positions[k[0]]));
        std::sort(k.begin(), k.end());
        if (k[0] == k[1] || k[1] == k[2] || !(norm(n) > 1e-14) || !seen.insert(k).second) ++bad;
    }
    return bad;
}

double point_triangle_distance(const V3& p, const V3& a, const V3& b, const V3& c) {
    // Closest point on a triangle (Ericson, Real-Time Collision Detection 5.1.5).
    const V3 ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
    auto dist = [&](const V3& q) { return norm(sub(p, q)); };
    auto lerp = [](const V3& o, const V3& d, double s) {
        return V3{o[0] + s * d[0], o[1] + s * d[1], o[2] + s * d[2]};
    };
    const double d1 = dot(ab, ap), d2 = dot(ac, ap);
    if (d1 <= 0 && d2 <= 0) return dist(a);
    const V3 bp = sub(p, b);
    const double d3 = dot(ab, bp), d4 = dot(ac, bp);
    if (d3 >= 0 && d4 <= d3) return dist(b);
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return dist(lerp(a, ab, d1 / (d1 - d3)));
    const V3 cp = sub(p, c);
    const double d5 = dot(ab, cp), d6 = dot(ac, cp);
    if (d6 >= 0 && d5 <= d6) return dist(c);
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return dist(lerp(a, ac, d2 / (d2 - d6)));
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
        return dist(lerp(b, sub(c, b), (d4 - d3) / ((d4 - d3) + (d5 - d6))));
    const double denom = 1 / (va + vb + vc);
    return dist(lerp(lerp(a, ab, vb * denom), ac, vc * denom));
}

}  // namespace

TEST(Simplify, ReachesTargetOnClosedIcosphereAndKeepsItClosedAndManifold) {
    const TestMesh m = icosphere(5);  // 20480 triangles
    ASSERT_EQ(m.triangles(), 20480u);
    for (size_t target : {10240u, 2000u, 500u}) {
        const SimplifyResult r = run(m, target);
        const size_t out = r.indices.size() / 3;
        EXPECT_LE(out, target);
        EXPECT_GE(double(out), 0.97 * double(target)) << "target " << target;
        bool ok = false;
        EXPECT_EQ(euler_closed_manifold(r.indices, ok), 2) << "a sphere stays a sphere";
        EXPECT_TRUE(ok) << "closed (no border edge), edge-manifold, consistently oriented";
        EXPECT_EQ(bad_triangles(m, r.indices), 0u);
        EXPECT_GT(r.error, 0);
    }
    // As far as it goes: still a sphere, down to a few dozen triangles at most (the tetrahedron,
    // 4 triangles, is the smallest closed surface).
    const SimplifyResult r = run(m, 0);
    bool ok = false;
    EXPECT_EQ(euler_closed_manifold(r.indices, ok), 2);
    EXPECT_TRUE(ok);
    EXPECT_EQ(bad_triangles(m, r.indices), 0u);
    EXPECT_GE(r.indices.size() / 3, 4u);
    EXPECT_LE(r.indices.size() / 3, 64u);
}

TEST(Simplify, SmallClosedMeshesStayClosedManifoldsDownToTheirLimit) {
    // Where the link condition matters most: the last collapses of a closed surface, where any
    // non-manifold shortcut (two faces glued back to back, an edge of three triangles) is near.
    // Tetrahedra (irregular, and flat enough to pass the geometric checks), then noisy spheres.
    for (uint64_t seed = 0; seed < 40; ++seed) {
        TestMesh tet;
        for (uint64_t i = 0; i < 4; ++i)
            tet.positions.push_back({unit_random(seed * 16 + i), unit_random(seed * 16 + i + 4),
                                     0.05 * unit_random(seed * 16 + i + 8)});
        tet.indices = {0, 1, 2, 0, 2, 3, 0, 3, 1, 1, 3, 2};
        // Orient consistently outwards: face (0, 1, 2) must not face vertex 3.
        const V3 n = cross(sub(tet.positions[1], tet.positions[0]), sub(tet.positions[2], tet.positions[0]));
        if (dot(n, sub(tet.positions[3], tet.positions[0])) > 0)
            for (size_t t = 0; t < tet.indices.size(); t += 3) std::swap(tet.indices[t + 1], tet.indices[t + 2]);
        const SimplifyResult r = run(tet, 0);
        EXPECT_EQ(r.indices.size(), 12u) << "seed " << seed << ": a tetrahedron cannot lose a vertex";
    }
    for (uint64_t seed = 0; seed < 40; ++seed) {
        const TestMesh m = icosphere(1 + int(seed % 2), 0.15, seed);
        const SimplifyResult r = run(m, 0);
        bool ok = false;
        EXPECT_EQ(euler_closed_manifold(r.indices, ok), 2) << "seed " << seed;
        EXPECT_TRUE(ok) << "seed " << seed;
        EXPECT_EQ(bad_triangles(m, r.indices), 0u) << "seed " << seed;
    }
}

TEST(Simplify, KeepsLockedVerticesAndOutputsOnlyInputVertices) {
    TestMesh m = icosphere(4, 0.02);  // 5120 triangles
    // Lock a band around the equator (interior vertices, not a topological border, like the
    // vertices on a diamond's faces) and a scattering of others; add unreferenced vertices.
    std::vector<uint8_t> locked(m.positions.size(), 0);
    for (size_t v = 0; v < m.positions.size(); ++v)
        locked[v] = std::fabs(m.positions[v][2]) < 0.08 || hash64(v) % 13 == 0;
    m.positions.push_back({5, 5, 5});
    locked.push_back(1);
    m.positions.push_back({6, 6, 6});
    locked.push_back(0);
    const SimplifyResult r = run(m, 0, &locked);
    const std::set<uint32_t> in = referenced(m.indices), out = referenced(r.indices);
    EXPECT_LT(r.indices.size(), m.indices.size() / 2) << "the unlocked parts were simplified";
    for (uint32_t v : out) EXPECT_TRUE(in.count(v)) << "output vertex " << v << " is not an input vertex";
    size_t locked_count = 0;
    for (uint32_t v : in)
        if (locked[v]) {
            ++locked_count;
            EXPECT_TRUE(out.count(v)) << "locked vertex " << v << " was removed";
        }
    EXPECT_GT(locked_count, 300u);
    bool ok = false;
    EXPECT_EQ(euler_closed_manifold(r.indices, ok), 2);
    EXPECT_TRUE(ok);
}

TEST(Simplify, PatchWithLockedBorderRingKeepsExactlyThatBorder) {
    const auto f = [](double x, double y) { return 0.1 * std::sin(6 * x) * std::cos(5 * y); };
    const TestMesh m = grid(40, f);
    const auto in_border = border_edges(m.indices);
    ASSERT_EQ(in_border.size(), 160u);
    std::vector<uint8_t> locked(m.positions.size(), 0);
    for (const auto& e : in_border) locked[e.first] = locked[e.second] = 1;
    // Locked by the caller, and locked as the topological border: both keep the ring.
    for (int mode = 0; mode < 2; ++mode) {
        const SimplifyResult r = mode == 0 ? run(m, 0, &locked) : run(m, 0, nullptr, INFINITY, true);
        EXPECT_LT(r.indices.size(), m.indices.size() / 4) << "mode " << mode;
        EXPECT_EQ(border_edges(r.indices), in_border) << "mode " << mode;
        EXPECT_EQ(bad_triangles(m, r.indices), 0u);
    }
}

TEST(Simplify, UnlockedBorderSlidesAlongItselfKeepingClosedLoopsAndTheirCount) {
    // A bumpy patch with two square holes: three border loops.
    const auto f = [](double x, double y) { return 0.05 * std::sin(9 * x + 2 * y) + 0.2 * x * y; };
    const auto hole = [](int i, int j) {
        return (i >= 10 && i < 18 && j >= 10 && j < 18) || (i >= 30 && i < 36 && j >= 25 && j < 40);
    };
    const TestMesh m = grid(48, f, hole);
    const auto in_border = border_edges(m.indices);
    std::set<uint32_t> in_border_vertices;
    for (const auto& e : in_border) in_border_vertices.insert(e.first);

    const SimplifyResult r = run(m, m.triangles() / 10);
    const auto out_border = border_edges(r.indices);
    EXPECT_LT(out_border.size(), in_border.size() * 3 / 4) << "the border was simplified";
    // Closed loops: every border vertex has exactly one outgoing and one incoming border edge.
    std::map<uint32_t, uint32_t> next;
    std::map<uint32_t, int> incoming;
    for (const auto& e : out_border) {
        EXPECT_TRUE(next.emplace(e.first, e.second).second) << "two border edges leave " << e.first;
        ++incoming[e.second];
        EXPECT_TRUE(in_border_vertices.count(e.first)) << "border vertex " << e.first << " was not on the input border";
    }
    for (const auto& [v, n] : incoming) EXPECT_EQ(n, 1) << v;
    size_t loops = 0;
    std::set<uint32_t> visited;
    for (const auto& [v, w] : next) {
        if (visited.count(v)) continue;
        ++loops;
        for (uint32_t u = v; visited.insert(u).second;) {
            ASSERT_TRUE(next.count(u)) << "open border chain at " << u;
            u = next[u];
        }
    }
    EXPECT_EQ(loops, 3u);
    for (const auto& [e, n] : edge_use(r.indices)) EXPECT_LE(n, 2);
    EXPECT_EQ(bad_triangles(m, r.indices), 0u);
}

TEST(Simplify, NoDegenerateOrDuplicateTrianglesEvenFromDirtyInput) {
    TestMesh m = icosphere(3, 0.03);
    const size_t clean = m.triangles();
    // Repeated indices, exact duplicates, duplicates with reversed winding, rotated duplicates.
    m.indices.insert(m.indices.end(), {0, 0, 1, 2, 2, 2, 5, 7, 5});
    for (size_t t = 0; t < 30; t += 3) {
        const uint32_t a = m.indices[3 * t], b = m.indices[3 * t + 1], c = m.indices[3 * t + 2];
        m.indices.insert(m.indices.end(), {a, b, c, c, b, a, b, c, a});
    }
    const SimplifyResult full = run(m, m.triangles());
    EXPECT_EQ(full.indices.size() / 3, clean) << "degenerate and duplicate triangles are dropped first";
    EXPECT_EQ(full.error, 0);
    const std::vector<uint8_t> all_locked(m.positions.size(), 1);
    const SimplifyResult frozen = run(m, 0, &all_locked);
    EXPECT_EQ(frozen.indices, std::vector<uint32_t>(m.indices.begin(), m.indices.begin() + long(3 * clean)))
        << "with every vertex locked only the dirt goes";
    const SimplifyResult r = run(m, clean / 8);
    EXPECT_LE(r.indices.size() / 3, clean / 8);
    EXPECT_EQ(bad_triangles(m, r.indices), 0u);
    bool ok = false;
    EXPECT_EQ(euler_closed_manifold(r.indices, ok), 2);
    EXPECT_TRUE(ok);
}

TEST(Simplify, SourcesNameEachOutputTrianglesInputTriangleWithItsCornersKeptOrCollapsed) {
    // Dirty input first (dropped triangles shift the numbering), then simplification.
    TestMesh m = icosphere(3, 0.03);
    m.indices.insert(m.indices.begin(), {0, 0, 1, 3, 4, 5, 5, 3, 4});  // degenerate, then a duplicate pair
    for (size_t target : {m.triangles(), m.triangles() / 2, m.triangles() / 8}) {
        const SimplifyResult r = run(m, target);
        ASSERT_EQ(r.sources.size() * 3, r.indices.size());
        const std::set<uint32_t> kept = referenced(r.indices);
        for (size_t t = 0; t < r.sources.size(); ++t) {
            const uint32_t s = r.sources[t];
            ASSERT_LT(size_t(s), m.triangles());
            if (t > 0) {
                EXPECT_LT(r.sources[t - 1], s) << "input order";
            }
            for (int k = 0; k < 3; ++k) {
                const uint32_t in = m.indices[3 * s + k], out = r.indices[3 * t + k];
                EXPECT_TRUE(in == out || !kept.count(in)) << "corner " << k << " of triangle " << t
                                                          << ": changed, yet its input vertex is still there";
            }
        }
        if (target == m.triangles()) {
            EXPECT_EQ(r.sources.front(), 1u) << "the degenerate triangle is dropped";
            for (size_t t = 0; t < r.sources.size(); ++t)
                for (int k = 0; k < 3; ++k) EXPECT_EQ(m.indices[3 * r.sources[t] + k], r.indices[3 * t + k]);
        }
    }
}

TEST(Simplify, NoNormalFlipsOnBumpyHeightField) {
    // Slopes up to about 1.3: steep enough that careless collapses fold triangles over.
    const auto f = [](double x, double y) {
        return 0.06 * std::sin(20 * x) * std::sin(17 * y) + 0.03 * std::cos(37 * x + 11 * y);
    };
    const auto normal = [](double x, double y) {
        const double fx = 0.06 * 20 * std::cos(20 * x) * std::sin(17 * y) - 0.03 * 37 * std::sin(37 * x + 11 * y);
        const double fy = 0.06 * 17 * std::sin(20 * x) * std::cos(17 * y) - 0.03 * 11 * std::sin(37 * x + 11 * y);
        return V3{-fx, -fy, 1};
    };
    const TestMesh m = grid(80, f);
    for (size_t target : {m.triangles() / 4, m.triangles() / 20, size_t(100)}) {
        const SimplifyResult r = run(m, target);
        EXPECT_LE(r.indices.size() / 3, target);
        size_t flipped = 0, folded = 0;
        for (size_t t = 0; t < r.indices.size(); t += 3) {
            const V3& a = m.positions[r.indices[t]];
            const V3& b = m.positions[r.indices[t + 1]];
            const V3& c = m.positions[r.indices[t + 2]];
            const V3 n = cross(sub(b, a), sub(c, a));
            // The surface's own area vector over the triangle's footprint (its normal integrated
            // over barycentric samples): a coarse triangle spans bumps, so one point's normal
            // would not say which way the surface it replaces faces.
            V3 area{0, 0, 0};
            const int k = 8;
            for (int i = 0; i < k; ++i)
                for (int j = 0; i + j < k; ++j) {
                    const double u = (i + 1.0 / 3) / k, v = (j + 1.0 / 3) / k, w = 1 - u - v;
                    const V3 sn = normal(u * a[0] + v * b[0] + w * c[0], u * a[1] + v * b[1] + w * c[1]);
                    for (int q = 0; q < 3; ++q) area[q] += sn[q];
                }
            flipped += !(dot(n, area) > 0);
            // Facing down: folded over in the xy projection (vertical triangles, n_z = 0 up to
            // rounding, can be legitimate in 3D and are not counted).
            folded += n[2] < -1e-9 * norm(n);
        }
        EXPECT_EQ(flipped, 0u) << "target " << target;
        EXPECT_EQ(folded, 0u) << "target " << target;
        EXPECT_EQ(bad_triangles(m, r.indices), 0u);
    }
}

TEST(Simplify, FlatPatchSimplifiesAtZeroErrorWithoutZeroAreaTriangles) {
    // On a plane every collapse off the corners is free, and exactly collinear vertices abound:
    // the patch must shrink to few triangles without slivers of zero area. Tilted, the
    // coordinates are no longer exact, so "free" becomes "within rounding".
    for (double tilt : {0.0, 0.5}) {
        const TestMesh m = grid(32, [&](double x, double y) { return 0.5 + tilt * (x + y); });
        const auto in_border = border_edges(m.indices);
        const double eps = 1e-9;
        // Border locked: 128 border vertices need at least 126 triangles; interior vertices whose
        // every collapse would make a collinear triangle are stuck, but few.
        const SimplifyResult locked = run(m, 0, nullptr, eps, true);
        EXPECT_EQ(border_edges(locked.indices), in_border);
        EXPECT_LE(locked.indices.size() / 3, in_border.size() * 3 / 2) << "tilt " << tilt;
        EXPECT_LE(locked.error, eps);
        EXPECT_EQ(bad_triangles(m, locked.indices), 0u);
        // Border sliding: the straight sides slide into the corners, which cost something.
        const SimplifyResult sliding = run(m, 0, nullptr, eps);
        EXPECT_EQ(sliding.indices.size() / 3, 2u) << "tilt " << tilt << ": the four corners' two triangles";
        EXPECT_LE(sliding.error, eps);
        EXPECT_EQ(bad_triangles(m, sliding.indices), 0u);
        for (uint32_t c : {0u, 32u, 33u * 32, 33u * 33 - 1})
            EXPECT_TRUE(referenced(sliding.indices).count(c)) << "corner " << c;
        // Without an error limit the corners go too, down to a single triangle's worth.
        const SimplifyResult all = run(m, 0);
        EXPECT_GE(all.indices.size() / 3, 1u);
        EXPECT_LE(all.indices.size() / 3, 2u);
        EXPECT_EQ(bad_triangles(m, all.indices), 0u);
    }
}

TEST(Simplify, MaxErrorIsRespectedAndStopsEarly) {
    const TestMesh m = icosphere(4, 0.01);
    const SimplifyResult unlimited = run(m, 0);
    ASSERT_GT(unlimited.error, 0);
    for (double fraction : {0.02, 0.1, 0.5}) {
        const double limit = unlimited.error * fraction;
        const SimplifyResult r = run(m, 0, nullptr, limit);
        EXPECT_LE(r.error, limit);
        EXPECT_GT(r.error, 0) << "something was simplified";
        EXPECT_GT(r.indices.size(), unlimited.indices.size()) << "stopped early at " << fraction;
        EXPECT_LT(r.indices.size(), m.indices.size());
    }
    // Nothing on a noisy sphere is free.
    const SimplifyResult none = run(m, 0, nullptr, 0);
    EXPECT_EQ(none.error, 0);
    EXPECT_EQ(none.indices, m.indices);
}

TEST(Simplify, ErrorIsMonotoneInTarget) {
    const TestMesh m = icosphere(4, 0.02, 7);
    double previous = 0;
    size_t previous_count = m.triangles() + 1;
    for (size_t target : {5000u, 4000u, 3000u, 2000u, 1200u, 600u, 300u, 100u, 20u}) {
        const SimplifyResult r = run(m, target);
        EXPECT_GE(r.error, previous) << "target " << target;
        EXPECT_LT(r.indices.size() / 3, previous_count);
        previous = r.error;
        previous_count = r.indices.size() / 3;
    }
}

TEST(Simplify, DeterministicAcrossRuns) {
    const TestMesh m = icosphere(4, 0.03, 3);
    std::vector<uint8_t> locked(m.positions.size(), 0);
    for (size_t v = 0; v < locked.size(); v += 11) locked[v] = 1;
    const SimplifyResult a = run(m, 1000, &locked), b = run(m, 1000, &locked);
    EXPECT_EQ(a.indices, b.indices);
    EXPECT_EQ(a.error, b.error);
}

TEST(Simplify, TranslationFarFromOriginGivesTheSameResult) {
    // Coordinates on a 2^-12 grid, so adding 2^20 is exact: the internal recentring makes the
    // far mesh simplify exactly like the near one (without it, quadrics lose their precision).
    TestMesh near = icosphere(3, 0.02, 5);
    for (V3& p : near.positions)
        for (double& c : p) c = std::round(c * 4096) / 4096;
    TestMesh far = near;
    for (V3& p : far.positions) p = {p[0] + 1048576, p[1] + 2097152, p[2] - 1048576};
    const SimplifyResult a = run(near, 300), b = run(far, 300);
    EXPECT_EQ(a.indices, b.indices);
    EXPECT_EQ(a.error, b.error);
}

TEST(Simplify, UnreferencedVerticesChangeNothing) {
    // The same mesh inside a larger vertex buffer whose other vertices are NaN (so reading them
    // would show): slightly larger (worked on in place) and much larger (compacted first).
    const TestMesh m = icosphere(3, 0.02, 11);
    std::vector<uint8_t> locked(m.positions.size(), 0);
    for (size_t v = 0; v < locked.size(); v += 5) locked[v] = 1;
    const SimplifyResult plain = run(m, 200, &locked);
    for (uint32_t spread : {2u, 9u}) {
        TestMesh padded;
        padded.positions.assign(m.positions.size() * spread, V3{NAN, NAN, NAN});
        std::vector<uint8_t> padded_locked(padded.positions.size(), 1);
        for (size_t v = 0; v < m.positions.size(); ++v) {
            padded.positions[v * spread + 1] = m.positions[v];
            padded_locked[v * spread + 1] = locked[v];
        }
        for (uint32_t v : m.indices) padded.indices.push_back(v * spread + 1);
        ASSERT_EQ(spread > 2, padded.positions.size() > padded.indices.size());
        const SimplifyResult r = run(padded, 200, &padded_locked);
        std::vector<uint32_t> back;
        for (uint32_t v : r.indices) back.push_back((v - 1) / spread);
        EXPECT_EQ(back, plain.indices) << "spread " << spread;
        EXPECT_EQ(r.error, plain.error);
    }
}

TEST(Simplify, EmptyInputSingleTriangleAndInvalidInput) {
    const SimplifyResult empty = simplify_mesh(nullptr, 0, nullptr, 0, nullptr, SimplifySettings{});
    EXPECT_TRUE(empty.indices.empty());
    EXPECT_EQ(empty.error, 0);

    TestMesh tri;
    tri.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    tri.indices = {0, 1, 2};
    const SimplifyResult one = run(tri, 0);
    EXPECT_EQ(one.indices, tri.indices) << "a lone triangle cannot lose a vertex without vanishing";
    EXPECT_EQ(one.error, 0);

    tri.indices = {0, 0, 1, 2, 1, 2};  // only degenerate triangles
    EXPECT_TRUE(run(tri, 0).indices.empty());
    tri.indices = {0, 1, 2, 0, 2, 1};  // a two-sided triangle: the second is a duplicate
    EXPECT_EQ(run(tri, 0).indices, std::vector<uint32_t>({0, 1, 2}));

    tri.indices = {0, 1};
    EXPECT_THROW(run(tri, 0), std::invalid_argument);
    tri.indices = {0, 1, 3};
    EXPECT_THROW(run(tri, 0), std::invalid_argument);
}

TEST(Simplify, NonManifoldEdgesDoNotCrashAndKeepTheirVertices) {
    // Three bumpy sheets, 120 degrees apart, hinged on a common spine of n edges along the z axis:
    // every spine edge is used by three triangles.
    TestMesh m;
    const int n = 16;
    for (int i = 0; i <= n; ++i) m.positions.push_back({0, 0, double(i) / n});  // spine: ids 0..n
    for (int sheet = 0; sheet < 3; ++sheet) {
        const double angle = 2.0943951023931953 * sheet;
        const uint32_t base = uint32_t(m.positions.size());
        auto id = [&](int i, int j) { return j == 0 ? uint32_t(i) : base + uint32_t(i * n + (j - 1)); };
        for (int i = 0; i <= n; ++i)
            for (int j = 1; j <= n; ++j) {
                const double d = double(j) / n, bump = 0.02 * std::sin(5.0 * j + 3.0 * i + sheet);
                m.positions.push_back({std::cos(angle) * d - std::sin(angle) * bump,
                                       std::sin(angle) * d + std::cos(angle) * bump, double(i) / n});
            }
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) {
                const uint32_t p = id(i, j), q = id(i + 1, j), r = id(i, j + 1), t = id(i + 1, j + 1);
                m.indices.insert(m.indices.end(), {p, r, q, q, r, t});
            }
    }
    const auto use_in = edge_use(m.indices);
    for (uint32_t i = 0; i < uint32_t(n); ++i) ASSERT_EQ(use_in.at({i, i + 1}), 3);

    const SimplifyResult r = run(m, 0);
    EXPECT_LT(r.indices.size(), m.indices.size() / 3) << "the sheets were simplified";
    const std::set<uint32_t> out = referenced(r.indices);
    const auto use_out = edge_use(r.indices);
    for (uint32_t i = 0; i <= uint32_t(n); ++i) EXPECT_TRUE(out.count(i)) << "spine vertex " << i << " was removed";
    for (uint32_t i = 0; i < uint32_t(n); ++i) {
        const auto it = use_out.find({i, i + 1});
        EXPECT_TRUE(it != use_out.end() && it->second == 3) << "spine edge " << i << " lost its three sheets";
    }
    for (const auto& [e, count] : use_out)
        if (e.second != e.first + 1 || e.second > uint32_t(n)) {
            EXPECT_LE(count, 2) << "new non-manifold edge";
        }
    EXPECT_EQ(bad_triangles(m, r.indices), 0u);
}

TEST(Simplify, HighValenceFansAndBowTieVertexAreHandled) {
    // Two closed bumpy cones touching at their apex (vertex 0, a bow tie: two fans of 48
    // triangles), each closed by a base fan of 48 triangles around a centre; plus a duplicate of
    // an apex triangle in reversed winding. Large fans take the sorted-query paths.
    TestMesh m;
    const int n = 48;
    m.positions.push_back({0, 0, 0});
    for (int cone = 0; cone < 2; ++cone) {
        const double z = cone == 0 ? 1 : -1;
        const uint32_t centre = uint32_t(m.positions.size());
        m.positions.push_back({0, 0, z});
        for (int i = 0; i < n; ++i) {
            const double a = 6.283185307179586 * i / n, r = 1 + 0.05 * std::sin(5.0 * i);
            m.positions.push_back({r * std::cos(a), r * std::sin(a), z * (1 + 0.03 * std::cos(7.0 * i))});
        }
        for (int i = 0; i < n; ++i) {
            const uint32_t p = centre + 1 + uint32_t(i), q = centre + 1 + uint32_t((i + 1) % n);
            if (cone == 0) {
                m.indices.insert(m.indices.end(), {0, p, q, centre, q, p});
            } else {
                m.indices.insert(m.indices.end(), {0, q, p, centre, p, q});
            }
        }
    }
    bool ok = false;
    ASSERT_EQ(euler_closed_manifold(m.indices, ok), 3);
    ASSERT_TRUE(ok);
    TestMesh dirty = m;
    dirty.indices.insert(dirty.indices.end(), {m.indices[2], m.indices[1], m.indices[0]});
    const SimplifyResult r = run(dirty, 0);
    EXPECT_LT(r.indices.size(), m.indices.size() / 4);
    EXPECT_TRUE(referenced(r.indices).count(0)) << "the bow-tie apex is locked";
    EXPECT_EQ(euler_closed_manifold(r.indices, ok), 3) << "still two closed surfaces sharing a vertex";
    EXPECT_TRUE(ok);
    EXPECT_EQ(bad_triangles(dirty, r.indices), 0u);
}

TEST(Simplify, RemovedVerticesLieWithinThreeTimesTheReportedErrorOfTheOutput) {
    // Brute-force one-sided Hausdorff distance from every removed input vertex to the output.
    for (uint64_t seed : {1u, 2u}) {
        const TestMesh m = icosphere(4, 0.01, seed);  // 5120 triangles, noise 1% of the radius
        for (size_t target : {1280u, 320u}) {
            const SimplifyResult r = run(m, target);
            ASSERT_GT(r.error, 0);
            const std::set<uint32_t> kept = referenced(r.indices);
            double worst = 0;
            for (uint32_t v = 0; v < m.positions.size(); ++v) {
                if (kept.count(v)) continue;
                double best = INFINITY;
                for (size_t t = 0; t < r.indices.size(); t += 3)
                    best = std::min(best, point_triangle_distance(m.positions[v], m.positions[r.indices[t]],
                                                              m.positions[r.indices[t + 1]],
                                                              m.positions[r.indices[t + 2]]));
                worst = std::max(worst, best);
            }
            EXPECT_LE(worst, 3 * r.error) << "seed " << seed << " target " << target << " error " << r.error;
            EXPECT_GT(worst, 0.2 * r.error) << "the reported error is not wildly pessimistic either";
        }
    }
}
