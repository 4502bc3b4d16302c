#include "catp/builder.h"

#include <algorithm>
#include <cassert>
#include <atomic>
#include <cmath>
#include <cstring>
#include <mutex>
#include <unordered_map>

#include <tbb/enumerable_thread_specific.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include "base/error.h"
#include "base/progress.h"
#include "base/sysinfo.h"
#include "catp/format.h"
#include "catp/simplify.h"
#include "clip.h"
#include "common_codec/archive.h"
#include "common_codec/exact_predicates.h"
#include "common_codec/octahedral.h"
#include "common_codec/packed_vertex.h"
#include "fragment_build.h"

namespace catpaq {

namespace {

// ----------------------------------------------------------------------------------------------
// Placement of the model in the lattice.

struct Placement {
    double origin[3];
    double cell;  // world units per lattice unit (a power of two)
};

Placement place_model(const Bounds& b) {
    double extent = 0;
    for (int i = 0; i < 3; ++i) extent = std::max(extent, b.max[i] - b.min[i]);
    if (!(extent > 0) || !std::isfinite(extent))
        fail("the model has zero extent (all vertices coincide): nothing to build a hierarchy over");
    // A power-of-two cube with at least 3% margin on every side, so no geometry touches the root
    // cube's boundary and the lattice mapping is an exact power-of-two scaling.
    double side = std::exp2(std::ceil(std::log2(extent * 1.0625)));
    Placement p;
    p.cell = side / double(kLatticeSize);
    for (int i = 0; i < 3; ++i) {
        double centre = 0.5 * (b.min[i] + b.max[i]);
        p.origin[i] = std::floor((centre - 0.5 * side) / p.cell) * p.cell;
        if (b.min[i] < p.origin[i] || b.max[i] > p.origin[i] + side)
            fail("cannot place the model in a lattice cube (coordinates too large for double precision?)");
    }
    return p;
}

// ----------------------------------------------------------------------------------------------
// Tetrahedra by explicit bisection (cheap, used to find the leaves a triangle overlaps).

int64_t len2(const LatticePoint& a, const LatticePoint& b) {
    int64_t s = 0;
    for (int i = 0; i < 3; ++i) s += int64_t(a[i] - b[i]) * (a[i] - b[i]);
    return s;
}

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

// Conservative rejection: true if all points are strictly outside one face (with a margin, so
// floating-point error can only make it keep a tetrahedron that the exact clipper then rejects).
bool separated(const Tetrahedron& t, const Vec3d* pts, int count) {
    // Axis-aligned boxes first: cheap and rejects most candidates.
    for (int i = 0; i < 3; ++i) {
        double tmin = std::min({t[0][i], t[1][i], t[2][i], t[3][i]}), tmax = std::max({t[0][i], t[1][i], t[2][i], t[3][i]});
        bool below = true, above = true;
        for (int k = 0; k < count; ++k) {
            below &= pts[k][i] < tmin - 1e-6;
            above &= pts[k][i] > tmax + 1e-6;
        }
        if (below || above) return true;
    }
    for (int f = 0; f < 4; ++f) {
        const LatticePoint &a = t[(f + 1) % 4], &b = t[(f + 2) % 4], &c = t[(f + 3) % 4], &o = t[f];
        double u[3], v[3], n[3];
        for (int i = 0; i < 3; ++i) {
            u[i] = double(b[i] - a[i]);
            v[i] = double(c[i] - a[i]);
        }
        n[0] = u[1] * v[2] - u[2] * v[1];
        n[1] = u[2] * v[0] - u[0] * v[2];
        n[2] = u[0] * v[1] - u[1] * v[0];
        double so = n[0] * (o[0] - a[0]) + n[1] * (o[1] - a[1]) + n[2] * (o[2] - a[2]);
        double sign = so > 0 ? 1.0 : -1.0;
        double scale = std::fabs(n[0]) + std::fabs(n[1]) + std::fabs(n[2]);
        bool all_out = true;
        for (int k = 0; k < count && all_out; ++k) {
            double s = sign * (n[0] * (pts[k][0] - a[0]) + n[1] * (pts[k][1] - a[1]) + n[2] * (pts[k][2] - a[2]));
            all_out = s < -1e-6 * scale;
        }
        if (all_out) return true;
    }
    return false;
}

// Calls f(tetrahedron) for every tetrahedron of `level` the points may overlap.
template <typename F>
void for_each_overlapping_tetrahedron(const Vec3d* pts, int count, int level, F&& f) {
    int octave = level / 3;
    int32_t side = kLatticeSize >> octave;
    int32_t lo[3], hi[3];
    for (int i = 0; i < 3; ++i) {
        double mn = pts[0][i], mx = pts[0][i];
        for (int k = 1; k < count; ++k) {
            mn = std::min(mn, pts[k][i]);
            mx = std::max(mx, pts[k][i]);
        }
        // ceil - 1, not floor: geometry exactly on a cube boundary plane belongs to both cubes (a
        // triangle lying in that plane is kept by exactly one of them, by the coplanar rule).
        lo[i] = std::max(0, int32_t(std::ceil(mn / side)) - 1);
        hi[i] = std::min((kLatticeSize / side) - 1, int32_t(std::floor(mx / side)));
    }
    for (int32_t z = lo[2]; z <= hi[2]; ++z)
        for (int32_t y = lo[1]; y <= hi[1]; ++y)
            for (int32_t x = lo[0]; x <= hi[0]; ++x) {
                LatticePoint corner = {x * side, y * side, z * side};
                // Descend the cube's tetrahedra, pruning those the points cannot reach.
                int32_t cs = side;
                LatticePoint centre = {corner[0] + cs / 2, corner[1] + cs / 2, corner[2] + cs / 2};
                DiamondInfo cube = diamond_info(DiamondId::from_centre(centre));
                struct Item { Tetrahedron t; int level; };
                Item stack[64];
                int top = 0;
                for (int s = 0; s < 6; ++s) stack[top++] = {diamond_tetrahedron(cube, s), 3 * octave};
                while (top > 0) {
                    Item it = stack[--top];
                    if (separated(it.t, pts, count)) continue;
                    if (it.level == level) {
                        f(it.t);
                        continue;
                    }
                    Tetrahedron a, b;
                    bisect(it.t, a, b);
                    stack[top++] = {a, it.level + 1};
                    stack[top++] = {b, it.level + 1};
                }
            }
}

// ----------------------------------------------------------------------------------------------
// Choosing the leaf level from the density.

// Tracks sample points down the hierarchy one bisection at a time (a point in a tetrahedron is
// in the child on its side of the splitting plane), counting the distinct tetrahedra hit.
int choose_leaf_level(const std::vector<Vec3d>& lattice, const std::vector<uint32_t>& indices, size_t target) {
    size_t triangles = indices.size() / 3;
    size_t sample = std::min<size_t>(triangles, 50000);
    size_t stride = std::max<size_t>(1, triangles / sample);
    struct Tracked { Vec3d p; Tetrahedron t; };
    std::vector<Tracked> points;
    DiamondInfo root = diamond_info(root_diamond());
    for (size_t t = 0; t < triangles; t += stride) {
        Vec3d c{0, 0, 0};
        for (int k = 0; k < 3; ++k)
            for (int i = 0; i < 3; ++i) c[i] += lattice[indices[3 * t + k]][i] / 3.0;
        for (int s = 0; s < 6; ++s) {
            Tetrahedron tet = diamond_tetrahedron(root, s);
            if (!separated(tet, &c, 1)) {
                points.push_back({c, tet});
                break;
            }
        }
    }
    double scale = double(triangles) / double(std::max<size_t>(1, points.size()));
    std::vector<uint64_t> keys(points.size());
    for (int level = 0; level <= kMaxLevel - 3; ++level) {
        for (size_t i = 0; i < points.size(); ++i) {
            Tetrahedron k = canonical_tetrahedron(points[i].t);
            uint64_t h = 1469598103934665603ull;
            for (auto& p : k)
                for (int v : p) h = (h ^ uint64_t(uint32_t(v))) * 1099511628211ull;
            keys[i] = h;
        }
        std::sort(keys.begin(), keys.end());
        size_t distinct = size_t(std::unique(keys.begin(), keys.end()) - keys.begin());
        double per_tet = scale * double(points.size()) / double(std::max<size_t>(1, distinct));
        if (per_tet <= double(target) * 1.4142) return level;
        for (Tracked& tp : points) {
            Tetrahedron a, b;
            bisect(tp.t, a, b);
            tp.t = separated(a, &tp.p, 1) ? b : a;
        }
    }
    return kMaxLevel - 3;
}

// ----------------------------------------------------------------------------------------------

struct SlotKey {
    uint64_t diamond;
    int slot;
    bool operator==(const SlotKey& o) const { return diamond == o.diamond && slot == o.slot; }
    bool operator<(const SlotKey& o) const { return diamond != o.diamond ? diamond < o.diamond : slot < o.slot; }
};
struct SlotKeyHash {
    size_t operator()(const SlotKey& k) const { return size_t((k.diamond * 0x9E3779B97F4A7C15ull) ^ uint64_t(k.slot)); }
};

SlotKey slot_key(const Tetrahedron& t) {
    DiamondId id;
    int slot;
    bool ok = tetrahedron_diamond(t, id, slot);
    (void)ok;
    assert(ok);
    return {id.bits, slot};
}

struct LevelFragments {
    std::unordered_map<SlotKey, WorkFragment, SlotKeyHash> fragments;
    // Error of each diamond's unquantized geometry from the original (lattice units): 0 at the
    // leaves, the largest child's plus the diamond's own measured simplification error above.
    // The stored bound adds the diamond's quantization step; both terms grow towards the root,
    // so stored bounds are monotone.
    std::unordered_map<uint64_t, double> diamond_error;
};

double tetrahedron_longest_edge(const Tetrahedron& t) {
    int64_t best = 0;
    for (int i = 0; i < 4; ++i)
        for (int j = i + 1; j < 4; ++j) best = std::max(best, len2(t[i], t[j]));
    return std::sqrt(double(best));
}

}  // namespace

// ----------------------------------------------------------------------------------------------

CatpBuildReport build_catp(const Mesh& input, const std::string& output_path, const CatpBuildSettings& settings) {
    double start = now_seconds();
    CatpBuildReport report;
    report.input_vertices = input.vertex_count();
    report.input_triangles = input.triangle_count();
    if (input.triangle_count() == 0) fail("the mesh has no triangles");
    std::unique_ptr<tbb::global_control> threads;
    if (settings.threads > 0)
        threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, settings.threads);

