#pragma once
// CATP's client plug-in (client/format.h): a dataset's diamonds as the Hierarchy the cut engine
// refines, nodes decoded into their slots' fragments (the 64-bit vertices stay packed: the
// vertex shader decodes them), and the geometric queries on decoded diamonds. Its GPU side is
// catp_client/catp_gpu.h (create_catp_renderer).
#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "catp/dataset.h"
#include "client/format.h"

namespace catpaq {

// The CATP hierarchy of a dataset: every index entry is a node (has_data); every missing parent
// (diamond_parents) of a node is added, recursively up to the root, as a virtual node. Bounds:
// the box of the diamond's existing tetrahedra in world units (origin + lattice * cell), grown
// to hold its children's; virtual nodes: the union of their children's boxes. View boxes: one
// per tetrahedron of the diamond that holds geometry, its own or in a descendant tetrahedron
// inside it (bisection nests a child's tetrahedron in the tetrahedron of its creating parent,
// so these boxes nest along creating edges). Parts: one per slot
// with geometry (the entry's slot mask), created by slot_parent(slot) (kNoNode for the root).
// Part primitive counts are estimates (the diamond's count split evenly over its slots) until the
// node is decoded.
Hierarchy build_catp_hierarchy(const CatpIndex& index);

// A decoded diamond. DecodedNode's fields: bytes cpu = its fragments' vertices (8 bytes) and
// indices (4 bytes) over its parts; gpu = what FragmentStore::upload allocates for the parts with
// triangles (16-bit indices below 65536 vertices); part_primitives = each slot's triangles;
// data_bounds = the box of its decoded vertices.
class CatpNode : public DecodedNode {
public:
    DiamondFragments fragments;
};
// The fragments of a CatpNode; throws Error for a node another format decoded.
const DiamondFragments& catp_fragments(const DecodedNode& node);

// The lattice point nearest `eye`, clamped to the lattice cube: the frame CATP draws and decodes
// in (frame_transform, drawn_geometry), so that anchor-relative positions stay small near the eye.
LatticePoint catp_frame_anchor(const CatpMeta& meta, const std::array<double, 3>& eye);

class CatpFormat : public DatasetFormat {
public:
    // Parses the CATP metadata and builds the hierarchy; throws Error naming the prefix's source.
    explicit CatpFormat(const DatasetPrefix& prefix);

    const CatpIndex& index() const { return index_; }
    const CatpMeta& meta() const { return index_.meta(); }

    const Hierarchy& hierarchy() const override { return hierarchy_; }
    // decode_diamond_node with the dataset's vertex layout, into a CatpNode.
    std::string decode(uint32_t node, const uint8_t* data, size_t size,
                       std::shared_ptr<const DecodedNode>& out) const override;
    // One slot's fragment (its range from the slot table), into a CatpNode holding that slot.
    std::string decode_part(uint32_t node, size_t part, const uint8_t* data, size_t size,
                            std::shared_ptr<const DecodedNode>& out) const override;
    // The distance to the triangles of all its parts (a superset of what it draws), from the
    // exact integer positions, a hair less than measured (decoding rounds).
    std::optional<double> data_distance(uint32_t node, const DecodedNode& decoded,
                                        const std::array<double, 3>& eye) const override;
    // Vertices decoded as the vertex shader does (decode_packed_vertex), relative to the lattice
    // point nearest the eye (catp_frame_anchor).
    DrawnGeometry drawn_geometry(const std::vector<DecodedPart>& parts, const std::array<double, 3>& eye) const override;
    Aabb world_bounds() const override;
    int up_axis() const override;
    FormatSummary summary() const override;

private:
    Aabb data_bounds(const HierarchyNode& node, const DiamondFragments& fragments) const;
    // DecodedNode's fields from the fragments of `node`'s parts that hold geometry.
    void account(const HierarchyNode& node, CatpNode& decoded) const;

    CatpIndex index_;
    Hierarchy hierarchy_;
};

}  // namespace catpaq
