// Half-edge collapse simplification with quadric error and per-vertex locks (see catp/simplify.h).
//
// Data layout: the live triangles are a flat index buffer. Every pass rebuilds a compact
// vertex -> triangle adjacency (CSR) in which each incident triangle (x, a, b) of vertex x is
// stored, rotated to start at x, as the pair (a, b): the pair list of x is x's fan. From it come
// the candidates (the two cheapest allowed targets of each removable vertex), bucket-sorted by
// cost; then the cheapest candidates are collapsed, each vertex taking part in at most one
// collapse per pass. Collapses inside a pass are recorded in a remap table (removed vertex ->
// kept vertex) that the checks of later collapses in the same pass resolve through, so the
// adjacency need not be updated until the next pass, which compacts the index buffer through the
// remap and rebuilds it.
//
// Why the checks stay valid within a pass: a vertex that took part in a collapse is frozen for
// the rest of the pass, so the two vertices of any later collapse in that pass have their
// original fans (their triangles are the pass's pairs with remapped vertices; triangles that a
// collapse removed are exactly those whose remapped vertices repeat), and their quadrics are
// unchanged, so the candidate costs computed at the start of the pass are still exact.
//
// No allocation happens after the start: one arena holds every array (see Arena), and the only
// std::vectors are the result and scratch for rare cases (fans above kLinearFan triangles,
// duplicate triangles, vertex buffers much larger than the mesh).
#include "catp/simplify.h"

#include <algorithm>
#include <bit>
#include <cassert>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <type_traits>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "base/large_buffer.h"