    Bounds bounds = input.bounds();
    report.diagonal = bounds.diagonal();
    Placement place = place_model(bounds);

    // Lattice positions on the snapping grid; attributes.
    std::vector<Vec3d> lattice(input.vertex_count());
    tbb::parallel_for(size_t(0), input.vertex_count(), [&](size_t v) {
        for (int i = 0; i < 3; ++i) lattice[v][i] = snap_to_grid((input.positions[v][i] - place.origin[i]) / place.cell);
    });
    std::vector<Vec3f> normals = input.has_normals() ? input.normals : compute_vertex_normals(input);
    const Rgb8 default_color{180, 180, 180};
    auto color_of = [&](uint32_t v) { return input.has_colors() ? input.colors[v] : default_color; };

    int leaf_level = settings.leaf_level >= 0 ? settings.leaf_level
                                              : choose_leaf_level(lattice, input.indices, settings.leaf_triangles);
    if (leaf_level > kMaxLevel - 3) fail("leaf level %d is deeper than the lattice allows (%d)", leaf_level, kMaxLevel - 3);
    report.leaf_level = leaf_level;

    report.seconds_prepare = now_seconds() - start;
    double phase_start = now_seconds();
    ArchiveWriter archive(output_path, ArchiveKind::Catp);
    std::vector<CatpLevelStats> stats(leaf_level + 1);
    for (int l = 0; l <= leaf_level; ++l) stats[l].level = l;
    std::mutex stats_mutex;

