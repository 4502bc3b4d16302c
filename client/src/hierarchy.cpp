#include "client/hierarchy.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <unordered_map>

#include "base/error.h"

namespace catpaq {

void Aabb::extend(const std::array<double, 3>& p) {
    for (int i = 0; i < 3; ++i) {
        min[i] = std::min(min[i], p[i]);
        max[i] = std::max(max[i], p[i]);
    }
}

void Aabb::extend(const Aabb& b) {
    if (b.empty()) return;
    for (int i = 0; i < 3; ++i) {
        min[i] = std::min(min[i], b.min[i]);
        max[i] = std::max(max[i], b.max[i]);
    }
}

bool Aabb::contains(const Aabb& b) const {
    if (b.empty()) return true;
    for (int i = 0; i < 3; ++i)
        if (b.min[i] < min[i] || b.max[i] > max[i]) return false;
    return true;
}

double Aabb::distance_to(const std::array<double, 3>& p) const {
    if (empty()) return std::numeric_limits<double>::infinity();
    double d2 = 0;
    for (int i = 0; i < 3; ++i) {
        double d = 0;
        if (p[i] < min[i]) d = min[i] - p[i];
        else if (p[i] > max[i]) d = p[i] - max[i];
        d2 += d * d;
    }
    return std::sqrt(d2);
}

uint32_t Hierarchy::add_node(uint64_t key, uint16_t level, double error, const Aabb& bounds, bool has_data) {
    if (nodes_.size() >= size_t(kNoNode)) fail("hierarchy: too many nodes");
    uint32_t index = uint32_t(nodes_.size());
    if (!by_key_.emplace(key, index).second) fail("hierarchy: duplicate node key %llu", (unsigned long long)key);
    HierarchyNode n;
    n.index = index;
    n.key = key;
    n.level = level;
    n.error = error;
    n.bounds = bounds;
    n.has_data = has_data;
    nodes_.push_back(std::move(n));
    return index;
}

void Hierarchy::add_parent(uint32_t node, uint32_t parent) { nodes_[node].parents.push_back(parent); }

uint32_t Hierarchy::find(uint64_t key) const {
    auto it = by_key_.find(key);
    return it == by_key_.end() ? kNoNode : it->second;
}

size_t Hierarchy::virtual_count() const {
    size_t n = 0;
    for (const HierarchyNode& node : nodes_) n += !node.has_data;
    return n;
}

void Hierarchy::finalize() {
    for (HierarchyNode& n : nodes_) {
        n.children.clear();
        std::sort(n.parents.begin(), n.parents.end());
        n.parents.erase(std::unique(n.parents.begin(), n.parents.end()), n.parents.end());
        for (uint32_t p : n.parents) {
            if (p >= nodes_.size() || p == n.index)
                fail("hierarchy: node %llu has an invalid parent", (unsigned long long)n.key);
            if (nodes_[p].level >= n.level)
                fail("hierarchy: parent %llu (level %d) of node %llu (level %d) is not coarser",
                     (unsigned long long)nodes_[p].key, int(nodes_[p].level), (unsigned long long)n.key, int(n.level));
        }
    }
    for (const HierarchyNode& n : nodes_)
        for (uint32_t p : n.parents) nodes_[p].children.push_back(n.index);
    roots_.clear();
    for (HierarchyNode& n : nodes_) {
        std::sort(n.children.begin(), n.children.end());
        if (n.children.empty()) n.leaf = true;
        if (n.parents.empty()) roots_.push_back(n.index);
    }
    // Bottom-up (levels strictly increase along edges, so decreasing level is a reverse
    // topological order): monotone errors and nested boxes.
    std::vector<uint32_t> order(nodes_.size());
    for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(),
                     [&](uint32_t a, uint32_t b) { return nodes_[a].level > nodes_[b].level; });
    for (uint32_t i : order) {
        HierarchyNode& n = nodes_[i];
        for (uint32_t c : n.children) {
            n.error = std::max(n.error, nodes_[c].error);
            n.bounds.extend(nodes_[c].bounds);
        }
    }
    decodes_against_parents_ = std::any_of(nodes_.begin(), nodes_.end(), [](const HierarchyNode& n) { return n.decode_parent != kNoNode; });
    std::string problem = check();
    if (!problem.empty()) fail("hierarchy: %s", problem.c_str());
}

