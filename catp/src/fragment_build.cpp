#include "fragment_build.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <unordered_map>
#if defined(__SSE__)
#include <xmmintrin.h>
#endif

#include <tbb/parallel_invoke.h>

#include "catp/simplify.h"
#include "common_codec/barycentric.h"
#include "common_codec/octahedral.h"
#include "common_codec/packed_vertex.h"

namespace catpaq {

size_t PositionHash::operator()(const Vec3d& p) const {
    uint64_t h = 0xcbf29ce484222325ull;
    for (int i = 0; i < 3; ++i) {
        uint64_t bits;
        std::memcpy(&bits, &p[i], 8);
        h = (h ^ bits) * 0x100000001b3ull;
        h ^= h >> 29;
    }
    return size_t(h);
}

FragmentWelder::FragmentWelder(WorkFragment& fragment) : f_(fragment) {
    size_t capacity = 64;
    while (capacity < fragment.positions.size() * 2 + 16) capacity *= 2;
    rehash(capacity);
}

void FragmentWelder::reserve(size_t vertices, size_t triangles) {
    const size_t v = f_.positions.size() + vertices;
    f_.positions.reserve(v);
    f_.normals.reserve(v);
    f_.colors.reserve(v);
    f_.indices.reserve(f_.indices.size() + 3 * triangles);
    size_t capacity = table_.size();
    while (capacity < 2 * v) capacity *= 2;
    if (capacity > table_.size()) rehash(capacity);
}

void FragmentWelder::grow() { rehash(table_.size() * 2); }

void FragmentWelder::rehash(size_t capacity) {
    table_.assign(capacity, 0);
    mask_ = capacity - 1;
    for (uint32_t i = 0; i < f_.positions.size(); ++i) {
        size_t h = PositionHash()(f_.positions[i]) & mask_;
        while (table_[h] != 0) h = (h + 1) & mask_;
        table_[h] = i + 1;
    }
}

uint32_t FragmentWelder::find_or_insert(const Vec3d& p, bool& inserted) {
    if ((f_.positions.size() + 1) * 2 > table_.size()) grow();
    size_t h = PositionHash()(p) & mask_;
    while (table_[h] != 0) {
        const Vec3d& q = f_.positions[table_[h] - 1];
        if (q[0] == p[0] && q[1] == p[1] && q[2] == p[2]) {
            inserted = false;
            return table_[h] - 1;
        }
        h = (h + 1) & mask_;
    }
    uint32_t index = uint32_t(f_.positions.size());
    table_[h] = index + 1;
    inserted = true;
    return index;
}

uint32_t FragmentWelder::add(const Vec3d& position, const float normal[3], const float color[3]) {
    bool inserted;
    uint32_t index = find_or_insert(position, inserted);
    if (!inserted) return index;
    float len = std::sqrt(normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]);
    Vec3f n = len > 0 ? Vec3f{normal[0] / len, normal[1] / len, normal[2] / len} : Vec3f{0, 0, 1};
    Rgb8 c;
    for (int i = 0; i < 3; ++i) c[i] = uint8_t(std::clamp(std::lround(color[i]), 0l, 255l));
    f_.positions.push_back(position);
    f_.normals.push_back(n);
    f_.colors.push_back(c);
    return index;
}

uint32_t FragmentWelder::add(const Vec3d& position, const Vec3f& normal, const Rgb8& color) {
    bool inserted;
    uint32_t index = find_or_insert(position, inserted);
    if (!inserted) return index;
    f_.positions.push_back(position);
    f_.normals.push_back(normal);
    f_.colors.push_back(color);
    return index;
}

void FragmentWelder::triangle(uint32_t a, uint32_t b, uint32_t c) {
    if (a == b || b == c || a == c) return;
    // Three push_backs, not insert(end, {a, b, c}): the range insert is an out-of-line call
    // that showed up in the clipping profile.
    f_.indices.push_back(a);
    f_.indices.push_back(b);
    f_.indices.push_back(c);
}

void FragmentWelder::append(const WorkFragment& other) {
    std::vector<uint32_t>& remap = remap_;  // a member: one allocation for all appended fragments
    remap.resize(other.positions.size());
    for (size_t v = 0; v < other.positions.size(); ++v)
        remap[v] = add(other.positions[v], other.normals[v], other.colors[v]);
    for (size_t i = 0; i + 2 < other.indices.size(); i += 3)
        triangle(remap[other.indices[i]], remap[other.indices[i + 1]], remap[other.indices[i + 2]]);
}

uint32_t FragmentWelder::add_corner(uint32_t* cached, const Vec3d& position, const Vec3f& normal, const Rgb8& color) {
    if (!cached) return add(position, normal, color);
    if (*cached == kNotWelded) *cached = add(position, normal, color);
    return *cached;
}

template <class Cache>
void FragmentWelder::whole(const Cache& cached, const std::array<Vec3d, 3>& tri, const std::array<Vec3f, 3>& normals,
                           const std::array<Rgb8, 3>& colors) {
    if (!has_area(tri)) return;
    uint32_t ids[3];
    for (int k = 0; k < 3; ++k) ids[k] = add_corner(cached(k), tri[k], normals[k], colors[k]);
    triangle(ids[0], ids[1], ids[2]);
}

template <class Cache>
void FragmentWelder::clipped(const Cache& cached, const std::array<Vec3d, 3>& tri, const std::array<Vec3f, 3>& normals,
                             const std::array<Rgb8, 3>& colors, const std::vector<ClipPlane>& planes) {
    clip_triangle(tri, planes, polygon_);
    if (polygon_.size() < 3) return;
    pieces_.clear();
    triangulate_polygon(polygon_, pieces_);
    uint32_t ids[16];
    assert(polygon_.size() <= 16);  // a triangle clipped by a tetrahedron has at most 7 corners
    for (size_t k = 0; k < polygon_.size(); ++k) {
        const ClipVertex& cv = polygon_[k];
        int corner = -1;
        for (int j = 0; j < 3; ++j)
            if (cv.weights[j] == 1.0) corner = j;
        if (corner >= 0) {
            // A construction can have a corner's weight 1 at a snapped position of its own:
            // only the corner's exact position is the source vertex.
            const Vec3d& p = tri[corner];
            const bool at_corner = cv.position[0] == p[0] && cv.position[1] == p[1] && cv.position[2] == p[2];
            ids[k] = add_corner(at_corner ? cached(corner) : nullptr, cv.position, normals[corner], colors[corner]);
            continue;
        }
        float n[3] = {0, 0, 0}, c[3] = {0, 0, 0};
        for (int j = 0; j < 3; ++j)
            for (int a = 0; a < 3; ++a) {
                n[a] += float(cv.weights[j]) * normals[j][a];
                c[a] += float(cv.weights[j]) * colors[j][a];
            }
        ids[k] = add(cv.position, n, c);
    }
    for (auto& piece : pieces_) triangle(ids[piece[0]], ids[piece[1]], ids[piece[2]]);
}

namespace {

// The caches of add_whole and add_clipped: none, an array by source index, a SourceVertexMap.
struct NoCache {
    uint32_t* operator()(int) const { return nullptr; }
};
struct ArrayCache {
    const uint32_t* source;
    uint32_t* welded;
    uint32_t* operator()(int k) const { return &welded[source[k]]; }
};
struct MapCache {
    const uint32_t* source;
    SourceVertexMap& welded;
    uint32_t* operator()(int k) const { return &welded[source[k]]; }
};

}  // namespace

void FragmentWelder::add_whole(const std::array<Vec3d, 3>& tri, const std::array<Vec3f, 3>& normals,
                               const std::array<Rgb8, 3>& colors) {
    whole(NoCache{}, tri, normals, colors);
}

void FragmentWelder::add_whole(const uint32_t source[3], uint32_t* welded, const std::array<Vec3d, 3>& tri,
                               const std::array<Vec3f, 3>& normals, const std::array<Rgb8, 3>& colors) {
    whole(ArrayCache{source, welded}, tri, normals, colors);
}

void FragmentWelder::add_whole(const uint32_t source[3], SourceVertexMap& welded, const std::array<Vec3d, 3>& tri,
                               const std::array<Vec3f, 3>& normals, const std::array<Rgb8, 3>& colors) {
    whole(MapCache{source, welded}, tri, normals, colors);
}

void FragmentWelder::add_clipped(const std::array<Vec3d, 3>& tri, const std::array<Vec3f, 3>& normals,
                                 const std::array<Rgb8, 3>& colors, const std::vector<ClipPlane>& planes) {
    clipped(NoCache{}, tri, normals, colors, planes);
}

void FragmentWelder::add_clipped(const uint32_t source[3], uint32_t* welded, const std::array<Vec3d, 3>& tri,
                                 const std::array<Vec3f, 3>& normals, const std::array<Rgb8, 3>& colors,
                                 const std::vector<ClipPlane>& planes) {
    clipped(ArrayCache{source, welded}, tri, normals, colors, planes);
}

void FragmentWelder::add_clipped(const uint32_t source[3], SourceVertexMap& welded, const std::array<Vec3d, 3>& tri,
                                 const std::array<Vec3f, 3>& normals, const std::array<Rgb8, 3>& colors,
                                 const std::vector<ClipPlane>& planes) {
    clipped(MapCache{source, welded}, tri, normals, colors, planes);
}

void SourceVertexMap::clear(size_t vertices) {
    size_t capacity = 64;
    while (capacity < 2 * vertices) capacity *= 2;
    size_ = 0;
    // Reuses the table when it is big enough: only its entries need clearing.
    if (table_.size() >= capacity && table_.size() <= 4 * capacity) {
        std::fill(table_.begin(), table_.end(), Slot{0, 0});
        return;
    }
    table_.assign(capacity, Slot{0, 0});
    mask_ = capacity - 1;
}