    // Progress: leaf clipping counts input triangles, each coarser level its gathered triangles.
    Progress progress("catp build", input.triangle_count() * 2, "tri");
    if (!settings.progress) progress.finish();

    // Writes the node of a diamond whose fragments are final.
    auto write_node = [&](DiamondId id, const DiamondInfo& info, std::array<WorkFragment*, 8>& slots, double error,
                          bool leaf) {
        DiamondFragments node;
        size_t triangles = 0, vertices = 0;
        for (int s = 0; s < 8; ++s) {
            if (!slots[s] || slots[s]->indices.empty()) continue;
            Tetrahedron t = canonical_tetrahedron(diamond_tetrahedron(info, s));
            quantize_fragment(*slots[s], t, node.slots[s]);
            if (node.slots[s].indices.empty()) continue;
            node.slot_mask |= uint8_t(1 << s);
            triangles += node.slots[s].triangle_count();
            vertices += node.slots[s].vertices.size();
        }
        std::vector<uint8_t> bytes = encode_diamond_node(node);
        ArchiveEntry entry;
        entry.key = id.bits;
        entry.level = uint16_t(info.level);
        entry.flags = uint16_t(node.slot_mask) | (leaf ? kCatpLeafFlag : 0);
        entry.count = uint32_t(triangles);
        entry.error = float(error * place.cell);
        archive.add_node(entry, bytes.data(), bytes.size());
        std::lock_guard lock(stats_mutex);
        CatpLevelStats& s = stats[info.level];
        s.diamonds++;
        s.fragments += size_t(__builtin_popcount(node.slot_mask));
        s.triangles += triangles;
        s.vertices += vertices;
        s.bytes += bytes.size();
        s.max_error = std::max(s.max_error, double(entry.error));
    };

