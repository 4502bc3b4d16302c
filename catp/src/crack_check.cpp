#include "catp/crack_check.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <stdexcept>
#include <vector>

namespace catpaq {

namespace {

// A cut decoded and welded by exact integer decoded position: the distinct positions, how many
// triangles use each undirected edge, and the counts cut_topology reports (all but the border).
struct WeldedCut {
    std::vector<std::array<int64_t, 3>> positions;
    std::map<std::pair<uint32_t, uint32_t>, int> edges;
    CutTopology topology;
};

WeldedCut weld_cut(const CatpFile& file, const RefinedSet& refined,
                   std::unordered_map<uint64_t, DiamondFragments>& cache) {
    WeldedCut out;
    std::map<std::array<int64_t, 3>, uint32_t> weld;
    std::vector<std::array<int64_t, 3>> positions;
    for (const DrawnSlot& d : drawn_slots(file.index(), refined)) {
        auto it = cache.find(d.entry->key);
        if (it == cache.end()) it = cache.emplace(d.entry->key, file.decode(*d.entry)).first;
        const FragmentMesh& frag = it->second.slots[d.slot];
        DiamondInfo info = diamond_info(DiamondId{d.entry->key});
        if (!decode_fragment_integer_positions(frag, info, d.slot, positions)) throw std::runtime_error("corrupt vertex");
        std::vector<uint32_t> ids(positions.size());
        for (size_t v = 0; v < positions.size(); ++v) {
            auto [w, inserted] = weld.emplace(positions[v], uint32_t(out.positions.size()));
            if (inserted) out.positions.push_back(positions[v]);
            ids[v] = w->second;
        }
        out.topology.fragments++;
        out.topology.max_level = std::max(out.topology.max_level, int(d.entry->level));
        out.topology.min_level = std::min(out.topology.min_level, int(d.entry->level));
        for (size_t t = 0; t + 2 < frag.indices.size(); t += 3) {
            uint32_t a = ids[frag.indices[t]], b = ids[frag.indices[t + 1]], c = ids[frag.indices[t + 2]];
            if (a == b || b == c || a == c) continue;
            out.topology.triangles++;
            for (auto [u, v] : {std::pair{a, b}, std::pair{b, c}, std::pair{c, a}}) out.edges[{std::min(u, v), std::max(u, v)}]++;
        }
    }
    return out;
}

}  // namespace

CutTopology cut_topology(const CatpFile& file, const RefinedSet& refined,
                         std::unordered_map<uint64_t, DiamondFragments>& cache) {
    WeldedCut cut = weld_cut(file, refined, cache);
    for (auto& [e, n] : cut.edges) cut.topology.border_edges += n == 1;
    return cut.topology;
}

RefinedSet random_cut(const CatpIndex& index, std::mt19937_64& rng, bool spatial) {
    RefinedSet refined;
    std::uniform_real_distribution<double> u(0, 1);
    double p = 0.2 + 0.7 * u(rng);
    const auto& entries = index.entries();
    LatticePoint focus = DiamondId{entries[size_t(u(rng) * entries.size()) % entries.size()].key}.centre();
    double radius = u(rng) * kLatticeSize * 0.5;
    for (const ArchiveEntry& e : entries) {
        if (e.flags & kCatpLeafFlag) continue;
        DiamondId id{e.key};
        bool want;
        if (spatial) {
            LatticePoint c = id.centre();
            double d2 = 0;
            for (int i = 0; i < 3; ++i) d2 += double(c[i] - focus[i]) * double(c[i] - focus[i]);
            want = d2 < radius * radius;
        } else {
            want = u(rng) < p;
        }
        if (want) refined.refine(id);
    }
    return refined;
}

size_t border_edges_off_original_border(const CatpFile& file, const RefinedSet& refined, const Mesh& original,
                                        double tolerance, std::unordered_map<uint64_t, DiamondFragments>& cache) {
    std::map<std::pair<uint32_t, uint32_t>, int> original_edges;
    for (size_t t = 0; t + 2 < original.indices.size(); t += 3)
        for (int k = 0; k < 3; ++k) {
            uint32_t a = original.indices[t + k], b = original.indices[t + (k + 1) % 3];
            if (a != b) original_edges[{std::min(a, b), std::max(a, b)}]++;
        }
    std::vector<std::pair<Vec3d, Vec3d>> border;
    for (auto& [e, n] : original_edges)
        if (n == 1) border.push_back({original.positions[e.first], original.positions[e.second]});
    auto distance_to_border = [&](const Vec3d& p) {
        double best = 1e300;
        for (auto& [a, b] : border) {
            double ab[3], ap[3], len2 = 0, t = 0;
            for (int i = 0; i < 3; ++i) {
                ab[i] = b[i] - a[i];
                ap[i] = p[i] - a[i];
                len2 += ab[i] * ab[i];
                t += ab[i] * ap[i];
            }
            t = len2 > 0 ? std::max(0.0, std::min(1.0, t / len2)) : 0.0;
            double d2 = 0;
            for (int i = 0; i < 3; ++i) d2 += (ap[i] - t * ab[i]) * (ap[i] - t * ab[i]);
            best = std::min(best, d2);
        }
        return std::sqrt(best);
    };
    const CatpMeta& meta = file.index().meta();
    WeldedCut cut = weld_cut(file, refined, cache);
    size_t off = 0;
    for (auto& [e, n] : cut.edges) {
        if (n != 1) continue;
        Vec3d mid;
        for (int i = 0; i < 3; ++i)
            mid[i] = meta.origin[i] + 0.5 * double(cut.positions[e.first][i] + cut.positions[e.second][i]) / meta.layout.grid * meta.cell;
        off += distance_to_border(mid) > tolerance;
    }
    return off;
}

}  // namespace catpaq
