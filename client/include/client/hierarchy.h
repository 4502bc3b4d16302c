#pragma once
// The format-agnostic multiresolution DAG the cut engine (client/cut_engine.h) works on.
//
// A node is one unit of streaming and of refinement: a CATP diamond, an AQP patch level or a
// point-cloud kd-tree node; each format builds the hierarchy from its archive index (its adapter:
// DatasetFormat::hierarchy in client/format.h; CATP's is build_catp_hierarchy in
// catp_client/catp_format.h). Every node knows its parents and children (node indices), its
// object-space error (monotone: a parent's error is >= each child's), a world-space box that
// bounds its geometry and its descendants' (so projected errors are monotone too), where its
// bytes are in the archive, and its *parts*: what it draws while unrefined, each part created by
// one parent (CATP: slot s of a diamond is drawn only while slot_parent(s) is refined; the root
// draws all its slots). A node without data (`has_data == false`) is *virtual*: a diamond absent
// from the index, which holds no geometry but is needed in the refined set so that the set stays
// closed under parents.
//
// Invariants after finalize(): levels strictly increase from parent to child, parents and
// children lists are mutually consistent and sorted, errors and boxes are monotone, every part's
// parent is a parent of its node (or kNoNode for a root).
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <unordered_map>
#include <vector>

#include "common_codec/archive.h"

namespace catpaq {

constexpr uint32_t kNoNode = std::numeric_limits<uint32_t>::max();

// Axis-aligned box in world coordinates (double: scans live around 1e6).
struct Aabb {
    std::array<double, 3> min{std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity(),
                              std::numeric_limits<double>::infinity()};
    std::array<double, 3> max{-std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity(),
                              -std::numeric_limits<double>::infinity()};

    bool empty() const { return min[0] > max[0] || min[1] > max[1] || min[2] > max[2]; }
    void extend(const std::array<double, 3>& p);
    void extend(const Aabb& b);
    bool contains(const Aabb& b) const;  // an empty b is contained in anything
    // Distance from p to the closest point of the box (0 inside; +inf for an empty box).
    double distance_to(const std::array<double, 3>& p) const;
};

// What a node draws while it is unrefined, under one condition: `parent` is refined (or, for
// kNoNode, always: the parts of a root). `id` is format-specific (CATP: the slot).
// `primitives` is the count known from the index alone: exact for formats whose index says it,
// an estimate for CATP (the index gives a diamond's total only; the exact per-slot counts are
// known once the node is decoded, see PartDrawCounter in client/cut_engine.h).
// When the format can fetch a part alone (HierarchyNode::fetch_parts), `offset` and `size` are
// its own byte range in the dataset file (CATP: the slot's fragment, from the slot table): a
// refinement then fetches only the parts it creates, not the whole node (what other parents
// create is drawn only once they are refined).
struct HierarchyPart {
    uint32_t parent = kNoNode;
    uint8_t id = 0;
    uint32_t primitives = 0;
    uint64_t offset = 0;
    uint32_t size = 0;
};
// Parts can be fetched alone only up to this many per node (residency keeps a bit per part).
constexpr size_t kMaxFetchedParts = 32;

struct HierarchyNode {
    uint32_t index = 0;
    uint64_t key = 0;       // format node id (CATP: DiamondId bits)
    uint16_t level = 0;     // 0 = coarsest; a child's level is greater than each parent's
    std::vector<uint32_t> parents, children;  // sorted node indices
    double error = 0;       // object-space error bound, world units (monotone)
    Aabb bounds;            // world box of the node's geometry and of all its descendants
    // The boxes the cut engine projects the node's error with and culls it by: where the node's
    // own geometry may be, tighter than `bounds` (which also holds the descendants' reaching out
    // of it through their other parents). Nested along parent edges: each box of a child lies in
    // a box of one of its parents, so a child that needs refinement has a parent that needs it
    // more. Used when the hierarchy has view boxes (Hierarchy::has_view_boxes), else `bounds`.
    std::vector<Aabb> view_boxes;
    bool has_data = false;  // false: virtual node (no bytes, draws nothing)
    bool leaf = false;      // never refined (no children, or the format says so)
    // Where the bytes are (valid when has_data).
    uint32_t entry = kNoNode;  // index in the archive's entry list
    uint64_t payload_offset = 0;
    uint32_t payload_bytes = 0;
    uint64_t checksum = 0;
    uint16_t flags = 0;      // the archive entry's flags (CATP: slot mask | leaf bit)
    uint32_t primitives = 0;  // total triangles / points of the node
    std::vector<HierarchyPart> parts;
    // True when every part has its own byte range (inside the node's payload) and is fetched
    // and decoded alone; false: the node is fetched whole.
    bool fetch_parts = false;
    // The parent whose decoded data this node's decoding needs (a format storing a node as a
    // difference from its parent: AQP's level deltas), or kNoNode: decoded alone. Such a node is
    // fetched only while that parent is decoded (the session hands it to the decoder,
    // DatasetFormat::decode_with_parent), and the cut engine never skips levels in a hierarchy
    // that has one (ViewParams::skip_factor), so a child is always wanted while its parent is
    // drawn, hence decoded. Must be one of `parents` and have data; not with fetch_parts.
    uint32_t decode_parent = kNoNode;
};

class Hierarchy {
public:
    // Appends a node (parents given as keys or indices later through add_parent). Returns its index.
    uint32_t add_node(uint64_t key, uint16_t level, double error, const Aabb& bounds, bool has_data);
    void add_parent(uint32_t node, uint32_t parent);
    HierarchyNode& mutable_node(uint32_t i) { return nodes_[i]; }