void SourceVertexMap::rehash(size_t capacity) {
    std::vector<Slot> old(capacity, Slot{0, 0});
    old.swap(table_);
    mask_ = capacity - 1;
    for (const Slot& e : old) {
        if (e.key == 0) continue;
        size_t h = size_t((uint64_t(e.key) * 0x9E3779B97F4A7C15ull) >> 32) & mask_;
        while (table_[h].key != 0) h = (h + 1) & mask_;
        table_[h] = e;
    }
}

uint32_t& SourceVertexMap::operator[](uint32_t source) {
    const uint32_t key = source + 1;
    size_t h = size_t((uint64_t(key) * 0x9E3779B97F4A7C15ull) >> 32) & mask_;
    while (table_[h].key != 0) {
        if (table_[h].key == key) return table_[h].value;
        h = (h + 1) & mask_;
    }
    if (2 * (size_ + 1) > table_.size()) {
        rehash(2 * table_.size());
        return (*this)[source];
    }
    ++size_;
    table_[h] = {key, FragmentWelder::kNotWelded};
    return table_[h].value;
}

static ClipPlane face_clip_plane(const LatticePoint& a, const LatticePoint& b, const LatticePoint& c,
                                 const LatticePoint& keep) {
    ClipPlane cp;
    cp.plane = make_plane(a, b, c);
    Vec3d k = {double(keep[0]), double(keep[1]), double(keep[2])};
    cp.sign = plane_side(cp.plane, k) > 0 ? 1 : -1;
    cp.corners = {a, b, c};
    cp.lines = {{a, b}, {b, c}, {a, c}};
    return cp;
}

std::vector<ClipPlane> tetrahedron_clip_planes(const Tetrahedron& t, unsigned face_mask) {
    std::vector<ClipPlane> planes;
    for (int f = 0; f < 4; ++f)
        if (face_mask & (1u << f)) planes.push_back(face_clip_plane(t[(f + 1) % 4], t[(f + 2) % 4], t[(f + 3) % 4], t[f]));
    return planes;
}

// True if three quantized vertices of one tetrahedron are not collinear: exactly, on their
// weights (an affine image of the positions, so collinear in one iff in the other), in small
// integers (weights <= 16383: products < 2^28).
static bool has_area(const BaryWeights& a, const BaryWeights& b, const BaryWeights& c) {
    int32_t u[3], v[3];
    for (int i = 0; i < 3; ++i) {
        u[i] = b[i + 1] - a[i + 1];
        v[i] = c[i + 1] - a[i + 1];
    }
    return u[1] * v[2] - u[2] * v[1] != 0 || u[2] * v[0] - u[0] * v[2] != 0 || u[0] * v[1] - u[1] * v[0] != 0;
}

// The position bits of every vertex of `in` in the layout (quantize_fragment's first pass): the
// barycentric index (Rgb24, Rgb18) or the three 16-bit weights (Position48); and the weights if
// `weights` is given.
static void quantize_positions(const WorkFragment& in, const Tetrahedron& corners, const VertexLayout& layout,
                               uint64_t* key, BaryWeights* weights) {
    LatticePlane faces[4];
    for (int f = 0; f < 4; ++f) faces[f] = make_plane(corners[(f + 1) % 4], corners[(f + 2) % 4], corners[(f + 3) % 4]);
    std::array<LatticePoint, 4> c = {corners[0], corners[1], corners[2], corners[3]};
    const uint8_t no_color[3] = {0, 0, 0};
    for (size_t v = 0; v < in.positions.size(); ++v) {
        const Vec3d& p = in.positions[v];
        SupportMask support = 0;
        for (int f = 0; f < 4; ++f)
            if (plane_side(faces[f], p) != 0) support |= SupportMask(1 << f);
        if (support == 0) support = 0xf;  // cannot happen for a point in the tetrahedron
        const BaryWeights w = bary_quantize(p.data(), c, support, layout.grid);
        key[v] = pack_vertex(layout, w, 0, no_color).payload();
        if (weights) weights[v] = w;
    }
}

void quantize_fragment(const WorkFragment& in, const Tetrahedron& corners, const VertexLayout& layout, FragmentMesh& out,
                       QuantizeTrace* trace) {
    out.layout = layout;
    out.vertices.clear();
    out.indices.clear();
    // Three passes: position keys; merging by key; the new vertices' normals. The merge probes a
    // hash table at random, and interleaved with the quantization (which fills the
    // out-of-order window) every probe's cache miss stalled the loop: that load was 65% of
    // quantize_fragment's own time in perf. Alone in a short loop, with prefetching, the
    // misses overlap.
    const size_t n = in.positions.size();
    // Arrays kept by each thread from call to call (quantize_fragment makes no nested call):
    // fresh ones for every slot of every node cost an allocation, a zero fill and page faults.
    struct Scratch {
        std::vector<uint64_t> key;
        std::vector<uint32_t> remap, first_of;
        std::vector<std::pair<uint64_t, uint32_t>> by_position;
    };
    thread_local Scratch scratch;
    std::vector<uint64_t>& key = scratch.key;
    key.resize(n);
    if (trace) trace->weights.resize(n);
    quantize_positions(in, corners, layout, key.data(), trace ? trace->weights.data() : nullptr);
    // Each input vertex's vertex in `out` (the trace's own array when there is one).
    std::vector<uint32_t>& remap = trace ? trace->vertex_of : scratch.remap;
    remap.resize(n);

    // Vertices closer than a grid step quantize to the same position: merge them (keeping the
    // first one's normal and colour) and drop the triangles that collapse.
    // Open addressing on the position key (std::unordered_map allocates a node per vertex;
    // quantize_fragment was 6% of the converter's CPU time with it, in perf).
    size_t capacity = 16;
    while (capacity < n * 2) capacity *= 2;
    const size_t mask = capacity - 1;
    constexpr uint64_t kEmpty = UINT64_MAX;  // no position key (they have at most 48 bits)
    std::vector<std::pair<uint64_t, uint32_t>>& by_position = scratch.by_position;  // key, vertex
    by_position.assign(capacity, {kEmpty, 0});
    auto slot_of = [mask](uint64_t k) {
        k *= 0x9E3779B97F4A7C15ull;
        return size_t(k ^ (k >> 32)) & mask;
    };
    constexpr size_t kPrefetchAhead = 8;
    std::vector<uint32_t>& first_of = scratch.first_of;  // the input vertex of each output vertex
    first_of.clear();
    first_of.reserve(n);
    for (size_t v = 0; v < n; ++v) {
        if (v + kPrefetchAhead < n) __builtin_prefetch(&by_position[slot_of(key[v + kPrefetchAhead])]);
        const uint64_t k = key[v];
        size_t h = slot_of(k);
        while (by_position[h].first != kEmpty && by_position[h].first != k) h = (h + 1) & mask;
        if (by_position[h].first == k) {
            remap[v] = by_position[h].second;
            continue;
        }
        by_position[h] = {k, uint32_t(first_of.size())};
        remap[v] = uint32_t(first_of.size());
        first_of.push_back(uint32_t(v));
    }

    out.vertices.resize(first_of.size());
    for (size_t i = 0; i < first_of.size(); ++i) {
        const uint32_t v = first_of[i];
        const Vec3f& nv = in.normals[v];
        const uint64_t payload = key[v] | color_payload(layout, in.colors[v].data());
        out.vertices[i] = PackedVertex::from_payload(payload, oct_encode_precise(nv[0], nv[1], nv[2]));
    }
    if (trace) {
        trace->triangle_source.clear();
        trace->flat.clear();
    }
    for (size_t i = 0; i + 2 < in.indices.size(); i += 3) {
        uint32_t a = remap[in.indices[i]], b = remap[in.indices[i + 1]], d = remap[in.indices[i + 2]];
        if (a == b || b == d || a == d) continue;
        if (trace) {
            // Tested here, where the weights are at hand (a later pass cost 5% of the build).
            const BaryWeights* w = trace->weights.data();
            if (!has_area(w[in.indices[i]], w[in.indices[i + 1]], w[in.indices[i + 2]]))
                trace->flat.push_back(uint32_t(out.indices.size() / 3));
            trace->triangle_source.push_back(uint32_t(i / 3));
        }
        out.indices.insert(out.indices.end(), {a, b, d});
    }
}

// Closest point on triangle (a, b, c) to p (Ericson, Real-Time Collision Detection 5.1.5);
// returns the squared distance.
double point_triangle_distance2(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    auto sub = [](const Vec3d& x, const Vec3d& y) { return Vec3d{x[0] - y[0], x[1] - y[1], x[2] - y[2]}; };
    auto dot = [](const Vec3d& x, const Vec3d& y) { return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]; };
    auto at = [&](double v, double w) {
        Vec3d q = {a[0] + v * (b[0] - a[0]) + w * (c[0] - a[0]), a[1] + v * (b[1] - a[1]) + w * (c[1] - a[1]),
                   a[2] + v * (b[2] - a[2]) + w * (c[2] - a[2])};
        Vec3d d = sub(p, q);
        return dot(d, d);
    };
    Vec3d ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
    double d1 = dot(ab, ap), d2 = dot(ac, ap);
    if (d1 <= 0 && d2 <= 0) return at(0, 0);
    Vec3d bp = sub(p, b);
    double d3 = dot(ab, bp), d4 = dot(ac, bp);
    if (d3 >= 0 && d4 <= d3) return at(1, 0);
    double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return at(d1 / (d1 - d3), 0);
    Vec3d cp = sub(p, c);
    double d5 = dot(ab, cp), d6 = dot(ac, cp);
    if (d6 >= 0 && d5 <= d6) return at(0, 1);
    double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return at(0, d2 / (d2 - d6));
    double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
        double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return at(1 - w, w);
    }
    double denom = 1.0 / (va + vb + vc);
    return at(vb * denom, vc * denom);
}

