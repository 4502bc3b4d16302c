// Input cleaning to an oriented two-manifold (aqp/clean.h): weld, degenerate and duplicate
// triangles, fan splitting of non-manifold edges and vertices, orientation, tiny components.
#include "aqp/clean.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <numeric>
#include <unordered_map>

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "base/error.h"
#include "common_codec/exact_predicates.h"

namespace catpaq::aqp {
namespace {

using Tri = std::array<uint32_t, 3>;

struct UnionFind {
    std::vector<uint32_t> parent;
    explicit UnionFind(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
    uint32_t find(uint32_t x) {
        while (parent[x] != x) x = parent[x] = parent[parent[x]];
        return x;
    }
    void unite(uint32_t a, uint32_t b) {
        a = find(a), b = find(b);
        if (a != b) parent[std::max(a, b)] = std::min(a, b);  // smallest index is the root
    }
};

uint64_t edge_key(uint32_t a, uint32_t b) { return a < b ? (uint64_t(a) << 32) | b : (uint64_t(b) << 32) | a; }

// A triangle's k-th edge runs from corner k to corner k+1.
struct EdgeUse {
    uint64_t key;
    uint32_t face;
    uint8_t k;
};

// Every (edge, triangle) use, sorted by edge then triangle: equal keys are one edge's triangles.
//
// Made in (face, k) order and sorted stably by key alone, which is the same order. The sort is
// an LSD radix sort in 16-bit digits (a digit every key shares skipped): std::sort on (key,
// face, k) was a quarter of the cleaning's time on a 1M-triangle scan (the uses are sorted
// once per pass over the mesh, three times for a clean input). Each pass counts and scatters
// kSortBlocks consecutive blocks of the uses in parallel, every block to its own offsets (the
// digit's earlier blocks first), so the order is the sequential sort's. (With the flat
// neighbour lists of orient_components and the sorted weld and duplicate search, the 1M scan's
// cleaning went from 1.31 to 0.90 s on 2 cores, the same output.)
std::vector<EdgeUse> edge_uses(const std::vector<Tri>& tris) {
    const size_t n = tris.size() * 3;
    std::vector<EdgeUse> uses(n);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, tris.size(), 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t f = r.begin(); f < r.end(); ++f)
            for (uint8_t k = 0; k < 3; ++k)
                uses[3 * f + k] = {edge_key(tris[f][k], tris[f][(k + 1) % 3]), uint32_t(f), k};
    });
    if (n < 4096) {
        std::stable_sort(uses.begin(), uses.end(), [](const EdgeUse& a, const EdgeUse& b) { return a.key < b.key; });
        return uses;
    }
    constexpr size_t kSortBlocks = 4, kBuckets = size_t(1) << 16;
    auto block_begin = [n](size_t b) { return n * b / kSortBlocks; };
    std::vector<EdgeUse> scratch(n);
    std::vector<uint32_t> counts(kSortBlocks * kBuckets);
    for (int shift = 0; shift < 64; shift += 16) {
        tbb::parallel_for(size_t(0), kSortBlocks, [&](size_t b) {
            uint32_t* c = &counts[b * kBuckets];
            std::fill(c, c + kBuckets, 0u);
            for (size_t i = block_begin(b); i < block_begin(b + 1); ++i) ++c[(uses[i].key >> shift) & 0xffff];
        });
        const size_t first = (uses[0].key >> shift) & 0xffff;
        size_t same = 0;
        for (size_t b = 0; b < kSortBlocks; ++b) same += counts[b * kBuckets + first];
        if (same == n) continue;
        uint32_t sum = 0;
        for (size_t d = 0; d < kBuckets; ++d)
            for (size_t b = 0; b < kSortBlocks; ++b) {
                uint32_t& c = counts[b * kBuckets + d];
                const uint32_t count = c;
                c = sum;
                sum += count;
            }
        tbb::parallel_for(size_t(0), kSortBlocks, [&](size_t b) {
            uint32_t* c = &counts[b * kBuckets];
            for (size_t i = block_begin(b); i < block_begin(b + 1); ++i) scratch[c[(uses[i].key >> shift) & 0xffff]++] = uses[i];
        });
        uses.swap(scratch);
    }
    return uses;
}

