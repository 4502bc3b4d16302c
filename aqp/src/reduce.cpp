// Out-of-core reduction by block-wise simplification (aqp/reduce.h).
#include "aqp/reduce.h"

#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#ifdef __GLIBC__
#include <malloc.h>
#endif

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <functional>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "base/error.h"
#include "base/progress.h"
#include "base/temp_file.h"
#include "catp/distance.h"
#include "catp/simplify.h"
#include "mesh/io.h"
#include "vec3.h"

namespace catpaq::aqp {
namespace {

using Clock = std::chrono::steady_clock;
constexpr size_t kChunk = size_t(1) << 16;  // vertices or faces per read
constexpr uint32_t kNone = UINT32_MAX, kSeam = UINT32_MAX - 1;
// Working memory per block triangle (simplify_mesh's 200 bytes per vertex and 12 per index, the
// block's copies and edge tables).
constexpr uint64_t kBlockBytesPerTriangle = 400;

// An input vertex in the scratch file.
struct StoredVertex {
    double p[3];
    float n[3];
    uint8_t rgb[3];
    uint8_t pad;
};
static_assert(sizeof(StoredVertex) == 40);

// An array in an anonymous scratch file, mapped.
template <class T>
class ScratchArray {
public:
    ScratchArray(const std::string& near, uint64_t n) : file_(near), n_(n) {
        if (n == 0) return;
        const uint8_t zero = 0;
        file_.write_at(bytes() - 1, &zero, 1);  // the file's size (sparse)
        data_ = static_cast<T*>(file_.map(bytes()));
    }
    ~ScratchArray() { unmap_file(data_, bytes()); }
    T* data() const { return data_; }
    T& operator[](uint64_t i) const { return data_[i]; }
    uint64_t bytes() const { return n_ * sizeof(T); }
    // Drops the resident pages (the data stays in the file): they stop counting as the process's.
    void release() const { release_mapped_pages(data_, bytes()); }

private:
    TempFile file_;
    uint64_t n_;
    T* data_ = nullptr;
};

// A regular grid of cubic blocks over the box from `origin`, `n` along each axis, shifted by
// `shift` blocks (round 2: 0.5).
struct BlockGrid {
    Vec3d origin{};
    double side = 1;
    uint32_t n[3] = {1, 1, 1};
    double shift = 0;

