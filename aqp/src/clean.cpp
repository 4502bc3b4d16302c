// Input cleaning to an oriented two-manifold (aqp/clean.h): weld, degenerate and duplicate
// triangles, fan splitting of non-manifold edges and vertices, orientation, tiny components.
#include "aqp/clean.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <numeric>
#include <unordered_map>

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
// once per pass over the mesh, five times for a clean input).
std::vector<EdgeUse> edge_uses(const std::vector<Tri>& tris) {
    std::vector<EdgeUse> uses;
    uses.reserve(tris.size() * 3);
    for (uint32_t f = 0; f < tris.size(); ++f)
        for (uint8_t k = 0; k < 3; ++k) uses.push_back({edge_key(tris[f][k], tris[f][(k + 1) % 3]), f, k});
    const size_t n = uses.size();
    if (n < 4096) {
        std::stable_sort(uses.begin(), uses.end(), [](const EdgeUse& a, const EdgeUse& b) { return a.key < b.key; });
        return uses;
    }
    std::vector<EdgeUse> scratch(n);
    std::vector<uint32_t> start(size_t(1) << 16);
    for (int shift = 0; shift < 64; shift += 16) {
        std::fill(start.begin(), start.end(), 0u);
        for (const EdgeUse& u : uses) ++start[(u.key >> shift) & 0xffff];
        if (start[(uses[0].key >> shift) & 0xffff] == n) continue;
        uint32_t sum = 0;
        for (uint32_t& c : start) {
            const uint32_t count = c;
            c = sum;
            sum += count;
        }
        for (const EdgeUse& u : uses) scratch[start[(u.key >> shift) & 0xffff]++] = u;
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
    struct Key {
        uint64_t bits[3];
        bool operator==(const Key& o) const { return std::memcmp(bits, o.bits, sizeof bits) == 0; }
    };
    struct Hash {
        size_t operator()(const Key& k) const {
            uint64_t h = k.bits[0] * 0x9E3779B97F4A7C15ull;
            h ^= (k.bits[1] + 0x632BE59BD9B4E019ull) * 0xC2B2AE3D27D4EB4Full;
            h ^= (k.bits[2] + 0x165667B19E3779F9ull) * 0x85EBCA77C2B2AE63ull;
            return size_t(h ^ (h >> 29));
        }
    };
    std::unordered_map<Key, uint32_t, Hash> first;
    first.reserve(input.positions.size());
    std::vector<uint32_t> rep(input.positions.size());
    welded = 0;
    for (uint32_t v = 0; v < input.positions.size(); ++v) {
        Key key;
        for (int i = 0; i < 3; ++i) {
            double x = input.positions[v][i] + 0.0;  // -0 becomes +0
            std::memcpy(&key.bits[i], &x, 8);
        }
        auto [it, inserted] = first.emplace(key, v);
        rep[v] = it->second;
        if (!inserted) ++welded;
    }
    return rep;
}

// Orients each component by breadth-first search over two-triangle edges, keeping the
// orientation most of its triangles had. Returns the component of every triangle; throws on a
// non-orientable component.
std::vector<uint32_t> orient_components(std::vector<Tri>& tris, size_t& flipped, size_t& components) {
    std::vector<EdgeUse> uses = edge_uses(tris);
    std::vector<std::vector<std::pair<uint32_t, bool>>> next(tris.size());  // neighbour, same direction
    for_each_edge(uses, [&](size_t i, size_t j) {
        if (j - i != 2) return;
        bool same = edge_start(tris, uses[i]) == edge_start(tris, uses[i + 1]);
        next[uses[i].face].push_back({uses[i + 1].face, same});
        next[uses[i + 1].face].push_back({uses[i].face, same});
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
            for (auto [g, same] : next[f]) {
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
    add(welded_vertices, "vertices welded to an earlier vertex at the same position");
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
    std::vector<uint32_t> source(input.vertex_count());
    std::iota(source.begin(), source.end(), 0u);
    std::vector<Tri> tris;
    tris.reserve(input.triangle_count());
    std::unordered_map<uint64_t, std::vector<uint32_t>> seen;  // smallest corner -> triangles
    for (size_t t = 0; t < input.triangle_count(); ++t) {
        Tri tri{rep[input.indices[3 * t]], rep[input.indices[3 * t + 1]], rep[input.indices[3 * t + 2]]};
        if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] ||
            exactly_collinear(input.positions[tri[0]], input.positions[tri[1]], input.positions[tri[2]])) {
            ++r.degenerate_triangles;
            continue;
        }
        Tri sorted = tri;
        std::sort(sorted.begin(), sorted.end());
        std::vector<uint32_t>& same_first = seen[sorted[0]];
        bool duplicate = false;
        for (uint32_t other : same_first) {
            Tri o = tris[other];
            std::sort(o.begin(), o.end());
            if (o == sorted) duplicate = true;
        }
        if (duplicate) {
            ++r.duplicate_triangles;
            continue;
        }
        same_first.push_back(uint32_t(tris.size()));
        tris.push_back(tri);
    }
    seen.clear();
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