namespace {

struct Box {
    double lo[3], hi[3];
};

Box bounding_box(const std::vector<Vec3d>& points) {
    Box box = {{1e300, 1e300, 1e300}, {-1e300, -1e300, -1e300}};
    for (const Vec3d& p : points)
        for (int i = 0; i < 3; ++i) {
            box.lo[i] = std::min(box.lo[i], p[i]);
            box.hi[i] = std::max(box.hi[i], p[i]);
        }
    return box;
}

// Four lanes of floats: one SSE register on x86-64 (GCC/Clang vector extensions, which compile
// to SSE there and to scalar code elsewhere).
using Float4 = float __attribute__((vector_size(16)));
using Int4 = int32_t __attribute__((vector_size(16)));

Float4 min4(Float4 a, Float4 b) { return a < b ? a : b; }
Float4 max4(Float4 a, Float4 b) { return a > b ? a : b; }

// Square roots of four lanes >= 0 as one instruction (std::sqrt keeps a branch to the library
// for negative input, errno; the grid's construction takes two roots per triangle).
Float4 root4(Float4 x) {
#if defined(__SSE__)
    return Float4(_mm_sqrt_ps(__m128(x)));
#else
    return Float4{std::sqrt(x[0]), std::sqrt(x[1]), std::sqrt(x[2]), std::sqrt(x[3])};
#endif
}

// Rows to columns.
void transpose4(Float4 m[4]) {
    const Float4 r0 = m[0], r1 = m[1], r2 = m[2], r3 = m[3];
    for (int i = 0; i < 4; ++i) m[i] = Float4{r0[i], r1[i], r2[i], r3[i]};
}

bool all_lanes(Int4 v) {
#if defined(__SSE__)
    return _mm_movemask_ps(reinterpret_cast<__m128>(v)) == 0xf;
#else
    return (v[0] & v[1] & v[2] & v[3]) != 0;
#endif
}

// What the pre-pass of GridDistance tests of a triangle, as a 4x4 matrix, one column per
// register: multiplied by a point (x, y, z, -1), it gives at once the point's height over the
// triangle's plane and the three barycentric coordinates of its projection onto that plane
// (rows: unit normal and offset, then the dual edge vectors and their constants). In floats
// relative to the grid's corner: it only picks the triangles whose exact distance is computed,
// in doubles, so its rounding cannot change a result.
struct alignas(16) TriangleProbe {
    Float4 x, y, z, constant;
};

// Bounding sphere of a triangle, relative to the grid's corner, in floats. The searches that
// rely on it to skip triangles widen it by the grid's probe slack, far above its rounding.
struct Sphere {
    float centre[3];
    float radius;
};

// First and last cell per axis of a triangle's box (a grid has at most 256 cells per axis).
struct CellRange {
    uint8_t first[3], last[3];
};

// (cell, triangle): one cell that a triangle's box overlaps, and its rank among the cell's
// entries (the triangles before it filed under the same cell).
struct CellEntry {
    uint32_t cell, triangle, rank;
};

// The arrays of a GridDistance. Each thread keeps one set from grid to grid, up to kKeepBytes:
// fresh memory costs a page fault per 4 KiB page on first touch (13 us on the development VM),
// and freshly allocated grids made 15% of the converter's page faults. A grid built while its
// thread's set is in use gets a set of its own.
struct GridArrays {
    std::vector<TriangleProbe> probes;
    std::vector<Sphere> spheres;
    std::vector<float> settle_margin;
    std::vector<CellRange> ranges;
    std::vector<uint32_t> start, items;
    std::vector<CellEntry> entries;
    bool in_use = false;

    // Within the converter's per-thread allowance (kMemoryPerThread), beside the simplifier's
    // block: a grid over 20k triangles (the gathered mesh of a typical diamond) takes 2.5 MiB.
    static constexpr size_t kKeepBytes = size_t(8) << 20;

    size_t bytes() const {
        return probes.capacity() * sizeof(TriangleProbe) + spheres.capacity() * sizeof(Sphere) +
               settle_margin.capacity() * sizeof(float) + ranges.capacity() * sizeof(CellRange) +
               (start.capacity() + items.capacity()) * sizeof(uint32_t) + entries.capacity() * sizeof(CellEntry);
    }
    // Grows an array to at least n elements (never shrinks it: elements are overwritten, so
    // what lies beyond n is left alone).
    template <class T>
    static T* at_least(std::vector<T>& v, size_t n) {
        if (v.size() < n) v.resize(n);
        return v.data();
    }

    // The calling thread's set (or a set of its own), given back when the lease ends.
    class Lease {
    public:
        Lease() {
            GridArrays& mine = thread_arrays();
            if (mine.in_use) {
                own_ = std::make_unique<GridArrays>();
                arrays_ = own_.get();
            } else {
                arrays_ = &mine;
            }
            arrays_->in_use = true;
        }
        ~Lease() {
            arrays_->in_use = false;
            if (!own_ && arrays_->bytes() > kKeepBytes) *arrays_ = GridArrays();
        }
        Lease(const Lease&) = delete;
        Lease& operator=(const Lease&) = delete;
        GridArrays* operator->() const { return arrays_; }

    private:
        static GridArrays& thread_arrays() {
            thread_local GridArrays arrays;
            return arrays;
        }
        GridArrays* arrays_ = nullptr;
        std::unique_ptr<GridArrays> own_;
    };
};

// Distance from points to a small triangle mesh through a uniform grid of its triangles' boxes.
// (CGAL's AABB tree took half of the converter's time here: a diamond has a few thousand
// triangles and each query lies close to the surface, which a grid answers in a cell or two.)
//
// The caller only wants the largest of many distances (a Hausdorff distance), so a query may
// stop as soon as it finds a triangle within `enough` of the point (the running maximum): the
// point cannot raise the maximum any more. Of the queries of a 1M-triangle scan, 98.3% end at
// the first candidate of over_in_cell (a triangle of the point's cell over which the point lies),
// 1.6% in its fallback near_in_cell, and 0.13% need the exact search, ring_search.
class GridDistance {
public:
    // box: contains the mesh and every query point.
    GridDistance(const std::vector<Vec3d>& positions, const std::vector<uint32_t>& indices, const Box& box)
        : positions_(positions), indices_(indices), triangles_(indices.size() / 3) {
        if (triangles_ > 0) build(box);
    }

    // Distance from p to the mesh; or, when that is at most `enough`, any value between it and
    // `enough` (the search stops at the first triangle within `enough`).
    double distance(const Vec3d& p, double enough = 0.0) const {
        if (triangles_ == 0) return 0.0;
        int c[3];
        for (int i = 0; i < 3; ++i) c[i] = std::max(0, std::min(dims_[i] - 1, int((p[i] - lo_[i]) * inv_cell_)));
        const Float4 q = relative(p);
        if (enough > 0) {
            const size_t cell = cell_index(c[0], c[1], c[2]);
            if (over_in_cell(p, q, cell, enough) || near_in_cell(p, q, cell, enough)) return enough;
        }
        return ring_search(p, q, c, enough);
    }

private:
    void build(const Box& box) {
        // The mean edge only sizes the grid: a sample of the triangles will do.
        double edges = 0;
        size_t measured = 0;
        for (size_t t = 0; t < triangles_; t += 8) {
            const Vec3d &a = corner(t, 0), &b = corner(t, 1), &c = corner(t, 2);
            edges += length(a, b) + length(b, c) + length(c, a);
            ++measured;
        }
        for (int i = 0; i < 3; ++i) lo_[i] = box.lo[i];
        const double extent = std::max({box.hi[0] - lo_[0], box.hi[1] - lo_[1], box.hi[2] - lo_[2], 1e-9});
        // Cells of about two mean edge lengths (a surface fills few of them, each holding a few
        // triangles), at most 128 per axis. (1.5 and 3 edges measured the same.)
        cell_ = std::max(extent / 128.0, 2.0 * edges / double(3 * measured)) * 1.0000001;
        // At most kCellsPerTriangle cells per triangle: a surface fills few cells of its box, and
        // the coarse diamonds of a large model (a box over 200 mean edges wide) reached 128^3
        // cells, 8 MiB of cell starts per grid, two grids per diamond, mostly empty. (Queries
        // are unaffected beyond speed: the grid only orders the search, the result is exact.)
        const double limit = std::max(4096.0, kCellsPerTriangle * double(triangles_));
        for (;;) {
            for (int i = 0; i < 3; ++i) dims_[i] = std::max(1, int((box.hi[i] - lo_[i]) / cell_) + 1);
            const double cells = double(dims_[0]) * dims_[1] * dims_[2];
            if (cells <= limit) break;
            cell_ *= std::max(1.01, std::cbrt(cells / limit));
        }
        inv_cell_ = 1.0 / cell_;
        assert(std::max({dims_[0], dims_[1], dims_[2]}) <= 256);
        max_dim_ = std::max({dims_[0], dims_[1], dims_[2]});
        inv_cell_f_ = float(inv_cell_);
        for (int i = 0; i < 3; ++i) last_cell_[i] = float(dims_[i] - 1);
        // Slack for the cell-box bounds: triangles are filed under the cells their box overlaps
        // as computed in floats (prepare), which may put a corner up to 3e-5 cells outside
        // them; a query's own cell, in doubles, is off by less than 1e-9.
        slack_ = cell_ * 1e-4 + 1e-6;
        // Float rounding of the probes and spheres is below 1e-6 of the extent.
        probe_slack_ = float(extent * 1e-5);
        const size_t cells = size_t(dims_[0]) * dims_[1] * dims_[2];
        // Every element of the probes, spheres, settle margins and items is written below.
        probes_ = GridArrays::at_least(arrays_->probes, triangles_);
        spheres_ = GridArrays::at_least(arrays_->spheres, triangles_);
        settle_margin_ = GridArrays::at_least(arrays_->settle_margin, triangles_);
        arrays_->start.assign(cells + 1, 0);
        start_ = arrays_->start.data();
        std::vector<CellEntry>& entries = arrays_->entries;
        entries.clear();
        entries.reserve(3 * triangles_);
        // Two passes over the triangles. The first, without branches, computes each one's
        // probe, sphere and range of cells: its divisions and roots overlap from triangle to
        // triangle, where in one pass with the filing below, whose loop exits mispredict, they
        // stalled it. The second files an entry per cell that the triangle's box overlaps,
        // counted per cell (for a counting sort of the entries by cell), with its rank in the
        // cell. The entries are kept, so that the fill below is one flat loop (nested loops over
        // the ranges mispredicted their exits).
        CellRange* ranges = GridArrays::at_least(arrays_->ranges, triangles_);
        for (size_t t = 0; t < triangles_; t += 4) prepare(t, std::min<size_t>(4, triangles_ - t), float(extent), ranges);
        for (size_t t = 0; t < triangles_; ++t) {
            const CellRange& r = ranges[t];
            for (int z = r.first[2]; z <= r.last[2]; ++z)
                for (int y = r.first[1]; y <= r.last[1]; ++y)
                    for (int x = r.first[0]; x <= r.last[0]; ++x) {
                        const uint32_t cell = uint32_t(cell_index(x, y, z));
                        entries.push_back({cell, uint32_t(t), start_[cell]++});
                    }
        }
        // Exclusive prefix sums: start_[c] is the start of cell c.
        uint32_t sum = 0;
        for (size_t c = 0; c < cells; ++c) {
            const uint32_t count = start_[c];
            start_[c] = sum;
            sum += count;
        }
        start_[cells] = sum;
        items_ = GridArrays::at_least(arrays_->items, entries.size());
        // Each entry goes to its cell's start plus its rank: a cell's triangles in increasing
        // order, as before. (Filling by decrementing each cell's end chained every entry to the
        // previous one's store to the same counter: a fifth of the grid's construction in perf.)
        for (const CellEntry& e : entries) items_[start_[e.cell] + e.rank] = e.triangle;
    }