// Calls fn(begin, end) for each run of uses of one edge.
template <class Fn>
void for_each_edge(const std::vector<EdgeUse>& uses, Fn&& fn) {
    for (size_t i = 0; i < uses.size();) {
        size_t j = i + 1;
        while (j < uses.size() && uses[j].key == uses[i].key) ++j;
        fn(i, j);
        i = j;
    }
}

uint32_t edge_start(const std::vector<Tri>& tris, const EdgeUse& u) { return tris[u.face][u.k]; }

// Corner (face * 3 + k) of `face` at vertex `v`.
uint32_t corner_at(const std::vector<Tri>& tris, uint32_t face, uint32_t v) {
    for (uint32_t k = 0; k < 3; ++k)
        if (tris[face][k] == v) return face * 3 + k;
    return face * 3;  // unreachable for a vertex of the face
}

// The pairs of triangles joined across each edge: all two-triangle edges; on an edge with more,
// the first triangle and the first later one running the edge the other way (else the second).
// Returns the number of edges with three or more triangles.
size_t joined_pairs(const std::vector<Tri>& tris, const std::vector<EdgeUse>& uses,
                    std::vector<std::pair<EdgeUse, EdgeUse>>& pairs) {
    pairs.clear();
    size_t nonmanifold = 0;
    for_each_edge(uses, [&](size_t i, size_t j) {
        if (j - i < 2) return;
        if (j - i == 2) {
            pairs.push_back({uses[i], uses[i + 1]});
            return;
        }
        ++nonmanifold;
        size_t partner = i + 1;
        for (size_t m = i + 1; m < j; ++m)
            if (edge_start(tris, uses[m]) != edge_start(tris, uses[i])) {
                partner = m;
                break;
            }
        pairs.push_back({uses[i], uses[partner]});
    });
    return nonmanifold;
}

// Gives every vertex one copy per fan of corners joined through `pairs`. Returns the number of
// copies made and counts the vertices that had more than one fan.
size_t split_fans(std::vector<Tri>& tris, std::vector<uint32_t>& source, const std::vector<std::pair<EdgeUse, EdgeUse>>& pairs,
                  size_t* split_vertex_count) {
    UnionFind corners(tris.size() * 3);
    for (const auto& [a, b] : pairs) {
        for (uint32_t v : {tris[a.face][a.k], tris[a.face][(a.k + 1) % 3]})
            corners.unite(corner_at(tris, a.face, v), corner_at(tris, b.face, v));
    }
    // The first fan of a vertex (in corner order) keeps its index; later fans get new vertices.
    std::unordered_map<uint32_t, uint32_t> fan_vertex;  // fan root corner -> vertex
    std::vector<uint32_t> first_root(source.size(), UINT32_MAX);
    std::vector<uint8_t> counted(source.size(), 0);
    size_t copies = 0, split = 0;
    std::vector<Tri> out = tris;
    for (uint32_t c = 0; c < tris.size() * 3; ++c) {
        uint32_t v = tris[c / 3][c % 3], root = corners.find(c);
        if (first_root[v] == UINT32_MAX) first_root[v] = root;
        if (root == first_root[v]) continue;
        auto [it, inserted] = fan_vertex.emplace(root, uint32_t(source.size()));
        if (inserted) {
            source.push_back(source[v]);
            ++copies;
            if (!counted[v]) counted[v] = 1, ++split;
        }
        out[c / 3][c % 3] = it->second;
    }
    tris.swap(out);
    if (split_vertex_count) *split_vertex_count = split;
    return copies;
}

