#include "grid_knn.h"

#include <algorithm>
#include <cassert>
#include <cmath>

// AVX2 kernels compiled alongside the baseline ones and chosen at run time (as codec.cpp's).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define CATPAQ_KNN_AVX2 1
#include <immintrin.h>
#else
#define CATPAQ_KNN_AVX2 0
#endif

namespace catpaq::points_detail {

// The k best found so far, nearest first, in the caller's arrays.
struct KnnList {
    size_t k, found = 0;
    float worst = INFINITY;  // distance2 of the k-th found (infinite until k are found)
    uint32_t* index;
    float* distance2;

    void offer(uint32_t id, float d2) { knn_insert(index, distance2, k, found, worst, id, d2); }
};

namespace {

// The cell size for which a box of these extents holds about `cells` cells, an axis thinner
// than a cell counting as one (points on a plane or a line get a 2D or 1D grid).
float cell_size(const float extent[3], double cells) {
    float e[3] = {extent[0], extent[1], extent[2]};
    std::sort(e, e + 3, [](float a, float b) { return a > b; });
    double h = std::cbrt(double(e[0]) * e[1] * e[2] / cells);
    if (!(double(e[2]) >= h)) {
        h = std::sqrt(double(e[0]) * e[1] / cells);
        if (!(double(e[1]) >= h)) h = double(e[0]) / cells;
    }
    return h > 0 && std::isfinite(h) ? float(h) : 1.0f;
}

}  // namespace

void GridKnn::build(const float* xyz, const uint32_t* ids, size_t n, double points_per_cell) {
    assert(n < (size_t(1) << 32));
    float hi[3];
    for (int a = 0; a < 3; ++a) {
        lo_[a] = INFINITY;
        hi[a] = -INFINITY;
    }
    for (size_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) {
            lo_[a] = std::min(lo_[a], xyz[3 * i + a]);
            hi[a] = std::max(hi[a], xyz[3 * i + a]);
        }
    if (n == 0)
        for (int a = 0; a < 3; ++a) lo_[a] = hi[a] = 0;
    const float extent[3] = {hi[0] - lo_[0], hi[1] - lo_[1], hi[2] - lo_[2]};
    // First as if the points filled their box; points on a surface then crowd into few cells,
    // and a second try shrinks the cells as a surface's occupancy scales (with the area).
    h_ = cell_size(extent, std::max(1.0, double(n) / points_per_cell));
    const double max_cells = std::max(64.0, kMaxCellsPerPoint * double(n));
    size_t cells = 0;
    uint64_t squares = 0;  // of the cells' point counts
    for (int attempt = 0;; ++attempt) {
        // Cells per axis are bounded so that the cell array stays within max_cells.
        for (;;) {
            double total = 1;
            for (int a = 0; a < 3; ++a) {
                dims_[a] = int(std::min(double(extent[a]) / h_, 4096.0)) + 1;
                total *= dims_[a];
            }
            if (total <= max_cells) break;
            h_ *= 1.25f;
        }
        inv_h_ = 1.0f / h_;
        cells = size_t(dims_[0]) * size_t(dims_[1]) * size_t(dims_[2]);
        cell_start_.assign(cells + 1, 0);
        cell_of_.resize(n);
        size_t occupied = 0;
        squares = 0;
        for (size_t i = 0; i < n; ++i) {
            int c[3];
            for (int a = 0; a < 3; ++a)
                c[a] = std::clamp(int((xyz[3 * i + a] - lo_[a]) * inv_h_), 0, dims_[a] - 1);
            const uint32_t cell = uint32_t((size_t(c[0]) * size_t(dims_[1]) + size_t(c[1])) * size_t(dims_[2]) + size_t(c[2]));
            cell_of_[i] = cell;
            // Counted in place (cell c's count at c); the sum of squared counts grows by
            // 2 count + 1 per point, exactly as summing them afterwards.
            const uint32_t count = cell_start_[cell]++;
            occupied += count == 0;
            squares += 2 * uint64_t(count) + 1;
        }
        const double crowd = double(n) / double(std::max<size_t>(occupied, 1));
        if (attempt > 0 || crowd < 1.5 * points_per_cell) break;
        h_ *= float(std::sqrt(points_per_cell / crowd));
    }
    // Counts to ends (cell c's points end at cell_start_[c]), then a scatter from the last point
    // back, the ends as cursors: each cursor ends at its cell's start, and a cell's points keep
    // their input order. (Two passes over the cells, which outnumber the points up to 16 times,
    // where a scatter forwards needs a third to shift the cursors back.)
    for (size_t c = 1; c < cells; ++c) cell_start_[c] += cell_start_[c - 1];
    cell_start_[cells] = uint32_t(n);
    expected_scan_ = n ? double(squares) / double(n) : 0;
    points_.resize(n);
    sorted_cell_.resize(n);
    for (size_t i = n; i-- > 0;) {
        const uint32_t at = --cell_start_[cell_of_[i]];
        points_[at] = {{xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]}, ids ? ids[i] : uint32_t(i)};
        sorted_cell_[at] = cell_of_[i];
    }
    // The occupied cells in order, from the sorted points (all_nearest visits only these).
    occupied_.clear();
    for (size_t i = 0; i < n; ++i)
        if (i == 0 || sorted_cell_[i] != sorted_cell_[i - 1]) occupied_.push_back(sorted_cell_[i]);
    px_.resize(n);
    py_.resize(n);
    pz_.resize(n);
    for (size_t i = 0; i < n; ++i) {
        px_[i] = points_[i].p[0];
        py_[i] = points_[i].p[1];
        pz_[i] = points_[i].p[2];
    }
}