std::string Hierarchy::check() const {
    for (const HierarchyNode& n : nodes_) {
        if (!std::isfinite(n.error) || n.error < 0) return strprintf("node %llu has a bad error", (unsigned long long)n.key);
        for (uint32_t p : n.parents) {
            const HierarchyNode& pn = nodes_[p];
            if (pn.level >= n.level) return strprintf("node %llu: parent not coarser", (unsigned long long)n.key);
            if (!std::binary_search(pn.children.begin(), pn.children.end(), n.index))
                return strprintf("node %llu: parent does not list it as a child", (unsigned long long)n.key);
            if (pn.error < n.error) return strprintf("node %llu: error above its parent's", (unsigned long long)n.key);
            if (!pn.bounds.contains(n.bounds)) return strprintf("node %llu: box outside its parent's", (unsigned long long)n.key);
        }
        for (const Aabb& box : n.view_boxes) {
            if (!n.bounds.contains(box)) return strprintf("node %llu: view box outside its bounds", (unsigned long long)n.key);
            if (n.parents.empty()) continue;
            bool nested = false;
            for (uint32_t p : n.parents)
                for (const Aabb& pb : nodes_[p].view_boxes) nested |= pb.contains(box);
            if (!nested) return strprintf("node %llu: a view box in no parent's", (unsigned long long)n.key);
        }
        for (uint32_t c : n.children)
            if (!std::binary_search(nodes_[c].parents.begin(), nodes_[c].parents.end(), n.index))
                return strprintf("node %llu: child does not list it as a parent", (unsigned long long)n.key);
        for (const HierarchyPart& part : n.parts) {
            if (part.parent == kNoNode) {
                if (!n.parents.empty()) return strprintf("node %llu: unconditional part of a non-root", (unsigned long long)n.key);
            } else if (!std::binary_search(n.parents.begin(), n.parents.end(), part.parent)) {
                return strprintf("node %llu: part created by a node that is not a parent", (unsigned long long)n.key);
            }
        }
        if (!n.has_data && !n.parts.empty()) return strprintf("virtual node %llu has parts", (unsigned long long)n.key);
        if (n.decode_parent != kNoNode) {
            if (!std::binary_search(n.parents.begin(), n.parents.end(), n.decode_parent))
                return strprintf("node %llu: decodes against a node that is not a parent", (unsigned long long)n.key);
            if (!nodes_[n.decode_parent].has_data || !n.has_data || n.fetch_parts)
                return strprintf("node %llu: decodes against a parent without data, or is fetched by parts",
                                 (unsigned long long)n.key);
        }
        if (n.fetch_parts) {
            if (n.key >> 63) return strprintf("node %llu: a node fetched by parts needs a key below 2^63", (unsigned long long)n.key);
            if (n.parts.size() > kMaxFetchedParts)
                return strprintf("node %llu: too many parts to fetch alone", (unsigned long long)n.key);
            for (const HierarchyPart& part : n.parts)
                if (part.size == 0 || part.offset < n.payload_offset ||
                    part.offset + part.size > n.payload_offset + n.payload_bytes)
                    return strprintf("node %llu: a part's byte range is outside the node's", (unsigned long long)n.key);
        }
    }
    return {};
}

}  // namespace catpaq

