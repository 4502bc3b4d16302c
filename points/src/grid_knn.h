#pragma once
// Private to the points module: k-nearest-neighbour queries over a small set of points (a leaf
// of the hierarchy with its surroundings, or one node's splats) through a uniform grid whose
// cells are sorted by a counting sort: a query scans rings of cells around its own until no
// unvisited cell can hold a nearer point.
//
// Why not the kd-tree (kdtree.h) here: on the 1M scan the global kd-tree's queries (k = 16, about
// 1.9 us each) and the per-node trees of the simplifier were half the conversion's CPU time.
// A grid over a few thousand points stays in the core's cache, costs two passes to build, and a
// query reads whole rows of cells as one contiguous range of points: no recursion, no
// branches per node. Its weakness is clumped points (many in one cell, which every query near
// it scans): expected_scan() tells the caller, who then uses a kd-tree instead.
#include <cstddef>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include "kdtree.h"

namespace catpaq::points_detail {

class GridKnn {
public:
    static constexpr size_t kMaxK = 64;
    // all_nearest selects among up to this many candidates by counting ranks, among more by
    // nth_element.
    static constexpr size_t kRankSelect = 48;
    // Every cell costs a few passes at build time (zeroing, prefix sums): on the scan, 64 cells
    // a point made that a fifth of the simplifier's instructions.
    static constexpr double kMaxCellsPerPoint = 16;

    // Builds over n points (xyz: 3 floats each); ids[i] is what queries report for point i
    // (null: i). The cell size is chosen for about points_per_cell points in an occupied cell
    // (on surfaces as in volumes), within kMaxCellsPerPoint cells a point (axes thinner than
    // a cell get one). Keeps its buffers for the next build.
    void build(const float* xyz, const uint32_t* ids, size_t n, double points_per_cell);

    // The min(k, n) nearest points to q (q may be one of them: it is then found first, at
    // distance 0), nearest first; k <= kMaxK. Returns how many were found.
    size_t nearest(const float q[3], size_t k, uint32_t* index, float* distance2) const;

    // For every point whose id passes is_query, in the grid's order, calls
    // visit(id, q, found, index, distance2) with its min(k, n) nearest as nearest() finds them
    // (ties aside). Batched by cell: the 3x3x3 cells around a cell are gathered once for all
    // its points, the distances to them computed in one vectorizable loop, and the k nearest
    // selected among those nearer than the block's faces (else nearest() finishes the query).
    template <class IsQuery, class Visit>
    void all_nearest(size_t k, IsQuery is_query, Visit visit);

    // The mean number of points in the cell of a point (sum of squared cell counts / n): what
    // one query scans at least. Large when points clump.
    double expected_scan() const { return expected_scan_; }

    size_t size() const { return points_.size(); }

private:
    struct Point {
        float p[3];
        uint32_t id;
    };
    void scan(uint32_t first_cell, uint32_t last_cell, const float q[3], struct KnnList& list) const;
    // nearest() for a query in cell c whose 3x3x3 block is searched already: index/distance2
    // hold the block's `found` nearest (sorted); the rings beyond it are searched as needed.
    size_t nearest_beyond(const float q[3], const int c[3], size_t k, size_t found, uint32_t* index, float* distance2) const;
    size_t search_rings(const float q[3], const int c[3], int first_ring, struct KnnList& list) const;
    static size_t keep_within(const float* d2, size_t m, float bound2, int32_t* near_d2, uint32_t* near_at);
    void select_nearest(int32_t* d2_bits, size_t n, size_t want, uint32_t* chosen);