    // The first pass of build() for triangles t to t + count - 1 (count <= 4), one triangle per
    // lane (lanes past count repeat the last triangle; only count are stored): each one's probe,
    // bounding sphere, settle margin and range of cells. (One division and one root for four
    // triangles: one triangle at a time, they were a fifth of the grid's construction.) The
    // corners are relative to the grid's corner, in floats.
    void prepare(size_t t, size_t count, float extent, CellRange* ranges) {
        Float4 a[3], b[3], c[3];  // by axis; lane k: triangle t + k
        for (size_t k = 0; k < 4; ++k) {
            const size_t tk = t + std::min(k, count - 1);
            const Vec3d &pa = corner(tk, 0), &pb = corner(tk, 1), &pc = corner(tk, 2);
            for (int i = 0; i < 3; ++i) {
                a[i][k] = float(pa[i] - lo_[i]);
                b[i][k] = float(pb[i] - lo_[i]);
                c[i][k] = float(pc[i] - lo_[i]);
            }
        }
        const Float4 zero = {0, 0, 0, 0}, ones = {1, 1, 1, 1};
        auto dot = [](const Float4 x[3], const Float4 y[3]) { return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]; };

        // The probe. With u, v the edges from a and n = u x v, its rows are the unit normal
        // n / |n|, the dual basis g0 = (|v|^2 u - (u.v) v) / |n|^2 (g0 . u = 1, g0 . v = 0) and
        // g1 = (|u|^2 v - (u.v) u) / |n|^2, and g2 = -g0 - g1: each column is a combination of
        // n, u and v. The constants make a's coordinates (h, u, v, w) = (0, 0, 0, 1).
        // Degenerate triangles get zero rows: every point lies on their plane and over them.
        Float4 u[3], v[3];
        for (int i = 0; i < 3; ++i) {
            u[i] = b[i] - a[i];
            v[i] = c[i] - a[i];
        }
        const Float4 n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
        const Float4 nn = dot(n, n), uu = dot(u, u), uv = dot(u, v), vv = dot(v, v);
        const Float4 inv_nn = nn > zero ? 1.0f / nn : zero, inv_len = root4(inv_nn);
        // The weights of n, u and v in the probe's four columns (h, u, v, w).
        const Float4 along_u[4] = {zero * inv_nn, vv * inv_nn, -uv * inv_nn, (uv - vv) * inv_nn};
        const Float4 along_v[4] = {zero * inv_nn, -uv * inv_nn, uu * inv_nn, (uv - uu) * inv_nn};
        Float4 rows[4][4];  // [x, y, z, constant][h, u, v, w]
        for (int i = 0; i < 3; ++i)
            for (int l = 0; l < 4; ++l)
                rows[i][l] = n[i] * (l == 0 ? inv_len : zero) + u[i] * along_u[l] + v[i] * along_v[l];
        for (int l = 0; l < 4; ++l)
            rows[3][l] = rows[0][l] * a[0] + rows[1][l] * a[1] + rows[2][l] * a[2] - (l == 3 ? 1.0f : 0.0f);
        for (int i = 0; i < 4; ++i) transpose4(rows[i]);
        for (size_t k = 0; k < count; ++k) probes_[t + k] = {rows[0][k], rows[1][k], rows[2][k], rows[3][k]};

        // The bounding sphere: about the centroid, its radius measured from the centre as rounded.
        Float4 centre[3], da[3], db[3], dc[3];
        for (int i = 0; i < 3; ++i) {
            centre[i] = (a[i] + b[i] + c[i]) * (1.0f / 3.0f);
            da[i] = a[i] - centre[i];
            db[i] = b[i] - centre[i];
            dc[i] = c[i] - centre[i];
        }
        const Float4 radius = root4(max4(max4(dot(da, da), dot(db, db)), dot(dc, dc)));
        for (size_t k = 0; k < count; ++k) spheres_[t + k] = {{centre[0][k], centre[1][k], centre[2][k]}, radius[k]};

        // The settle margin: how far below `enough` a candidate's height must be for its probe
        // to settle it (over_in_cell). Infinite unless the triangle is well shaped (no side more
        // than 10 times its smallest height, that height at least 1e-3 of the grid's extent).
        // Float rounding of the corners and of a query (6e-8 of the extent each) then tilts and
        // shifts the probe's plane by less than 1e-6 of the extent within the grid (probe_slack_
        // is ten times that) and moves its barycentric coordinates by less than 1e-3: a
        // candidate (coordinates at least -1e-4) projects at most 2.2e-3 of the longest side
        // outside the triangle. nn = (2 area)^2 = smallest height^2 longest side^2.
        const Float4 longest2 = max4(max4(uu, vv), uu + vv - 2 * uv);  // |c - b|^2 = |v - u|^2
        const Float4 floor = max4(ones * (1e-6f * extent * extent), 1e-2f * longest2);
        const Float4 margin = nn >= longest2 * floor ? probe_slack_ + 3e-3f * root4(longest2)
                                                     : ones * std::numeric_limits<float>::infinity();
        for (size_t k = 0; k < count; ++k) settle_margin_[t + k] = margin[k];

        // The first and last cell per axis of the triangle's box, clamped to the grid: in
        // floats, not doubles, as that cut the grid's construction by a tenth; their rounding
        // may put a corner up to 3e-5 cells off, which the slack covers.
        for (int i = 0; i < 3; ++i) {
            const Float4 last = ones * last_cell_[i];
            const Int4 first = __builtin_convertvector(min4(max4(min4(min4(a[i], b[i]), c[i]) * inv_cell_f_, zero), last), Int4);
            const Int4 end = __builtin_convertvector(min4(max4(max4(max4(a[i], b[i]), c[i]) * inv_cell_f_, zero), last), Int4);
            for (size_t k = 0; k < count; ++k) {
                ranges[t + k].first[i] = uint8_t(first[k]);
                ranges[t + k].last[i] = uint8_t(end[k]);
            }
        }
    }

    // Whether a triangle of `cell` over which p lies (its projection inside the triangle), near
    // its plane, is within `enough` of p (q: p relative to the grid's corner). For a point on or
    // near the surface, nearly always the first such candidate is: 1.03 candidates per query,
    // where testing bounding spheres and planes (the previous pre-pass) took 2.5. One probe is a
    // few SSE instructions and one well-predicted branch.
    //
    // A candidate's exact distance is only computed when the probe cannot vouch for it: the
    // probe settles a candidate whose height is below 0.99 enough less the triangle's
    // settle_margin, which bounds both the probe's rounding and how far p may project outside
    // the triangle (its exact distance then is at most its height plus that much). The answer
    // is the one the exact test (point_triangle_distance2, in doubles) gives.
    bool over_in_cell(const Vec3d& p, Float4 q, size_t cell, double enough) const {
        const double enough2 = enough * enough;
        const float limit = float(enough) + probe_slack_;
        constexpr float kTolerance = 1e-4f;  // barycentric: a point on an edge is over both sides
        const Float4 low = {-limit, -kTolerance, -kTolerance, -kTolerance}, high = {limit, 2.0f, 2.0f, 2.0f};
        const float sure = float(enough) * 0.99f;
        for (uint32_t k = start_[cell], end = start_[cell + 1]; k < end; ++k) {
            const uint32_t t = items_[k];
            const TriangleProbe& probe = probes_[t];
            const Float4 hits = probe.x * q[0] + probe.y * q[1] + probe.z * q[2] - probe.constant;  // (h, u, v, w)
            if (!all_lanes((hits >= low) & (hits <= high))) continue;
            if (std::fabs(hits[0]) <= sure - settle_margin_[t]) return true;
            if (triangle_distance2(p, t) <= enough2) return true;
        }
        return false;
    }

