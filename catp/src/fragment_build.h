#pragma once
// Fragments under construction in the converter (private to the catp module): lattice-space
// double positions, welding by exact position, quantization to the 64-bit vertex, and the
// coarsening step of one diamond (gather -> simplify with locked outer faces -> clip).
#include <array>
#include <cstdint>
#include <unordered_map>
#include <vector>

#include "catp/lattice.h"
#include "catp/distance.h"
#include "clip.h"
#include "common_codec/barycentric.h"
#include "common_codec/fragment_codec.h"
#include "mesh/mesh.h"

namespace catpaq {

struct WorkFragment {
    std::vector<Vec3d> positions;  // lattice units, on the 2^-32 snapping grid
    std::vector<Vec3f> normals;    // unit
    std::vector<Rgb8> colors;
    std::vector<uint32_t> indices;
};

struct PositionHash {
    size_t operator()(const Vec3d& p) const;
};

// Which fragment vertex each source vertex became, for source vertices numbered globally (the
// converter's input vertices: far too many for an array per fragment, as clip_into_slots keeps
// for a diamond's gathered vertices). Open addressing on the source index.
class SourceVertexMap {
public:
    SourceVertexMap() { clear(0); }
    // Empties the map, sized for about `vertices` entries (it grows as needed).
    void clear(size_t vertices);
    // The entry of source vertex `source`: FragmentWelder::kNotWelded when it is new. Valid
    // until the next call (an insert may move the table).
    uint32_t& operator[](uint32_t source);

private:
    struct Slot {
        uint32_t key;    // source index + 1, 0 = empty
        uint32_t value;  // fragment vertex
    };
    void rehash(size_t capacity);  // a power of two

    std::vector<Slot> table_;
    size_t size_ = 0, mask_ = 0;
};

// Adds vertices to a fragment, merging those at exactly the same position (the clipper makes
// shared vertices bit-identical, so exact welding is the right test).
class FragmentWelder {
public:
    explicit FragmentWelder(WorkFragment& fragment);
    // Makes room for about this many more vertices and triangles (growing the arrays and the
    // table step by step copies them and touches fresh memory each time).
    void reserve(size_t vertices, size_t triangles);
    // normal: not necessarily unit; color: 0..255 floats.
    uint32_t add(const Vec3d& position, const float normal[3], const float color[3]);
    uint32_t add(const Vec3d& position, const Vec3f& normal, const Rgb8& color);
    // Adds a triangle unless two corners coincide.
    void triangle(uint32_t a, uint32_t b, uint32_t c);
    // Appends a whole fragment (welding its vertices).
    void append(const WorkFragment& other);
    // Adds a whole triangle (what add_clipped does with no planes, without the clipper).
    void add_whole(const std::array<Vec3d, 3>& tri, const std::array<Vec3f, 3>& normals,
                   const std::array<Rgb8, 3>& colors);
    // Clips triangle `tri` by `planes` and adds the pieces (triangulated without slivers). New
    // vertices interpolate the corners' normals and colours; the corners keep theirs exactly.
    void add_clipped(const std::array<Vec3d, 3>& tri, const std::array<Vec3f, 3>& normals,
                     const std::array<Rgb8, 3>& colors, const std::vector<ClipPlane>& planes);

    // The same for triangles of a source mesh with numbered vertices: `source` holds the corners'
    // vertex indices and `welded` (one entry per source vertex, kNotWelded at first, kept
    // between calls) the fragment vertex each corner became. A source vertex is then welded by
    // position once, not once per triangle using it. `welded` only caches what the position
    // lookup answers, so the fragment is the same as without it.
    static constexpr uint32_t kNotWelded = ~0u;
    void add_whole(const uint32_t source[3], uint32_t* welded, const std::array<Vec3d, 3>& tri,
                   const std::array<Vec3f, 3>& normals, const std::array<Rgb8, 3>& colors);
    void add_clipped(const uint32_t source[3], uint32_t* welded, const std::array<Vec3d, 3>& tri,
                     const std::array<Vec3f, 3>& normals, const std::array<Rgb8, 3>& colors,
                     const std::vector<ClipPlane>& planes);
    // The same with the cache as a SourceVertexMap, for globally numbered source vertices.
    void add_whole(const uint32_t source[3], SourceVertexMap& welded, const std::array<Vec3d, 3>& tri,
                   const std::array<Vec3f, 3>& normals, const std::array<Rgb8, 3>& colors);
    void add_clipped(const uint32_t source[3], SourceVertexMap& welded, const std::array<Vec3d, 3>& tri,
                     const std::array<Vec3f, 3>& normals, const std::array<Rgb8, 3>& colors,
                     const std::vector<ClipPlane>& planes);

private:
    // Open addressing on vertex indices (a std::unordered_map allocated per insert and was a
    // measured hot spot of the converter).
    uint32_t find_or_insert(const Vec3d& position, bool& inserted);
    void grow();
    void rehash(size_t capacity);  // a power of two
    // A source triangle's corner at `position` with its normal and colour: through its cache
    // entry `cached` if given (null: by position only).
    uint32_t add_corner(uint32_t* cached, const Vec3d& position, const Vec3f& normal, const Rgb8& color);
    // add_whole and add_clipped for any cache: cached(k) gives corner k's cache entry or null.
    template <class Cache>
    void whole(const Cache& cached, const std::array<Vec3d, 3>& tri, const std::array<Vec3f, 3>& normals,
               const std::array<Rgb8, 3>& colors);
    template <class Cache>
    void clipped(const Cache& cached, const std::array<Vec3d, 3>& tri, const std::array<Vec3f, 3>& normals,
                 const std::array<Rgb8, 3>& colors, const std::vector<ClipPlane>& planes);

