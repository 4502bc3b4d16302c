#pragma once
// The seam between the format-agnostic client and a dataset format (CATP, AQP and points:
// client/catp, client/aqp, client/points).
//
// The generic side (fetcher, caches, cut engine, streaming session, viewer, the render, view and
// info commands) knows nodes, keys, byte ranges, bounds, errors and dependencies: the Hierarchy.
// A node's decoded data is an opaque DecodedNode to it, carrying only what the generic side
// counts (bytes, exact primitives per part, the box of its data). A format supplies the rest,
// created from the dataset's prefix:
//   DatasetFormat  the hierarchy (its adapter from the archive index), the decoder, geometric
//                  queries on decoded nodes (distance for close views; the drawn geometry for
//                  picking and export), the world bounds and up axis, what `info` says;
//   NodeRenderer   (client/node_renderer.h) its GPU store and renderer.
// A FormatModule pairs the two factories for one archive kind; a FormatRegistry holds the
// modules a program can stream (client/builtin_formats.h: the ones this build has). Adding a
// format adds a module and registers it: the engine, the fetcher and the server stay as they
// are. docs/ARCHITECTURE.md shows the seam.
#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "client/cut_engine.h"
#include "client/hierarchy.h"
#include "common_codec/archive.h"
#include "mesh/mesh.h"

namespace catpaq {

class NodeRenderer;  // client/node_renderer.h (client_gl)

// The first bytes of a dataset, parsed and validated: what every format is created from.
struct DatasetPrefix {
    std::string source;                 // where it was read from (for messages)
    ArchiveHeader header;
    std::vector<uint8_t> meta;          // the format's metadata, checksum-verified
    std::vector<ArchiveEntry> entries;  // the node index, sorted by (level, key)

    // Parses at least header, meta and index (the bytes may go on); throws Error naming `source`.
    static DatasetPrefix parse(const uint8_t* data, size_t size, const std::string& source);
};

// A node's data as its format decoded it. The format's subclass holds the data; the generic
// side reads only these fields. Immutable once made: the fetcher's workers create it, the
// session and the caches share it. The fields are filled by the decoder rather than asked of
// the format later, so that their work (CATP: a pass over every vertex for the data box) runs on
// the workers, not on the render thread.
class DecodedNode {
public:
    virtual ~DecodedNode() = default;

    // What the node costs while it is in the cut (Residency::bytes): cpu, its decoded data;
    // gpu, its parts uploaded.
    NodeBytes bytes;
    // Exact primitives of each part, in HierarchyNode::parts order (PartDrawCounter::set_counts).
    std::vector<uint32_t> part_primitives;
    // The box of the node's own data, world coordinates (Residency::data_bounds); empty when
    // unknown. Must lie within the node's hierarchy box.
    Aabb data_bounds;
};

// One drawn part of a resident node, for DatasetFormat::drawn_geometry.
struct DecodedPart {
    uint32_t node = kNoNode;  // hierarchy index
    const DecodedNode* decoded = nullptr;
    uint8_t part = 0;  // HierarchyPart::id
};

// Geometry as the renderer draws it, in a frame near the eye so that large world coordinates
// keep their precision: world = origin + position. Triangles in `mesh.indices`; a vertex the
// format cannot decode is left out with its triangles.
struct DrawnGeometry {
    std::array<double, 3> origin{0, 0, 0};
    Mesh mesh;  // positions relative to origin; normals and colours when the format has them
};

// What `catpaq info` says of a dataset beyond its container (header and index).
struct FormatSummary {
    std::string node_noun = "nodes";            // what a node is ("diamonds")
    std::string primitive_noun = "primitives";  // what a node's count counts ("triangles")
    std::string levels_note;                    // after the level count ("leaf level 12")
    // Labelled lines in order ("input", "bounds", ...), each one line of text.
    std::vector<std::pair<std::string, std::string>> lines;
};

class DatasetFormat {
public:
    virtual ~DatasetFormat() = default;

    virtual const Hierarchy& hierarchy() const = 0;
    // Decodes a node's verified bytes (`node`: a hierarchy index with data). Called from the
    // fetcher's worker threads, concurrently. Returns an empty string and sets `out`, or what is
    // wrong with the bytes (it may also throw Error).
    virtual std::string decode(uint32_t node, const uint8_t* data, size_t size,
                               std::shared_ptr<const DecodedNode>& out) const = 0;
    // Decodes one part's bytes (HierarchyPart::offset, size) of a node fetched by parts
    // (HierarchyNode::fetch_parts; `part`: index in HierarchyNode::parts) into a DecodedNode that
    // holds only that part: its bytes and data box are the part's, part_primitives has the
    // part's count at `part`. Formats whose hierarchy fetches no parts need not override it.
    virtual std::string decode_part(uint32_t node, size_t part, const uint8_t* data, size_t size,
                                    std::shared_ptr<const DecodedNode>& out) const {
        (void)node, (void)part, (void)data, (void)size, (void)out;
        return "this format fetches whole nodes only";
    }
    // Decodes the bytes of a node that decodes against its parent (HierarchyNode::decode_parent)
    // given that parent's decoded data (`parent`, what this format's decoder made of it). Called
    // like decode(). Formats without such nodes need not override it.
    virtual std::string decode_with_parent(uint32_t node, const DecodedNode& parent, const uint8_t* data, size_t size,
                                           std::shared_ptr<const DecodedNode>& out) const {
        (void)node, (void)parent, (void)data, (void)size, (void)out;
        return "this format decodes every node alone";
    }
    // A lower bound of the distance from `eye` to the node's own geometry (world units), or
    // nothing when it has none to measure (Residency::data_distance). Asked for close views only.
    virtual std::optional<double> data_distance(uint32_t node, const DecodedNode& decoded,
                                                const std::array<double, 3>& eye) const = 0;
    // The geometry of these parts as drawn, in a frame the format picks near `eye` (picking in
    // the viewer, render --export-cut).
    virtual DrawnGeometry drawn_geometry(const std::vector<DecodedPart>& parts, const std::array<double, 3>& eye) const = 0;

    // The dataset's world bounds (what cameras frame and clip planes fit).
    virtual Aabb world_bounds() const = 0;
    // The up axis the dataset records: 1 (y) or 2 (z); 0 when it records none (viewers take z).
    virtual int up_axis() const = 0;
    virtual FormatSummary summary() const = 0;
};

// One format's factories. The GPU side is a factory of its own, not a method of DatasetFormat, so
// that what needs only the CPU side (the fetcher and engine tests, `info`, the benches) links
// no GL.
struct FormatModule {
    ArchiveKind kind = ArchiveKind::Catp;
    // Creates the format from a dataset's prefix; throws Error for metadata or an index it
    // cannot use.
    std::function<std::unique_ptr<DatasetFormat>(const DatasetPrefix&)> open;
    // Creates its GPU store and renderer for an opened dataset (a GL context must be current).
    std::function<std::unique_ptr<NodeRenderer>(const DatasetFormat&)> create_renderer;
};

// The formats a program streams, by archive kind.
class FormatRegistry {
public:
    // Adds a module (replacing one of the same kind).
    void add(FormatModule module);
    // The module for `kind`, or nullptr.
    const FormatModule* find(ArchiveKind kind) const;
    // The module for the prefix's kind; throws Error naming the source when there is none.
    const FormatModule& module_for(const DatasetPrefix& prefix) const;

private:
    std::vector<FormatModule> modules_;
};

}  // namespace catpaq