    // ---- Leaves: clip the input by the leaf tetrahedra.
    LevelFragments current;
    {
        struct Hit { SlotKey key; uint32_t triangle; };
        tbb::enumerable_thread_specific<std::vector<Hit>> local_hits;
        size_t triangles = input.triangle_count();
        tbb::parallel_for(tbb::blocked_range<size_t>(0, triangles, 4096), [&](const tbb::blocked_range<size_t>& r) {
            auto& hits = local_hits.local();
            for (size_t t = r.begin(); t != r.end(); ++t) {
                const uint32_t* f = &input.indices[3 * t];
                if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) continue;
                Vec3d pts[3] = {lattice[f[0]], lattice[f[1]], lattice[f[2]]};
                for_each_overlapping_tetrahedron(pts, 3, leaf_level, [&](const Tetrahedron& tet) {
                    hits.push_back({slot_key(tet), uint32_t(t)});
                });
            }
        });
        std::vector<Hit> hits;
        for (auto& h : local_hits) hits.insert(hits.end(), h.begin(), h.end());
        local_hits.clear();
        tbb::parallel_sort(hits.begin(), hits.end(), [](const Hit& a, const Hit& b) {
            return a.key < b.key || (a.key == b.key && a.triangle < b.triangle);
        });
        std::vector<size_t> group_start;
        for (size_t i = 0; i < hits.size(); ++i)
            if (i == 0 || !(hits[i].key == hits[i - 1].key)) group_start.push_back(i);
        group_start.push_back(hits.size());
        size_t groups = group_start.size() - 1;
        std::vector<WorkFragment> fragments(groups);
        tbb::parallel_for(size_t(0), groups, [&](size_t g) {
            SlotKey key = hits[group_start[g]].key;
            DiamondInfo info = diamond_info(DiamondId{key.diamond});
            Tetrahedron tet = diamond_tetrahedron(info, key.slot);
            std::vector<ClipPlane> planes = tetrahedron_clip_planes(tet, 0xf);
            FragmentWelder welder(fragments[g]);
            for (size_t i = group_start[g]; i < group_start[g + 1]; ++i) {
                const uint32_t* f = &input.indices[3 * hits[i].triangle];
                welder.add_clipped({lattice[f[0]], lattice[f[1]], lattice[f[2]]},
                                   {normals[f[0]], normals[f[1]], normals[f[2]]},
                                   {color_of(f[0]), color_of(f[1]), color_of(f[2])}, planes);
            }
            progress.add(group_start[g + 1] - group_start[g]);
        });
        for (size_t g = 0; g < groups; ++g) {
            if (fragments[g].indices.empty()) continue;
            current.fragments.emplace(hits[group_start[g]].key, std::move(fragments[g]));
        }
    }

    // Leaf diamonds' nodes.
    auto write_level_nodes = [&](LevelFragments& level, bool leaf) {
        std::unordered_map<uint64_t, std::array<WorkFragment*, 8>> by_diamond;
        for (auto& [key, frag] : level.fragments) {
            auto& slots = by_diamond[key.diamond];
            slots[key.slot] = &frag;
        }
        std::vector<std::pair<uint64_t, std::array<WorkFragment*, 8>>> list(by_diamond.begin(), by_diamond.end());
        tbb::parallel_for(size_t(0), list.size(), [&](size_t i) {
            DiamondId id{list[i].first};
            DiamondInfo info = diamond_info(id);
            double quant = 0;
            for (int s = 0; s < 8; ++s)
                if (list[i].second[s]) quant = std::max(quant, tetrahedron_longest_edge(diamond_tetrahedron(info, s)));
            quant /= kBaryGrid;
            write_node(id, info, list[i].second, level.diamond_error.at(id.bits) + quant, leaf);
        });
    };
    {
        // Pre-insert keys so the parallel writers only assign existing entries.
        for (auto& [key, frag] : current.fragments) current.diamond_error.emplace(key.diamond, 0.0);
        write_level_nodes(current, true);
    }

    report.seconds_leaves = now_seconds() - phase_start;
    phase_start = now_seconds();
    // ---- Coarser levels, bottom-up.
    for (int level = leaf_level - 1; level >= 0; --level) {
        // Group the finer fragments by the diamond whose refinement created their tetrahedron.
        std::unordered_map<uint64_t, std::vector<std::pair<SlotKey, WorkFragment*>>> by_parent;
        for (auto& [key, frag] : current.fragments) {
            DiamondInfo child = diamond_info(DiamondId{key.diamond});
            by_parent[slot_parent(child, key.slot).bits].push_back({key, &frag});
        }
        std::vector<uint64_t> parents;
        for (auto& [p, list] : by_parent) parents.push_back(p);
        std::sort(parents.begin(), parents.end());
        LevelFragments next;
        for (uint64_t p : parents) next.diamond_error.emplace(p, 0.0);
        std::vector<std::array<WorkFragment, 8>> produced(parents.size());
        std::vector<double> produced_error(parents.size(), 0.0);
        tbb::parallel_for(size_t(0), parents.size(), [&](size_t i) {
            DiamondId id{parents[i]};
            DiamondInfo info = diamond_info(id);
            auto& children = by_parent[parents[i]];
            std::sort(children.begin(), children.end(),
                      [](const auto& a, const auto& b) { return a.first < b.first; });
            // Every child with geometry counts, also those whose gathered slots came from other
            // parents: that keeps the stored errors monotone along every parent-child edge.
            double child_error = 0;
            for (DiamondId child : diamond_children(id)) {
                auto it = current.diamond_error.find(child.bits);
                if (it != current.diamond_error.end()) child_error = std::max(child_error, it->second);
            }
            WorkFragment gathered;
            {
                FragmentWelder welder(gathered);
                for (auto& [key, frag] : children) welder.append(*frag);
            }
            size_t gathered_triangles = gathered.indices.size() / 3;
            double simplify_error = coarsen_diamond(info, gathered, produced[i]);
            double quant = 0;
            for (int s = 0; s < 8; ++s)
                if (!produced[i][s].indices.empty())
                    quant = std::max(quant, tetrahedron_longest_edge(diamond_tetrahedron(info, s)));
            quant /= kBaryGrid;
            // Monotone: a diamond's error bounds its children's plus its own simplification.
            produced_error[i] = child_error + simplify_error;
            std::array<WorkFragment*, 8> slots;
            for (int s = 0; s < 8; ++s) slots[s] = &produced[i][s];
            write_node(id, info, slots, produced_error[i] + quant, false);
            progress.add(gathered_triangles / 2);
        });
        for (size_t i = 0; i < parents.size(); ++i) {
            next.diamond_error[parents[i]] = produced_error[i];
            for (int s = 0; s < 8; ++s)
                if (!produced[i][s].indices.empty())
                    next.fragments.emplace(SlotKey{parents[i], s}, std::move(produced[i][s]));
        }
        current = std::move(next);
    }
    progress.finish();
    report.seconds_coarsen = now_seconds() - phase_start;
    phase_start = now_seconds();

    CatpMeta meta;
    for (int i = 0; i < 3; ++i) {
        meta.origin[i] = place.origin[i];
        meta.bounds_min[i] = bounds.min[i];
        meta.bounds_max[i] = bounds.max[i];
    }
    meta.cell = place.cell;
    meta.leaf_level = uint32_t(leaf_level);
    meta.flags = (input.has_colors() ? 1u : 0u) | (input.has_normals() ? 2u : 0u);
    meta.input_vertices = input.vertex_count();
    meta.input_triangles = input.triangle_count();
    meta.default_rgb = uint32_t(default_color[0]) | (uint32_t(default_color[1]) << 8) | (uint32_t(default_color[2]) << 16);
    report.file_bytes = archive.finish(encode_catp_meta(meta));
    report.seconds_write = now_seconds() - phase_start;
    for (auto& s : stats) {
        if (s.diamonds) report.nodes += s.diamonds;
        report.levels.push_back(s);
    }
    report.seconds = now_seconds() - start;
    report.peak_rss = peak_rss_bytes();
    return report;
}

}  // namespace catpaq