namespace catpaq {

Hierarchy build_synthetic_hierarchy(const SyntheticHierarchySettings& settings) {
    std::mt19937_64 rng(settings.seed);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    auto key_of = [](int level, int64_t x, int64_t y) {
        return (uint64_t(level) << 56) | (uint64_t(y) << 28) | uint64_t(x);
    };
    struct Cell {
        uint32_t node;
        int64_t x, y;
    };
    Hierarchy h;
    int levels = std::max(1, std::min(settings.levels, 14));
    std::vector<std::unordered_map<uint64_t, Cell>> cells(static_cast<size_t>(levels));
    auto cell_box = [&](int level, int64_t x, int64_t y) {
        double side = settings.size / double(int64_t(1) << level);
        Aabb b;
        double z = settings.size * 0.01 * (0.5 + u(rng));
        b.extend(std::array<double, 3>{double(x) * side, double(y) * side, 0.0});
        b.extend(std::array<double, 3>{double(x + 1) * side, double(y + 1) * side, z});
        return b;
    };
    auto add_cell = [&](int level, int64_t x, int64_t y) {
        double side = settings.size / double(int64_t(1) << level);
        double error = side * 0.01 * (0.8 + 0.4 * u(rng));
        uint32_t n = h.add_node(key_of(level, x, y), uint16_t(level), error, cell_box(level, x, y), true);
        cells[size_t(level)][key_of(level, x, y)] = Cell{n, x, y};
        return n;
    };
    add_cell(0, 0, 0);
    for (int level = 0; level + 1 < levels; ++level) {
        std::vector<Cell> parents;
        for (const auto& [key, cell] : cells[size_t(level)]) parents.push_back(cell);
        std::sort(parents.begin(), parents.end(), [](const Cell& a, const Cell& b) { return a.node < b.node; });
        for (const Cell& p : parents) {
            std::array<bool, 4> keep{};
            bool any = false;
            for (int c = 0; c < 4; ++c) any |= keep[size_t(c)] = u(rng) < settings.keep;
            if (!any) keep[size_t(rng() % 4)] = true;
            for (int c = 0; c < 4; ++c) {
                if (!keep[size_t(c)]) continue;
                int64_t cx = 2 * p.x + (c & 1), cy = 2 * p.y + (c >> 1);
                uint32_t child = add_cell(level + 1, cx, cy);
                h.add_parent(child, p.node);
                int64_t dx = (cx & 1) ? 1 : -1, dy = (cy & 1) ? 1 : -1;
                for (auto [nx, ny] : {std::pair{p.x + dx, p.y}, std::pair{p.x, p.y + dy}, std::pair{p.x + dx, p.y + dy}}) {
                    auto it = cells[size_t(level)].find(key_of(level, nx, ny));
                    if (it != cells[size_t(level)].end() && u(rng) < settings.extra_parent) h.add_parent(child, it->second.node);
                }
            }
        }
    }
    // Virtual interior nodes.
    std::vector<uint8_t> has_children(h.size(), 0);
    std::vector<uint32_t> children_of(h.size(), 0);
    for (uint32_t n = 0; n < h.size(); ++n)
        for (uint32_t p : h.node(n).parents) {
            has_children[p] = 1;
            children_of[p]++;
        }
    for (uint32_t n = 1; n < h.size(); ++n)
        if (has_children[n] && u(rng) < settings.virtual_fraction) h.mutable_node(n).has_data = false;
    // As in CATP, geometry is created by a parent with geometry: a node with data keeps at least
    // one data parent (bottom-up, so chains are fixed too).
    for (uint32_t n = uint32_t(h.size()); n-- > 1;) {
        HierarchyNode& node = h.mutable_node(n);
        if (!node.has_data || node.parents.empty()) continue;
        bool any = false;
        for (uint32_t p : node.parents) any |= h.node(p).has_data;
        if (!any) h.mutable_node(node.parents[0]).has_data = true;
    }
    // Primitives bottom-up (nodes were added level by level, so reverse order is children first).
    std::vector<uint64_t> drawn_for(h.size(), 0);  // what a node's children draw for it
    for (uint32_t n = uint32_t(h.size()); n-- > 0;) {
        HierarchyNode& node = h.mutable_node(n);
        if (!node.has_data) continue;
        // Interior nodes are about as large as their children (as in CATP, where every diamond
        // holds about the same number of triangles), and never larger than what the children
        // draw for them, so refining never lowers the primitives drawn.
        uint64_t total = 50 + rng() % 101;
        if (has_children[n]) total = std::max<uint64_t>(1, std::min<uint64_t>(drawn_for[n], drawn_for[n] * 3 / (2 * children_of[n])));
        node.primitives = uint32_t(total);
        node.payload_bytes = uint32_t(16 + total * 6);
        node.payload_offset = uint64_t(n) * 4096;
        std::vector<uint32_t> data_parents;
        std::sort(node.parents.begin(), node.parents.end());
        node.parents.erase(std::unique(node.parents.begin(), node.parents.end()), node.parents.end());
        for (uint32_t p : node.parents)
            if (h.node(p).has_data) data_parents.push_back(p);
        if (node.parents.empty()) {
            node.parts.push_back(HierarchyPart{kNoNode, 0, uint32_t(total)});
            continue;
        }
        if (data_parents.empty()) continue;  // only virtual parents: nothing is ever drawn for it
        std::vector<double> w(data_parents.size());
        double sum = 0;
        for (double& x : w) sum += x = 0.2 + u(rng);
        uint64_t left = total;
        for (size_t i = 0; i < data_parents.size(); ++i) {
            uint64_t share = i + 1 == data_parents.size() ? left : std::min<uint64_t>(left, uint64_t(double(total) * w[i] / sum));
            left -= share;
            node.parts.push_back(HierarchyPart{data_parents[i], uint8_t(i), uint32_t(share)});
            drawn_for[data_parents[i]] += share;
        }
    }
    if (settings.fetch_parts)
        for (uint32_t n = 0; n < h.size(); ++n) {
            // Each part its own range: 6 bytes per primitive, one after another (at least 1).
            HierarchyNode& node = h.mutable_node(n);
            if (!node.has_data) continue;
            uint64_t at = node.payload_offset + 16;
            for (HierarchyPart& part : node.parts) {
                part.offset = at;
                part.size = std::max<uint32_t>(1, part.primitives * 6);
                at += part.size;
            }
            node.payload_bytes = uint32_t(std::max<uint64_t>(node.payload_bytes, at - node.payload_offset));
            node.fetch_parts = true;
        }
    h.finalize();
    return h;
}

}  // namespace catpaq