// Removes every triangle on an edge with more than two triangles except the joined pair.
size_t remove_extra_triangles(std::vector<Tri>& tris) {
    std::vector<EdgeUse> uses = edge_uses(tris);
    std::vector<std::pair<EdgeUse, EdgeUse>> pairs;
    joined_pairs(tris, uses, pairs);
    std::vector<uint8_t> keep(tris.size(), 1);
    // The joined pair of each edge with more than two triangles (usually none: a map of every
    // pair was a tenth of the cleaning's time on a 1M-triangle scan).
    std::unordered_map<uint64_t, std::pair<uint32_t, uint32_t>> joined;
    for_each_edge(uses, [&](size_t i, size_t j) {
        if (j - i > 2) joined.emplace(uses[i].key, std::pair<uint32_t, uint32_t>{0, 0});
    });
    if (joined.empty()) return 0;
    for (const auto& [a, b] : pairs) {
        auto it = joined.find(a.key);
        if (it != joined.end()) it->second = {a.face, b.face};
    }
    for_each_edge(uses, [&](size_t i, size_t j) {
        if (j - i <= 2) return;
        auto pair = joined[uses[i].key];
        for (size_t m = i; m < j; ++m)
            if (uses[m].face != pair.first && uses[m].face != pair.second) keep[uses[m].face] = 0;
    });
    std::vector<Tri> out;
    for (size_t f = 0; f < tris.size(); ++f)
        if (keep[f]) out.push_back(tris[f]);
    size_t removed = tris.size() - out.size();
    tris.swap(out);
    return removed;
}

double triangle_area(const Mesh& mesh, const std::vector<uint32_t>& source, const Tri& t) {
    const Vec3d& a = mesh.positions[source[t[0]]];
    const Vec3d& b = mesh.positions[source[t[1]]];
    const Vec3d& c = mesh.positions[source[t[2]]];
    double u[3], v[3];
    for (int i = 0; i < 3; ++i) u[i] = b[i] - a[i], v[i] = c[i] - a[i];
    double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    return 0.5 * std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
}

bool exactly_collinear(const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    return orient2d(a.data(), b.data(), c.data(), 0, 1) == 0 && orient2d(a.data(), b.data(), c.data(), 1, 2) == 0 &&
           orient2d(a.data(), b.data(), c.data(), 0, 2) == 0;
}

// Welds bit-equal positions: returns the representative of every input vertex.
std::vector<uint32_t> weld_equal_positions(const Mesh& input, size_t& welded) {
    // Every vertex goes to the first with the same position bits: the vertices sorted by (bits,
    // index), in parallel, each run to its first. (A hash map of first vertices did the same in
    // 2.5 times the time on a 1M-triangle scan.)
    struct Keyed {
        uint64_t bits[3];
        uint32_t vertex;
        bool operator<(const Keyed& o) const {
            for (int i = 0; i < 3; ++i)
                if (bits[i] != o.bits[i]) return bits[i] < o.bits[i];
            return vertex < o.vertex;
        }
        bool same_place(const Keyed& o) const { return std::memcmp(bits, o.bits, sizeof bits) == 0; }
    };
    const size_t n = input.positions.size();
    std::vector<Keyed> keyed(n);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t v = r.begin(); v < r.end(); ++v) {
            for (int i = 0; i < 3; ++i) {
                double x = input.positions[v][i] + 0.0;  // -0 becomes +0
                std::memcpy(&keyed[v].bits[i], &x, 8);
            }
            keyed[v].vertex = uint32_t(v);
        }
    });
    tbb::parallel_sort(keyed.begin(), keyed.end());
    std::vector<uint32_t> rep(n);
    welded = 0;
    for (size_t i = 0; i < n; ++i) {
        const bool first = i == 0 || !keyed[i].same_place(keyed[i - 1]);
        rep[keyed[i].vertex] = first ? keyed[i].vertex : rep[keyed[i - 1].vertex];
        welded += !first;
    }
    return rep;
}

