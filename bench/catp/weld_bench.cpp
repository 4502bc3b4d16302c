// weld_bench: the converter's clipping and welding paths, timed one by one on a scan-like
// surface placed in the lattice, single-threaded (thread CPU time, best of runs):
//
// - leaves: what CatpBuild::build_leaves does per block: route every triangle to its leaf
//   tetrahedra (single_leaf, else for_each_leaf_slot) and weld each leaf's triangles into its
//   fragment (FragmentWelder::add_whole, or add_clipped by the leaf's four faces);
// - clip: clip_into_slots on the root diamond (the mesh as the "simplified" surface), the last
//   step of every coarsening;
// - gather: the clip's slot fragments appended into one welder (FragmentWelder::append), as
//   coarsening gathers a diamond's children.
//
// Each column is CPU time per input triangle (ns). The checksum covers every fragment built (the
// vertex and triangle order included), so that a change can be checked to keep the output.
//
// Usage: weld_bench [triangles ...]   (default 200000)
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

struct Hit {
    SlotKey key;
    uint32_t triangle;
    bool whole;
};

// The leaf routing of every triangle, sorted by leaf (as build_leaves sorts its hits).
std::vector<Hit> route(const WorkFragment& s, int level, const BlockCube& block) {
    std::vector<Hit> hits;
    for (uint32_t t = 0; t * 3 < s.indices.size(); ++t) {
        const Vec3d tri[3] = {s.positions[s.indices[3 * t]], s.positions[s.indices[3 * t + 1]],
                              s.positions[s.indices[3 * t + 2]]};
        SlotKey key;
        if (single_leaf(tri, level, block, key)) {
            hits.push_back({key, t, true});
            continue;
        }
        for_each_leaf_slot(tri, level, block, [&](SlotKey k) { hits.push_back({k, t, false}); });
    }
    std::sort(hits.begin(), hits.end(), [](const Hit& a, const Hit& b) {
        return a.key < b.key || (a.key == b.key && a.triangle < b.triangle);
    });
    return hits;
}

// build_leaves' welding of the routed triangles, leaf by leaf; returns the fragments' checksum.
uint64_t weld_leaves(const WorkFragment& s, const std::vector<Hit>& hits) {
    uint64_t h = 0xcbf29ce484222325ull;
    for (size_t begin = 0; begin < hits.size();) {
        size_t end = begin + 1;
        while (end < hits.size() && hits[end].key == hits[begin].key) ++end;
        std::vector<ClipPlane> planes = tetrahedron_clip_planes(
            diamond_tetrahedron(diamond_info(DiamondId{hits[begin].key.diamond}), hits[begin].key.slot), 0xf);
        WorkFragment fragment;
        FragmentWelder welder(fragment);
        const size_t triangles = end - begin;
        welder.reserve(triangles * 5 / 8 + 64, triangles * 9 / 8 + 16);
        for (size_t i = begin; i < end; ++i) {
            const uint32_t* f = &s.indices[3 * size_t(hits[i].triangle)];
            const std::array<Vec3d, 3> tri = {s.positions[f[0]], s.positions[f[1]], s.positions[f[2]]};
            const std::array<Vec3f, 3> normals = {s.normals[f[0]], s.normals[f[1]], s.normals[f[2]]};
            const std::array<Rgb8, 3> colors = {s.colors[f[0]], s.colors[f[1]], s.colors[f[2]]};
            if (hits[i].whole)
                welder.add_whole(tri, normals, colors);
            else
                welder.add_clipped(tri, normals, colors, planes);
        }
        h = checksum(h, fragment);
        begin = end;
    }
    return h;
}

}  // namespace

int main(int argc, char** argv) {
    std::vector<size_t> sizes;
    for (int i = 1; i < argc; ++i) sizes.push_back(size_t(std::strtoull(argv[i], nullptr, 10)));
    if (sizes.empty()) sizes = {200000};
    const int kRuns = 7;
    std::printf("thread CPU time per input triangle (ns), best of %d\n\n", kRuns);
    std::printf("%10s %6s %9s %9s %9s %9s %9s   %s\n", "triangles", "level", "tri/leaf", "route", "leaves", "clip",
                "gather", "checksum");
    for (size_t n : sizes) {
        const WorkFragment surface = make_surface(n);
        const size_t triangles = surface.indices.size() / 3;
        // The leaf level the converter would pick: about 2000 triangles per leaf.
        BlockCube block;  // the whole lattice cube as one block (octave 0)
        int level = 3;
        std::vector<Hit> hits = route(surface, level, block);
        auto leaves = [&] {
            size_t count = 0;
            for (size_t i = 0; i < hits.size(); ++i) count += i == 0 || !(hits[i].key == hits[i - 1].key);
            return count;
        };
        while (hits.size() / leaves() > 2000 && level < kMaxLevel) hits = route(surface, ++level, block);
        const double t_route = best_of(kRuns, [&] { hits = route(surface, level, block); }, thread_cpu_seconds);
        uint64_t h_leaves = 0;
        const double t_leaves = best_of(kRuns, [&] { h_leaves = weld_leaves(surface, hits); }, thread_cpu_seconds);

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

        const double scale = 1e9 / double(triangles);
        std::printf("%10zu %6d %9zu %9.1f %9.1f %9.1f %9.1f   %016llx %016llx %016llx\n", triangles, level,
                    hits.size() / leaves(), t_route * scale, t_leaves * scale, t_clip * scale, t_gather * scale,
                    (unsigned long long)h_leaves, (unsigned long long)h_clip, (unsigned long long)h_gather);
    }
    return 0;
}