    BlockGrid(const Bounds& b, uint32_t along_longest, double shift_blocks) : origin(b.min), shift(shift_blocks) {
        const double longest = std::max({b.max[0] - b.min[0], b.max[1] - b.min[1], b.max[2] - b.min[2]});
        side = longest > 0 ? longest / along_longest : 1.0;
        for (int a = 0; a < 3; ++a)
            n[a] = uint32_t(std::clamp(std::ceil((b.max[a] - b.min[a]) / side + shift), 1.0, 4096.0));
    }
    uint32_t count() const { return n[0] * n[1] * n[2]; }
    uint32_t block_of(const double* p0, const double* p1, const double* p2) const {
        uint32_t c[3];
        for (int a = 0; a < 3; ++a) {
            const double centroid = (p0[a] + p1[a] + p2[a]) / 3.0;
            c[a] = uint32_t(std::clamp(std::floor((centroid - origin[a]) / side + shift), 0.0, double(n[a] - 1)));
        }
        return c[0] + n[0] * (c[1] + n[1] * c[2]);
    }
};


// Distance between the segments p0 p1 and q0 q1 (closest points by clamped parameters, Ericson
// 5.1.9).
double segment_distance(const Vec3d& p0, const Vec3d& p1, const Vec3d& q0, const Vec3d& q1) {
    const Vec3d d1 = sub(p1, p0), d2 = sub(q1, q0), r = sub(p0, q0);
    const double a = dot(d1, d1), e = dot(d2, d2), f = dot(d2, r);
    double s = 0, t = 0;
    if (a <= 0 && e <= 0) return std::sqrt(dot(r, r));
    if (a <= 0) {
        t = std::clamp(f / e, 0.0, 1.0);
    } else {
        const double c = dot(d1, r);
        if (e <= 0) {
            s = std::clamp(-c / a, 0.0, 1.0);
        } else {
            const double b = dot(d1, d2), denom = a * e - b * b;
            s = denom > 0 ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
            t = (b * s + f) / e;
            if (t < 0) t = 0, s = std::clamp(-c / a, 0.0, 1.0);
            else if (t > 1) t = 1, s = std::clamp((b - c) / a, 0.0, 1.0);
        }
    }
    const Vec3d x{p0[0] + d1[0] * s, p0[1] + d1[1] * s, p0[2] + d1[2] * s}, y{q0[0] + d2[0] * t, q0[1] + d2[1] * t, q0[2] + d2[2] * t};
    return std::sqrt(dot(sub(x, y), sub(x, y)));
}

// Flips edges of the triangles `tri` (vertex ids into xyz) towards a Delaunay triangulation where
// that changes the surface little: quadric simplification leaves slivers (most of them obtuse
// caps along creases), which the AQP domain's parameterization cannot flatten. An interior edge
// (a, b) between (a, b, c) and (b, a, d) becomes (c, d) when the angles at c and d sum to more
// than pi, the segments a b and c d are within a fiftieth of |a b| (a tenth where one of the two
// is a sliver: shape below 0.2; the flip moves the surface by no more than that distance), the
// new triangles face the way the old ones did, with area, and (c, d) is no edge yet. Vertices
// never move; borders and non-manifold edges stay.
void flip_towards_delaunay(const double* xyz, std::vector<uint32_t>& tri) {
    auto at = [xyz](uint32_t v) { return Vec3d{xyz[3 * v], xyz[3 * v + 1], xyz[3 * v + 2]}; };
    auto angle = [&](const Vec3d& apex, const Vec3d& p, const Vec3d& q) {
        const Vec3d u = sub(p, apex), w = sub(q, apex);
        return std::atan2(std::sqrt(dot(cross(u, w), cross(u, w))), dot(u, w));
    };
    // 1 for an equilateral triangle, 0 for a degenerate one (twice the area: cross_length).
    auto shape = [](double cross_length, const Vec3d& p, const Vec3d& q, const Vec3d& r) {
        const double sum = dot(sub(q, p), sub(q, p)) + dot(sub(r, q), sub(r, q)) + dot(sub(p, r), sub(p, r));
        return sum > 0 ? 2 * std::sqrt(3.0) * cross_length / sum : 0.0;
    };
    auto key = [](uint32_t a, uint32_t b) { return uint64_t(a) << 32 | b; };
    // Directed edge -> 3 triangle + corner (the edge runs from that corner to the next).
    std::unordered_map<uint64_t, uint32_t> edge;
    edge.reserve(tri.size() * 2);
    for (uint32_t k = 0; k < tri.size(); ++k) {
        const uint32_t t = k / 3, a = tri[k], b = tri[3 * t + (k + 1) % 3];
        if (!edge.emplace(key(a, b), k).second) edge[key(a, b)] = kNone;  // used twice one way
    }
    std::vector<uint32_t> queue(tri.size());
    for (uint32_t k = 0; k < tri.size(); ++k) queue[k] = k;
    size_t budget = 10 * tri.size();  // flips terminate in the plane; on a surface, bounded
    while (!queue.empty() && budget > 0) {
        const uint32_t k = queue.back();
        queue.pop_back();
        const uint32_t t = k / 3, a = tri[k], b = tri[3 * t + (k + 1) % 3], c = tri[3 * t + (k + 2) % 3];
        const auto ab = edge.find(key(a, b)), ba = edge.find(key(b, a));
        if (ab == edge.end() || ba == edge.end() || ab->second != k || ba->second == kNone) continue;
        const uint32_t m = ba->second, u = m / 3, d = tri[3 * u + (m + 2) % 3];
        if (c == d || edge.count(key(c, d)) || edge.count(key(d, c))) continue;
        const Vec3d pa = at(a), pb = at(b), pc = at(c), pd = at(d);
        if (angle(pc, pa, pb) + angle(pd, pb, pa) <= M_PI + 1e-9) continue;
        const Vec3d nt = cross(sub(pb, pa), sub(pc, pa)), nu = cross(sub(pa, pb), sub(pd, pb));
        const double lt = std::sqrt(dot(nt, nt)), lu = std::sqrt(dot(nu, nu));
        if (!(lt > 0 && lu > 0)) continue;
        const double gap = segment_distance(pa, pb, pc, pd);
        const bool sliver = std::min(shape(lt, pa, pb, pc), shape(lu, pb, pa, pd)) < 0.2;
        if (!(gap <= (sliver ? 0.1 : 0.02) * std::sqrt(dot(sub(pb, pa), sub(pb, pa))))) continue;
        const Vec3d n1 = cross(sub(pd, pa), sub(pc, pa)), n2 = cross(sub(pb, pd), sub(pc, pd));
        const bool same_way = (dot(n1, nt) > 0 || dot(n1, nu) > 0) && (dot(n2, nt) > 0 || dot(n2, nu) > 0) &&
                              dot(n1, n2) > 0;
        if (!same_way) continue;
        // (a, b, c), (b, a, d) -> (a, d, c) in t, (d, b, c) in u.
        for (uint32_t i = 0; i < 3; ++i) {
            edge.erase(key(tri[3 * t + i], tri[3 * t + (i + 1) % 3]));
            edge.erase(key(tri[3 * u + i], tri[3 * u + (i + 1) % 3]));
        }
        tri[3 * t] = a, tri[3 * t + 1] = d, tri[3 * t + 2] = c;
        tri[3 * u] = d, tri[3 * u + 1] = b, tri[3 * u + 2] = c;
        for (uint32_t i = 0; i < 3; ++i) {
            edge[key(tri[3 * t + i], tri[3 * t + (i + 1) % 3])] = 3 * t + i;
            edge[key(tri[3 * u + i], tri[3 * u + (i + 1) % 3])] = 3 * u + i;
            queue.push_back(3 * t + i);
            queue.push_back(3 * u + i);
        }
        --budget;
    }
}

// Removes the unlocked vertices with exactly three triangles around them, which close into a
// fan (a -> b -> c): the three become (a, b, c), unless that triangle exists already. Quadric
// simplification leaves such spikes where a collapse would have broken its checks; the AQP
// domain's flattening handles them badly.
void remove_valence_three(std::vector<uint32_t>& tri, const uint8_t* locked, size_t vertex_count) {
    std::vector<uint32_t> start(vertex_count + 1, 0), fan(tri.size());
    for (uint32_t v : tri) ++start[v + 1];
    for (size_t v = 0; v < vertex_count; ++v) start[v + 1] += start[v];
    {
        std::vector<uint32_t> cursor(start.begin(), start.end() - 1);
        for (uint32_t k = 0; k < tri.size(); ++k) fan[cursor[tri[k]]++] = k;
    }
    auto key = [](uint32_t a, uint32_t b, uint32_t c) {  // rotation-invariant
        const uint32_t m = std::min({a, b, c});
        if (m == b) return std::array<uint32_t, 3>{b, c, a};
        if (m == c) return std::array<uint32_t, 3>{c, a, b};
        return std::array<uint32_t, 3>{a, b, c};
    };
    std::vector<std::array<uint32_t, 3>> existing(tri.size() / 3);
    for (size_t t = 0; t < existing.size(); ++t) existing[t] = key(tri[3 * t], tri[3 * t + 1], tri[3 * t + 2]);
    std::sort(existing.begin(), existing.end());
    std::vector<uint8_t> dead(tri.size() / 3, 0);
    for (uint32_t v = 0; v < vertex_count; ++v) {
        if (start[v + 1] - start[v] != 3 || locked[v]) continue;
        uint32_t t[3], next_of[3][2];  // each triangle's corners after v: (x, y) with v -> x -> y
        bool ok = true;
        for (int i = 0; i < 3; ++i) {
            const uint32_t k = fan[start[v] + uint32_t(i)];
            t[i] = k / 3;
            ok &= !dead[t[i]];
            next_of[i][0] = tri[3 * t[i] + (k + 1) % 3];
            next_of[i][1] = tri[3 * t[i] + (k + 2) % 3];
        }
        if (!ok) continue;
        // The outer edges x -> y must chain into one loop a -> b -> c -> a.
        const uint32_t a = next_of[0][0], b = next_of[0][1];
        int i1 = -1, i2 = -1;
        for (int i = 1; i < 3; ++i) {
            if (next_of[i][0] == b) i1 = i;
            if (next_of[i][1] == a) i2 = i;
        }
        if (i1 < 0 || i2 < 0 || i1 == i2) continue;
        const uint32_t c = next_of[i1][1];
        if (next_of[i2][0] != c || c == a || c == b) continue;
        const auto k = key(a, b, c);
        if (std::binary_search(existing.begin(), existing.end(), k)) continue;
        tri[3 * t[0]] = a, tri[3 * t[0] + 1] = b, tri[3 * t[0] + 2] = c;
        dead[t[i1]] = dead[t[i2]] = 1;
        dead[t[0]] = 2;  // rewritten: its corners are no longer what `fan` says
    }
    size_t kept = 0;
    for (size_t t = 0; t < dead.size(); ++t) {
        if (dead[t] == 1) continue;
        for (int i = 0; i < 3; ++i) tri[3 * kept + size_t(i)] = tri[3 * t + size_t(i)];
        ++kept;
    }
    tri.resize(3 * kept);
}

// Simplifies one block's triangles (input vertex ids) to `target` triangles, its seam vertices
// (vertex_block == kSeam) locked; then the valence-3 spikes and the slivers go.
std::vector<uint32_t> simplify_block(const uint32_t* tris, size_t count, uint64_t target, double max_edge,
                                     const StoredVertex* store, const uint32_t* vertex_block) {
    std::vector<uint32_t> ids(tris, tris + 3 * count);
    std::sort(ids.begin(), ids.end());
    ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
    std::vector<double> positions(3 * ids.size());
    std::vector<uint8_t> locked(ids.size());
    for (size_t i = 0; i < ids.size(); ++i) {
        std::memcpy(&positions[3 * i], store[ids[i]].p, 24);  // (simplify_mesh works relative to a vertex)
        locked[i] = vertex_block[ids[i]] == kSeam;
    }
    std::vector<uint32_t> local(3 * count);
    for (size_t k = 0; k < local.size(); ++k)
        local[k] = uint32_t(std::lower_bound(ids.begin(), ids.end(), tris[k]) - ids.begin());
    SimplifySettings settings;
    settings.target_triangles = size_t(std::max<uint64_t>(target, 1));
    settings.max_edge_length = max_edge;
    SimplifyResult s = simplify_mesh(positions.data(), ids.size(), local.data(), local.size(), locked.data(), settings);
    remove_valence_three(s.indices, locked.data(), ids.size());
    flip_towards_delaunay(positions.data(), s.indices);
    for (uint32_t& v : s.indices) v = ids[v];
    return std::move(s.indices);
}

// One round: the triangles sorted by block (`offsets` into `sorted`), each block simplified to
// `ratio` of its triangles, its seam vertices (mark_seams) locked. Returns the kept triangles,
// block after block (the same on any number of threads).
template <class Sorted>
std::vector<uint32_t> simplify_blocks(const Sorted& sorted, const std::vector<uint64_t>& offsets, double ratio,
                                      double max_edge, const StoredVertex* store, const uint32_t* vertex_block, Progress* progress,
                                      const std::function<void()>& between_blocks) {
    const uint32_t blocks = uint32_t(offsets.size() - 1);
    std::vector<std::vector<uint32_t>> results(blocks);
    std::mutex mutex;
    tbb::parallel_for(tbb::blocked_range<uint32_t>(0, blocks, 1), [&](const tbb::blocked_range<uint32_t>& range) {
        for (uint32_t b = range.begin(); b < range.end(); ++b) {
            const uint64_t count = offsets[b + 1] - offsets[b];
            if (count == 0) continue;
            const uint64_t target = uint64_t(std::ceil(double(count) * ratio));
            results[b] = simplify_block(&sorted[3 * offsets[b]], size_t(count), target, max_edge, store, vertex_block);
            if (progress) progress->add(count);
            std::lock_guard<std::mutex> lock(mutex);
            if (between_blocks) between_blocks();
        }
    });
    size_t total = 0;
    for (const std::vector<uint32_t>& r : results) total += r.size();
    std::vector<uint32_t> out;
    out.reserve(total);
    for (std::vector<uint32_t>& r : results) {
        out.insert(out.end(), r.begin(), r.end());
        std::vector<uint32_t>().swap(r);
    }
    return out;
}

// Counting sort of `n` triangles (3 ids each) by their blocks (< `blocks`) into `out`; returns
// the offsets: block b's triangles are out[3 offsets[b] .. 3 offsets[b + 1]). `every_million`,
// if given, runs after each million triangles of either pass (scratch mappings drop their
// pages there, so they do not count as the process's memory).
std::vector<uint64_t> sort_by_block(const uint32_t* tris, const uint32_t* block, uint64_t n, uint32_t blocks,
                                    uint32_t* out, const std::function<void()>& every_million = {}) {
    std::vector<uint64_t> offsets(size_t(blocks) + 1, 0);
    for (uint64_t t = 0; t < n; ++t) {
        ++offsets[block[t] + 1];
        if (every_million && t % 1000000 == 999999) every_million();
    }
    for (size_t b = 1; b < offsets.size(); ++b) offsets[b] += offsets[b - 1];
    std::vector<uint64_t> cursor(offsets.begin(), offsets.end() - 1);
    for (uint64_t t = 0; t < n; ++t) {
        std::memcpy(out + 3 * cursor[block[t]]++, tris + 3 * t, 12);
        if (every_million && t % 1000000 == 999999) every_million();
    }
    return offsets;
}

// Marks vertex_block for the triangles of each block (offsets into sorted): the block, or kSeam
// for a vertex of two.
template <class Sorted>
void mark_seams(const Sorted& sorted, const std::vector<uint64_t>& offsets, uint32_t* vertex_block) {
    for (uint32_t b = 0; b + 1 < offsets.size(); ++b)
        for (uint64_t k = 3 * offsets[b]; k < 3 * offsets[b + 1]; ++k) {
            uint32_t& vb = vertex_block[sorted[k]];
            vb = vb == kNone || vb == b ? b : kSeam;
        }
}

// Blocks along the longest side for about `per_block` triangles in each of a surface's blocks
// (a surface through n^3 blocks occupies about 3 n^2 of them).
uint32_t blocks_along(uint64_t triangles, uint64_t per_block) {
    return uint32_t(std::clamp(std::ceil(std::sqrt(double(triangles) / (3.0 * double(per_block)))), 1.0, 4096.0));
}

// Triangles per block: two blocks at work, each up to twice the average, within half the budget.
uint64_t block_triangles(uint64_t budget) {
    if (budget == 0) return 2000000;
    return std::clamp<uint64_t>(budget / (8 * kBlockBytesPerTriangle), 20000, 2000000);
}

}  // namespace

uint64_t reduce_memory_estimate(uint64_t input_vertices, uint64_t target_triangles, uint64_t budget) {
    // Per input vertex its block (then its new number) and a bit; and the larger of two phases:
    // the rounds (two blocks at work, each up to twice the average, and round 1's result, about
    // 1.5 target triangles as the seams are kept, twice while round 2 sorts it) and the measure
    // (the output mesh, about 40 bytes a triangle, and the AABB tree over it, about 200).
    const uint64_t blocks = std::min(2 * 2 * block_triangles(budget), 2 * 2 * target_triangles) * kBlockBytesPerTriangle;
    const uint64_t rounds = blocks + target_triangles * 3 / 2 * 24, measure = target_triangles * 240;
    return input_vertices * 4 + std::max(rounds, measure) + (uint64_t(32) << 20);
}

Mesh reduce_ply_out_of_core(const std::string& path, const ReduceOptions& options, ReduceReport* report_out) {
    const auto start = Clock::now();
    if (options.target_triangles == 0) fail("the reduction's target must be at least one triangle");
    std::unique_ptr<tbb::global_control> threads;
    if (options.threads)
        threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, options.threads);
    ReduceReport r;
    PlyStream ply(path);
    const bool colours = ply.has_colors(), normals = ply.has_normals();
    r.input_vertices = ply.vertex_count();
    if (ply.face_count() == 0) fail("'%s' has no faces: nothing to reduce", path.c_str());
    if (r.input_vertices >= kSeam)
        fail("'%s' has %llu vertices: the reduction handles fewer than 2^32", path.c_str(), (unsigned long long)r.input_vertices);
    r.memory_estimate = reduce_memory_estimate(r.input_vertices, options.target_triangles, options.memory_budget);
    if (options.memory_budget && r.memory_estimate > options.memory_budget)
        fail("reducing the %llu vertices of '%s' to %llu triangles needs about %llu MiB, above the budget of %llu MiB",
             (unsigned long long)r.input_vertices, path.c_str(), (unsigned long long)options.target_triangles,
             (unsigned long long)(r.memory_estimate >> 20), (unsigned long long)(options.memory_budget >> 20));
    const std::string near = options.scratch_near.empty() ? path : options.scratch_near;
    std::unique_ptr<Progress> progress;
    if (options.progress) progress = std::make_unique<Progress>("convert", "reducing: vertices", r.input_vertices, "vtx");

