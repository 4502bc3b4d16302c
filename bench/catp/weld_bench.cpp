// weld_bench: the converter's clipping and welding paths, timed one by one on a scan-like
// surface placed in the lattice, single-threaded (thread CPU time, best of runs):
//
// - route: what CatpBuild::build_leaves does first per block: route every triangle to its leaf
//   tetrahedra (single_leaf, else search_leaf_slots) and group the hits by leaf (LeafGroups);
// - leaves: then it welds each leaf's triangles into its fragment (FragmentWelder::add_whole,
//   or add_clipped by the leaf's four faces), by position (with TriangleRecords);
// - by index: the same through a SourceVertexMap of the input vertex indices (with
//   TriangleCorners, the usual case); its checksum must be the leaves column's;
// - clip: clip_into_slots on the root diamond (the mesh as the "simplified" surface), the last
//   step of every coarsening;
// - gather: the clip's slot fragments appended into one welder (FragmentWelder::append), as
//   coarsening gathers a diamond's children.
//
// Each column is CPU time per input triangle (ns); "ratio" is route + leaves + clip relative to
// meshoptimizer's meshopt_simplify (to half, float positions) on the same surface in the same
// run, as this machine's speed drifts by a fifth from run to run. The checksum covers every
// fragment built (the vertex and triangle order included), so that a change can be checked to
// keep the output; welding by index must give the leaves' checksum (exit status 1 otherwise).
//
// Usage: weld_bench [triangles ...]   (default 200000)
#include <meshoptimizer.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "../../catp/src/fragment_build.h"
#include "../../catp/src/leaf_routing.h"
#include "base/sysinfo.h"
#include "mesh/generators.h"

using namespace catpaq;

namespace {

// A scan-like surface scaled into the middle of the lattice cube, on the clipper's 2^-32 grid.
WorkFragment make_surface(size_t triangles) {
    Mesh mesh = make_scan_like(triangles, 11);
    Bounds b = mesh.bounds();
    double extent = 0;
    for (int i = 0; i < 3; ++i) extent = std::max(extent, b.max[i] - b.min[i]);
    WorkFragment f;
    const double lo = 0.1 * kLatticeSize, size = 0.8 * kLatticeSize;
    for (const Vec3d& p : mesh.positions) {
        Vec3d q;
        for (int i = 0; i < 3; ++i) q[i] = snap_to_grid(lo + size * (p[i] - b.min[i]) / extent);
        f.positions.push_back(q);
    }
    f.normals = mesh.has_normals() ? mesh.normals : std::vector<Vec3f>(mesh.positions.size(), Vec3f{0, 0, 1});
    f.colors = mesh.has_colors() ? mesh.colors : std::vector<Rgb8>(mesh.positions.size(), Rgb8{200, 200, 200});
    f.indices = mesh.indices;
    return f;
}

uint64_t fnv(uint64_t h, const void* data, size_t bytes) {
    const unsigned char* p = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < bytes; ++i) h = (h ^ p[i]) * 0x100000001b3ull;
    return h;
}

uint64_t checksum(uint64_t h, const WorkFragment& f) {
    h = fnv(h, f.positions.data(), f.positions.size() * sizeof(Vec3d));
    h = fnv(h, f.normals.data(), f.normals.size() * sizeof(Vec3f));
    h = fnv(h, f.colors.data(), f.colors.size() * sizeof(Rgb8));
    return fnv(h, f.indices.data(), f.indices.size() * sizeof(uint32_t));
}

// The leaf routing of every triangle, grouped by leaf (as build_leaves groups its hits).
void route(const WorkFragment& s, int level, const BlockCube& block, std::vector<std::vector<LeafHit>>& hits,
           LeafGroups& groups) {
    hits.resize(1);
    std::vector<LeafHit>& out = hits[0];
    out.clear();
    for (uint32_t t = 0; t * 3 < s.indices.size(); ++t) {
        const Vec3d tri[3] = {s.positions[s.indices[3 * t]], s.positions[s.indices[3 * t + 1]],
                              s.positions[s.indices[3 * t + 2]]};
        SlotKey key;
        if (single_leaf(tri, level, block, key)) {
            out.push_back({key, t, true});
            continue;
        }
        search_leaf_slots(tri, level, block, [&](SlotKey k) { out.push_back({k, t, false}); });
    }
    groups.build(hits);
}

// The groups in key order: the order of the checksum (kept from when the hits were sorted).
std::vector<size_t> key_order(const LeafGroups& groups) {
    std::vector<size_t> order(groups.size());
    for (size_t g = 0; g < order.size(); ++g) order[g] = g;
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return groups.key(a) < groups.key(b); });
    return order;
}

