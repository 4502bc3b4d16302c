#pragma once
// The point format's client plug-in (client/format.h): a point dataset's binary kd-tree as the
// Hierarchy the cut engine refines, nodes decoded (the Rice node codec, points/codec.h) and packed
// for the GPU (points_client/splat_layout.h), and the geometric queries on decoded nodes. Its GPU
// side is points_client/points_gpu.h (create_points_renderer).
//
// An inner node holds a simplified half of its children's splats and stands for them: a node is
// drawn while its parent is refined and it is not (one part per node, created by its parent), so
// the drawn nodes replace each other, they never add up.
#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "client/format.h"
#include "points/format.h"
#include "points_client/splat_layout.h"

namespace catpaq {

// The hierarchy of a point dataset, from its metadata and index (checked as PointDataset checks
// a file: one record per entry with the same key, levels equal to the ids' depths, a parent for
// every node but the root, both children for every inner node; throws Error naming `source`).
// Every node has data and one part (id 0) created by its parent (kNoNode for the root).
// Error: the larger of the index's error bound (how far an input point is from its splat) and
// the node's mean splat radius (how far apart the drawn samples are: what a coarse node shows
// as blobs, seed 002's projected sample size); finalize() makes it monotone. Bounds: the node's
// box (splat balls of the node and its descendants) in world units, rounded outwards.
Hierarchy build_points_hierarchy(const PointsMeta& meta, const std::vector<ArchiveEntry>& entries,
                                 const std::string& source);

// A decoded node: only its packed splats (8 or 6 bytes a point, what the renderer uploads; the
// decoded arrays, 21 more bytes a point, are dropped after packing). DecodedNode's fields: bytes
// cpu = gpu = PackedSplats::stride per point; part_primitives = {points}; data_bounds = the box
// of the decoded splat balls (centre +- radius), within the node's box.
class PointsNode : public DecodedNode {
public:
    PackedSplats splats;   // as uploaded
};
// The data of a PointsNode; throws Error for a node another format decoded.
const PointsNode& points_node(const DecodedNode& node);

class PointsFormat : public DatasetFormat {
public:
    // Parses the point metadata and builds the hierarchy; throws Error naming the prefix's source.
    explicit PointsFormat(const DatasetPrefix& prefix);

    const PointsMeta& meta() const { return meta_; }

    const Hierarchy& hierarchy() const override { return hierarchy_; }
    // decode_point_node into a PointsNode (also checking the count against the index), packed.
    std::string decode(uint32_t node, const uint8_t* data, size_t size,
                       std::shared_ptr<const DecodedNode>& out) const override;
    // The distance to the nearest packed splat ball (centre distance minus radius, the splats as
    // drawn: each covers its decoded splat), a hair less.
    std::optional<double> data_distance(uint32_t node, const DecodedNode& decoded,
                                        const std::array<double, 3>& eye) const override;
    // The drawn splat centres as vertices without triangles (normals, colours when present),
    // relative to the eye: the packed splats, as the shader decodes them.
    DrawnGeometry drawn_geometry(const std::vector<DecodedPart>& parts, const std::array<double, 3>& eye) const override;
    Aabb world_bounds() const override;
    int up_axis() const override;
    FormatSummary summary() const override;

private:
    std::string source_;
    PointsMeta meta_;
    Hierarchy hierarchy_;
};

}  // namespace catpaq
