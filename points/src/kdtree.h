#pragma once
// Private to the points module: a static kd-tree over float points for k-nearest-neighbour
// queries. The converter's searches use grids (grid_knn.h); this tree serves where points
// clump, which a grid handles badly (LocalKnn), and any caller of a one-off query. Median splits on
// the longest axis of each node's tight box, leaves of at most kLeafSize points; node slots are
// computed from the subtree sizes, so the two halves build in parallel into disjoint slots.
// The tree keeps the points themselves, with their ids, in tree order (16 bytes a point): a
// leaf's points are contiguous in memory (k=16 queries in spatial order took 1.85 us through an
// index array into the caller's points, 1.45 us so). Queries are read-only and thread-safe.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "mesh/mesh.h"

namespace catpaq::points_detail {

// Inserts a candidate into a k-nearest list being filled: `index` and `distance2` sorted nearest
// first, `found` entries of at most k; when full the farthest drops out. `worst` becomes the
// k-th's distance once there are k (callers start it at infinity, or at a search bound). Every
// neighbour search of the converter (kd-tree, grids, the hierarchy-wide search) keeps its list so.
inline void knn_insert(uint32_t* index, float* distance2, size_t k, size_t& found, float& worst, uint32_t id, float d2) {
    size_t at = found < k ? found++ : k - 1;
    while (at > 0 && distance2[at - 1] > d2) {
        distance2[at] = distance2[at - 1];
        index[at] = index[at - 1];
        --at;
    }
    distance2[at] = d2;
    index[at] = id;
    if (found == k) worst = distance2[k - 1];
}

class KdTree {
public:
    static constexpr uint32_t kLeafSize = 12;
    static constexpr size_t kMaxK = 64;

    // Builds over n points (copied as floats; their ids are their indices). Uses TBB for large
    // inputs when `parallel`.
    void build(const float* xyz, size_t n, bool parallel = true);
    void build(const Vec3d* positions, size_t n, bool parallel = true);

    // The min(k, n) points nearest to q (which may be one of the points: it is then found first,
    // at distance 0), nearest first. k <= kMaxK. Returns how many were found.
    size_t nearest(const float q[3], size_t k, uint32_t* index, float* distance2) const;

    size_t size() const { return points_.size(); }

private:
    struct Point {
        float p[3];
        uint32_t id;
    };
    struct Node {
        uint32_t begin, end;  // range in points_
        uint32_t right;       // slot of the right child (the left is the next slot); 0 for a leaf
        uint32_t axis;        // split axis
        float left_high;      // the left child's largest coordinate on the axis
        float right_low;      // the right child's smallest
    };
    struct Query;
    void build_tree(bool parallel);
    void build_node(uint32_t slot, uint32_t begin, uint32_t end, bool parallel);
    void search(const Node& node, float min_distance2, float offset[3], Query& query) const;
    static uint32_t subtree_nodes(uint32_t count);

    std::vector<Point> points_;
    std::vector<Node> nodes_;
    float lo_[3] = {0, 0, 0}, hi_[3] = {0, 0, 0};  // the root's box
};

}  // namespace catpaq::points_detail
