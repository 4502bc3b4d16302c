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
    xyz_ = xyz;
    index_.resize(n);
    for (size_t i = 0; i < n; ++i) index_[i] = uint32_t(i);
    nodes_.clear();
    if (n == 0) return;
    nodes_.resize(subtree_nodes(uint32_t(n)));
    build_node(0, 0, uint32_t(n), parallel);
}

void KdTree::build_node(uint32_t slot, uint32_t begin, uint32_t end, bool parallel) {
    Node& node = nodes_[slot];
    node.begin = begin;
    node.end = end;
    for (int a = 0; a < 3; ++a) {
        node.lo[a] = INFINITY;
        node.hi[a] = -INFINITY;
    }
    for (uint32_t i = begin; i < end; ++i) {
        const float* p = xyz_ + 3 * size_t(index_[i]);
        for (int a = 0; a < 3; ++a) {
            node.lo[a] = std::min(node.lo[a], p[a]);
            node.hi[a] = std::max(node.hi[a], p[a]);
        }
    }
    const uint32_t count = end - begin;
    if (count <= kLeafSize) {
        node.right = 0;
        return;
    }
    int axis = 0;
    for (int a = 1; a < 3; ++a)
        if (node.hi[a] - node.lo[a] > node.hi[axis] - node.lo[axis]) axis = a;
    const uint32_t middle = begin + count / 2;
    const float* xyz = xyz_;
    std::nth_element(index_.begin() + begin, index_.begin() + middle, index_.begin() + end,
                     [xyz, axis](uint32_t a, uint32_t b) { return xyz[3 * size_t(a) + axis] < xyz[3 * size_t(b) + axis]; });
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

size_t KdTree::nearest(const float q[3], size_t k, uint32_t* out_index, float* out_distance2) const {
    assert(k >= 1 && k <= kMaxK);
    if (nodes_.empty()) return 0;
    size_t found = 0;
    float worst = INFINITY;  // distance2 of the k-th found (infinite until k are found)
    auto box_distance2 = [q](const Node& node) {
        float d2 = 0;
        for (int a = 0; a < 3; ++a) {
            float d = std::max(std::max(node.lo[a] - q[a], q[a] - node.hi[a]), 0.0f);
            d2 += d * d;
        }
        return d2;
    };
    struct Pending {
        uint32_t slot;
        float distance2;
    };
    Pending stack[64];
    int top = 0;
    stack[top++] = {0, 0.0f};
    while (top > 0) {
        Pending pending = stack[--top];
        if (pending.distance2 >= worst && found == k) continue;
        const Node* node = &nodes_[pending.slot];
        while (node->right != 0) {
            const Node& a = nodes_[size_t(node - nodes_.data()) + 1];
            const Node& b = nodes_[node->right];
            float da = box_distance2(a), db = box_distance2(b);
            const Node* near = &a;
            const Node* far = &b;
            if (db < da) {
                std::swap(near, far);
                std::swap(da, db);
            }
            if (!(found == k && db >= worst)) stack[top++] = {uint32_t(far - nodes_.data()), db};
            if (found == k && da >= worst) {
                node = nullptr;
                break;
            }
            node = near;
        }
        if (!node) continue;
        for (uint32_t i = node->begin; i < node->end; ++i) {
            const uint32_t id = index_[i];
            const float* p = xyz_ + 3 * size_t(id);
            float dx = p[0] - q[0], dy = p[1] - q[1], dz = p[2] - q[2];
            float d2 = dx * dx + dy * dy + dz * dz;
            if (found == k && d2 >= worst) continue;
            // Insertion into the sorted list of the best found so far.
            size_t at = found < k ? found++ : k - 1;
            while (at > 0 && out_distance2[at - 1] > d2) {
                out_distance2[at] = out_distance2[at - 1];
                out_index[at] = out_index[at - 1];
                --at;
            }
            out_distance2[at] = d2;
            out_index[at] = id;
            if (found == k) worst = out_distance2[k - 1];
        }
    }
    return found;
}

}  // namespace catpaq::points_detail