// Welds, after weld_equal_positions, the ends of every edge shorter than a billionth of the
// model's diagonal (each to the smaller index of its group; `welded` counts them too).
// Coordinates computed with rounding leave rings of distinct vertices a few ulps apart: a UV
// sphere's south pole from sin(pi) = 1.2e-16 was a ring of 80 vertices, a fan of needles the
// domain's simplification could not remove (it stopped at 478 triangles, asking for more).
// Only vertices that a triangle joins are welded: separate sheets that nearly touch stay apart.
void weld_short_edges(const Mesh& input, std::vector<uint32_t>& rep, size_t& welded) {
    const size_t n = input.positions.size();
    const double limit = 1e-9 * input.bounds().diagonal(), limit2 = limit * limit;
    if (!(limit2 > 0)) return;
    std::vector<uint32_t> parent(n);
    std::iota(parent.begin(), parent.end(), 0u);
    auto find = [&parent](uint32_t v) {
        while (parent[v] != v) {
            parent[v] = parent[parent[v]];
            v = parent[v];
        }
        return v;
    };
    for (size_t i = 0; i < input.indices.size(); i += 3)
        for (int k = 0; k < 3; ++k) {
            const uint32_t a = rep[input.indices[i + size_t(k)]], b = rep[input.indices[i + size_t(k + 1) % 3]];
            if (a == b) continue;
            const Vec3d &p = input.positions[a], &q = input.positions[b];
            const double d2 =
                (p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) + (p[2] - q[2]) * (p[2] - q[2]);
            if (d2 > limit2) continue;
            const uint32_t ra = find(a), rb = find(b);
            if (ra == rb) continue;
            parent[std::max(ra, rb)] = std::min(ra, rb);
            ++welded;
        }
    for (uint32_t& r : rep) r = find(r);
}

// Orients each component by breadth-first search over two-triangle edges, keeping the
// orientation most of its triangles had. Returns the component of every triangle; throws on a
// non-orientable component.
std::vector<uint32_t> orient_components(std::vector<Tri>& tris, size_t& flipped, size_t& components) {
    std::vector<EdgeUse> uses = edge_uses(tris);
    // Each triangle's neighbours across its (at most three) two-triangle edges, and whether they
    // run them the same way, in the order of the sorted edges. (Flat: a list per triangle was a
    // million allocations on a 1M-triangle scan.)
    struct Neighbour {
        uint32_t face;
        bool same;
    };
    std::vector<std::array<Neighbour, 3>> next(tris.size());
    std::vector<uint8_t> next_count(tris.size(), 0);
    for_each_edge(uses, [&](size_t i, size_t j) {
        if (j - i != 2) return;
        bool same = edge_start(tris, uses[i]) == edge_start(tris, uses[i + 1]);
        const uint32_t a = uses[i].face, b = uses[i + 1].face;
        next[a][next_count[a]++] = {b, same};
        next[b][next_count[b]++] = {a, same};
    });
    std::vector<uint32_t> component(tris.size(), UINT32_MAX);
    std::vector<uint8_t> flip(tris.size(), 0);
    flipped = components = 0;
    std::vector<uint32_t> queue, members;
    for (uint32_t seed = 0; seed < tris.size(); ++seed) {
        if (component[seed] != UINT32_MAX) continue;
        uint32_t id = uint32_t(components++);
        queue.assign(1, seed);
        members.clear();
        component[seed] = id;
        for (size_t q = 0; q < queue.size(); ++q) {
            uint32_t f = queue[q];
            members.push_back(f);
            for (uint8_t e = 0; e < next_count[f]; ++e) {
                const auto [g, same] = next[f][e];
                uint8_t want = flip[f] ^ uint8_t(same);
                if (component[g] == UINT32_MAX) {
                    component[g] = id;
                    flip[g] = want;
                    queue.push_back(g);
                } else if (flip[g] != want) {
                    fail("the surface is not orientable (a Moebius strip or similar, component %u near triangle %u): "
                         "AQP needs an orientable surface",
                         id, f);
                }
            }
        }
        size_t reversed = 0;
        for (uint32_t f : members) reversed += flip[f];
        bool invert = reversed * 2 > members.size();
        for (uint32_t f : members) {
            if (invert) flip[f] ^= 1;
            if (flip[f]) {
                std::swap(tris[f][1], tris[f][2]);
                ++flipped;
            }
        }
    }
    return component;
}

