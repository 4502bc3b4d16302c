// Dataset checks and level meshes (aqp/verify.h).
#include "aqp/verify.h"

#include <map>

#include "base/error.h"
#include "common_codec/octahedral.h"

namespace catpaq::aqp {
namespace {

// Grid position (i, j) of the t-th sample along edge e (from corner e to corner e+1) of a patch
// with `size` samples per side.
void edge_sample(int e, int t, int size, int& i, int& j) {
    const int last = size - 1;
    switch (e) {
        case 0: i = t, j = 0; break;
        case 1: i = last, j = t; break;
        case 2: i = last - t, j = last; break;
        default: i = 0, j = last - t; break;
    }
}

void note(AqpVerifyReport& r, const std::string& problem) {
    if (r.problems.size() < 8) r.problems.push_back(problem);
}

}  // namespace

AqpVerifyReport verify_aqp(const AqpDataset& d) {
    AqpVerifyReport r;
    const AqpMeta& m = d.meta();
    const int k = d.finest_level();
    // Every patch's levels, coarse to fine, a tile at a time (a level decodes from the one below).
    std::vector<std::vector<PatchGrid>> all(d.patch_count());
    std::vector<int> decoded_levels(d.patch_count(), 0);  // levels that decoded
    for (int l = 0; l <= k; ++l)
        for (uint32_t t = 0; t < m.tile_count(l); ++t) {
            ++r.nodes;
            const uint32_t first = m.first_patch(t, l), count = m.tile_patches(t, l);
            std::vector<const PatchGrid*> coarser;
            bool any = l == 0;
            for (uint32_t p = first; l > 0 && p < first + count; ++p) {
                coarser.push_back(decoded_levels[p] == l ? &all[p].back() : nullptr);
                any |= coarser.back() != nullptr;
            }
            if (!any) {  // a coarser tile was corrupt: this one cannot be decoded
                ++r.corrupt_nodes;
                continue;
            }
            try {
                std::vector<PatchGrid> grids = d.decode_tile(t, l, coarser);
                for (uint32_t q = 0; q < count; ++q)
                    if (l == 0 || coarser[q]) {
                        all[first + q].push_back(std::move(grids[q]));
                        decoded_levels[first + q] = l + 1;
                    }
            } catch (const Error& e) {
                ++r.corrupt_nodes;
                note(r, e.what());
            }
        }
    std::vector<PatchGrid> finer(d.patch_count());
    for (int l = k; l >= 0; --l) {
        std::vector<PatchGrid> grids(d.patch_count());
        std::vector<uint8_t> valid(d.patch_count(), 0);
        for (uint32_t p = 0; p < d.patch_count(); ++p)
            if (decoded_levels[p] > l) {
                grids[p] = std::move(all[p][l]);
                valid[p] = 1;
            }
        for (uint32_t p = 0; p < d.patch_count(); ++p) {
            if (!valid[p]) continue;
            const PatchGrid& g = grids[p];
            for (size_t s = 0; s < g.position.size(); ++s)
                for (int a = 0; a < 3; ++a)
                    if (g.position[s][a] > m.patches[p].extent[a]) {
                        ++r.extent_violations;
                        note(r, strprintf("patch %u level %d: a sample beyond the patch's extent", p, l));
                    }
            // Shared edges, compared from the side with the smaller patch number.
            for (int e = 0; e < 4; ++e) {
                const PatchLink& link = m.patches[p].link[e];
                if (link.patch == kNone || link.patch < p || !valid[link.patch]) continue;
                const PatchGrid& h = grids[link.patch];
                for (int t = 0; t < g.size; ++t) {
                    int i, j, oi, oj;
                    edge_sample(e, t, g.size, i, j);
                    edge_sample(link.edge, link.reversed ? g.size - 1 - t : t, g.size, oi, oj);
                    const size_t a = g.index(i, j), b = h.index(oi, oj);
                    const bool same = d.grid_position(g, a) == d.grid_position(h, b) && g.normal[a] == h.normal[b] &&
                                      (g.color.empty() || g.color[a] == h.color[b]);
                    if (!same) {
                        ++r.shared_sample_mismatches;
                        note(r, strprintf("level %d: patch %u edge %d and patch %u edge %u differ at sample %d", l, p, e,
                                          link.patch, unsigned(link.edge), t));
                    }
                }
            }
            if (l < k) {
                if (!finer[p].position.empty()) {  // (always equal now that finer levels decode from coarser ones)
                    for (int j = 0; j < g.size; ++j)
                        for (int i = 0; i < g.size; ++i) {
                            const size_t a = g.index(i, j), b = finer[p].index(2 * i, 2 * j);
                            if (g.position[a] != finer[p].position[b] || g.normal[a] != finer[p].normal[b] ||
                                (!g.color.empty() && g.color[a] != finer[p].color[b])) {
                                ++r.nesting_mismatches;
                                note(r, strprintf("patch %u level %d sample (%d, %d) is not level %d's", p, l, i, j, l + 1));
                            }
                        }
                }
                if (d.entry(p, l).error < d.entry(p, l + 1).error) {
                    ++r.monotonicity_violations;
                    note(r, strprintf("patch %u: level %d's bound %g is below level %d's %g", p, l, d.entry(p, l).error, l + 1,
                                      d.entry(p, l + 1).error));
                }
            }
        }
        finer.swap(grids);
    }
    return r;
}

Mesh aqp_level_mesh(const AqpDataset& d, int level, bool weld) {
    Mesh mesh;
    std::map<std::array<uint64_t, 3>, uint32_t> welded;
    const bool colors = d.meta().has_colors();
    const std::vector<PatchGrid> grids = d.decode_level(level);
    for (uint32_t p = 0; p < d.patch_count(); ++p) {
        const PatchGrid& g = grids[p];
        std::vector<uint32_t> vertex(g.position.size());
        for (size_t s = 0; s < g.position.size(); ++s) {
            const std::array<uint64_t, 3> key = d.grid_position(g, s);
            if (weld) {
                auto [it, inserted] = welded.emplace(key, uint32_t(mesh.positions.size()));
                vertex[s] = it->second;
                if (!inserted) continue;
            } else {
                vertex[s] = uint32_t(mesh.positions.size());
            }
            mesh.positions.push_back(d.world_position(g, s));
            float n[3];
            oct_decode(g.normal[s], n);
            mesh.normals.push_back({n[0], n[1], n[2]});
            if (colors) mesh.colors.push_back(g.color[s]);
        }
        for (int j = 0; j + 1 < g.size; ++j)
            for (int i = 0; i + 1 < g.size; ++i) {
                const uint32_t a = vertex[g.index(i, j)], b = vertex[g.index(i + 1, j)];
                const uint32_t c = vertex[g.index(i + 1, j + 1)], e = vertex[g.index(i, j + 1)];
                for (std::array<uint32_t, 3> t : {std::array<uint32_t, 3>{a, b, c}, std::array<uint32_t, 3>{a, c, e}}) {
                    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) continue;
                    mesh.indices.insert(mesh.indices.end(), t.begin(), t.end());
                }
            }
    }
    return mesh;
}

}  // namespace catpaq::aqp