// Offers the points of cells [first_cell, last_cell] (one row along z: contiguous in points_).
inline void GridKnn::scan(uint32_t first_cell, uint32_t last_cell, const float q[3], KnnList& list) const {
    const Point* p = points_.data() + cell_start_[first_cell];
    const Point* end = points_.data() + cell_start_[last_cell + 1];
    for (; p < end; ++p) {
        const float dx = p->p[0] - q[0], dy = p->p[1] - q[1], dz = p->p[2] - q[2];
        const float d2 = dx * dx + dy * dy + dz * dz;
        if (d2 < list.worst) list.offer(p->id, d2);
    }
}

namespace {

// For each 8-bit mask, the positions of its set bits in order (then zeros).
struct PackTable {
    uint8_t lanes[256][8];
};
constexpr PackTable make_pack_table() {
    PackTable t{};
    for (int mask = 0; mask < 256; ++mask) {
        int n = 0;
        for (int lane = 0; lane < 8; ++lane)
            if (mask >> lane & 1) t.lanes[mask][n++] = uint8_t(lane);
    }
    return t;
}
constexpr PackTable kPackTable = make_pack_table();

size_t keep_within_from(const float* d2, size_t j, size_t m, float bound2, int32_t* near_d2, uint32_t* near_at,
                        size_t found) {
    for (; j < m; ++j) {
        int32_t bits;
        std::memcpy(&bits, &d2[j], 4);
        near_d2[found] = bits;
        near_at[found] = uint32_t(j);
        found += d2[j] <= bound2;
    }
    return found;
}

#if CATPAQ_KNN_AVX2
// keep_within eight at a time: the lanes within the bound packed to the front by a permutation
// from a table (AVX2 has no compress instruction) and stored whole.
__attribute__((target("avx2,popcnt")))
size_t keep_within_avx2(const float* d2, size_t m, float bound2, int32_t* near_d2, uint32_t* near_at) {
    const __m256 bound = _mm256_set1_ps(bound2);
    __m256i at = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    size_t found = 0, j = 0;
    for (; j + 8 <= m; j += 8) {
        const __m256 d = _mm256_loadu_ps(d2 + j);
        const int mask = _mm256_movemask_ps(_mm256_cmp_ps(d, bound, _CMP_LE_OQ));
        const __m256i lanes = _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(kPackTable.lanes[mask])));
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(near_d2 + found),
                            _mm256_permutevar8x32_epi32(_mm256_castps_si256(d), lanes));
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(near_at + found), _mm256_permutevar8x32_epi32(at, lanes));
        found += size_t(__builtin_popcount(unsigned(mask)));
        at = _mm256_add_epi32(at, _mm256_set1_epi32(8));
    }
    return keep_within_from(d2, j, m, bound2, near_d2, near_at, found);
}

// (__builtin_cpu_init first: this runs among the static constructors, maybe before libgcc's.)
const bool g_avx2 = (__builtin_cpu_init(), __builtin_cpu_supports("avx2") && __builtin_cpu_supports("popcnt"));
#endif