// Border edges, border loops and genus of the oriented manifold `tris` (vertex ids < n).
void count_topology(const std::vector<Tri>& tris, const std::vector<uint32_t>& component, size_t components, size_t n,
                    CleanReport& r) {
    std::vector<EdgeUse> uses = edge_uses(tris);
    std::vector<int64_t> euler(components, 0);  // V - E + F per component
    std::vector<int64_t> loops(components, 0);
    std::vector<uint32_t> vertex_component(n, UINT32_MAX);
    for (uint32_t f = 0; f < tris.size(); ++f) {
        euler[component[f]] += 1;
        for (uint32_t v : tris[f]) vertex_component[v] = component[f];
    }
    for (uint32_t v = 0; v < n; ++v)
        if (vertex_component[v] != UINT32_MAX) euler[vertex_component[v]] += 1;
    UnionFind border(n);
    std::vector<uint8_t> on_border(n, 0);
    r.border_edges = 0;
    for_each_edge(uses, [&](size_t i, size_t j) {
        euler[component[uses[i].face]] -= 1;
        if (j - i != 1) return;
        ++r.border_edges;
        uint32_t a = tris[uses[i].face][uses[i].k], b = tris[uses[i].face][(uses[i].k + 1) % 3];
        border.unite(a, b);
        on_border[a] = on_border[b] = 1;
    });
    r.border_loops = 0;
    for (uint32_t v = 0; v < n; ++v)
        if (on_border[v] && border.find(v) == v) {
            ++r.border_loops;
            ++loops[vertex_component[v]];
        }
    r.genus = 0;
    for (size_t c = 0; c < components; ++c) r.genus += int((2 - euler[c] - loops[c]) / 2);
}

}  // namespace

std::vector<std::string> CleanReport::summary() const {
    std::vector<std::string> lines;
    auto add = [&](size_t n, const char* what) {
        if (n) lines.push_back(strprintf("%zu %s", n, what));
    };
    add(welded_vertices, "vertices welded to an earlier vertex at the same position or within a billionth of the "
                         "diagonal along an edge");
    add(degenerate_triangles, "degenerate triangles removed (repeated or collinear corners)");
    add(duplicate_triangles, "duplicate triangles removed");
    add(nonmanifold_edges, "non-manifold edges (three or more triangles) split");
    add(nonmanifold_vertices, "non-manifold vertices (several fans) split");
    add(split_vertices, "vertex copies made by splitting");
    add(nonmanifold_triangles_removed, "triangles removed from edges splitting could not make manifold");
    add(flipped_triangles, "triangles reversed to orient their component consistently");
    if (dropped_components)
        lines.push_back(strprintf("%zu tiny components dropped (%zu triangles)", dropped_components,
                                  dropped_component_triangles));
    add(unreferenced_vertices, "unused vertices dropped");
    return lines;
}