    // Fallback of over_in_cell, for points over no triangle near them (near an edge or a corner
    // of the surface): the triangles of the cell whose bounding sphere and plane are within
    // `enough` of p.
    bool near_in_cell(const Vec3d& p, Float4 q, size_t cell, double enough) const {
        const double enough2 = enough * enough;
        const float limit = float(enough) + probe_slack_;
        for (uint32_t k = start_[cell], end = start_[cell + 1]; k < end; ++k) {
            const uint32_t t = items_[k];
            if (!sphere_within(q, t, limit)) continue;
            const TriangleProbe& probe = probes_[t];
            const float height = probe.x[0] * q[0] + probe.y[0] * q[1] + probe.z[0] * q[2] - probe.constant[0];
            if (std::fabs(height) <= limit && triangle_distance2(p, t) <= enough2) return true;
        }
        return false;
    }

    // The exact search: rings of cells around p's cell c. Every triangle not yet seen before
    // ring r is at least margin + (r - 1) cells away, margin being p's distance to the faces of
    // its own cell (0 if p lies outside the grid), less the slack: stop once the best found is
    // closer than that.
    double ring_search(const Vec3d& p, Float4 q, const int c[3], double enough) const {
        double best2 = 1e300, best = 1e150;  // squared and plain
        const double enough2 = enough * enough;
        double margin = 1e300;
        for (int i = 0; i < 3; ++i) {
            double in_cell = p[i] - (lo_[i] + c[i] * cell_);
            margin = std::min({margin, in_cell, cell_ - in_cell});
        }
        margin = std::max(0.0, margin) - slack_;
        for (int r = 0; r <= max_dim_; ++r) {
            if (r > 0 && best2 < 1e300 && best <= margin + double(r - 1) * cell_) break;
            for (int z = std::max(0, c[2] - r); z <= std::min(dims_[2] - 1, c[2] + r); ++z) {
                const double gz = axis_gap(2, z, p[2]);
                for (int y = std::max(0, c[1] - r); y <= std::min(dims_[1] - 1, c[1] + r); ++y) {
                    const double gy = axis_gap(1, y, p[1]);
                    const bool shell_zy = std::abs(z - c[2]) == r || std::abs(y - c[1]) == r;
                    for (int x = std::max(0, c[0] - r); x <= std::min(dims_[0] - 1, c[0] + r); ++x) {
                        if (!shell_zy && std::abs(x - c[0]) != r) continue;  // inner rings: done
                        // The cell's box is farther than the best: nothing in it is closer.
                        const double gx = axis_gap(0, x, p[0]);
                        if (gx * gx + gy * gy + gz * gz >= best2) continue;
                        const size_t cell = cell_index(x, y, z);
                        for (uint32_t k = start_[cell]; k < start_[cell + 1]; ++k) {
                            const uint32_t t = items_[k];
                            // Bounding-sphere lower bound first: |p - centre| - radius >= best.
                            if (!sphere_within(q, t, float(best) + probe_slack_)) continue;
                            const double d2 = triangle_distance2(p, t);
                            if (d2 < best2) {
                                best2 = d2;
                                best = std::sqrt(d2);
                                if (best2 <= enough2) return best;
                            }
                        }
                    }
                }
            }
        }
        return best;
    }

    // Whether q may be within `reach` of triangle t's bounding sphere.
    bool sphere_within(Float4 q, uint32_t t, float reach) const {
        const Sphere& s = spheres_[t];
        const float dx = q[0] - s.centre[0], dy = q[1] - s.centre[1], dz = q[2] - s.centre[2];
        const float r = s.radius + reach;
        return dx * dx + dy * dy + dz * dz <= r * r;
    }
    const Vec3d& corner(size_t t, int k) const { return positions_[indices_[3 * t + k]]; }
    double triangle_distance2(const Vec3d& p, uint32_t t) const {
        return point_triangle_distance2(p, corner(t, 0), corner(t, 1), corner(t, 2));
    }
    static double length(const Vec3d& a, const Vec3d& b) {
        return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
    }
    // A point relative to the grid's corner, in floats.
    Float4 relative(const Vec3d& v) const {
        return Float4{float(v[0] - lo_[0]), float(v[1] - lo_[1]), float(v[2] - lo_[2]), 0.0f};
    }
    size_t cell_index(int x, int y, int z) const { return (size_t(z) * dims_[1] + y) * dims_[0] + x; }
    // Distance along one axis from v to cell i's slab (0 inside), less the slack.
    double axis_gap(int axis, int i, double v) const {
        const double a = lo_[axis] + i * cell_, b = a + cell_;
        return std::max(0.0, std::max(a - v, v - b) - slack_);
    }

    const std::vector<Vec3d>& positions_;
    const std::vector<uint32_t>& indices_;
    const size_t triangles_;
    double lo_[3] = {0, 0, 0}, cell_ = 1, inv_cell_ = 1, slack_ = 0;
    float probe_slack_ = 0;           // widens the float bounds, ten times their rounding
    float inv_cell_f_ = 1, last_cell_[3] = {0, 0, 0};  // 1 / cell and the last cell per axis, for prepare
    static constexpr double kCellsPerTriangle = 4.0;
    int dims_[3] = {1, 1, 1};
    int max_dim_ = 1;
    GridArrays::Lease arrays_;
    // Views into arrays_, set by build().
    TriangleProbe* probes_ = nullptr;
    Sphere* spheres_ = nullptr;
    float* settle_margin_ = nullptr;  // per triangle, see prepare()
    // Cell c lists items_[start_[c] .. start_[c + 1]).
    uint32_t* start_ = nullptr;
    uint32_t* items_ = nullptr;
};

// Largest distance from the vertices that the simplification removed to the simplified surface.
double removed_vertices_error(const std::vector<Vec3d>& pos, const std::vector<uint32_t>& simplified, const Box& box) {
    std::vector<uint8_t> kept(pos.size(), 0);
    for (uint32_t v : simplified) kept[v] = 1;
    GridDistance to_simplified(pos, simplified, box);
    double error = 0;
    for (size_t v = 0; v < pos.size(); ++v)
        if (!kept[v]) error = std::max(error, to_simplified.distance(pos[v], error));
    return error;
}

// Largest distance from the simplified edges' midpoints to the gathered surface. (Triangle
// centroids were sampled too until they proved not worth their queries: on the 10M-triangle
// scan they raised a diamond's maximum in 3 diamonds of 1800, by at most 3%, and took a fifth
// of the measurement's time.)
//
// With `sources` (SimplifyResult::sources), edges that the simplification left as they were are
// not queried: both ends of such an edge are unchanged corners of its source triangle, so it is
// an edge of the gathered surface and its midpoint lies on it (distance 0, which cannot raise
// the maximum). That is more than half of the edges, and their queries and bucketing were a
// tenth of the measurement's time.
double simplified_points_error(const std::vector<Vec3d>& pos, const std::vector<uint32_t>& gathered,
                               const std::vector<uint32_t>& simplified, const std::vector<uint32_t>* sources,
                               const Box& box) {
    assert(!sources || sources->size() * 3 == simplified.size());
    // Bit k of changed(t): the edge from corner k to corner k + 1 of simplified triangle t may
    // not be a gathered edge.
    auto changed = [&](size_t t) -> unsigned {
        if (!sources) return 7;
        const uint32_t* in = &gathered[3 * size_t((*sources)[t])];
        const uint32_t* out = &simplified[3 * t];
        const unsigned same = unsigned(in[0] == out[0]) | unsigned(in[1] == out[1]) << 1 | unsigned(in[2] == out[2]) << 2;
        const unsigned same_next = (same >> 1 | same << 2) & 7;  // bit k: corner k + 1 unchanged
        return ~(same & same_next) & 7;
    };
    // Edges, each once: bucketed by their smaller vertex (a counting sort; sorting 64-bit edge
    // keys cost a third as much as the queries it saved), duplicates found within a bucket.
    // Without branches on which edges changed: that pattern is random, and the branches
    // mispredicted (a skipped edge adds 0 to its count and is stored past the end).
    const size_t triangles = simplified.size() / 3;
    std::vector<uint8_t> changed_edges(triangles);
    std::vector<uint32_t> first(pos.size() + 1, 0);
    size_t edges = 0;
    for (size_t t = 0; t < triangles; ++t) {
        const unsigned bits = changed(t);
        changed_edges[t] = uint8_t(bits);
        for (unsigned k = 0; k < 3; ++k) {
            const unsigned counted = bits >> k & 1;
            first[std::min(simplified[3 * t + k], simplified[3 * t + (k + 1) % 3]) + 1] += counted;
            edges += counted;
        }
    }
    if (edges == 0) return 0.0;
    for (size_t v = 1; v < first.size(); ++v) first[v] += first[v - 1];
    std::vector<uint32_t> other(edges + 1);
    {
        std::vector<uint32_t> fill(first.begin(), first.end() - 1);
        for (size_t t = 0; t < triangles; ++t)
            for (unsigned k = 0; k < 3; ++k) {
                const unsigned counted = changed_edges[t] >> k & 1;
                const uint32_t u = simplified[3 * t + k], w = simplified[3 * t + (k + 1) % 3];
                uint32_t& next = fill[std::min(u, w)];
                other[counted ? next : edges] = std::max(u, w);
                next += counted;
            }
    }
    GridDistance to_gathered(pos, gathered, box);
    double error = 0;
    for (size_t u = 0; u < pos.size(); ++u)
        for (uint32_t k = first[u]; k < first[u + 1]; ++k) {
            const uint32_t w = other[k];
            if (std::find(&other[first[u]], &other[k], w) != &other[k]) continue;  // seen
            const Vec3d &a = pos[u], &b = pos[w];
            const Vec3d midpoint = {(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2};
            error = std::max(error, to_gathered.distance(midpoint, error));
        }
    return error;
}

}  // namespace