    // 1. Vertices to scratch.
    ScratchArray<StoredVertex> store(near, r.input_vertices);
    Bounds bounds;
    {
        std::vector<Vec3d> p;
        std::vector<Vec3f> n;
        std::vector<Rgb8> c;
        uint64_t v = 0;
        while (true) {
            p.clear(), n.clear(), c.clear();
            const size_t got = ply.read_vertices(kChunk, p, normals ? &n : nullptr, colours ? &c : nullptr);
            if (got == 0) break;
            for (size_t i = 0; i < got; ++i, ++v) {
                StoredVertex s{};
                std::memcpy(s.p, p[i].data(), 24);
                if (normals) std::memcpy(s.n, n[i].data(), 12);
                if (colours) std::memcpy(s.rgb, c[i].data(), 3);
                store[v] = s;
                bounds.add(p[i]);
            }
            if (progress) progress->add(got);
        }
        store.release();
    }

    // 2. Faces to scratch (the PLY's face count is of polygons: triangles may be more, so the
    //    triangles go to a growing file), then sorted by block.
    const uint64_t per_block = options.block_triangles ? options.block_triangles : block_triangles(options.memory_budget);
    if (progress) progress->phase("reducing: faces", ply.face_count(), "face");
    TempFile tri_file(near);
    std::vector<uint32_t> indices;
    uint64_t triangles = 0;
    while (true) {
        indices.clear();
        const size_t faces = ply.read_faces(kChunk, indices);
        if (faces == 0) break;
        tri_file.write_at(triangles * 12, indices.data(), indices.size() * 4);
        triangles += indices.size() / 3;
        if (progress) progress->add(faces);
    }
    ply.finish();
    r.input_triangles = triangles;
    r.scratch_bytes = store.bytes() + 2 * triangles * 12 + triangles * 4;
    const BlockGrid grid1(bounds, blocks_along(triangles, per_block), 0.0);
    if (progress) progress->phase("reducing: sorting by block", triangles, "tri");
    ScratchArray<uint32_t> sorted(near, 3 * triangles), block(near, triangles);
    double area = 0;
    {
        // Each triangle's block (and the surface's area) in one pass over the triangles, read back
        // in chunks; then the counting sort reads only the blocks and the triangles, in order.
        std::vector<uint32_t> chunk(3 * kChunk);
        for (uint64_t t = 0; t < triangles; t += kChunk) {
            const size_t n = size_t(std::min<uint64_t>(kChunk, triangles - t));
            tri_file.read_at(t * 12, chunk.data(), n * 12);
            for (size_t i = 0; i < n; ++i) {
                const double *a = store[chunk[3 * i]].p, *b = store[chunk[3 * i + 1]].p, *c = store[chunk[3 * i + 2]].p;
                block[t + i] = grid1.block_of(a, b, c);
                const Vec3d n3 = cross(Vec3d{b[0] - a[0], b[1] - a[1], b[2] - a[2]}, Vec3d{c[0] - a[0], c[1] - a[1], c[2] - a[2]});
                area += 0.5 * std::sqrt(dot(n3, n3));
            }
            if (progress) progress->add(n);
            if ((t / kChunk) % 64 == 63) store.release();
        }
        store.release();
    }
    uint32_t* const tris = static_cast<uint32_t*>(tri_file.map(triangles * 12));
    const std::vector<uint64_t> offsets =
        sort_by_block(tris, block.data(), triangles, grid1.count(), sorted.data(), [&] {
            release_mapped_pages(tris, triangles * 12);
            block.release();
            sorted.release();
        });
    unmap_file(tris, triangles * 12);
    block.release();
    for (size_t b = 0; b + 1 < offsets.size(); ++b) {
        r.blocks += offsets[b + 1] > offsets[b];
        r.largest_block = std::max(r.largest_block, offsets[b + 1] - offsets[b]);
    }