    std::vector<Point> points_;         // by cell
    std::vector<uint32_t> cell_start_;  // points_ of cell c: [cell_start_[c], cell_start_[c + 1])
    std::vector<uint32_t> cell_of_;     // build scratch: each input point's cell,
    std::vector<uint32_t> sorted_cell_;  // each of points_'s
    std::vector<uint32_t> occupied_;    // the cells holding points, in order
    std::vector<float> px_, py_, pz_;   // points_'s coordinates by axis, for all_nearest's loops
    std::vector<float> block_[3];       // all_nearest's scratch: a block's points by axis,
    std::vector<float> block_d2_;       // their distances to a query,
    std::vector<uint32_t> block_at_;    // their positions in points_,
    std::vector<int32_t> near_d2_;      // the selection's candidates (8 spare each): distance bits,
    std::vector<uint32_t> near_at_;     // positions in the block
    std::vector<uint64_t> keys_;        // and keys (as big as the largest block yet)
    float lo_[3] = {0, 0, 0};
    float h_ = 1, inv_h_ = 1;
    int dims_[3] = {1, 1, 1};
    double expected_scan_ = 0;
};

template <class IsQuery, class Visit>
void GridKnn::all_nearest(size_t k, IsQuery is_query, Visit visit) {
    uint32_t index[kMaxK];
    float distance2[kMaxK];
    const float slack = h_ * 1e-4f;
    const size_t dy = size_t(dims_[1]), dz = size_t(dims_[2]);
    // The previous query and the distance to its k-th nearest: by the triangle inequality, the
    // next query's k nearest are within that plus the distance between the two queries, which
    // (with neighbouring queries, as in the cell order) prunes most of the block before the
    // selection.
    float previous[3] = {0, 0, 0}, previous_reach = -1;
    for (const uint32_t cell : occupied_) {
        const int cz = int(cell % dz), cy = int((cell / dz) % dy), cx = int(cell / dz / dy);
        const uint32_t first = cell_start_[cell], last = cell_start_[cell + 1];
        bool any = false;
        for (uint32_t i = first; i < last && !any; ++i) any = is_query(points_[i].id);
        if (!any) continue;
        // The block's points: rows along z are contiguous in the cell order.
        uint32_t ranges[9][2];
        size_t rows = 0;
        const int z0 = std::max(cz - 1, 0), z1 = std::min(cz + 1, dims_[2] - 1);
        for (int x = std::max(cx - 1, 0); x <= std::min(cx + 1, dims_[0] - 1); ++x)
            for (int y = std::max(cy - 1, 0); y <= std::min(cy + 1, dims_[1] - 1); ++y) {
                const size_t row = (size_t(x) * dy + size_t(y)) * dz;
                const uint32_t b = cell_start_[row + size_t(z0)], e = cell_start_[row + size_t(z1) + 1];
                if (b < e) {
                    ranges[rows][0] = b;
                    ranges[rows][1] = e;
                    // The query's own row first: its points are the nearest on average, so the
                    // selection's worst kept drops early and fewer later candidates get in.
                    if (x == cx && y == cy) std::swap(ranges[0], ranges[rows]);
                    ++rows;
                }
            }
        // Gathered once for the cell's queries (by axis, with their positions in points_), so
        // that each query's distances are one vectorizable loop (per row, rows of a few points
        // spent more on loop overhead than on distances).
        size_t m = 0;
        for (size_t r = 0; r < rows; ++r) m += ranges[r][1] - ranges[r][0];
        if (block_d2_.size() < m) {
            block_d2_.resize(m);
            block_at_.resize(m);
            near_d2_.resize(m + 8);
            near_at_.resize(m + 8);
            keys_.resize(m);
            for (auto& b : block_) b.resize(m);
        }
        // (A plain loop: rows hold a few points, for which calls to memmove cost more than
        // the copy.)
        float* __restrict bx = block_[0].data();
        float* __restrict by = block_[1].data();
        float* __restrict bz = block_[2].data();
        for (size_t r = 0, to = 0; r < rows; ++r)
            for (uint32_t j = ranges[r][0]; j < ranges[r][1]; ++j, ++to) {
                bx[to] = px_[j];
                by[to] = py_[j];
                bz[to] = pz_[j];
                block_at_[to] = j;
            }
        const int c[3] = {cx, cy, cz};
        for (uint32_t i = first; i < last; ++i) {
            const Point& point = points_[i];
            if (!is_query(point.id)) continue;
            const float* q = point.p;
            float bound = INFINITY;
            for (int a = 0; a < 3; ++a) {
                if (c[a] - 1 > 0) bound = std::min(bound, q[a] - (lo_[a] + float(c[a] - 1) * h_));
                if (c[a] + 1 < dims_[a] - 1) bound = std::min(bound, lo_[a] + float(c[a] + 2) * h_ - q[a]);
            }
            bound = std::max(bound - slack, 0.0f);
            float bound2 = bound == INFINITY ? INFINITY : bound * bound;
            if (previous_reach >= 0) {
                float apart2 = 0;
                for (int a = 0; a < 3; ++a) apart2 += (q[a] - previous[a]) * (q[a] - previous[a]);
                const float reach = (previous_reach + std::sqrt(apart2)) * (1 + 1e-4f);
                bound2 = std::min(bound2, reach * reach);
            }
            float* __restrict d2 = block_d2_.data();
            const uint32_t* at_point = block_at_.data();
            const float* __restrict x = block_[0].data();
            const float* __restrict y = block_[1].data();
            const float* __restrict z = block_[2].data();
            const float qx = q[0], qy = q[1], qz = q[2];
            for (size_t j = 0; j < m; ++j) {
                const float dx = x[j] - qx, dyy = y[j] - qy, dzz = z[j] - qz;
                d2[j] = dx * dx + dyy * dyy + dzz * dzz;
            }
            // Those certain to be nearer than anything outside the block, as the bits of their
            // distances (a non-negative float's bits order as it does, also as int32) and
            // their positions in the block; the nearest of them by rank (ties: the earlier in
            // the block).
            const size_t want = std::min(k, points_.size());
            int32_t* __restrict near_d2 = near_d2_.data();
            uint32_t* __restrict near_at = near_at_.data();
            size_t found = keep_within(d2, m, bound2, near_d2, near_at);
            if (found >= want) {
                uint32_t chosen[kMaxK + 1];  // [want]: a place for the others
                select_nearest(near_d2, found, want, chosen);
                for (size_t j = 0; j < want; ++j) {
                    const uint32_t at = near_at[chosen[j]];
                    index[j] = points_[at_point[at]].id;
                    distance2[j] = d2[at];
                }
                found = want;
            }
            if (found < want) {
                // The block does not settle it: its `want` nearest (the block's points are all
                // gathered and their distances known) seed a search of the rings beyond it.
                const size_t seed = std::min(want, m);
                keep_within(d2, m, INFINITY, near_d2, near_at);
                uint32_t chosen[kMaxK + 1];
                select_nearest(near_d2, m, seed, chosen);
                for (size_t j = 0; j < seed; ++j) {
                    const uint32_t at = near_at[chosen[j]];
                    index[j] = points_[at_point[at]].id;
                    distance2[j] = d2[at];
                }
                found = nearest_beyond(q, c, k, seed, index, distance2);
            }
            std::copy(q, q + 3, previous);
            previous_reach = found == k ? std::sqrt(distance2[k - 1]) : -1;
            visit(point.id, q, found, index, distance2);
        }
    }
}

// A grid (GridKnn), or a kd-tree where the grid would scan clumps (duplicates, a dense cluster
// in a sparse region: kClumped points per query cell at least), over a few thousand points.
class LocalKnn {
public:
    static constexpr double kClumped = 48;