// Hausdorff-style distance between the gathered surface and its simplification, both ways:
// removed vertices to the simplified surface, and the simplified edges' midpoints to the gathered
// surface. (The simplifier's quadric cost is a mean, not a bound: measured here so the stored
// errors can be trusted by the cut engine.)
//
// The result is exactly the maximum of the sample points' distances: every query gets the
// running maximum as its `enough`, so a query is only cut short when its distance cannot raise
// the maximum; and an edge shared by two simplified triangles has one midpoint, measured once
// (the same point, bit for bit, as (a + b) / 2 is symmetric).
double measured_simplification_error(const WorkFragment& gathered, const std::vector<uint32_t>& simplified,
                                     const std::vector<uint32_t>* sources) {
    if (simplified.size() == gathered.indices.size()) return 0.0;
    // The two directions are independent (each is the exact maximum over its own points), so
    // they may run side by side.
    double removed = 0, points = 0;
    // One box for both grids: every corner and every sample point is a gathered position or
    // lies between gathered positions.
    const Box box = bounding_box(gathered.positions);
    tbb::parallel_invoke([&] { removed = removed_vertices_error(gathered.positions, simplified, box); },
                         [&] { points = simplified_points_error(gathered.positions, gathered.indices, simplified, sources, box); });
    return std::max(removed, points);
}

namespace {

// The side (plane_side times the plane's sign) of every referenced vertex for each clip plane of
// each slot, as bit masks (a branchy per-plane loop over bytes was most of clip_into_slots' own
// time), and from them the fate of a triangle in a slot, decided exactly as clip_triangle
// decides it: clip_triangle tests the planes in order, and while the triangle is still whole, a
// plane with every corner strictly inside leaves it whole, one with no corner inside and some
// strictly outside drops it. Anything else (a real cut, a corner on a plane) goes to
// clip_triangle itself.
class SlotSides {
public:
    enum Fate { kOutside, kInside, kCut };

    SlotSides(const std::vector<Vec3d>& positions, const std::vector<uint32_t>& indices,
              const std::vector<std::vector<ClipPlane>>& slot_planes) {
        // Neighbouring slots share an interior face (with opposite keep sides), so a diamond has
        // only about half as many distinct planes as slot planes: each vertex is tested against
        // the distinct ones (plane_side was most of this constructor's time).
        std::vector<const LatticePlane*> distinct;
        struct Use { size_t plane; int sign; };  // slot plane side = distinct side * sign
        std::vector<Use> uses;
        // Slot planes are numbered in slot order, then plane order: bit k of a mask is plane k.
        for (size_t s = 0; s < slot_planes.size(); ++s) {
            slot_bits_[s] = ((1u << slot_planes[s].size()) - 1) << uses.size();
            for (const ClipPlane& cp : slot_planes[s]) {
                size_t u = 0;
                while (u < distinct.size() && !(*distinct[u] == cp.plane)) ++u;
                if (u == distinct.size()) distinct.push_back(&cp.plane);
                uses.push_back({u, cp.sign * same_direction(*distinct[u], cp.plane)});
            }
        }
        assert(uses.size() <= 16);  // 8 slots with 2 interior faces each
        // Per vertex, bit k of `inside` / `outside`: the vertex is strictly inside / strictly
        // outside slot plane k. Vertices of no triangle keep 0, unread.
        sides_.assign(positions.size(), Sides{0, 0});
        std::vector<uint8_t> seen(positions.size(), 0);
        int side[16];
        for (uint32_t v : indices) {
            if (seen[v]) continue;
            seen[v] = 1;
            for (size_t u = 0; u < distinct.size(); ++u) side[u] = plane_side(*distinct[u], positions[v]);
            Sides& out = sides_[v];
            for (size_t k = 0; k < uses.size(); ++k) {
                const int value = side[uses[k].plane] * uses[k].sign;
                out.inside |= uint16_t(unsigned(value > 0) << k);
                out.outside |= uint16_t(unsigned(value < 0) << k);
            }
        }
    }

    // A triangle's corners against every slot's planes, for fate().
    struct TriangleSides {
        unsigned inside;   // bit k: every corner strictly inside slot plane k
        unsigned dropped;  // ... no corner inside and some strictly outside
    };
    TriangleSides triangle_sides(const uint32_t* corners) const {
        const Sides &a = sides_[corners[0]], &b = sides_[corners[1]], &c = sides_[corners[2]];
        return {unsigned(a.inside & b.inside & c.inside),
                unsigned(~(a.inside | b.inside | c.inside) & (a.outside | b.outside | c.outside))};
    }
    // The triangle's fate in `slot`: decided by the first of the slot's planes (in order) that
    // does not have every corner strictly inside; inside if there is none.
    Fate fate(const TriangleSides& t, int slot) const {
        const unsigned undecided = ~t.inside & slot_bits_[slot];
        if (undecided == 0) return kInside;
        return t.dropped & undecided & (0u - undecided) ? kOutside : kCut;
    }

private:
    // +1 if b's plane_side agrees with a's (the same plane, as LatticePlane::operator== tests,
    // with the normal the same way), -1 if it is the opposite. plane_side is the sign of n.p - d
    // and n, d are a's or their negation.
    static int same_direction(const LatticePlane& a, const LatticePlane& b) {
        assert(a == b && (a.n == b.n || (a.n[0] == -b.n[0] && a.n[1] == -b.n[1] && a.n[2] == -b.n[2])));
        return a.n == b.n ? 1 : -1;
    }

    struct Sides {
        uint16_t inside, outside;
    };
    std::array<unsigned, 8> slot_bits_{};  // the bits of each slot's planes
    std::vector<Sides> sides_;
};

}  // namespace

void clip_into_slots(const DiamondInfo& d, const WorkFragment& gathered, const std::vector<uint32_t>& simplified,
                     std::array<WorkFragment, 8>& out) {
    const uint8_t slots = existing_slots(d);
    const int n = d.ring_size;
    // Clip by the interior faces into the slots.
    std::vector<std::vector<ClipPlane>> slot_planes(n);
    std::vector<FragmentWelder> welders;
    welders.reserve(8);
    for (int s = 0; s < 8; ++s) welders.emplace_back(out[s]);
    for (int s = 0; s < n; ++s) {
        if (!(slots & (1 << s))) continue;
        Tetrahedron t = diamond_tetrahedron(d, s);
        // Faces opposite corners 3 and 2 are (A, B, r0) and (A, B, r1): the interior ones.
        slot_planes[s] = tetrahedron_clip_planes(t, (1u << 2) | (1u << 3));
    }
    // Which side of each slot plane every vertex lies on, decided once per vertex (exactly as
    // clip_triangle would decide it for the same point): most triangles lie inside one slot and
    // outside the others, and those need no clipping. (With this, clip_triangle's share of the
    // 1M-triangle scan's profile fell by half.)
    SlotSides sides(gathered.positions, simplified, slot_planes);
    // Per slot, the fragment vertex each gathered vertex became: a vertex is shared by about six
    // triangles, and only the first of them welds it by position.
    const size_t vertex_count = gathered.positions.size();
    std::vector<uint32_t> welded(size_t(n) * vertex_count, FragmentWelder::kNotWelded);
    // Every triangle's fate in every slot first, so that each slot's arrays are allocated once
    // at about their final size (grown push by push, they were copied and faulted in anew at
    // each doubling, and kept up to twice the memory they needed in the spill).
    const size_t triangles = simplified.size() / 3;
    std::vector<uint8_t> fates(triangles * size_t(n));
    std::array<size_t, 8> whole{}, cut{};
    for (size_t t = 0; t < triangles; ++t) {
        const SlotSides::TriangleSides corners = sides.triangle_sides(&simplified[3 * t]);
        for (int s = 0; s < n; ++s) {
            if (slot_planes[s].empty()) continue;
            const SlotSides::Fate fate = sides.fate(corners, s);
            fates[t * size_t(n) + size_t(s)] = uint8_t(fate);
            whole[size_t(s)] += fate == SlotSides::kInside;
            cut[size_t(s)] += fate == SlotSides::kCut;
        }
    }
    // A slot's fragment has about 0.6 vertices per triangle, and a cut triangle leaves about one
    // piece in each slot it meets (1M scan: 1.43M whole and cut triangles, 1.42M out, 0.84M
    // vertices).
    for (size_t s = 0; s < size_t(n); ++s)
        if (whole[s] + cut[s] > 0) welders[s].reserve((whole[s] + cut[s]) * 5 / 8 + 16, whole[s] + cut[s] * 5 / 4 + 16);
    for (size_t t = 0; t < triangles; ++t) {
        const uint32_t* f = &simplified[3 * t];
        std::array<Vec3d, 3> tri = {gathered.positions[f[0]], gathered.positions[f[1]], gathered.positions[f[2]]};
        std::array<Vec3f, 3> normals = {gathered.normals[f[0]], gathered.normals[f[1]], gathered.normals[f[2]]};
        std::array<Rgb8, 3> colors = {gathered.colors[f[0]], gathered.colors[f[1]], gathered.colors[f[2]]};
        for (int s = 0; s < n; ++s) {
            if (slot_planes[s].empty()) continue;
            uint32_t* slot_welded = &welded[size_t(s) * vertex_count];
            switch (SlotSides::Fate(fates[t * size_t(n) + size_t(s)])) {
                case SlotSides::kOutside: break;
                case SlotSides::kInside: welders[s].add_whole(f, slot_welded, tri, normals, colors); break;
                case SlotSides::kCut:
                    welders[s].add_clipped(f, slot_welded, tri, normals, colors, slot_planes[s]);
                    break;
            }
        }
    }
}