    // 3. Round 1, block by block from the scratch file.
    std::vector<uint32_t> vertex_block(r.input_vertices, kNone);
    mark_seams(sorted, offsets, vertex_block.data());
    // The vertices of some triangle: the others (stray points) are not surface, and not measured.
    std::vector<bool> used(r.input_vertices);
    for (uint64_t v = 0; v < r.input_vertices; ++v) used[v] = vertex_block[v] != kNone;
    sorted.release();
    if (progress) progress->phase("reducing: round 1", triangles, "tri");
    const double ratio1 = std::min(1.0, double(options.target_triangles) / double(triangles));
    // Edges at most 2.5 times those of a uniform mesh of the target's triangles (equilateral, of
    // the same area): the quadric error alone leaves flat parts in triangles tens of times larger
    // than curved ones, and the AQP domain's flattening folded on a 10M-triangle scan reduced so.
    const double max_edge = 2.5 * std::sqrt(4.0 * area / (std::sqrt(3.0) * double(options.target_triangles)));
    std::vector<uint32_t> round1 = simplify_blocks(sorted, offsets, ratio1, max_edge, store.data(), vertex_block.data(),
                                                   progress.get(), [&] {
                                                       store.release();
                                                       sorted.release();
                                                   });
    store.release();
    r.round1_triangles = round1.size() / 3;

