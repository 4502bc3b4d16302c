#include "kdtree.h"

#include <algorithm>
#include <cassert>
#include <cmath>

#include <tbb/parallel_invoke.h>

namespace catpaq::points_detail {

// Nodes of a subtree over `count` points: median splits give the left half count / 2.
uint32_t KdTree::subtree_nodes(uint32_t count) {
    if (count <= kLeafSize) return 1;
    return 1 + subtree_nodes(count / 2) + subtree_nodes(count - count / 2);
}

void KdTree::build(const float* xyz, size_t n, bool parallel) {
    assert(n < (size_t(1) << 31));
    points_.resize(n);
    for (size_t i = 0; i < n; ++i) points_[i] = {{xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]}, uint32_t(i)};
    build_tree(parallel);
}

void KdTree::build(const Vec3d* positions, size_t n, bool parallel) {
    assert(n < (size_t(1) << 31));
    points_.resize(n);
    for (size_t i = 0; i < n; ++i)
        points_[i] = {{float(positions[i][0]), float(positions[i][1]), float(positions[i][2])}, uint32_t(i)};
    build_tree(parallel);
}

void KdTree::build_tree(bool parallel) {
    nodes_.clear();
    const size_t n = points_.size();
    if (n == 0) return;
    for (int a = 0; a < 3; ++a) {
        lo_[a] = INFINITY;
        hi_[a] = -INFINITY;
    }
    for (const Point& point : points_)
        for (int a = 0; a < 3; ++a) {
            lo_[a] = std::min(lo_[a], point.p[a]);
            hi_[a] = std::max(hi_[a], point.p[a]);
        }
    nodes_.resize(subtree_nodes(uint32_t(n)));
    build_node(0, 0, uint32_t(n), parallel);
}

void KdTree::build_node(uint32_t slot, uint32_t begin, uint32_t end, bool parallel) {
    Node& node = nodes_[slot];
    node.begin = begin;
    node.end = end;
    node.right = 0;
    const uint32_t count = end - begin;
    if (count <= kLeafSize) return;
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = begin; i < end; ++i)
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], points_[i].p[a]);
            hi[a] = std::max(hi[a], points_[i].p[a]);
        }
    uint32_t axis = 0;
    for (uint32_t a = 1; a < 3; ++a)
        if (hi[a] - lo[a] > hi[axis] - lo[axis]) axis = a;
    const uint32_t middle = begin + count / 2;
    std::nth_element(points_.begin() + begin, points_.begin() + middle, points_.begin() + end,
                     [axis](const Point& a, const Point& b) { return a.p[axis] < b.p[axis]; });
    node.axis = axis;
    node.right_low = points_[middle].p[axis];
    float left_high = -INFINITY;
    for (uint32_t i = begin; i < middle; ++i) left_high = std::max(left_high, points_[i].p[axis]);
    node.left_high = left_high;
    const uint32_t left = slot + 1, right = left + subtree_nodes(count / 2);
    node.right = right;
    if (parallel && count > 100000) {
        tbb::parallel_invoke([&] { build_node(left, begin, middle, true); },
                             [&] { build_node(right, middle, end, true); });
    } else {
        build_node(left, begin, middle, false);
        build_node(right, middle, end, false);
    }
}

struct KdTree::Query {
    float q[3];
    size_t k, found = 0;
    float worst = INFINITY;  // distance2 of the k-th found (infinite until k are found)
    uint32_t* index;
    float* distance2;

    void offer(uint32_t id, float d2) {
        if (d2 < worst) knn_insert(index, distance2, k, found, worst, id, d2);
    }
};

// Visits the nearer child first; the farther one only if the query's ball reaches it. The lower
// bound of the distance to a node is kept incrementally, one axis per level (Arya and Mount's
// incremental distance, as in nanoflann): offset[a] is the query's distance to the node's
// region along axis a.
void KdTree::search(const Node& node, float min_distance2, float offset[3], Query& query) const {
    if (node.right == 0) {
        for (uint32_t i = node.begin; i < node.end; ++i) {
            const Point& point = points_[i];
            float dx = point.p[0] - query.q[0], dy = point.p[1] - query.q[1], dz = point.p[2] - query.q[2];
            float d2 = dx * dx + dy * dy + dz * dz;
            if (d2 < query.worst) query.offer(point.id, d2);
        }
        return;
    }
    const uint32_t axis = node.axis;
    const float value = query.q[axis];
    const float to_left = value - node.left_high, to_right = node.right_low - value;
    const Node* near = &node + 1;
    const Node* far = &nodes_[node.right];
    float cut = to_right > 0 ? to_right : 0;
    if (to_left > 0 && to_left > to_right) {  // nearer the right child
        std::swap(near, far);
        cut = to_left;
    }
    search(*near, min_distance2, offset, query);
    const float saved = offset[axis];
    const float far_distance2 = min_distance2 - saved * saved + cut * cut;
    if (far_distance2 < query.worst) {
        offset[axis] = cut;
        search(*far, far_distance2, offset, query);
        offset[axis] = saved;
    }
}

size_t KdTree::nearest(const float q[3], size_t k, uint32_t* out_index, float* out_distance2) const {
    assert(k >= 1 && k <= kMaxK);
    if (nodes_.empty()) return 0;
    Query query{{q[0], q[1], q[2]}, k, 0, INFINITY, out_index, out_distance2};
    float offset[3], d2 = 0;
    for (int a = 0; a < 3; ++a) {
        offset[a] = std::max(std::max(lo_[a] - q[a], q[a] - hi_[a]), 0.0f);
        d2 += offset[a] * offset[a];
    }
    search(nodes_[0], d2, offset, query);
    return query.found;
}

}  // namespace catpaq::points_detail
