#include "catp/verify.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <iterator>
#include <map>
#include <set>
#include <random>
#include <unordered_map>

#include <tbb/parallel_for.h>

#include "base/error.h"
#include "base/progress.h"
#include "catp/cut.h"
#include "catp/dataset.h"
#include "catp/distance.h"

namespace catpaq {

namespace {

using IntPoint = std::array<int64_t, 3>;
using FaceKey = std::array<LatticePoint, 3>;
using Edge = std::pair<IntPoint, IntPoint>;

// One tetrahedron's view of a face: edges where its surface leaves the face, and borders of
// its patches lying in the face.
struct FaceSide {
    std::set<Edge> open, patch;
    std::set<Edge> nonmanifold;  // used by several triangles of this side: not compared
};

std::set<Edge> symmetric_difference(const std::set<Edge>& a, const std::set<Edge>& b) {
    std::set<Edge> out;
    std::set_symmetric_difference(a.begin(), a.end(), b.begin(), b.end(), std::inserter(out, out.begin()));
    return out;
}

// What the two sides of a shared face show along it. Where the surface crosses the face, each
// edge on it is used once on either side (an open edge on both, or an open edge on one and a
// patch border on the other); the edges used an odd number of times are where the surface,
// joined across the face, has a border in the face. Such a border is a crack when both sides
// leave one, connected to each other: the two sides end at different edges (a T-junction, or
// two polylines between the same points). A border that only one side leaves is where the
// *input* ends exactly in the face's plane (an open or non-manifold mesh: a grid's edge, a fin,
// a flap), or geometry missing on the other side; the face alone cannot tell which, so these
// are counted (FaceCheck::one_sided) and, with the original mesh, checked against its border.
struct FaceCheck {
    size_t crack_edges = 0;  // odd edges in a component that both sides leave borders in
    size_t one_sided = 0;    // odd edges in components of one side only
};

// on_input_border: with the original mesh, whether an edge lies on its border. There the input
// itself ends in the face's plane, and when the surface lies in the face on both sides (a noisy
// scan whose noise is below a coarse level's grid step collapses into the face), each side's
// patch may take part of that border: a two-sided border that is no crack (the border check of
// the welded cut judges those edges).
FaceCheck check_face(const std::array<FaceSide, 2>& sides, const std::function<bool(const Edge&)>& on_input_border) {
    std::set<Edge> odd = symmetric_difference(symmetric_difference(sides[0].open, sides[1].open),
                                              symmetric_difference(sides[0].patch, sides[1].patch));
    FaceCheck out;
    if (on_input_border)
        for (auto it = odd.begin(); it != odd.end();) {
            if (on_input_border(*it)) {
                out.one_sided++;
                it = odd.erase(it);
            } else {
                ++it;
            }
        }
    if (odd.empty()) return out;
    // Components of the odd edges (union-find on their end points), and which side left each
    // edge only it has (an edge both sides have, as a three-sheet edge, belongs to neither).
    std::map<IntPoint, IntPoint> parent;
    std::function<IntPoint(const IntPoint&)> root = [&](const IntPoint& p) {
        auto it = parent.find(p);
        if (it == parent.end() || it->second == p) return p;
        return it->second = root(it->second);
    };
    for (const Edge& e : odd) {
        IntPoint a = root(e.first), b = root(e.second);
        parent.emplace(a, a);
        parent.emplace(b, b);
        if (a != b) parent[a] = b;
    }
    auto has = [](const FaceSide& s, const Edge& e) { return s.open.count(e) || s.patch.count(e); };
    std::map<IntPoint, std::array<size_t, 3>> components;  // root: edges only side 0 has, only side 1, all
    for (const Edge& e : odd) {
        std::array<size_t, 3>& c = components[root(e.first)];
        bool on0 = has(sides[0], e), on1 = has(sides[1], e);
        c[0] += on0 && !on1;
        c[1] += on1 && !on0;
        c[2]++;
    }
    for (auto& [r, c] : components) (c[0] && c[1] ? out.crack_edges : out.one_sided) += c[2];
    return out;
}

struct DecodedCut {
    std::vector<std::array<double, 3>> positions;  // world, welded by exact integer position
    std::vector<uint32_t> indices;
};

double longest_edge(const Tetrahedron& t) {
    double best = 0;
    for (int i = 0; i < 4; ++i)
        for (int j = i + 1; j < 4; ++j) {
            double s = 0;
            for (int k = 0; k < 3; ++k) s += double(t[i][k] - t[j][k]) * double(t[i][k] - t[j][k]);
            best = std::max(best, std::sqrt(s));
        }
    return best;
}

class Checker {
public:
    Checker(const CatpFile& file, VerifyReport& report) : file_(file), report_(report) {}