    // 4. Round 2, in memory, on the grid shifted by half a block (not needed after one block).
    const BlockGrid grid2(bounds, blocks_along(triangles, per_block), 0.5);
    std::vector<uint32_t> round2;
    if (r.blocks == 1) {
        round2.swap(round1);
    } else {
        const uint64_t t1 = round1.size() / 3;
        std::vector<uint32_t> block2(t1);
        for (uint64_t t = 0; t < t1; ++t)
            block2[t] = grid2.block_of(store[round1[3 * t]].p, store[round1[3 * t + 1]].p, store[round1[3 * t + 2]].p);
        std::vector<uint32_t> sorted2(round1.size());
        const std::vector<uint64_t> offsets2 = sort_by_block(round1.data(), block2.data(), t1, grid2.count(), sorted2.data());
        std::vector<uint32_t>().swap(block2);
        std::vector<uint32_t>().swap(round1);
        for (uint32_t v : sorted2) vertex_block[v] = kNone;
        mark_seams(sorted2, offsets2, vertex_block.data());
        if (progress) progress->phase("reducing: round 2", t1, "tri");
        const double ratio2 = std::min(1.0, double(options.target_triangles) / double(std::max<uint64_t>(t1, 1)));
        round2 = simplify_blocks(sorted2, offsets2, ratio2, max_edge, store.data(), vertex_block.data(), progress.get(),
                                 [&] { store.release(); });
    }