namespace {

// The planes of a diamond's outer faces: those not containing the spine; plus interior faces on
// the root boundary of a partial diamond (their neighbour slot does not exist).
std::vector<LatticePlane> outer_planes(const DiamondInfo& d) {
    const uint8_t slots = existing_slots(d);
    const int n = d.ring_size;
    std::vector<LatticePlane> outer;
    for (int s = 0; s < n; ++s) {
        if (!(slots & (1 << s))) continue;
        const LatticePoint &r0 = d.ring[s], &r1 = d.ring[(s + 1) % n];
        outer.push_back(make_plane(d.spine_a, r0, r1));
        outer.push_back(make_plane(d.spine_b, r0, r1));
        if (!(slots & (1 << ((s + n - 1) % n)))) outer.push_back(make_plane(d.spine_a, d.spine_b, r0));
        if (!(slots & (1 << ((s + 1) % n)))) outer.push_back(make_plane(d.spine_a, d.spine_b, r1));
    }
    return outer;
}

bool on_outer_face(const std::vector<LatticePlane>& outer, const Vec3d& p) {
    for (const LatticePlane& plane : outer) {
        const double value = plane.n[0] * p[0] + plane.n[1] * p[1] + plane.n[2] * p[2] - double(plane.d);
        if (std::fabs(value) < 1e-3 && plane_side(plane, p) == 0) return true;
    }
    return false;
}

}  // namespace

LostGeometryReach lost_geometry_reach(const DiamondInfo& d, const std::array<const WorkFragment*, 8>& slots) {
    const std::vector<LatticePlane> outer = outer_planes(d);
    // Vertices of all slots, one per position (a piece crossing an interior face has a copy of
    // its vertices there in each slot), joined by the triangles (union-find).
    struct PositionHash {
        size_t operator()(const Vec3d& p) const {
            uint64_t h = 0;
            for (double v : p) {
                uint64_t bits;
                std::memcpy(&bits, &v, 8);
                h = (h ^ bits) * 0x9E3779B97F4A7C15ull;
            }
            return size_t(h ^ (h >> 29));
        }
    };
    std::unordered_map<Vec3d, uint32_t, PositionHash> number;
    std::vector<uint32_t> parent;
    std::vector<Vec3d> position;
    auto find = [&](uint32_t v) {
        while (parent[v] != v) v = parent[v] = parent[parent[v]];
        return v;
    };
    LostGeometryReach reach;
    double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
    for (const WorkFragment* f : slots) {
        if (!f) continue;
        std::vector<uint32_t> id(f->positions.size());
        for (size_t v = 0; v < f->positions.size(); ++v) {
            auto [it, fresh] = number.emplace(f->positions[v], uint32_t(parent.size()));
            if (fresh) {
                parent.push_back(uint32_t(parent.size()));
                position.push_back(f->positions[v]);
            }
            id[v] = it->second;
        }
        for (size_t t = 0; t + 2 < f->indices.size(); t += 3) {
            for (int k = 0; k < 3; ++k) {
                const Vec3d& p = f->positions[f->indices[t + size_t(k)]];
                for (int a = 0; a < 3; ++a) {
                    lo[a] = std::min(lo[a], p[a]);
                    hi[a] = std::max(hi[a], p[a]);
                }
            }
            const uint32_t a = find(id[f->indices[t]]);
            for (int k = 1; k < 3; ++k) {
                const uint32_t b = find(id[f->indices[t + size_t(k)]]);
                if (a != b) parent[b] = a;
            }
        }
    }
    if (parent.empty()) return reach;
    std::vector<uint8_t> anchored(parent.size(), 0);
    for (uint32_t v = 0; v < parent.size(); ++v)
        if (on_outer_face(outer, position[v])) anchored[find(v)] = 1;
    for (uint32_t v = 0; v < parent.size(); ++v)
        if (!anchored[find(v)]) return reach;  // a piece inside, alone: nothing near bounds it
    reach.anchored = true;
    reach.diameter = std::sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                               (hi[2] - lo[2]) * (hi[2] - lo[2]));
    return reach;
}

double coarsen_diamond(const DiamondInfo& d, const WorkFragment& gathered, std::array<WorkFragment, 8>& out) {
    for (auto& f : out) f = WorkFragment{};
    const std::vector<LatticePlane> outer = outer_planes(d);
    size_t vertex_count = gathered.positions.size();
    std::vector<uint8_t> locked(vertex_count, 0);
    // The planes as arrays, so that the first test below, the smallest |n.p - d| over every
    // plane, is one loop without exits that the compiler vectorizes: nearly every vertex is far
    // from all of them (they bound the diamond) and needs nothing else.
    const size_t planes = outer.size();
    std::vector<double> nx(planes), ny(planes), nz(planes), nd(planes);
    for (size_t k = 0; k < planes; ++k) {
        nx[k] = outer[k].n[0];
        ny[k] = outer[k].n[1];
        nz[k] = outer[k].n[2];
        nd[k] = double(outer[k].d);
    }
    for (size_t v = 0; v < vertex_count; ++v) {
        const Vec3d& p = gathered.positions[v];
        double nearest = 1e300;
        for (size_t k = 0; k < planes; ++k)
            nearest = std::min(nearest, std::fabs(nx[k] * p[0] + ny[k] * p[1] + nz[k] * p[2] - nd[k]));
        if (nearest < 1e-3 && on_outer_face(outer, p)) locked[v] = 1;
    }
    SimplifySettings settings;
    settings.target_triangles = gathered.indices.size() / 3 / 2;
    SimplifyResult simplified = simplify_mesh(&gathered.positions[0][0], vertex_count, gathered.indices.data(),
                                              gathered.indices.size(), locked.data(), settings);
    // The measurement and the clipping only read the gathered and simplified meshes: run them
    // side by side (the coarsest levels have fewer diamonds than cores).
    double error = 0;
    tbb::parallel_invoke([&] { error = measured_simplification_error(gathered, simplified.indices, &simplified.sources); },
                         [&] { clip_into_slots(d, gathered, simplified.indices, out); });
    return error;
}

namespace {

// The exact lattice position of quantized barycentric weights in corners c (the weights sum to
// the grid).
Vec3d lattice_of(const BaryWeights& w, const Tetrahedron& c) {
    const double grid = double(w[0] + w[1] + w[2] + w[3]);
    Vec3d p;
    for (int k = 0; k < 3; ++k)
        p[k] = double(int64_t(w[0]) * c[0][k] + int64_t(w[1]) * c[1][k] + int64_t(w[2]) * c[2][k] + int64_t(w[3]) * c[3][k]) /
               grid;
    return p;
}

double triangle_area(const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    double u[3], v[3];
    for (int i = 0; i < 3; ++i) {
        u[i] = b[i] - a[i];
        v[i] = c[i] - a[i];
    }
    double x = u[1] * v[2] - u[2] * v[1], y = u[2] * v[0] - u[0] * v[2], z = u[0] * v[1] - u[1] * v[0];
    return 0.5 * std::sqrt(x * x + y * y + z * z);
}


// Points along the edges of triangle c, no farther apart than `spacing`, and its centroid,
// appended to `out`; returns the triangle's inradius (every point of it lies within that of
// its edges, and a point of an edge within spacing / 2 of a sample).
double sample_lost_triangle(const Vec3d* const c[3], double spacing, std::vector<Vec3d>& out) {
    double perimeter = 0;
    for (int e = 0; e < 3; ++e) {
        const Vec3d &a = *c[e], &b = *c[(e + 1) % 3];
        double length =
            std::sqrt((b[0] - a[0]) * (b[0] - a[0]) + (b[1] - a[1]) * (b[1] - a[1]) + (b[2] - a[2]) * (b[2] - a[2]));
        perimeter += length;
        int steps = std::max(1, int(std::min(4096.0, std::ceil(length / spacing))));
        for (int i = 0; i < steps; ++i) {
            double f = double(i) / steps;
            out.push_back({a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2])});
        }
    }
    out.push_back({((*c[0])[0] + (*c[1])[0] + (*c[2])[0]) / 3, ((*c[0])[1] + (*c[1])[1] + (*c[2])[1]) / 3,
                   ((*c[0])[2] + (*c[1])[2] + (*c[2])[2]) / 3});
    return perimeter > 0 ? 2 * triangle_area(*c[0], *c[1], *c[2]) / perimeter : 0.0;
}

double longest_edge(const Vec3d* const c[3]) {
    double best = 0;
    for (int e = 0; e < 3; ++e) {
        const Vec3d &a = *c[e], &b = *c[(e + 1) % 3];
        best = std::max(best, (b[0] - a[0]) * (b[0] - a[0]) + (b[1] - a[1]) * (b[1] - a[1]) + (b[2] - a[2]) * (b[2] - a[2]));
    }
    return std::sqrt(best);
}

// The distance from p (inside tetrahedron t) to the nearest of t's faces, lattice units.
double face_distance(const Vec3d& p, const Tetrahedron& t) {
    double best = 1e300;
    for (int f = 0; f < 4; ++f) {
        const LatticePoint& a = t[size_t((f + 1) % 4)];
        const std::array<double, 3> n = face_normal(t, f);
        const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (!(len > 0)) continue;
        const double d = n[0] * (p[0] - a[0]) + n[1] * (p[1] - a[1]) + n[2] * (p[2] - a[2]);
        best = std::min(best, std::fabs(d) / len);
    }
    return best;
}

}  // namespace