// How many of d[0, padded) are below each of d[0, n): the ranks of the values, but for ties,
// which share the lowest of their ranks. d is padded to a multiple of 8 with values above every
// distance's bits. With AVX2, eight values to a register, each d[j] compared with all of them
// and the counts kept in the register: where each value's count was a vectorized loop over d
// ending in a horizontal sum, 5.7% of the 1M scan's conversion; now 4.1-4.6% (one register at a
// time did better than all of a query's at once, 5.3%).
void count_below_scalar(const int32_t* __restrict d, int n, int padded, int32_t* __restrict below) {
    for (int i = 0; i < n; ++i) {
        const int32_t v = d[i];
        int32_t count = 0;
        for (int j = 0; j < padded; ++j) count += int32_t(d[j] < v);
        below[i] = count;
    }
}

#if CATPAQ_KNN_AVX2
__attribute__((target("avx2")))
void count_below_avx2(const int32_t* __restrict d, int n, int padded, int32_t* __restrict below) {
    for (int i = 0; i < n; i += 8) {
        const __m256i values = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(d + i));
        __m256i counts = _mm256_setzero_si256();
        for (int j = 0; j < padded; ++j)  // (d[j] < v) is -1 where true: subtracted, it counts
            counts = _mm256_sub_epi32(counts, _mm256_cmpgt_epi32(values, _mm256_set1_epi32(d[j])));
        alignas(32) int32_t out[8];
        _mm256_store_si256(reinterpret_cast<__m256i*>(out), counts);
        for (int l = 0; l < 8 && i + l < n; ++l) below[i + l] = out[l];
    }
}
#endif

void count_below(const int32_t* __restrict d, int n, int padded, int32_t* __restrict below) {
#if CATPAQ_KNN_AVX2
    if (g_avx2) return count_below_avx2(d, n, padded, below);
#endif
    count_below_scalar(d, n, padded, below);
}

}  // namespace

// The d2[j] (j < m) at most bound2, as their bits and their j, in order: what all_nearest
// selects from. (A loop storing every value and counting the kept, every store waiting for the
// previous count, was about 4% of the 1M scan's samples; eight at a time with AVX2, 1.9%.)
size_t GridKnn::keep_within(const float* d2, size_t m, float bound2, int32_t* near_d2, uint32_t* near_at) {
#if CATPAQ_KNN_AVX2
    if (g_avx2) return keep_within_avx2(d2, m, bound2, near_d2, near_at);
#endif
    return keep_within_from(d2, 0, m, bound2, near_d2, near_at, 0);
}

// The positions of the `want` smallest of d2_bits[0, n) (n >= want), smallest first, ties by
// position: what sorting (value, position) pairs gives. Few candidates: each one's rank counted
// against all (n^2 comparisons), where nth_element and a sort mispredicted most of their
// branches. Pads d2_bits past n.
void GridKnn::select_nearest(int32_t* d2_bits, size_t n, size_t want, uint32_t* chosen) {
    if (n > kRankSelect) {
        uint64_t* keys = keys_.data();
        for (size_t i = 0; i < n; ++i) keys[i] = uint64_t(uint32_t(d2_bits[i])) << 32 | uint64_t(i);
        if (n > want) std::nth_element(keys, keys + (want - 1), keys + n);
        std::sort(keys, keys + want);
        for (size_t i = 0; i < want; ++i) chosen[i] = uint32_t(keys[i]);
        return;
    }
    const int padded = int((n + 7) & ~size_t(7));
    for (int j = int(n); j < padded; ++j) d2_bits[j] = INT32_MAX;  // above every distance's bits
    int32_t below[kRankSelect];
    count_below(d2_bits, int(n), padded, below);
    // Distinct values: their counts are their ranks, each place below `want` taken once (from
    // the last candidate back, without a branch: a branch per candidate mispredicted).
    std::fill(chosen, chosen + want, UINT32_MAX);
    for (size_t i = n; i-- > 0;) chosen[std::min(size_t(below[i]), want)] = uint32_t(i);
    if (std::find(chosen, chosen + want, UINT32_MAX) == chosen + want) return;
    // Ties (rare): t equal values all count the same r below them, and no other value counts
    // r + 1 .. r + t - 1: in position order, each takes the first free place from r on.
    std::fill(chosen, chosen + want, UINT32_MAX);
    for (size_t i = 0; i < n; ++i) {
        size_t rank = size_t(below[i]);
        while (rank < want && chosen[rank] != UINT32_MAX) ++rank;
        if (rank < want) chosen[rank] = uint32_t(i);
    }
}