    // Derives children from parents, sorts the lists, makes errors and boxes monotone (bottom-up:
    // a parent's error becomes at least the max of its children's, its box grows to hold
    // theirs), marks nodes without children as leaves and checks the invariants above.
    // Throws Error naming the problem (a cycle, a level that does not increase, a part whose
    // parent is not a parent, duplicate keys).
    void finalize();

    size_t size() const { return nodes_.size(); }
    const HierarchyNode& node(uint32_t i) const { return nodes_[i]; }
    const std::vector<HierarchyNode>& nodes() const { return nodes_; }
    // Node with `key`, or kNoNode.
    uint32_t find(uint64_t key) const;
    const std::vector<uint32_t>& roots() const { return roots_; }
    // True when the nodes' view boxes are given (a node without any is never seen for its own
    // sake); false: the engine projects with `bounds`.
    bool has_view_boxes() const { return has_view_boxes_; }
    void set_has_view_boxes(bool given) { has_view_boxes_ = given; }
    // True when some node decodes against its parent (HierarchyNode::decode_parent; set by
    // finalize): the cut engine then fetches every level.
    bool decodes_against_parents() const { return decodes_against_parents_; }
    size_t virtual_count() const;
    size_t data_count() const { return nodes_.size() - virtual_count(); }
    // Empty string if the invariants hold, else the first problem (used by finalize and tests).
    std::string check() const;

private:
    std::vector<HierarchyNode> nodes_;
    std::unordered_map<uint64_t, uint32_t> by_key_;
    std::vector<uint32_t> roots_;
    bool has_view_boxes_ = false;
    bool decodes_against_parents_ = false;
};

// A random DAG for tests and benchmarks: a quadtree of cells over [0, size]^2 (thin in z), where
// each child cell also gets, with probability `extra_parent`, the parent-level cells next to it
// (on the side it lies on) as parents, so nodes have 1 to 4 parents. Cells are kept with
// probability `keep` (at least one child per refined cell), interior non-root nodes are virtual
// with probability `virtual_fraction`. Errors shrink with the cell size; primitives: leaves 50 to
// 150, interior nodes about as many as one child (1.5 / children of what their children draw for
// them, at most all of it); one part per data parent (a node's primitives split among them), so
// refining never lowers the primitives drawn. With fetch_parts, each part has its own byte range.
struct SyntheticHierarchySettings {
    int levels = 7;  // level 0 is the root cell
    double keep = 1.0;
    double extra_parent = 0.3;
    double virtual_fraction = 0.0;
    double size = 1000.0;
    uint64_t seed = 1;
    bool fetch_parts = false;  // every part with its own byte range (HierarchyNode::fetch_parts)
};
Hierarchy build_synthetic_hierarchy(const SyntheticHierarchySettings& settings);

}  // namespace catpaq