CleanMesh clean_to_manifold(const Mesh& input, const CleanOptions& options, CleanReport* report) {
    validate_mesh(input, "AQP input");
    if (input.triangle_count() == 0) fail("the input mesh has no triangles");
    CleanReport r;
    r.input_vertices = input.vertex_count();
    r.input_triangles = input.triangle_count();

    // 1-3: weld, degenerate and duplicate triangles. `source` maps working vertex ids (input ids,
    // later with fan copies appended) to input vertices.
    std::vector<uint32_t> rep = weld_equal_positions(input, r.welded_vertices);
    weld_short_edges(input, rep, r.welded_vertices);
    std::vector<uint32_t> source(input.vertex_count());
    std::iota(source.begin(), source.end(), 0u);
    // A triangle is degenerate, the first with its corners (kept), or a duplicate of that one:
    // decided in parallel, the duplicates by sorting the triangles by (sorted corners, index).
    const size_t input_triangles = input.triangle_count();
    enum : uint8_t { kKept, kDegenerate, kDuplicate };
    std::vector<uint8_t> fate(input_triangles, kKept);
    struct Corners {
        Tri sorted;
        uint32_t triangle;
        bool operator<(const Corners& o) const { return sorted != o.sorted ? sorted < o.sorted : triangle < o.triangle; }
    };
    std::vector<Corners> corners(input_triangles);
    auto welded_triangle = [&](size_t t) {
        return Tri{rep[input.indices[3 * t]], rep[input.indices[3 * t + 1]], rep[input.indices[3 * t + 2]]};
    };
    tbb::parallel_for(tbb::blocked_range<size_t>(0, input_triangles, 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t t = r.begin(); t < r.end(); ++t) {
            const Tri tri = welded_triangle(t);
            Tri sorted = tri;
            std::sort(sorted.begin(), sorted.end());
            corners[t] = {sorted, uint32_t(t)};
            if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] ||
                exactly_collinear(input.positions[tri[0]], input.positions[tri[1]], input.positions[tri[2]])) {
                fate[t] = kDegenerate;
                corners[t].sorted = {UINT32_MAX, UINT32_MAX, UINT32_MAX};  // (sorted last, never compared)
            }
        }
    });
    tbb::parallel_sort(corners.begin(), corners.end());
    for (size_t i = 1; i < input_triangles; ++i)
        if (fate[corners[i].triangle] != kDegenerate && corners[i].sorted == corners[i - 1].sorted)
            fate[corners[i].triangle] = kDuplicate;
    std::vector<Corners>().swap(corners);
    std::vector<Tri> tris;
    tris.reserve(input_triangles);
    for (size_t t = 0; t < input_triangles; ++t) {
        r.degenerate_triangles += fate[t] == kDegenerate;
        r.duplicate_triangles += fate[t] == kDuplicate;
        if (fate[t] == kKept) tris.push_back(welded_triangle(t));
    }
    if (tris.empty()) fail("the input mesh has no triangle with area (all %zu are degenerate)", r.input_triangles);

    // 4: split fans until no edge has more than two triangles, then remove what still does.
    std::vector<std::pair<EdgeUse, EdgeUse>> pairs;
    for (int round = 0; round < 4; ++round) {
        size_t nonmanifold = joined_pairs(tris, edge_uses(tris), pairs);
        size_t split = 0;
        size_t copies = split_fans(tris, source, pairs, &split);
        if (round == 0) r.nonmanifold_edges = nonmanifold, r.nonmanifold_vertices = split;
        r.split_vertices += copies;
        if (nonmanifold == 0 && copies == 0) break;
    }
    r.nonmanifold_triangles_removed = remove_extra_triangles(tris);
    if (r.nonmanifold_triangles_removed) {
        joined_pairs(tris, edge_uses(tris), pairs);
        r.split_vertices += split_fans(tris, source, pairs, nullptr);
    }

    // 5: orientation.
    size_t components = 0;
    std::vector<uint32_t> component = orient_components(tris, r.flipped_triangles, components);

    // 6: tiny components.
    std::vector<double> area(components, 0.0);
    std::vector<size_t> count(components, 0);
    double total_area = 0;
    for (size_t f = 0; f < tris.size(); ++f) {
        double a = triangle_area(input, source, tris[f]);
        area[component[f]] += a;
        total_area += a;
        ++count[component[f]];
    }
    std::vector<uint8_t> keep_component(components, 1);
    for (size_t c = 0; c < components; ++c)
        if (!(area[c] >= options.min_component_area_fraction * total_area) || area[c] <= 0) {
            keep_component[c] = 0;
            ++r.dropped_components;
            r.dropped_component_triangles += count[c];
        }
    if (r.dropped_components == components) fail("no component of the input has any area after cleaning");

    // 7: compact: kept triangles, their vertices in first-use order, components renumbered.
    CleanMesh out;
    std::vector<uint32_t> new_index(source.size(), UINT32_MAX), new_component(components, UINT32_MAX);
    std::vector<Tri> kept;
    std::vector<uint32_t> kept_component;
    size_t kept_components = 0;
    for (size_t f = 0; f < tris.size(); ++f) {
        if (!keep_component[component[f]]) continue;
        if (new_component[component[f]] == UINT32_MAX) new_component[component[f]] = uint32_t(kept_components++);
        Tri t;
        for (int k = 0; k < 3; ++k) {
            uint32_t v = tris[f][k];
            if (new_index[v] == UINT32_MAX) {
                new_index[v] = uint32_t(out.source_vertex.size());
                out.source_vertex.push_back(source[v]);
            }
            t[k] = new_index[v];
        }
        kept.push_back(t);
        kept_component.push_back(new_component[component[f]]);
    }
    r.unreferenced_vertices = input.vertex_count() + r.split_vertices - out.source_vertex.size() - r.welded_vertices;
    Mesh& m = out.mesh;
    m.positions.reserve(out.source_vertex.size());
    for (uint32_t s : out.source_vertex) m.positions.push_back(input.positions[s]);
    if (input.has_normals())
        for (uint32_t s : out.source_vertex) m.normals.push_back(input.normals[s]);
    if (input.has_colors())
        for (uint32_t s : out.source_vertex) m.colors.push_back(input.colors[s]);
    m.indices.reserve(kept.size() * 3);
    for (const Tri& t : kept) m.indices.insert(m.indices.end(), t.begin(), t.end());

    r.vertices = m.vertex_count();
    r.triangles = m.triangle_count();
    r.components = kept_components;
    count_topology(kept, kept_component, kept_components, m.vertex_count(), r);
    if (report) *report = r;
    return out;
}