namespace catpaq {
namespace {

// Vertex kinds. Kinds never change during simplification: collapses preserve the manifold
// structure (link condition), so interior vertices stay interior and border vertices stay border.
constexpr uint8_t kInterior = 0;  // manifold, closed fan (a disk)
constexpr uint8_t kBorder = 1;    // manifold, open fan (a half-disk): may slide along the border
constexpr uint8_t kLocked = 2;    // locked by the caller, non-manifold, or locked border
constexpr uint8_t kFrozen = 0x80;  // flag: took part in a collapse in the current pass

// Weight of a border edge's perpendicular plane, relative to the squared edge length.
constexpr double kBorderWeight = 1.0;
// A collapse may not turn a triangle's normal by more than acos(kMinCosine) (~78 degrees).
constexpr double kMinCosine = 0.2;
// ... nor make a triangle face away from the input surface its corners stand for (the sum of
// their merged area-weighted normals) by more than acos(kMinSurfaceCosine) (~73 degrees): this
// catches folds that build up over several collapses, each within the first limit,
constexpr double kMinSurfaceCosine = 0.3;
// ... nor leave a triangle with sin^2(angle at the kept vertex) below this (zero area).
constexpr double kMinSine2 = 1e-12;
// Pass schedule: the error allowed in a pass is kPassSlack times the cost of the candidate at
// kPassQuantile of the sorted candidates. Independent of the target (see simplify.h).
constexpr double kPassQuantile = 0.25;
constexpr double kPassSlack = 1.5;
// Fans up to this size are searched linearly, larger ones through sorted copies.
constexpr uint32_t kLinearFan = 16;
// Candidates ahead of the one being tried whose data is prefetched (see prefetch_collapse).
constexpr size_t kPrefetchAhead = 8;
static_assert(kLinearFan % 4 == 0 && kLinearFan < 32);  // FanFirsts: groups of four, one bit each

struct Vec {
    double x, y, z;
};
inline Vec operator-(const Vec& a, const Vec& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Vec cross(const Vec& a, const Vec& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double dot(const Vec& a, const Vec& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

// Symmetric 4x4 quadric: sum of w * (n.p + d)^2 over planes. Its total weight is kept apart
// (VertexData::w), next to the position, where the cost evaluation reads it.
struct Quadric {
    double a00, a11, a22, a01, a02, a12, b0, b1, b2, c;

    void add_plane(const Vec& n, double d, double weight) {
        const double nx = n.x * weight, ny = n.y * weight, nz = n.z * weight;
        a00 += nx * n.x;
        a11 += ny * n.y;
        a22 += nz * n.z;
        a01 += nx * n.y;
        a02 += nx * n.z;
        a12 += ny * n.z;
        b0 += nx * d;
        b1 += ny * d;
        b2 += nz * d;
        c += weight * d * d;
    }
    void add(const Quadric& q) {
        a00 += q.a00;
        a11 += q.a11;
        a22 += q.a22;
        a01 += q.a01;
        a02 += q.a02;
        a12 += q.a12;
        b0 += q.b0;
        b1 += q.b1;
        b2 += q.b2;
        c += q.c;
    }
    double eval(const Vec& p) const {
        const double rx = a00 * p.x + a01 * p.y + a02 * p.z;
        const double ry = a01 * p.x + a11 * p.y + a12 * p.z;
        const double rz = a02 * p.x + a12 * p.y + a22 * p.z;
        return p.x * rx + p.y * ry + p.z * rz + 2 * (b0 * p.x + b1 * p.y + b2 * p.z) + c;
    }
};

// condition ? a : b, computed with masks: no branch for the compiler to emit.
inline uint64_t select(bool condition, uint64_t a, uint64_t b) {
    const uint64_t mask = uint64_t(0) - uint64_t(condition);
    return (a & mask) | (b & ~mask);
}

// Triangle (x, a, b) around vertex x, stored as (a, b).
struct Pair {
    uint32_t a, b;
};

struct Candidate {
    uint32_t x, y;  // collapse x onto y
    float cost;     // normalized quadric cost (squared distance), for ordering
};

// Per-vertex data read when a vertex is a collapse target, packed for locality.
struct VertexData {
    Vec p;     // position, relative to the first vertex of the first triangle
    double e;  // the vertex's quadric at its own position (0 until it absorbs a vertex)
    double w;  // the quadric's total weight (area, plus border-edge weights)
    Vec n;     // sum of the area-weighted normals of the input triangles merged into the vertex
};

// Sort key: the top 11 bits of the float cost (non-negative, so its bits order like its values):
// the exponent and 3 bits of mantissa, i.e. buckets 12.5% wide. Within a bucket candidates stay
// in vertex order, which keeps the collapses of a pass walking memory mostly forwards: on large
// meshes that is worth more than ordering finer than the costs' own accuracy.
inline uint32_t sort_key(float cost) { return std::bit_cast<uint32_t>(cost) >> 20; }

// Stable counting sort of the candidates by sort_key.
void bucket_sort(const Candidate* items, Candidate* out, size_t n) {
    constexpr uint32_t kSize = 1u << 11;
    uint32_t start[kSize] = {};
    for (size_t i = 0; i < n; ++i) ++start[sort_key(items[i].cost)];
    uint32_t sum = 0;
    for (uint32_t i = 0; i < kSize; ++i) {
        const uint32_t c = start[i];
        start[i] = sum;
        sum += c;
    }
    for (size_t i = 0; i < n; ++i) out[start[sort_key(items[i].cost)]++] = items[i];
}

// Queries on one fan (the pairs of one vertex): linear for small fans, binary search in sorted
// copies for large ones. Scratch storage is owned by the caller's Simplifier and reused.
class FanQuery {
public:
    FanQuery(std::vector<uint64_t>& as, std::vector<uint32_t>& bs) : as_(as), bs_(bs) {}

    void reset(const Pair* p, uint32_t k) {
        p_ = p;
        k_ = k;
        if (k > kLinearFan) {
            as_.resize(k);
            bs_.resize(k);
            for (uint32_t i = 0; i < k; ++i) {
                as_[i] = uint64_t(p[i].a) << 32 | i;
                bs_[i] = p[i].b;
            }
            std::sort(as_.begin(), as_.end());
            std::sort(bs_.begin(), bs_.end());
        }
    }
    // Index of the pair whose first element is v (the first such), or k if none.
    uint32_t find_a(uint32_t v) const {
        if (k_ > kLinearFan) {
            const auto it = std::lower_bound(as_.begin(), as_.end(), uint64_t(v) << 32);
            return it != as_.end() && uint32_t(*it >> 32) == v ? uint32_t(*it) : k_;
        }
        for (uint32_t i = 0; i < k_; ++i)
            if (p_[i].a == v) return i;
        return k_;
    }
    bool has_a(uint32_t v) const { return find_a(v) != k_; }
    bool has_b(uint32_t v) const {
        if (k_ > kLinearFan) return std::binary_search(bs_.begin(), bs_.end(), v);
        for (uint32_t i = 0; i < k_; ++i)
            if (p_[i].b == v) return true;
        return false;
    }
    // True when some vertex appears twice as a first or twice as a second element.
    bool has_repeats() const {
        if (k_ > kLinearFan) {
            for (uint32_t i = 1; i < k_; ++i)
                if ((as_[i] >> 32) == (as_[i - 1] >> 32) || bs_[i] == bs_[i - 1]) return true;
            return false;
        }
        for (uint32_t i = 0; i < k_; ++i)
            for (uint32_t j = i + 1; j < k_; ++j)
                if (p_[i].a == p_[j].a || p_[i].b == p_[j].b) return true;
        return false;
    }

private:
    const Pair* p_ = nullptr;
    uint32_t k_ = 0;
    std::vector<uint64_t>& as_;
    std::vector<uint32_t>& bs_;
};

// All working memory of one call lives in one block, carved into arrays: one allocation and one
// free per call. Fresh memory costs a page fault per 4 KiB page on first touch, which on virtual
// machines (11-13 us measured on the development VM) can cost more than the simplification
// itself. So a block up to kReuseBytes (a diamond of about 90k gathered triangles) is the
// calling thread's, kept from call to call (warm pages; the heap's own reuse was not enough:
// glibc trims and remaps blocks of this size, and the simplifier made a quarter of the
// converter's page faults); larger blocks (big meshes) are a LargeBuffer, with huge pages (one
// fault per 2 MiB, though each still costs about 4 ms on the development VM); a nested call on a
// thread whose block is in use takes a block from the heap, or a LargeBuffer from kLargeBytes.
class Arena {
public:
    Arena() = default;
    Arena(const Arena&) = delete;
    Arena& operator=(const Arena&) = delete;
    ~Arena() {
        if (thread_block_) thread_block_->in_use = false;
    }

    // Reserves n elements of T (trivial types only; contents uninitialized) before allocate().
    template <class T>
    void reserve(T*& out, size_t n) {
        static_assert(std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T>);
        assert(count_ < kMaxSlots);
        slots_[count_++] = {reinterpret_cast<void**>(&out), (n * sizeof(T) + 63) & ~size_t(63)};
    }
    void allocate() {
        size_t total = 0;
        for (size_t i = 0; i < count_; ++i) total += slots_[i].bytes;
        std::byte* p = nullptr;
        ThreadBlock& mine = thread_block();
        if (total <= kReuseBytes && !mine.in_use) {
            if (mine.bytes < total) {
                mine.block.reset();  // free first: the peak holds one block per thread
                mine.block = std::make_unique_for_overwrite<std::byte[]>(total + 64);
                mine.bytes = total;
            }
            mine.in_use = true;
            thread_block_ = &mine;
            p = mine.block.get();
        } else if (total >= kLargeBytes) {
            large_ = LargeBuffer(total);
            p = large_.data();
        } else {
            block_ = std::make_unique_for_overwrite<std::byte[]>(total + 64);
            p = block_.get();
        }
        p += (64 - reinterpret_cast<uintptr_t>(p) % 64) % 64;
        for (size_t i = 0; i < count_; ++i) {
            *slots_[i].out = p;
            p += slots_[i].bytes;
        }
    }

private:
    struct Slot {
        void** out;
        size_t bytes;
    };
    struct ThreadBlock {
        std::unique_ptr<std::byte[]> block;
        size_t bytes = 0;
        bool in_use = false;  // an Arena of this thread holds it
    };
    static ThreadBlock& thread_block() {
        thread_local ThreadBlock block;
        return block;
    }
    static constexpr size_t kMaxSlots = 16;
    // Kept per thread: within the converter's per-thread memory allowance (kMemoryPerThread).
    static constexpr size_t kReuseBytes = size_t(12) << 20;
    static constexpr size_t kLargeBytes = size_t(8) << 20;
    Slot slots_[kMaxSlots];
    size_t count_ = 0;
    ThreadBlock* thread_block_ = nullptr;
    std::unique_ptr<std::byte[]> block_;
    LargeBuffer large_;
};

class Simplifier {
public:
    Simplifier(const SimplifySettings& settings, size_t vertex_count, size_t index_count)
        : settings_(settings), vertex_count_(uint32_t(vertex_count)) {
        const size_t v = vertex_count;
        arena_.reserve(tris_, index_count);
        arena_.reserve(source_, index_count / 3);
        arena_.reserve(pairs_, index_count);
        arena_.reserve(start_, v + 1);
        arena_.reserve(valence_, v);
        arena_.reserve(remap_, v);
        arena_.reserve(mark_, v);
        arena_.reserve(kind_, v);
        arena_.reserve(vertex_, v);
        arena_.reserve(quadric_, v);
        arena_.reserve(candidates_, 2 * v);
        arena_.reserve(sorted_, 2 * v);
        arena_.allocate();
    }

    // Copies the input's non-degenerate triangles; throws on indices out of range.
    void load(const double* positions, const uint32_t* indices, size_t index_count, const uint8_t* locked);
    SimplifyResult run();

private:
    void init_positions(const double* positions);
    void build_adjacency();
    bool has_duplicate_triangles();
    void remove_duplicate_triangles();
    uint8_t fan_kind(const Pair* p, uint32_t k);
    bool classify(const uint8_t* locked);
    void init_quadrics();
    void collect_candidates();
    bool border_neighbours(uint32_t x, uint32_t& first, uint32_t& last);
    enum Outcome { kDone, kBusy, kRejected };
    Outcome try_collapse(uint32_t x, uint32_t y, double max_error2);
    void prefetch_collapse(const Candidate& c) const;
    void compact();

    const SimplifySettings settings_;
    const double max_edge2_ = settings_.max_edge_length * settings_.max_edge_length;
    const uint32_t vertex_count_;
    Arena arena_;
    uint32_t* tris_ = nullptr;  // live triangles, 3 indices each
    uint32_t* source_ = nullptr;  // per live triangle, its index in the input
    size_t tri_count_ = 0;      // in the buffer; live_ counts them within a pass
    // Adjacency of the current pass: the pairs of v are [start_[v], start_[v + 1]).
    Pair* pairs_ = nullptr;
    uint32_t* start_ = nullptr;
    uint32_t* valence_ = nullptr;  // live triangles per vertex, kept up to date within a pass
    uint32_t* remap_ = nullptr;    // collapses of the current pass: removed -> kept; else identity
    uint32_t* mark_ = nullptr;     // neighbour marks of the link check, by check number
    uint8_t* kind_ = nullptr;      // kInterior, kBorder or kLocked, | kFrozen
    VertexData* vertex_ = nullptr;
    Quadric* quadric_ = nullptr;
    Candidate* candidates_ = nullptr;
    Candidate* sorted_ = nullptr;
    size_t candidate_count_ = 0;
    uint32_t check_ = 0;
    size_t live_ = 0;
    double error2_ = 0;
    // Scratch for large fans and for the duplicate check (rarely used).
    std::vector<uint64_t> scratch_a_;
    std::vector<uint32_t> scratch_b_;
};

void Simplifier::load(const double* positions, const uint32_t* indices, size_t index_count, const uint8_t* locked) {
    size_t w = 0;
    for (size_t i = 0; i < index_count; i += 3) {
        const uint32_t a = indices[i], b = indices[i + 1], c = indices[i + 2];
        if (a >= vertex_count_ || b >= vertex_count_ || c >= vertex_count_)
            throw std::invalid_argument("simplify_mesh: vertex index out of range");
        tris_[w] = a;
        tris_[w + 1] = b;
        tris_[w + 2] = c;
        source_[w / 3] = uint32_t(i / 3);
        w += (a != b && b != c && a != c) ? 3 : 0;
    }
    tri_count_ = w / 3;
    init_positions(positions);
    build_adjacency();
    if (classify(locked) && has_duplicate_triangles()) {
        remove_duplicate_triangles();
        build_adjacency();
        classify(locked);
    }
    init_quadrics();
}

void Simplifier::init_positions(const double* positions) {
    // Work relative to a vertex of the mesh: quadrics of coordinates around 1e6 would lose their
    // precision to cancellation. (Any point of the mesh does; a vertex makes the translation exact
    // for inputs on a grid, so a translated mesh simplifies exactly alike.)
    Vec origin{0, 0, 0};
    if (tri_count_ > 0) {
        const double* o = positions + size_t(tris_[0]) * 3;
        origin = {o[0], o[1], o[2]};
    }
    for (uint32_t v = 0; v < vertex_count_; ++v) {
        const double* p = positions + size_t(v) * 3;
        vertex_[v] = {Vec{p[0], p[1], p[2]} - origin, 0, 0, Vec{0, 0, 0}};
    }
}

void Simplifier::build_adjacency() {
    const size_t n = tri_count_ * 3;
    std::fill(valence_, valence_ + vertex_count_, 0u);
    for (size_t i = 0; i < n; ++i) ++valence_[tris_[i]];
    uint32_t sum = 0;
    for (uint32_t v = 0; v < vertex_count_; ++v) {
        sum += valence_[v];
        start_[v] = sum;  // end of v's range for now
    }
    start_[vertex_count_] = sum;
    // Filling backwards by decrementing leaves start_[v] at the beginning of v's range, with
    // each fan in triangle order.
    for (size_t t = n; t > 0;) {
        t -= 3;
        const uint32_t i0 = tris_[t], i1 = tris_[t + 1], i2 = tris_[t + 2];
        pairs_[--start_[i2]] = {i0, i1};
        pairs_[--start_[i1]] = {i2, i0};
        pairs_[--start_[i0]] = {i1, i2};
    }
}

bool Simplifier::has_duplicate_triangles() {
    // Two triangles on the same three vertices meet in the fan of their smallest vertex x as
    // pairs (a, b) and (a, b) or (b, a) with both a and b above x.
    for (uint32_t x = 0; x < vertex_count_; ++x) {
        const uint32_t b0 = start_[x], b1 = start_[x + 1];
        if (b1 - b0 < 2) continue;
        if (b1 - b0 <= kLinearFan) {
            for (uint32_t i = b0; i < b1; ++i) {
                const Pair p = pairs_[i];
                if (p.a < x || p.b < x) continue;
                for (uint32_t j = i + 1; j < b1; ++j) {
                    const Pair q = pairs_[j];
                    if ((q.a == p.a && q.b == p.b) || (q.a == p.b && q.b == p.a)) return true;
                }
            }
        } else {
            scratch_a_.clear();
            for (uint32_t i = b0; i < b1; ++i) {
                const Pair p = pairs_[i];
                if (p.a < x || p.b < x) continue;
                scratch_a_.push_back(uint64_t(std::min(p.a, p.b)) << 32 | std::max(p.a, p.b));
            }
            std::sort(scratch_a_.begin(), scratch_a_.end());
            if (std::adjacent_find(scratch_a_.begin(), scratch_a_.end()) != scratch_a_.end()) return true;
        }
    }
    return false;
}

void Simplifier::remove_duplicate_triangles() {
    // Rare path: sort the triangles by their vertex set and keep the first of each set.
    struct Key {
        uint32_t v[3];
        uint32_t t;
    };
    const size_t n = tri_count_;
    std::vector<Key> keys(n);
    for (size_t t = 0; t < n; ++t) {
        Key& k = keys[t];
        std::copy(tris_ + 3 * t, tris_ + 3 * t + 3, k.v);
        std::sort(k.v, k.v + 3);
        k.t = uint32_t(t);
    }
    std::sort(keys.begin(), keys.end(), [](const Key& a, const Key& b) {
        for (int i = 0; i < 3; ++i)
            if (a.v[i] != b.v[i]) return a.v[i] < b.v[i];
        return a.t < b.t;
    });
    std::vector<uint8_t> keep(n, 1);
    for (size_t i = 1; i < n; ++i)
        if (std::equal(keys[i].v, keys[i].v + 3, keys[i - 1].v)) keep[keys[i].t] = 0;
    size_t w = 0;
    for (size_t t = 0; t < n; ++t)
        if (keep[t]) {
            source_[w / 3] = source_[t];
            for (int j = 0; j < 3; ++j) tris_[w++] = tris_[3 * t + j];
        }
    tri_count_ = w / 3;
}

// The first elements of a fan's pairs (at most kLinearFan), for finding the pairs that start at
// a vertex four at a time with SSE2: a scalar search mispredicted its exit for nearly every pair
// (classify, which runs it for every pair of every vertex, was 3% of a 10M-triangle build).
class FanFirsts {
public:
    FanFirsts(const Pair* p, uint32_t k) : groups_((k + 3) / 4), valid_((uint32_t(1) << k) - 1) {
        alignas(16) uint32_t firsts[kLinearFan] = {};  // lanes past k stay 0, masked off by valid_
        for (uint32_t i = 0; i < k; ++i) firsts[i] = p[i].a;
#if defined(__SSE2__)
        for (uint32_t g = 0; g < groups_; ++g) v_[g] = _mm_load_si128(reinterpret_cast<const __m128i*>(firsts + 4 * g));
#else
        std::copy(firsts, firsts + kLinearFan, v_);
#endif
    }
    // Bit j set for each pair j whose first element is v.
    uint32_t starting_at(uint32_t v) const {
        uint32_t mask = 0;
#if defined(__SSE2__)
        const __m128i key = _mm_set1_epi32(int(v));
        for (uint32_t g = 0; g < groups_; ++g)
            mask |= uint32_t(_mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(v_[g], key)))) << (4 * g);
#else
        for (uint32_t j = 0; j < 4 * groups_; ++j) mask |= uint32_t(v_[j] == v) << j;
#endif
        return mask & valid_;
    }

private:
    uint32_t groups_, valid_;
#if defined(__SSE2__)
    __m128i v_[kLinearFan / 4];
#else
    uint32_t v_[kLinearFan];
#endif
};

// The shape of a fan, from the pairs (a, b) of its triangles (x, a, b): kInterior for one closed
// cycle a -> b -> ... of at least 3 triangles (a disk), kBorder for one open chain (a half-disk),
// kLocked for anything else: an edge used twice in the same direction (a vertex repeated as a
// first or as a second element: non-manifold or inconsistently oriented), several cycles or
// chains (a bow tie), two triangles folded onto each other.
uint8_t Simplifier::fan_kind(const Pair* p, uint32_t k) {
    if (k <= kLinearFan) {
        // next[i]: the pair continuing pair i (its a is i's b); in: the pairs some pair leads to.
        const FanFirsts firsts(p, k);
        int next[kLinearFan];
        uint32_t in = 0;
        for (uint32_t i = 0; i < k; ++i) {
            const uint32_t continuing = firsts.starting_at(p[i].b);
            if (continuing & (continuing - 1)) return kLocked;  // two pairs start at the same vertex
            next[i] = -1;
            if (continuing) {
                const uint32_t bit = continuing & (0u - continuing);
                if (in & bit) return kLocked;  // two pairs end at the same vertex
                in |= bit;
                next[i] = std::countr_zero(continuing);
            }
        }
        const uint32_t start_mask = ((uint32_t(1) << k) - 1) & ~in;  // pairs no pair leads to
        const int starts = std::popcount(start_mask);
        if (starts > 1) return kLocked;
        const uint32_t first = starts ? uint32_t(std::countr_zero(start_mask)) : 0;
        uint32_t steps = 1;
        int cur = int(first);
        while (next[cur] >= 0 && next[cur] != int(first) && steps < k) {
            cur = next[cur];
            ++steps;
        }
        if (steps != k) return kLocked;
        if (starts == 1) return kBorder;
        return next[cur] == int(first) && k >= 3 ? kInterior : kLocked;
    }
    FanQuery fan(scratch_a_, scratch_b_);
    fan.reset(p, k);
    if (fan.has_repeats()) return kLocked;
    // Each directed edge x -> a of a pair (a, b) has a twin a -> x iff a is some pair's b.
    uint32_t starts = 0, first = 0;
    for (uint32_t i = 0; i < k; ++i)
        if (!fan.has_b(p[i].a) && starts++ == 0) first = i;
    if (starts > 1) return kLocked;
    uint32_t steps = 1, cur = p[first].b;
    const uint32_t stop = starts == 0 ? p[first].a : UINT32_MAX;
    while (cur != stop && steps <= k) {
        const uint32_t i = fan.find_a(cur);
        if (i == k) break;
        cur = p[i].b;
        ++steps;
    }
    if (steps != k || (starts == 0 && cur != stop)) return kLocked;
    return starts == 0 ? kInterior : kBorder;
}

// Sets every vertex's kind; returns whether some fan is not a disk or half-disk (duplicate
// triangles always make such fans, so only then is it worth looking for them).
bool Simplifier::classify(const uint8_t* locked) {
    bool irregular = false;
    for (uint32_t x = 0; x < vertex_count_; ++x) {
        const uint32_t b0 = start_[x], k = start_[x + 1] - b0;
        kind_[x] = kLocked;
        if (k == 0) continue;
        const uint8_t kind = fan_kind(pairs_ + b0, k);
        irregular |= kind == kLocked;
        if ((locked && locked[x]) || (kind == kBorder && settings_.lock_topological_border)) continue;
        kind_[x] = kind;
    }
    return irregular;
}

void Simplifier::init_quadrics() {
    std::fill(quadric_, quadric_ + vertex_count_, Quadric{});
    for (size_t t = 0; t < tri_count_ * 3; t += 3) {
        const uint32_t i0 = tris_[t], i1 = tris_[t + 1], i2 = tris_[t + 2];
        const Vec& p0 = vertex_[i0].p;
        const Vec nrm = cross(vertex_[i1].p - p0, vertex_[i2].p - p0);
        const double len2 = dot(nrm, nrm);
        if (!(len2 > 0)) continue;
        // The unit normal's plane weighted by the area |nrm| / 2: nrm nrm^T / (2 |nrm|).
        const double len = std::sqrt(len2);
        Quadric q{};
        q.add_plane(nrm, -dot(nrm, p0), 0.5 / len);
        quadric_[i0].add(q);
        quadric_[i1].add(q);
        quadric_[i2].add(q);
        for (uint32_t v : {i0, i1, i2}) {
            VertexData& d = vertex_[v];
            d.w += len / 2;
            d.n = {d.n.x + nrm.x, d.n.y + nrm.y, d.n.z + nrm.z};
        }
    }
    if (settings_.lock_topological_border) return;
    // Border edges: the directed edge x -> a of pair (a, b) of x with no twin (a is no pair's b).
    // Only border-kind vertices can slide, so only they need the perpendicular planes.
    FanQuery fan(scratch_a_, scratch_b_);
    for (uint32_t x = 0; x < vertex_count_; ++x) {
        const uint32_t b0 = start_[x], k = start_[x + 1] - b0;
        if (k == 0) continue;
        const Pair* p = pairs_ + b0;
        bool any = kind_[x] == kBorder;
        for (uint32_t i = 0; i < k && !any; ++i) any = kind_[p[i].a] == kBorder;
        if (!any) continue;
        fan.reset(p, k);
        for (uint32_t i = 0; i < k; ++i) {
            const uint32_t a = p[i].a;
            if (kind_[x] != kBorder && kind_[a] != kBorder) continue;
            if (fan.has_b(a)) continue;
            const Vec& px = vertex_[x].p;
            const Vec e = vertex_[a].p - px;
            const Vec nrm = cross(e, vertex_[p[i].b].p - px);
            const Vec perp = cross(e, nrm);
            const double len = std::sqrt(dot(perp, perp));
            if (!(len > 0)) continue;
            const Vec u{perp.x / len, perp.y / len, perp.z / len};
            const double weight = dot(e, e) * kBorderWeight;
            Quadric q{};
            q.add_plane(u, -dot(u, px), weight);
            for (uint32_t v : {x, a})
                if (kind_[v] == kBorder) {
                    quadric_[v].add(q);
                    vertex_[v].w += weight;
                }
        }
    }
}

// The two border neighbours of border vertex x in the current adjacency: the first element of
// the pair starting its fan and the second element of the pair ending it.
bool Simplifier::border_neighbours(uint32_t x, uint32_t& first, uint32_t& last) {
    const uint32_t b0 = start_[x], k = start_[x + 1] - b0;
    const Pair* p = pairs_ + b0;
    FanQuery fan(scratch_a_, scratch_b_);
    fan.reset(p, k);
    uint32_t nf = 0, nl = 0;
    for (uint32_t i = 0; i < k; ++i) {
        if (!fan.has_b(p[i].a)) {
            first = p[i].a;
            ++nf;
        }
        if (!fan.has_a(p[i].b)) {
            last = p[i].b;
            ++nl;
        }
    }
    return nf == 1 && nl == 1;
}

// Each removable vertex contributes its two cheapest allowed collapses: if the cheaper one is
// blocked by a check, the other still comes up in its turn (a vertex with only one candidate
// whose target is blocked for good would otherwise stay forever).
void Simplifier::collect_candidates() {
    size_t n = 0;
    for (uint32_t x = 0; x < vertex_count_; ++x) {
        const uint32_t b0 = start_[x], b1 = start_[x + 1];
        if (b0 == b1 || kind_[x] == kLocked) continue;
        const Quadric q = quadric_[x];
        const double w = vertex_[x].w;
        // The two cheapest, selected without branches (which neighbour wins is a coin toss, and
        // mispredicted branches would cost more than the evaluation itself): each target as the
        // key (float cost bits, vertex), which orders by cost, then by vertex, under integer min.
        uint64_t k1 = UINT64_MAX, k2 = UINT64_MAX;
        auto consider = [&](uint32_t y) {
            const VertexData& t = vertex_[y];
            const double num = q.eval(t.p) + t.e, den = w + t.w;
            const float c = num > 0 && den > 0 ? float(num / den) : 0.0f;
            const uint64_t key = uint64_t(std::bit_cast<uint32_t>(c)) << 32 | y;
            // By masks (select): GCC 12 compiled std::min and std::max here into a branch on
            // key < k1, which mispredicted (simplify_mesh's share of the 10M-scan build
            // 16.8% -> 14.2%, coarsen_bench's simplify column x0.85).
            const bool below = key < k1;
            const uint64_t larger = select(below, k1, key);  // max(k1, key)
            k1 = select(below, key, k1);                     // min(k1, key)
            k2 = select(larger < k2, larger, k2);
        };
        // Targets: every neighbour (the first elements of the fan's pairs) of an interior vertex,
        // the two border neighbours of a border vertex. One loop, so the evaluation inlines.
        const Pair* targets = pairs_ + b0;
        uint32_t count = b1 - b0;
        Pair border[2];
        if (kind_[x] == kBorder) {
            if (!border_neighbours(x, border[0].a, border[1].a)) continue;
            targets = border;
            count = border[0].a == border[1].a ? 1 : 2;
        }
        for (uint32_t i = 0; i < count; ++i) consider(targets[i].a);
        for (uint64_t k : {k1, k2})
            if (k != UINT64_MAX) candidates_[n++] = {x, uint32_t(k), std::bit_cast<float>(uint32_t(k >> 32))};
    }
    candidate_count_ = n;
}

// Asks the cache for what try_collapse(c.x, c.y) reads first: both vertices' kinds, data,
// quadrics and fan starts. The candidates of a pass come in cost order, so these lie at random:
// in perf, the loads of vertex and quadric data were a fifth of simplify_mesh's own time, nearly
// all of it waiting for memory. A prefetch changes no result.
void Simplifier::prefetch_collapse(const Candidate& c) const {
    __builtin_prefetch(&kind_[c.x]);
    __builtin_prefetch(&kind_[c.y]);
    __builtin_prefetch(&vertex_[c.x]);
    __builtin_prefetch(&vertex_[c.y]);
    // A Quadric (80 bytes) spans two cache lines.
    __builtin_prefetch(&quadric_[c.x]);
    __builtin_prefetch(reinterpret_cast<const char*>(&quadric_[c.x]) + 64);
    __builtin_prefetch(&quadric_[c.y]);
    __builtin_prefetch(reinterpret_cast<const char*>(&quadric_[c.y]) + 64);
    __builtin_prefetch(&start_[c.x]);
    __builtin_prefetch(&start_[c.y]);
}

// Collapses x onto y unless a vertex is frozen (kBusy) or the collapse costs more than
// max_error2 or fails a check (kRejected).
Simplifier::Outcome Simplifier::try_collapse(uint32_t x, uint32_t y, double max_error2) {
    if ((kind_[x] | kind_[y]) & kFrozen) return kBusy;
    // The exact cost (candidates hold it rounded to float, for sorting).
    VertexData& vy = vertex_[y];
    const double merged_e = std::max(quadric_[x].eval(vy.p) + vy.e, 0.0);
    const double merged_w = vertex_[x].w + vy.w;
    const double cost = merged_w > 0 ? merged_e / merged_w : 0;
    if (cost > max_error2) return kRejected;
    const Pair* px = pairs_ + start_[x];
    const uint32_t kx = start_[x + 1] - start_[x];
    const Pair* py = pairs_ + start_[y];
    const uint32_t ky = start_[y + 1] - start_[y];

    // Triangles on the edge x-y are removed; their third vertices are the opposites.
    uint32_t opp[2] = {UINT32_MAX, UINT32_MAX}, nopp = 0;
    for (uint32_t i = 0; i < kx; ++i) {
        const uint32_t a = remap_[px[i].a], b = remap_[px[i].b];
        if (a == b) continue;  // removed earlier in this pass
        if (a == y || b == y) {
            if (nopp == 2) return kRejected;
            opp[nopp++] = a == y ? b : a;
        }
    }
    if (nopp != (kind_[x] == kInterior ? 2u : 1u)) return kRejected;
    if (nopp == 2 && opp[0] == opp[1]) return kRejected;
    // An opposite whose only triangle is removed would vanish (and its border with it).
    for (uint32_t j = 0; j < nopp; ++j)
        if (valence_[opp[j]] < 2) return kRejected;

    // Link condition: the only common neighbours of x and y may be the opposites.
    const uint32_t check = ++check_;
    for (uint32_t i = 0; i < ky; ++i) {
        mark_[remap_[py[i].a]] = check;
        mark_[remap_[py[i].b]] = check;
    }
    const Vec& p0 = vertex_[x].p;
    const Vec& p1 = vertex_[y].p;
    const Vec& nx = vertex_[x].n;
    const Vec nxy{nx.x + vy.n.x, nx.y + vy.n.y, nx.z + vy.n.z};
    for (uint32_t i = 0; i < kx; ++i) {
        const uint32_t a = remap_[px[i].a], b = remap_[px[i].b];
        if (a == b || a == y || b == y) continue;
        const bool a_opp = a == opp[0] || a == opp[1];
        const bool b_opp = b == opp[0] || b == opp[1];
        if ((mark_[a] == check && !a_opp) || (mark_[b] == check && !b_opp)) return kRejected;
        if (a_opp && b_opp) {
            // (x, o0, o1) becomes (y, o0, o1): a duplicate if y already has that triangle.
            for (uint32_t j = 0; j < ky; ++j) {
                const uint32_t c = remap_[py[j].a], d = remap_[py[j].b];
                if ((c == a && d == b) || (c == b && d == a)) return kRejected;
            }
        }
        // Normal flips and zero areas.
        const Vec& pa = vertex_[a].p;
        const Vec& pb = vertex_[b].p;
        const Vec n0 = cross(pa - p0, pb - p0);
        const Vec ea = pa - p1, eb = pb - p1;
        const Vec n1 = cross(ea, eb);
        const double d = dot(n0, n1);
        if (!(d > 0)) return kRejected;
        const double l0 = dot(n0, n0), l1 = dot(n1, n1);
        if (d * d < kMinCosine * kMinCosine * l0 * l1) return kRejected;
        const double la = dot(ea, ea), lb = dot(eb, eb);
        if (l1 <= kMinSine2 * la * lb) return kRejected;
        if (la > max_edge2_ || lb > max_edge2_) return kRejected;  // (never, unless asked)
        // Facing against the input surface that its corners stand for (the sum of their merged
        // normals): catches folds that build up over several collapses, each within the limit.
        const Vec& na = vertex_[a].n;
        const Vec& nb = vertex_[b].n;
        const Vec ns{nxy.x + na.x + nb.x, nxy.y + na.y + nb.y, nxy.z + na.z + nb.z};
        const double ds = dot(n1, ns);
        if (!(ds > 0) || ds * ds < kMinSurfaceCosine * kMinSurfaceCosine * l1 * dot(ns, ns)) return kRejected;
    }

    remap_[x] = y;
    vy.e = merged_e;
    vy.w = merged_w;
    vy.n = nxy;
    quadric_[y].add(quadric_[x]);
    kind_[x] |= kFrozen;
    kind_[y] |= kFrozen;
    for (uint32_t j = 0; j < nopp; ++j) --valence_[opp[j]];
    valence_[y] += valence_[x] - 2 * nopp;
    valence_[x] = 0;
    live_ -= nopp;
    error2_ = std::max(error2_, cost);
    return kDone;
}

void Simplifier::compact() {
    size_t kept = 0;
    for (size_t t = 0; t < tri_count_; ++t) {
        const uint32_t a = remap_[tris_[3 * t]], b = remap_[tris_[3 * t + 1]], c = remap_[tris_[3 * t + 2]];
        tris_[3 * kept] = a;
        tris_[3 * kept + 1] = b;
        tris_[3 * kept + 2] = c;
        source_[kept] = source_[t];
        kept += (a != b && b != c && a != c) ? 1 : 0;
    }
    tri_count_ = kept;
}

SimplifyResult Simplifier::run() {
    live_ = tri_count_;
    const size_t target = settings_.target_triangles;
    const double max_error2 = settings_.max_error >= 0 ? settings_.max_error * settings_.max_error : 0;
    if (live_ > target) {
        for (uint32_t v = 0; v < vertex_count_; ++v) remap_[v] = v;
        std::fill(mark_, mark_ + vertex_count_, 0u);
        bool adjacency_current = true;  // load() built it
        while (live_ > target) {
            if (!adjacency_current) {
                build_adjacency();
                for (uint32_t v = 0; v < vertex_count_; ++v) kind_[v] &= uint8_t(~kFrozen);
            }
            adjacency_current = false;
            collect_candidates();
            const size_t n = candidate_count_;
            if (n == 0) break;
            bucket_sort(candidates_, sorted_, n);
            const double pass_limit = sorted_[std::min(n - 1, size_t(double(n) * kPassQuantile))].cost * kPassSlack;
            size_t done = 0;
            for (size_t i = 0; i < n; ++i) {
                if (i + kPrefetchAhead < n) prefetch_collapse(sorted_[i + kPrefetchAhead]);
                const Candidate& c = sorted_[i];
                if (live_ <= target || c.cost > max_error2) break;
                if (c.cost > pass_limit && done > 0) break;
                done += try_collapse(c.x, c.y, max_error2) == kDone;
            }
            if (done == 0) break;
            compact();
            assert(tri_count_ == live_);
        }
    }
    SimplifyResult result;
    result.indices.assign(tris_, tris_ + tri_count_ * 3);
    result.sources.assign(source_, source_ + tri_count_);
    result.error = std::sqrt(error2_);
    return result;
}

}  // namespace

SimplifyResult simplify_mesh(const double* positions, size_t vertex_count, const uint32_t* indices,
                             size_t index_count, const uint8_t* locked,
                             const SimplifySettings& settings) {
    if (index_count % 3 != 0) throw std::invalid_argument("simplify_mesh: index count is not a multiple of 3");
    if (index_count >= (size_t(1) << 32) || vertex_count > UINT32_MAX)
        throw std::invalid_argument("simplify_mesh: mesh too large (2^32 indices or vertices)");
    if (index_count == 0) return {};
    if (!indices || !positions) throw std::invalid_argument("simplify_mesh: null positions or indices");
    if (vertex_count > index_count) {
        // Most vertices are unreferenced (a shared vertex buffer, say): work on the referenced
        // ones only, so memory follows the mesh. Numbered in input order, they give exactly the
        // result the full buffer would.
        std::vector<uint32_t> local(vertex_count, 0);
        for (size_t i = 0; i < index_count; ++i) {
            if (indices[i] >= vertex_count) throw std::invalid_argument("simplify_mesh: vertex index out of range");
            local[indices[i]] = 1;
        }
        std::vector<uint32_t> global;
        for (size_t v = 0; v < vertex_count; ++v)
            if (local[v]) {
                local[v] = uint32_t(global.size());
                global.push_back(uint32_t(v));
            }
        std::vector<double> sub_positions(global.size() * 3);
        std::vector<uint8_t> sub_locked(locked ? global.size() : 0);
        for (size_t i = 0; i < global.size(); ++i) {
            std::copy(positions + size_t(global[i]) * 3, positions + size_t(global[i]) * 3 + 3, &sub_positions[i * 3]);
            if (locked) sub_locked[i] = locked[global[i]];
        }
        std::vector<uint32_t> sub_indices(index_count);
        for (size_t i = 0; i < index_count; ++i) sub_indices[i] = local[indices[i]];
        SimplifyResult r = simplify_mesh(sub_positions.data(), global.size(), sub_indices.data(), index_count,
                                         locked ? sub_locked.data() : nullptr, settings);
        for (uint32_t& v : r.indices) v = global[v];
        return r;
    }
    Simplifier simplifier(settings, vertex_count, index_count);
    simplifier.load(positions, indices, index_count, locked);
    return simplifier.run();
}

}  // namespace catpaq
