// CATP's hierarchy adapter: the diamonds of a dataset's index as a Hierarchy (client/hierarchy.h).
#include <algorithm>

#include "base/error.h"
#include "catp/dataset.h"
#include "catp/lattice.h"
#include "catp_client/catp_format.h"

namespace catpaq {

namespace {

Aabb tetrahedron_bounds(const CatpIndex& index, const Tetrahedron& t) {
    Aabb box;
    for (const LatticePoint& p : t) {
        double lattice[3] = {double(p[0]), double(p[1]), double(p[2])};
        double world[3];
        index.lattice_to_world(lattice, world);
        box.extend(std::array<double, 3>{world[0], world[1], world[2]});
    }
    return box;
}

Aabb tetrahedra_bounds(const CatpIndex& index, const DiamondInfo& info) {
    Aabb box;
    uint8_t mask = existing_slots(info);
    for (int s = 0; s < info.ring_size; ++s)
        if (mask & (1 << s)) box.extend(tetrahedron_bounds(index, diamond_tetrahedron(info, s)));
    return box;
}

// The view boxes of every node (see build_catp_hierarchy): bottom-up, a slot is kept when it has
// geometry or one of the two tetrahedra it splits into is kept in its child diamond.
void set_view_boxes(const CatpIndex& index, Hierarchy& h) {
    std::vector<uint32_t> order(h.size());
    for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return h.node(a).level > h.node(b).level; });
    std::vector<uint8_t> kept(h.size(), 0);
    for (uint32_t n : order) {
        HierarchyNode& node = h.mutable_node(n);
        DiamondInfo info = diamond_info(DiamondId{node.key});
        uint8_t mask = node.has_data ? uint8_t(node.flags & 0xff) : 0;
        const uint8_t existing = existing_slots(info);
        for (int s = 0; s < info.ring_size; ++s) {
            if (!(existing & (1 << s)) || (mask & (1 << s))) continue;
            for (const Tetrahedron& half : split_tetrahedron(info, s)) {
                DiamondId child;
                int slot;
                if (!tetrahedron_diamond(half, child, slot)) continue;
                const uint32_t c = h.find(child.bits);
                if (c != kNoNode && (kept[c] & (1 << slot))) mask |= uint8_t(1 << s);
            }
        }
        kept[n] = mask;
        for (int s = 0; s < info.ring_size; ++s)
            if (mask & (1 << s)) {
                node.view_boxes.push_back(tetrahedron_bounds(index, diamond_tetrahedron(info, s)));
                node.bounds.extend(node.view_boxes.back());  // a virtual node's bounds start empty
            }
    }
}

}  // namespace

Hierarchy build_catp_hierarchy(const CatpIndex& index) {
    Hierarchy h;
    const std::vector<ArchiveEntry>& entries = index.entries();
    for (size_t e = 0; e < entries.size(); ++e) {
        const ArchiveEntry& entry = entries[e];
        DiamondId id{entry.key};
        if (!is_valid_diamond_centre(id.centre()))
            fail("index entry %llu is not a diamond", (unsigned long long)entry.key);
        if (diamond_level(id) != int(entry.level))
            fail("index entry %llu has level %d, its diamond is at level %d", (unsigned long long)entry.key,
                 int(entry.level), diamond_level(id));
        DiamondInfo info = diamond_info(id);
        uint32_t n = h.add_node(entry.key, entry.level, std::max(0.0, double(entry.error)), tetrahedra_bounds(index, info), true);
        HierarchyNode& node = h.mutable_node(n);
        node.entry = uint32_t(e);
        node.payload_offset = entry.offset;
        node.payload_bytes = entry.size;
        node.checksum = entry.checksum;
        node.flags = entry.flags;
        node.primitives = entry.count;
        node.leaf = (entry.flags & kCatpLeafFlag) != 0;
    }
    // Missing parents, recursively, as virtual nodes.
    std::vector<uint32_t> work(h.size());
    for (uint32_t i = 0; i < work.size(); ++i) work[i] = i;
    while (!work.empty()) {
        uint32_t n = work.back();
        work.pop_back();
        DiamondId id{h.node(n).key};
        for (DiamondId p : diamond_parents(id)) {
            uint32_t pi = h.find(p.bits);
            if (pi == kNoNode) {
                pi = h.add_node(p.bits, uint16_t(diamond_level(p)), 0.0, Aabb{}, false);
                work.push_back(pi);
            }
            h.add_parent(n, pi);
        }
    }
    // Parts: one per slot with geometry.
    DiamondId root = root_diamond();
    for (uint32_t n = 0; n < h.size(); ++n) {
        HierarchyNode& node = h.mutable_node(n);
        if (!node.has_data) continue;
        uint8_t mask = uint8_t(node.flags & 0xff);
        int slots = __builtin_popcount(mask);
        if (!slots) continue;
        uint32_t estimate = uint32_t((uint64_t(node.primitives) + uint64_t(slots) - 1) / uint64_t(slots));
        DiamondId id{node.key};
        DiamondInfo info = diamond_info(id);
        uint8_t existing = existing_slots(info);
        for (int s = 0; s < 8; ++s) {
            if (!(mask & (1 << s))) continue;
            if (s >= info.ring_size || !(existing & (1 << s)))
                fail("diamond %llu has geometry in slot %d, which does not exist", (unsigned long long)node.key, s);
            HierarchyPart part;
            part.id = uint8_t(s);
            part.primitives = estimate;
            if (id == root) {
                part.parent = kNoNode;
            } else {
                part.parent = h.find(slot_parent(info, s).bits);
                if (part.parent == kNoNode)
                    fail("diamond %llu: the parent of slot %d is not a parent", (unsigned long long)node.key, s);
            }
            if (index.slot_range(node.entry, s, part.offset, part.size) && part.size == 0)
                fail("diamond %llu: slot %d has an empty byte range", (unsigned long long)node.key, s);
            node.parts.push_back(part);
        }
        node.fetch_parts = index.has_slot_ranges();
    }
    set_view_boxes(index, h);
    h.set_has_view_boxes(true);
    h.finalize();
    // The leaf flag of an entry stays (finalize only adds leaves); a flagged leaf with children
    // would be inconsistent data, but refining it is never needed.
    return h;
}

}  // namespace catpaq