    void build(const float* xyz, const uint32_t* ids, size_t n, double points_per_cell);
    size_t nearest(const float q[3], size_t k, uint32_t* index, float* distance2) const;
    // As GridKnn::all_nearest (the kd-tree: queries in input order). The build's points must
    // still be there.
    template <class IsQuery, class Visit>
    void all_nearest(size_t k, IsQuery is_query, Visit visit);

private:
    const float* xyz_ = nullptr;
    size_t n_ = 0;
    GridKnn grid_;
    KdTree tree_;
    std::vector<uint32_t> ids_;  // the tree's: its results are positions in the input
    bool use_tree_ = false;
};

template <class IsQuery, class Visit>
void LocalKnn::all_nearest(size_t k, IsQuery is_query, Visit visit) {
    if (!use_tree_) return grid_.all_nearest(k, is_query, visit);
    uint32_t index[GridKnn::kMaxK];
    float distance2[GridKnn::kMaxK];
    for (size_t i = 0; i < n_; ++i) {
        const uint32_t id = ids_.empty() ? uint32_t(i) : ids_[i];
        if (!is_query(id)) continue;
        const size_t found = nearest(&xyz_[3 * i], k, index, distance2);
        visit(id, &xyz_[3 * i], found, index, distance2);
    }
}

}  // namespace catpaq::points_detail