    WorkFragment& f_;
    std::vector<ClipVertex> polygon_;  // scratch for add_clipped
    std::vector<std::array<int, 3>> pieces_;
    std::vector<uint32_t> remap_;  // scratch for append
    std::vector<uint32_t> table_;  // vertex index + 1, 0 = empty
    size_t mask_ = 0;
};

// Half-spaces of the faces of tetrahedron t selected by face_mask (bit f: the face opposite
// corner f), each keeping the side of the opposite corner.
std::vector<ClipPlane> tetrahedron_clip_planes(const Tetrahedron& t, unsigned face_mask);

// Where quantize_fragment put what: for error bookkeeping only (the output is the same with or
// without it).
struct QuantizeTrace {
    std::vector<uint32_t> vertex_of;        // the output vertex of each input vertex
    std::vector<uint32_t> triangle_source;  // the input triangle of each output triangle
    std::vector<uint32_t> flat;             // output triangles whose corners are collinear (no area)
    std::vector<BaryWeights> weights;       // of each input vertex, quantized
};

// Quantizes a fragment in the tetrahedron with canonical corners `corners` (face rule by exact
// predicates) into 64-bit vertices. Triangles that collapse (two corners with the same position)
// are dropped. `trace`, if given, records where input vertices and triangles went.
void quantize_fragment(const WorkFragment& in, const Tetrahedron& corners, const VertexLayout& layout, FragmentMesh& out,
                       QuantizeTrace* trace = nullptr);

// One slot of a node as quantized, for quantization_loss.
struct QuantizedSlot {
    const WorkFragment* in = nullptr;   // unquantized, lattice units
    const FragmentMesh* out = nullptr;  // what quantize_fragment made of it
    Tetrahedron corners{};              // the canonical corners it was quantized in
    QuantizeTrace trace;
};

// What quantization loses from a node: the input triangles that collapse, or keep no area once
// their corners are quantized (three collinear points), are drawn nowhere. Thin geometry (a
// needle, a sliver thinner than the grid step) can vanish whole this way.
struct QuantizationLoss {
    size_t triangles = 0;  // input triangles lost
    double area = 0;       // their area (lattice units squared)
    // Bound (lattice units) of the distance from the lost triangles to the node's drawn
    // triangles: measured at points along their edges no farther apart than `spacing` (plus
    // what may lie between them); `settled` when it is at most that (the caller's bound, the
    // grid step, covers it). When nothing
    // of the node is drawn, nothing local bounds it: `nothing_drawn` is set and error is 0.
    double error = 0;
    bool nothing_drawn = false;
};
// Where the geometry of a node that draws nothing (all of it thinner than the grid step) can be
// found from: when every connected piece of it (joined across the node's slots by position)
// reaches an outer face of the diamond, the surface it belongs to goes on into a neighbour, so
// every point of it is within `diameter` (of its bounding box, lattice units) of surface that
// the neighbours draw, to within their own bounds. `anchored` is false when a piece lies inside
// alone: then nothing near bounds it.
struct LostGeometryReach {
    bool anchored = false;
    double diameter = 0;
};
LostGeometryReach lost_geometry_reach(const DiamondInfo& d, const std::array<const WorkFragment*, 8>& slots);

// excuse_length: pieces up to this long (lattice units) that lie along a face of their
// tetrahedron count as covered by the neighbour across it (see the definition). measure_area:
// fill `area` (else 0).
QuantizationLoss quantization_loss(const std::vector<QuantizedSlot>& slots, double spacing, double settled,
                                   double excuse_length, bool measure_area);

// point_triangle_distance2: catp/distance.h.

// Distance between the gathered surface of a diamond and its simplification (triangles indexing
// gathered.positions), both ways: the removed vertices to the simplified surface, and the
// midpoints of the simplified edges to the gathered surface (lattice units). sources: null, or
// the simplification's SimplifyResult::sources, which lets it skip the edges left unchanged (the
// result is the same, up to the rounding of distances that are 0).
double measured_simplification_error(const WorkFragment& gathered, const std::vector<uint32_t>& simplified,
                                     const std::vector<uint32_t>* sources = nullptr);

// Clips the simplified triangles (indexing gathered's vertices) by the diamond's interior faces
// into its slots' fragments (appended to out[slot]): the last part of coarsen_diamond.
void clip_into_slots(const DiamondInfo& d, const WorkFragment& gathered, const std::vector<uint32_t>& simplified,
                     std::array<WorkFragment, 8>& out);

// One coarsening step: `gathered` holds the welded fragments of the diamond's child tetrahedra.
// Simplifies to about half with every vertex on the diamond's outer faces locked, then clips by
// the interior faces into one fragment per slot. Returns the simplification error (lattice units).
double coarsen_diamond(const DiamondInfo& diamond, const WorkFragment& gathered, std::array<WorkFragment, 8>& out);

}  // namespace catpaq