// A lost triangle is settled without measuring when what it became lies on the drawn surface:
// each of its points p = sum l_i c_i has the point sum l_i q(c_i) of its quantized corners q(c_i)
// within the largest corner displacement, which the grid step (`settled`) already bounds; that
// point lies on the drawn surface when the quantized corners are one drawn vertex, or span an
// edge of a drawn triangle (three collinear corners: two of their three edges, which cover the
// segment they span). The others are sampled along their edges (a lost triangle is thin: that
// is how it lost its area, so its points lie within its small inradius of its edges) and at
// their centroid; a triangle whose samples all lie close enough to the drawn triangles around
// its quantized corners is settled too (an upper bound: a nearest triangle can only be nearer).
// What remains, each sample is measured to all the node's drawn triangles (GridDistance, the
// running maximum as its early exit); the result adds what lies between the samples.
// A piece lying along a face of its tetrahedron continues across that face in the neighbour's
// fragment (clipping cut it there): a clipping sliver is as close to the drawn surface as it is
// to the face, so a sample's distance is at most its distance to the nearest face. (Without
// this, slivers whose neighbouring surface lies in another node counted as lost far away: on a
// 60k-triangle sphere the finest bounds became ten grid steps, and flattened every coarser
// level's to the same value.) A needle crossing the tetrahedron is far from the faces in its
// middle, and still counts; so does a piece longer than `excuse_length` (the input's typical
// triangle: longer, it is a needle, which may lie along a face or an edge and be lost by every
// neighbour alike). A node that draws nothing has no bound only if such a piece remains.
// On a 1M-triangle scan 69k triangles are lost over all levels, 25 of them in 15 nodes need the
// grid, and every node's bound stays the grid step (the same bytes); the converter's task-clock
// was 1.92-2.17 s against 1.85-2.17 s without this bookkeeping.
QuantizationLoss quantization_loss(const std::vector<QuantizedSlot>& slots, double spacing, double settled,
                                   double excuse_length, bool measure_area) {
    QuantizationLoss loss;
    bool drawn_anything = false;
    std::vector<std::pair<size_t, uint32_t>> unsettled;  // slot, input triangle
    // Scratch kept by each thread from node to node (fresh arrays for every slot of every node
    // were a third of this function's cost, in malloc and memset).
    struct Scratch {
        std::vector<uint8_t> kept, on_surface, involved, out_drawn;
        std::vector<uint32_t> lost, first_incident, incident;
        std::vector<uint64_t> wanted, found;  // edges (vertex pairs) of lost triangles' images
        std::vector<Vec3d> samples;
    };
    thread_local Scratch scratch;
    auto& [kept, on_surface, involved, out_drawn, lost, first_incident, incident, wanted, found, samples] = scratch;
    auto edge_key = [](uint32_t a, uint32_t b) { return uint64_t(std::min(a, b)) << 32 | std::max(a, b); };
    for (size_t si = 0; si < slots.size(); ++si) {
        const QuantizedSlot& slot = slots[si];
        const WorkFragment& in = *slot.in;
        const FragmentMesh& out = *slot.out;
        const size_t out_triangles = slot.trace.triangle_source.size();
        kept.assign(in.indices.size() / 3, 0);
        out_drawn.assign(out_triangles, 1);
        for (uint32_t t : slot.trace.flat) out_drawn[t] = 0;
        for (size_t t = 0; t < out_triangles; ++t) kept[slot.trace.triangle_source[t]] = out_drawn[t];
        drawn_anything |= out_triangles > slot.trace.flat.size();
        lost.clear();
        for (size_t t = 0; t < kept.size(); ++t) {
            if (kept[t]) continue;
            lost.push_back(uint32_t(t));
            const uint32_t* f = &in.indices[3 * t];
            if (measure_area) loss.area += triangle_area(in.positions[f[0]], in.positions[f[1]], in.positions[f[2]]);
        }
        if (lost.empty()) continue;
        loss.triangles += lost.size();
        // The vertices and edges of the drawn triangles that the lost ones' images need.
        on_surface.assign(out.vertices.size(), 0);
        involved.assign(out.vertices.size(), 0);
        wanted.clear();
        auto image = [&](uint32_t t, uint32_t q[3]) {
            for (int k = 0; k < 3; ++k) q[k] = slot.trace.vertex_of[in.indices[3 * size_t(t) + k]];
        };
        for (uint32_t t : lost) {
            uint32_t q[3];
            image(t, q);
            for (int k = 0; k < 3; ++k) {
                involved[q[k]] = 1;
                if (q[k] != q[(k + 1) % 3]) wanted.push_back(edge_key(q[k], q[(k + 1) % 3]));
            }
        }
        std::sort(wanted.begin(), wanted.end());
        wanted.erase(std::unique(wanted.begin(), wanted.end()), wanted.end());
        found.clear();
        for (size_t t = 0; t < out_triangles; ++t) {
            if (!out_drawn[t]) continue;
            const uint32_t* f = &out.indices[3 * t];
            for (int k = 0; k < 3; ++k) {
                on_surface[f[k]] = 1;
                if (involved[f[k]] && involved[f[(k + 1) % 3]]) {
                    uint64_t e = edge_key(f[k], f[(k + 1) % 3]);
                    if (std::binary_search(wanted.begin(), wanted.end(), e)) found.push_back(e);
                }
            }
        }
        std::sort(found.begin(), found.end());
        auto is_drawn_edge = [&](uint32_t a, uint32_t b) {
            return std::binary_search(found.begin(), found.end(), edge_key(a, b));
        };
        bool incidence_built = false;
        for (uint32_t t : lost) {
            uint32_t q[3];
            image(t, q);
            bool on;
            if (q[0] == q[1] && q[1] == q[2]) on = on_surface[q[0]];
            else if (q[0] == q[1] || q[1] == q[2] || q[0] == q[2]) on = is_drawn_edge(q[0], q[0] == q[1] ? q[2] : q[1]);
            else on = int(is_drawn_edge(q[0], q[1])) + is_drawn_edge(q[1], q[2]) + is_drawn_edge(q[2], q[0]) >= 2;
            if (on) continue;
            if (!incidence_built) {
                // The drawn triangles around each involved vertex (counting sort).
                first_incident.assign(out.vertices.size() + 1, 0);
                for (size_t d = 0; d < out_triangles; ++d)
                    if (out_drawn[d])
                        for (int k = 0; k < 3; ++k) first_incident[out.indices[3 * d + k] + 1] += involved[out.indices[3 * d + k]];
                for (size_t v = 1; v < first_incident.size(); ++v) first_incident[v] += first_incident[v - 1];
                incident.resize(first_incident.back());
                std::vector<uint32_t> fill(first_incident.begin(), first_incident.end() - 1);
                for (size_t d = 0; d < out_triangles; ++d)
                    if (out_drawn[d])
                        for (int k = 0; k < 3; ++k)
                            if (involved[out.indices[3 * d + k]]) incident[fill[out.indices[3 * d + k]]++] = uint32_t(d);
                incidence_built = true;
            }
            const Vec3d* c[3] = {&in.positions[in.indices[3 * size_t(t)]], &in.positions[in.indices[3 * size_t(t) + 1]],
                                 &in.positions[in.indices[3 * size_t(t) + 2]]};
            samples.clear();
            const double reach = settled - sample_lost_triangle(c, spacing, samples) - spacing / 2;
            const bool short_piece = longest_edge(c) <= excuse_length;
            bool near = reach > 0;
            for (size_t i = 0; near && i < samples.size(); ++i) {
                double best = short_piece ? face_distance(samples[i], slot.corners) : 1e150;
                best *= best;
                for (int k = 0; k < 3; ++k)
                    for (uint32_t j = first_incident[q[k]]; j < first_incident[q[k] + 1]; ++j) {
                        const uint32_t* f = &out.indices[3 * size_t(incident[j])];
                        Vec3d corner[3];
                        for (int m = 0; m < 3; ++m) {
                            BaryWeights w;
                            vertex_weights(out.vertices[f[m]], out.layout, w);
                            corner[m] = lattice_of(w, slot.corners);
                        }
                        best = std::min(best, point_triangle_distance2(samples[i], corner[0], corner[1], corner[2]));
                    }
                near = std::sqrt(best) <= reach;
            }
            if (!near) unsettled.push_back({si, t});
        }
    }
    if (loss.triangles == 0) return loss;
    loss.error = settled;
    if (unsettled.empty()) return loss;
    if (!drawn_anything) {
        loss.nothing_drawn = true;
        loss.error = 0;
        return loss;
    }

    // Measured: the drawn triangles of every slot (a lost piece near a slot's face may be
    // closest to the neighbour's surface), sample points along the unsettled triangles' edges.
    std::vector<Vec3d> drawn_positions;
    std::vector<uint32_t> drawn;
    for (const QuantizedSlot& slot : slots) {
        const uint32_t base = uint32_t(drawn_positions.size());
        for (const PackedVertex& v : slot.out->vertices) {
            BaryWeights w;
            vertex_weights(v, slot.out->layout, w);
            drawn_positions.push_back(lattice_of(w, slot.corners));
        }
        out_drawn.assign(slot.trace.triangle_source.size(), 1);
        for (uint32_t t : slot.trace.flat) out_drawn[t] = 0;
        for (size_t t = 0; t < out_drawn.size(); ++t)
            if (out_drawn[t]) {
                const uint32_t* f = &slot.out->indices[3 * t];
                drawn.insert(drawn.end(), {base + f[0], base + f[1], base + f[2]});
            }
    }
    samples.clear();
    std::vector<double> to_face;  // of each sample, to the nearest face of its tetrahedron
    double inradius = 0;  // the largest of the unsettled triangles'
    for (auto [si, t] : unsettled) {
        const WorkFragment& in = *slots[si].in;
        const Vec3d* c[3] = {&in.positions[in.indices[3 * size_t(t)]], &in.positions[in.indices[3 * size_t(t) + 1]],
                             &in.positions[in.indices[3 * size_t(t) + 2]]};
        inradius = std::max(inradius, sample_lost_triangle(c, spacing, samples));
        const bool short_piece = longest_edge(c) <= excuse_length;
        while (to_face.size() < samples.size())
            to_face.push_back(short_piece ? face_distance(samples[to_face.size()], slots[si].corners) : 1e300);
    }
    std::vector<Vec3d> box_points = drawn_positions;
    box_points.insert(box_points.end(), samples.begin(), samples.end());
    GridDistance to_drawn(drawn_positions, drawn, bounding_box(box_points));
    double error = 0;
    for (size_t i = 0; i < samples.size(); ++i)
        if (to_face[i] > error) error = std::max(error, std::min(to_face[i], to_drawn.distance(samples[i], error)));
    // From the samples to every point (distances are 1-Lipschitz): a point of a triangle lies
    // within its inradius of its edges, and a point of an edge within spacing / 2 of a sample.
    loss.error = std::max(settled, error + inradius + spacing / 2);
    return loss;
}

}  // namespace catpaq