    // 5. The output: the vertices round 2 kept, renumbered in order of first use.
    if (progress) progress->phase("reducing: output", round2.size() / 3, "tri");
    std::vector<uint32_t>& renumber = vertex_block;  // (its memory, reused)
    std::fill(renumber.begin(), renumber.end(), kNone);
    Mesh out;
    out.indices.resize(round2.size());
    for (size_t k = 0; k < round2.size(); ++k) {
        uint32_t& id = renumber[round2[k]];
        if (id == kNone) {
            id = uint32_t(out.positions.size());
            const StoredVertex& s = store[round2[k]];
            out.positions.push_back({s.p[0], s.p[1], s.p[2]});
            if (normals) out.normals.push_back({s.n[0], s.n[1], s.n[2]});
            if (colours) out.colors.push_back({s.rgb[0], s.rgb[1], s.rgb[2]});
        }
        out.indices[k] = id;
    }
    std::vector<uint32_t>().swap(round2);
    std::vector<uint32_t>().swap(vertex_block);
    store.release();
    r.vertices = out.positions.size();
    r.triangles = out.triangle_count();
    if (out.indices.empty()) fail("the reduction of '%s' left no triangle", path.c_str());
    validate_mesh(out, "the reduced mesh");

    // 6. The distance: every input vertex against the result, both cores.
    if (progress) progress->phase("reducing: measuring", r.input_vertices, "vtx");
    {
        const SurfaceDistance surface(out.positions, out.indices);
        constexpr uint64_t kGrain = 1 << 14;
        std::atomic<uint64_t> done{0};
        r.vertex_distance = tbb::parallel_reduce(
            tbb::blocked_range<uint64_t>(0, r.input_vertices, kGrain), 0.0,
            [&](const tbb::blocked_range<uint64_t>& range, double worst) {
                for (uint64_t v = range.begin(); v < range.end(); ++v)
                    if (used[v]) worst = std::max(worst, surface.distance({store[v].p[0], store[v].p[1], store[v].p[2]}));
                if (progress) progress->add(range.size());
                if ((done += range.size()) % (64 * kGrain) < range.size()) store.release();
                return worst;
            },
            [](double a, double b) { return std::max(a, b); });
        store.release();
    }
#ifdef __GLIBC__
    // The blocks' memory goes back to the system, not to the allocator's per-thread arenas, where
    // the converter's next phase (on other threads) would not find it and would grow the process
    // beyond the budget instead.
    malloc_trim(0);
#endif
    r.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    if (report_out) *report_out = r;
    return out;
}

}  // namespace catpaq::aqp