    const DiamondFragments* node(const ArchiveEntry& e) {
        auto it = cache_.find(e.key);
        if (it != cache_.end()) return it->second.get();
        std::unique_ptr<DiamondFragments> out;
        std::string error;
        const uint8_t* bytes = file_.archive().node(file_.index().entry_index(&e), &error);
        if (!bytes) {
            report_.checksum_failures++;
            problem(error);
        } else {
            out.reset(new DiamondFragments);
            std::string bad = decode_diamond_node(bytes, e.size, file_.index().meta().layout, *out);
            if (!bad.empty()) {
                report_.corrupt_nodes++;
                problem(strprintf("diamond %llu: %s", (unsigned long long)e.key, bad.c_str()));
                out.reset();
            }
        }
        return (cache_[e.key] = std::move(out)).get();
    }

    void problem(const std::string& text) {
        if (report_.problems.size() < 20) report_.problems.push_back(text);
    }

    // Decodes cut R; checks that the fragment borders on every face shared by two drawn
    // tetrahedra match (as multisets of integer edges). Returns the welded world mesh. With the
    // original's border, edges whose midpoint lies within `tolerance` of it are the input's own
    // border (check_face).
    DecodedCut decode_cut(const RefinedSet& refined, const SegmentDistance* input_border = nullptr,
                          double tolerance = 0) {
        DecodedCut out;
        std::map<IntPoint, uint32_t> weld;
        std::map<FaceKey, std::vector<FaceSide>> faces;
        const CatpMeta& meta = file_.index().meta();
        std::vector<std::array<int64_t, 3>> ints;
        for (const DrawnSlot& d : drawn_slots(file_.index(), refined)) {
            const DiamondFragments* f = node(*d.entry);
            if (!f) continue;
            const FragmentMesh& frag = f->slots[d.slot];
            DiamondInfo info = diamond_info(DiamondId{d.entry->key});
            if (!decode_fragment_integer_positions(frag, info, d.slot, ints)) {
                report_.corrupt_nodes++;
                continue;
            }
            Tetrahedron t = canonical_tetrahedron(diamond_tetrahedron(info, d.slot));
            std::vector<BaryWeights> w(frag.vertices.size());
            for (size_t v = 0; v < w.size(); ++v) vertex_weights(frag.vertices[v], frag.layout, w[v]);
            std::vector<uint32_t> ids(ints.size());
            for (size_t v = 0; v < ints.size(); ++v) {
                auto [it, inserted] = weld.emplace(ints[v], uint32_t(out.positions.size()));
                if (inserted) {
                    double lattice[3], world[3];
                    for (int k = 0; k < 3; ++k) lattice[k] = double(ints[v][k]) / meta.layout.grid;
                    for (int k = 0; k < 3; ++k) world[k] = meta.origin[k] + lattice[k] * meta.cell;
                    out.positions.push_back({world[0], world[1], world[2]});
                }
                ids[v] = it->second;
            }
            // Where the fragment meets each face: edges on the face used once by triangles
            // that leave the face ("open" borders), and borders of patches lying in the face.
            struct Use { int open = 0, patch = 0; uint32_t u = 0, v = 0; };
            std::map<std::pair<uint32_t, uint32_t>, Use> edge_use;
            for (size_t i = 0; i + 2 < frag.indices.size(); i += 3) {
                uint32_t a = frag.indices[i], b = frag.indices[i + 1], c = frag.indices[i + 2];
                if (ids[a] == ids[b] || ids[b] == ids[c] || ids[a] == ids[c]) continue;
                out.indices.insert(out.indices.end(), {ids[a], ids[b], ids[c]});
                bool in_face = false;
                for (int k = 0; k < 4; ++k) in_face |= w[a][k] == 0 && w[b][k] == 0 && w[c][k] == 0;
                for (auto [u, v] : {std::pair{a, b}, std::pair{b, c}, std::pair{c, a}}) {
                    // Count by welded position (a fragment may repeat a position), keep a local id.
                    auto key = std::minmax(ids[u], ids[v]);
                    Use& use = edge_use[{key.first, key.second}];
                    (in_face ? use.patch : use.open)++;
                    use.u = u;
                    use.v = v;
                }
            }
            std::map<FaceKey, FaceSide> local;
            for (auto& [welded, use] : edge_use) {
                if (use.open == 0 && use.patch == 0) continue;
                const BaryWeights &wa = w[use.u], &wb = w[use.v];
                int zero_face = -1;
                for (int k = 0; k < 4; ++k)
                    if (wa[k] == 0 && wb[k] == 0) zero_face = zero_face < 0 ? k : 4;  // 4: on a tetrahedron edge
                if (zero_face < 0 || zero_face == 4) continue;
                FaceKey key;
                int m = 0;
                for (int k = 0; k < 4; ++k)
                    if (k != zero_face) key[m++] = t[k];
                IntPoint pa = ints[use.u], pb = ints[use.v];
                if (pb < pa) std::swap(pa, pb);
                if (use.open == 1) local[key].open.insert({pa, pb});
                if (use.patch == 1) local[key].patch.insert({pa, pb});
                if (use.open > 1 || use.patch > 1) local[key].nonmanifold.insert({pa, pb});
            }
            for (auto& [key, side] : local) faces[key].push_back(std::move(side));
        }
        for (auto& [key, sides] : faces) {
            if (sides.size() != 2) continue;
            report_.faces_checked++;
            // Non-manifold edges (several sheets meeting on the face) are left to the topological
            // crack tests: a local count cannot tell how the sheets pair up.
            for (FaceSide& side : sides)
                for (const Edge& e : sides[0].nonmanifold) {
                    side.open.erase(e);
                    side.patch.erase(e);
                }
            for (FaceSide& side : sides)
                for (const Edge& e : sides[1].nonmanifold) {
                    side.open.erase(e);
                    side.patch.erase(e);
                }
            std::function<bool(const Edge&)> on_input_border;
            if (input_border)
                on_input_border = [&](const Edge& e) {  // its ends are welded cut vertices
                    const std::array<double, 3>& a = out.positions[weld.at(e.first)], &b = out.positions[weld.at(e.second)];
                    return input_border->distance({(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2}) <= tolerance;
                };
            FaceCheck c = check_face({sides[0], sides[1]}, on_input_border);
            report_.face_border_edges += c.one_sided;
            if (c.crack_edges) {
                report_.face_mismatches++;
                problem(strprintf("face (%d,%d,%d)-(%d,%d,%d)-(%d,%d,%d): the two sides' borders differ (%zu edges "
                                  "where both sides end differently: a crack)",
                                  key[0][0], key[0][1], key[0][2], key[1][0], key[1][1], key[1][2], key[2][0], key[2][1],
                                  key[2][2], c.crack_edges));
            }
        }
        return out;
    }

private:
    const CatpFile& file_;
    VerifyReport& report_;
    std::unordered_map<uint64_t, std::unique_ptr<DiamondFragments>> cache_;
};

// The border edges (used by one triangle) of a mesh, as segments.
std::vector<std::pair<std::array<double, 3>, std::array<double, 3>>> mesh_border(const Mesh& mesh) {
    std::map<std::pair<uint32_t, uint32_t>, int> uses;
    for (size_t t = 0; t + 2 < mesh.indices.size(); t += 3)
        for (int k = 0; k < 3; ++k) {
            uint32_t a = mesh.indices[t + k], b = mesh.indices[t + (k + 1) % 3];
            if (a != b) uses[{std::min(a, b), std::max(a, b)}]++;
        }
    std::vector<std::pair<std::array<double, 3>, std::array<double, 3>>> out;
    for (auto& [e, n] : uses)
        if (n == 1) out.push_back({mesh.positions[e.first], mesh.positions[e.second]});
    return out;
}

// Border edges of a decoded cut (welded by exact position) whose midpoint lies farther than
// `tolerance` from the original's border: a crack, or geometry missing, opens borders where
// the original has none. (The face check alone cannot tell those from an input border lying
// in a face; this can, since it knows where the input's borders are.)
size_t check_borders(const DecodedCut& cut, const SegmentDistance& original_border, double tolerance) {
    std::map<std::pair<uint32_t, uint32_t>, int> uses;
    for (size_t t = 0; t + 2 < cut.indices.size(); t += 3)
        for (int k = 0; k < 3; ++k) {
            uint32_t a = cut.indices[t + k], b = cut.indices[t + (k + 1) % 3];
            uses[{std::min(a, b), std::max(a, b)}]++;
        }
    size_t off = 0;
    for (auto& [e, n] : uses) {
        if (n != 1) continue;
        const auto &a = cut.positions[e.first], &b = cut.positions[e.second];
        std::array<double, 3> mid{(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2};
        off += !(original_border.distance(mid) <= tolerance);
    }
    return off;
}

// The stored bound must hold: a level whose measured distance, either way, exceeds its stored
// error fails, with the excess.
void check_bound(VerifyLevel& lv, VerifyReport& report, Checker& checker) {
    // The stored error is a float: its rounding is not a violation.
    double bound = lv.stored_error * (1 + 1e-6);
    auto over = [&](const char* direction, double measured) {
        if (!(measured > bound)) return;
        lv.bound_exceeded = true;
        checker.problem(strprintf("level %d: %s distance %.6g exceeds the stored bound %.6g by %.6g (%.3gx the bound)",
                                  lv.level, direction, measured, lv.stored_error, measured - lv.stored_error,
                                  lv.stored_error > 0 ? measured / lv.stored_error : INFINITY));
    };
    over("level->original", lv.distance_to_original_max);
    over("original->level", lv.distance_from_original_max);
    report.bound_violations += lv.bound_exceeded;
}

}  // namespace

VerifyReport verify_catp(const std::string& path, const Mesh* original, const VerifySettings& settings) {
    CatpFile file(path);
    const CatpIndex& index = file.index();
    const CatpMeta& meta = index.meta();
    VerifyReport report;
    report.file_bytes = file.archive().size();
    report.layout = meta.layout;
    report.precision = meta.precision;
    report.mean_edge = meta.mean_edge;
    double d2 = 0;
    for (int i = 0; i < 3; ++i) d2 += (meta.bounds_max[i] - meta.bounds_min[i]) * (meta.bounds_max[i] - meta.bounds_min[i]);
    report.diagonal = std::sqrt(d2);
    Checker checker(file, report);
    Progress progress("verify", "checking nodes", index.entries().size(), "nodes");
    if (!settings.progress) progress.silence();

    int max_level = 0;
    for (const ArchiveEntry& e : index.entries()) max_level = std::max(max_level, int(e.level));
    report.levels.resize(max_level + 1);
    for (int l = 0; l <= max_level; ++l) report.levels[l].level = l;

    // Per node: decode, flags, counts, monotone errors.
    for (const ArchiveEntry& e : index.entries()) {
        report.nodes++;
        DiamondId id{e.key};
        DiamondInfo info = diamond_info(id);
        VerifyLevel& lv = report.levels[e.level];
        lv.diamonds++;
        lv.bytes += e.size;
        lv.stored_error = std::max(lv.stored_error, double(e.error));
        uint8_t mask = uint8_t(e.flags & 0xff);
        if ((mask & ~existing_slots(info)) != 0) {
            report.bad_flags++;
            checker.problem(strprintf("diamond %llu claims slots that do not exist", (unsigned long long)e.key));
        }
        // Leaves may sit at any level (they follow the density), but the deepest level holds
        // only leaves, and no slot is created by a leaf (a leaf is never refined).
        bool leaf = e.flags & kCatpLeafFlag;
        if (!leaf && uint32_t(e.level) >= meta.leaf_level) {
            report.bad_flags++;
            checker.problem(strprintf("diamond %llu: not a leaf, at the leaf level", (unsigned long long)e.key));
        }
        if (e.key != root_diamond().bits)
            for (int s = 0; s < info.ring_size; ++s) {
                if (!(e.flags & (1u << s))) continue;
                const ArchiveEntry* parent = index.find(slot_parent(info, s));
                if (parent && (parent->flags & kCatpLeafFlag)) {
                    report.bad_flags++;
                    checker.problem(strprintf("diamond %llu: slot %d is created by a leaf", (unsigned long long)e.key, s));
                    break;
                }
            }
        for (DiamondId p : diamond_parents(id)) {
            const ArchiveEntry* pe = index.find(p);
            if (pe && pe->error < e.error) {
                report.monotonicity_violations++;
                checker.problem(strprintf("diamond %llu: error %g exceeds its parent's %g", (unsigned long long)e.key,
                                          double(e.error), double(pe->error)));
            }
        }
        const DiamondFragments* f = checker.node(e);
        if (!f) continue;
        if (f->slot_mask != mask) {
            report.bad_flags++;
            checker.problem(strprintf("diamond %llu: slot mask differs between index and payload", (unsigned long long)e.key));
        }
        size_t triangles = 0;
        for (int s = 0; s < 8; ++s) {
            if (!(f->slot_mask & (1 << s))) continue;
            triangles += f->slots[s].triangle_count();
            lv.vertices += f->slots[s].vertices.size();
            lv.fragments++;
            report.fragments++;
            lv.quantization_step = std::max(lv.quantization_step,
                                            longest_edge(diamond_tetrahedron(info, s)) * meta.cell / meta.layout.grid);
        }
        if (triangles != e.count) {
            report.bad_flags++;
            checker.problem(strprintf("diamond %llu: index says %u triangles, payload has %zu", (unsigned long long)e.key,
                                      e.count, triangles));
        }
        lv.triangles += triangles;
        report.triangles += triangles;
        progress.add(1);
    }

    // Uniform cuts, coarse to fine: face consistency and (with the original) distances, the
    // stored bounds against them, and the cut's borders against the original's.
    std::unique_ptr<SurfaceDistance> to_original;
    std::unique_ptr<SegmentDistance> original_border;
    std::vector<std::array<double, 3>> original_samples;
    if (original) {
        progress.phase("sampling the original", 0, "samples");
        std::vector<std::array<double, 3>> p(original->positions.begin(), original->positions.end());
        to_original.reset(new SurfaceDistance(p, original->indices));
        original_samples = sample_surface(p, original->indices, settings.samples_per_level);
        original_border.reset(new SegmentDistance(mesh_border(*original)));
    }
    // Leaves follow the density, so a level's uniform cut also draws the leaves of coarser
    // levels: its bound and step are the largest of the diamonds it draws.
    std::vector<std::array<double, 3>> leaves;  // level, stored error, quantization step
    for (const ArchiveEntry& e : index.entries()) {
        if (!(e.flags & kCatpLeafFlag)) continue;
        const DiamondInfo info = diamond_info(DiamondId{e.key});
        double step = 0;
        for (int s = 0; s < info.ring_size; ++s)
            if (e.flags & (1u << s))
                step = std::max(step, longest_edge(diamond_tetrahedron(info, s)) * meta.cell / meta.layout.grid);
        leaves.push_back({double(e.level), double(e.error), step});
    }
    double largest_stored = 0;
    for (int level = 0; level <= max_level; ++level) {
        VerifyLevel& lv = report.levels[level];
        for (const auto& [leaf_level, error, step] : leaves)
            if (leaf_level < level) {
                lv.stored_error = std::max(lv.stored_error, error);
                lv.quantization_step = std::max(lv.quantization_step, step);
            }
        largest_stored = std::max(largest_stored, lv.stored_error);
        progress.phase(strprintf("level %d of %d", level, max_level), original ? 2 * settings.samples_per_level : 0,
                       "samples");
        RefinedSet refined;
        for (const ArchiveEntry& e : index.entries())
            if (e.level < level && !(e.flags & kCatpLeafFlag)) refined.refine(DiamondId{e.key});
        DecodedCut cut = checker.decode_cut(refined, original_border.get(), lv.stored_error + lv.quantization_step);
        lv.cut_vertices = cut.positions.size();
        if (!original || cut.indices.empty()) continue;
        lv.border_edges_off_original = check_borders(cut, *original_border, lv.stored_error + lv.quantization_step);
        if (lv.border_edges_off_original)
            checker.problem(strprintf("level %d: %zu border edges of the cut are not on the original's border (cracks "
                                      "or missing geometry)",
                                      level, lv.border_edges_off_original));
        report.border_cracks += lv.border_edges_off_original;
        DistanceStats to = measure_distances(
            *to_original, sample_surface(cut.positions, cut.indices, settings.samples_per_level), &progress);
        lv.distance_to_original_max = to.max;
        lv.distance_to_original_rms = to.rms;
        SurfaceDistance to_level(cut.positions, cut.indices);
        DistanceStats from = measure_distances(to_level, original_samples, &progress);
        lv.distance_from_original_max = from.max;
        lv.distance_from_original_rms = from.rms;
        check_bound(lv, report, checker);
    }
    // The finest level against the precision the converter guaranteed (version-1 datasets
    // recorded none).
    const VerifyLevel& finest = report.levels.back();
    if (original && meta.precision > 0 && finest.distance_to_original_max >= 0) {
        const double measured = std::max(finest.distance_to_original_max, finest.distance_from_original_max);
        if (measured > meta.precision) {
            report.precision_exceeded = true;
            checker.problem(strprintf("the finest level is %g from the original, more than the precision %g (by %.3gx)",
                                      measured, meta.precision, measured / meta.precision));
        }
    }
    // A random mixed cut too.
    {
        progress.phase("a mixed cut", 0, "");
        std::mt19937_64 rng(5);
        RefinedSet refined;
        std::uniform_real_distribution<double> u(0, 1);
        for (const ArchiveEntry& e : index.entries())
            if (!(e.flags & kCatpLeafFlag) && u(rng) < 0.5) refined.refine(DiamondId{e.key});
        DecodedCut cut = checker.decode_cut(refined, original_border.get(), largest_stored);
        if (original && !cut.indices.empty()) {
            size_t off = check_borders(cut, *original_border, largest_stored);
            if (off)
                checker.problem(strprintf("mixed cut: %zu border edges are not on the original's border", off));
            report.border_cracks += off;
        }
    }
    report.border_checked = original != nullptr;
    return report;
}

}  // namespace catpaq