// build_leaves' welding of the routed triangles into one fragment per leaf (kept, as the
// converter keeps them). by_index: welds through a SourceVertexMap on the surface's vertex
// indices, as build_leaves does when the input vertices stay in memory (else by position alone,
// as with TriangleRecords).
void weld_leaves(const WorkFragment& s, const LeafGroups& groups, const std::vector<size_t>& order, bool by_index,
                 std::vector<WorkFragment>& fragments) {
    fragments.clear();
    fragments.reserve(order.size());
    SourceVertexMap welded;
    for (size_t g : order) {
        std::vector<ClipPlane> planes = tetrahedron_clip_planes(
            diamond_tetrahedron(diamond_info(DiamondId{groups.key(g).diamond}), groups.key(g).slot), 0xf);
        WorkFragment& fragment = fragments.emplace_back();
        FragmentWelder welder(fragment);
        const size_t triangles = size_t(groups.end(g) - groups.begin(g));
        welder.reserve(triangles * 5 / 8 + 64, triangles * 9 / 8 + 16);
        welded.clear(triangles * 5 / 8 + 64);
        for (const LeafGroups::Entry* e = groups.begin(g); e != groups.end(g); ++e) {
            const uint32_t* f = &s.indices[3 * size_t(e->triangle)];
            const std::array<Vec3d, 3> tri = {s.positions[f[0]], s.positions[f[1]], s.positions[f[2]]};
            const std::array<Vec3f, 3> normals = {s.normals[f[0]], s.normals[f[1]], s.normals[f[2]]};
            const std::array<Rgb8, 3> colors = {s.colors[f[0]], s.colors[f[1]], s.colors[f[2]]};
            if (by_index) {
                if (e->whole)
                    welder.add_whole(f, welded, tri, normals, colors);
                else
                    welder.add_clipped(f, welded, tri, normals, colors, planes);
            } else if (e->whole) {
                welder.add_whole(tri, normals, colors);
            } else {
                welder.add_clipped(tri, normals, colors, planes);
            }
        }
    }
}

// The checksum of fragments in order (outside the timing: byte-wise, it took a third of the
// welding's time).
uint64_t checksum(const std::vector<WorkFragment>& fragments) {
    uint64_t h = 0xcbf29ce484222325ull;
    for (const WorkFragment& f : fragments) h = checksum(h, f);
    return h;
}

}  // namespace

int main(int argc, char** argv) {
    std::vector<size_t> sizes;
    for (int i = 1; i < argc; ++i) sizes.push_back(size_t(std::strtoull(argv[i], nullptr, 10)));
    if (sizes.empty()) sizes = {200000};
    const int kRuns = 7;
    std::printf("thread CPU time per input triangle (ns), best of %d\n\n", kRuns);
    std::printf("%10s %6s %9s %9s %9s %9s %9s %9s %9s %7s   %s\n", "triangles", "level", "tri/leaf", "route",
                "leaves", "by index", "clip", "gather", "meshopt", "ratio", "checksum");
    bool same = true;
    for (size_t n : sizes) {
        const WorkFragment surface = make_surface(n);
        const size_t triangles = surface.indices.size() / 3;
        // The leaf level the converter would pick: about 2000 triangles per leaf.
        BlockCube block;  // the whole lattice cube as one block (octave 0)
        int level = 3;
        std::vector<std::vector<LeafHit>> hits;
        LeafGroups groups;
        route(surface, level, block, hits, groups);
        while (hits[0].size() / groups.size() > 2000 && level < kMaxLevel) route(surface, ++level, block, hits, groups);
        const double t_route = best_of(kRuns, [&] { route(surface, level, block, hits, groups); }, thread_cpu_seconds);
        const std::vector<size_t> order = key_order(groups);
        std::vector<WorkFragment> fragments;
        const double t_leaves =
            best_of(kRuns, [&] { weld_leaves(surface, groups, order, false, fragments); }, thread_cpu_seconds);
        const uint64_t h_leaves = checksum(fragments);
        const double t_index =
            best_of(kRuns, [&] { weld_leaves(surface, groups, order, true, fragments); }, thread_cpu_seconds);
        const uint64_t h_index = checksum(fragments);
        if (h_index != h_leaves) {
            std::printf("welding by index changed the leaves' fragments\n");
            same = false;
        }

        const DiamondInfo root = diamond_info(root_diamond());
        std::array<WorkFragment, 8> slots;
        const double t_clip = best_of(kRuns, [&] {
            for (auto& f : slots) f = WorkFragment{};
            clip_into_slots(root, surface, surface.indices, slots);
        }, thread_cpu_seconds);
        uint64_t h_clip = 0xcbf29ce484222325ull;
        for (const WorkFragment& f : slots) h_clip = checksum(h_clip, f);

        WorkFragment gathered;
        const double t_gather = best_of(kRuns, [&] {
            gathered = WorkFragment{};
            FragmentWelder welder(gathered);
            size_t vertices = 0, tris = 0;
            for (const WorkFragment& f : slots) {
                vertices += f.positions.size();
                tris += f.indices.size() / 3;
            }
            welder.reserve(vertices, tris);
            for (const WorkFragment& f : slots) welder.append(f);
        }, thread_cpu_seconds);
        const uint64_t h_gather = checksum(0xcbf29ce484222325ull, gathered);

        std::vector<float> floats;
        for (const Vec3d& p : surface.positions) floats.insert(floats.end(), {float(p[0]), float(p[1]), float(p[2])});
        std::vector<uint32_t> kept(surface.indices.size());
        const double t_meshopt = best_of(kRuns, [&] {
            meshopt_simplify(kept.data(), surface.indices.data(), surface.indices.size(), floats.data(),
                             surface.positions.size(), 3 * sizeof(float), triangles / 2 * 3, 1e-2f, 0, nullptr);
        }, thread_cpu_seconds);

        const double scale = 1e9 / double(triangles);
        std::printf("%10zu %6d %9zu %9.1f %9.1f %9.1f %9.1f %9.1f %9.1f %7.2f   %016llx %016llx %016llx\n", triangles,
                    level, hits[0].size() / groups.size(), t_route * scale, t_leaves * scale, t_index * scale,
                    t_clip * scale, t_gather * scale, t_meshopt * scale, (t_route + t_leaves + t_clip) / t_meshopt,
                    (unsigned long long)h_leaves, (unsigned long long)h_clip, (unsigned long long)h_gather);
    }
    return same ? 0 : 1;
}
