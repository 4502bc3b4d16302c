#pragma once
// AQP's client plug-in (client/format.h): an AQP dataset's (tile, level) nodes as the Hierarchy
// the cut engine refines, nodes decoded into patch grids, and the geometric queries on them.
// Its GPU side is aqp_client/aqp_gpu.h (create_aqp_renderer). docs/formats/aqp.md has the format.
//
// Level deltas: a level l > 0 is stored as its difference from level l - 1 (decoding needs the
// decoded coarser level). The hierarchy says so (HierarchyNode::decode_parent = the tile one
// level down holding the node's patches): the session fetches a level only while the level below is decoded and hands
// it to decode_with_parent, and the cut engine never skips levels here. Why this and not another
// reconstruction: the streaming client refines one level at a time anyway (a patch's level is
// wanted only once the coarser one is drawn), a node's decode then costs one PNG inflate plus an
// add per channel, and the deltas make the nodes 40-48% smaller (docs/formats/aqp.md); fetching
// every level of a patch costs about what its finest level alone costs without deltas, so
// skipping levels would save little. Decoding a level without its parent is a clear error.
#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "aqp/format.h"
#include "client/format.h"

namespace catpaq {

// The AQP hierarchy of a dataset: one node per (tile, level), key tile << 8 | level (format.h);
// node (t, l) has the one parent at level l - 1, the tile holding its patches, which creates its
// one part (id 0) and which it decodes against: tiles form a tree (a chain for a patch that is a
// tile of its own at every level). Errors: the stored bounds (made monotone). Bounds: the union
// of its patches' boxes (origin + step * (patch origin + [0, extent])). Primitives: its patches'
// 2 (n - 1)^2 grid triangles each.
Hierarchy build_aqp_hierarchy(const aqp::AqpMeta& meta, const std::vector<ArchiveEntry>& entries);

// A patch's box at every level, world coordinates (origin + step * (patch origin + [0, extent])).
Aabb aqp_patch_box(const aqp::AqpMeta& meta, uint32_t patch);

// A decoded (tile, level) node: its patches' grids, in patch order. DecodedNode's fields: bytes
// cpu = the grids' samples (position, normal and colour arrays); gpu = what the renderer uploads
// (aqp_gpu_bytes per patch); part_primitives = the grids' triangles; data_bounds = the box of
// its decoded samples.
class AqpNode : public DecodedNode {
public:
    std::vector<aqp::PatchGrid> grids;
};
// The grids of an AqpNode; throws Error for a node another format decoded.
const std::vector<aqp::PatchGrid>& aqp_grids(const DecodedNode& node);

// GPU bytes of a level's textures: positions and normal (RGBA16UI, 8 bytes per sample) and, with
// colours, RGBA8 (4 bytes per sample).
uint64_t aqp_gpu_bytes(int level, bool colors);

// The point on the dataset's quantization grid nearest `eye`, clamped to the grid's box: the frame
// AQP draws in (positions are (grid point - anchor) * step, the integer difference exact).
std::array<int64_t, 3> aqp_frame_anchor(const aqp::AqpMeta& meta, const std::array<double, 3>& eye);

class AqpFormat : public DatasetFormat {
public:
    // Parses the AQP metadata, checks the index and builds the hierarchy; throws Error naming the
    // prefix's source.
    explicit AqpFormat(const DatasetPrefix& prefix);

    const aqp::AqpMeta& meta() const { return meta_; }
    const Hierarchy& hierarchy() const override { return hierarchy_; }
    // Level 0 nodes; a finer level without its parent is an error (decode_with_parent).
    std::string decode(uint32_t node, const uint8_t* data, size_t size,
                       std::shared_ptr<const DecodedNode>& out) const override;
    // A level l > 0 given the decoded tile at level l - 1 holding its patches.
    std::string decode_with_parent(uint32_t node, const DecodedNode& parent, const uint8_t* data, size_t size,
                                   std::shared_ptr<const DecodedNode>& out) const override;
    // A lower bound of the distance to whatever the node draws, stitched or not: its grid's
    // triangles away from the border, and near each edge (where stitching replaces the first
    // row of cells) the box of the samples a stitched triangle there can use.
    std::optional<double> data_distance(uint32_t node, const DecodedNode& decoded,
                                        const std::array<double, 3>& eye) const override;
    // The patches as the renderer draws them: every edge at the coarser of the two drawn levels
    // sharing it (aqp_client/stitch.h), positions (grid point - anchor) * step in float as the
    // vertex shader computes them, relative to aqp_frame_anchor(eye).
    DrawnGeometry drawn_geometry(const std::vector<DecodedPart>& parts, const std::array<double, 3>& eye) const override;
    Aabb world_bounds() const override;
    int up_axis() const override;
    FormatSummary summary() const override;

private:
    // DecodedNode's fields of a decoded tile.
    void account(AqpNode& node) const;
    // data_distance's bound for one patch grid (infinity for a grid without cells).
    double grid_distance(const aqp::PatchGrid& g, const std::array<double, 3>& eye) const;
    // (tile, level) of a hierarchy node.
    std::string node_tile_level(uint32_t node, uint32_t& tile, int& level) const;

    aqp::AqpMeta meta_;
    Hierarchy hierarchy_;
};

}  // namespace catpaq