bool is_oriented_manifold(const Mesh& mesh, std::string* why) {
    std::vector<Tri> tris(mesh.triangle_count());
    for (size_t f = 0; f < tris.size(); ++f)
        tris[f] = {mesh.indices[3 * f], mesh.indices[3 * f + 1], mesh.indices[3 * f + 2]};
    auto problem = [&](const std::string& text) {
        if (why) *why = text;
        return false;
    };
    for (size_t f = 0; f < tris.size(); ++f)
        if (tris[f][0] == tris[f][1] || tris[f][1] == tris[f][2] || tris[f][0] == tris[f][2])
            return problem(strprintf("triangle %zu repeats a vertex", f));
    std::vector<EdgeUse> uses = edge_uses(tris);
    std::vector<std::pair<EdgeUse, EdgeUse>> pairs;
    std::string first;
    for_each_edge(uses, [&](size_t i, size_t j) {
        if (!first.empty()) return;
        if (j - i > 2) first = strprintf("an edge has %zu triangles", j - i);
        if (j - i == 2) {
            if (edge_start(tris, uses[i]) == edge_start(tris, uses[i + 1]))
                first = strprintf("triangles %u and %u run their shared edge the same way", uses[i].face, uses[i + 1].face);
            pairs.push_back({uses[i], uses[i + 1]});
        }
    });
    if (!first.empty()) return problem(first);
    std::vector<uint32_t> source(mesh.vertex_count());
    std::iota(source.begin(), source.end(), 0u);
    size_t split = 0;
    if (split_fans(tris, source, pairs, &split) != 0) return problem(strprintf("%zu vertices have several fans", split));
    return true;
}

}  // namespace catpaq::aqp