size_t GridKnn::nearest(const float q[3], size_t k, uint32_t* index, float* distance2) const {
    assert(k >= 1 && k <= kMaxK);
    if (points_.empty()) return 0;
    KnnList list{k, 0, INFINITY, index, distance2};
    int c[3];
    for (int a = 0; a < 3; ++a) c[a] = std::clamp(int((q[a] - lo_[a]) * inv_h_), 0, dims_[a] - 1);
    return search_rings(q, c, 0, list);
}

// (In all_nearest, 7% of the 1M scan's estimate queries go past their block: restarting them
// at ring 0 re-offered the whole block to the list, and these queries were 4.4% of the
// conversion's time.)
size_t GridKnn::nearest_beyond(const float q[3], const int c[3], size_t k, size_t found, uint32_t* index,
                               float* distance2) const {
    KnnList list{k, found, found == k ? distance2[k - 1] : INFINITY, index, distance2};
    return search_rings(q, c, 2, list);
}

// Scans the rings of cells around c from first_ring out (ring r: the cells at Chebyshev
// distance r), offering their points to the list, until no unvisited cell can hold a point
// nearer than its k-th; the rings before first_ring must be offered already.
size_t GridKnn::search_rings(const float q[3], const int c[3], int first_ring, KnnList& list) const {
    const size_t dy = size_t(dims_[1]), dz = size_t(dims_[2]);
    // Rounding may put a point a hair outside the cell its coordinates say: the distance bound
    // of the unvisited cells is lowered by that much.
    const float slack = h_ * 1e-4f;
    // The nearest an unvisited point can be after ring r: the nearest face of the visited block
    // that is not a face of the grid (infinite: the whole grid is visited).
    auto bound_after = [&](int r) {
        float bound = INFINITY;
        for (int a = 0; a < 3; ++a) {
            if (c[a] - r > 0) bound = std::min(bound, q[a] - (lo_[a] + float(c[a] - r) * h_));
            if (c[a] + r < dims_[a] - 1) bound = std::min(bound, lo_[a] + float(c[a] + r + 1) * h_ - q[a]);
        }
        return bound;
    };
    auto settled_after = [&](int r) {
        float bound = bound_after(r);
        if (bound == INFINITY) return true;
        bound = std::max(bound - slack, 0.0f);
        return list.found == list.k && list.worst <= bound * bound;
    };
    if (first_ring > 0 && settled_after(first_ring - 1)) return list.found;
    for (int r = first_ring;; ++r) {
        const int x0 = std::max(c[0] - r, 0), x1 = std::min(c[0] + r, dims_[0] - 1);
        const int y0 = std::max(c[1] - r, 0), y1 = std::min(c[1] + r, dims_[1] - 1);
        const int z0 = std::max(c[2] - r, 0), z1 = std::min(c[2] + r, dims_[2] - 1);
        for (int x = x0; x <= x1; ++x) {
            const bool x_face = x == c[0] - r || x == c[0] + r;
            for (int y = y0; y <= y1; ++y) {
                const uint32_t row = uint32_t((size_t(x) * dy + size_t(y)) * dz);
                if (x_face || y == c[1] - r || y == c[1] + r) {
                    scan(row + uint32_t(z0), row + uint32_t(z1), q, list);
                } else {  // inside the ring's x and y range: only its two z faces are new
                    if (c[2] - r >= 0) scan(row + uint32_t(c[2] - r), row + uint32_t(c[2] - r), q, list);
                    if (r > 0 && c[2] + r < dims_[2]) scan(row + uint32_t(c[2] + r), row + uint32_t(c[2] + r), q, list);
                }
            }
        }
        if (settled_after(r)) break;
    }
    return list.found;
}

void LocalKnn::build(const float* xyz, const uint32_t* ids, size_t n, double points_per_cell) {
    xyz_ = xyz;
    n_ = n;
    grid_.build(xyz, ids, n, points_per_cell);
    use_tree_ = grid_.expected_scan() > kClumped;
    if (!use_tree_) return;
    tree_.build(xyz, n, false);
    ids_.assign(ids ? ids : nullptr, ids ? ids + n : nullptr);
}

size_t LocalKnn::nearest(const float q[3], size_t k, uint32_t* index, float* distance2) const {
    if (!use_tree_) return grid_.nearest(q, k, index, distance2);
    const size_t found = tree_.nearest(q, k, index, distance2);
    if (!ids_.empty())
        for (size_t i = 0; i < found; ++i) index[i] = ids_[index[i]];
    return found;
}

}  // namespace catpaq::points_detail
