#pragma once
// The AQP dataset: an archive (common_codec/archive.h) of kind Aqp whose nodes are tiles: the
// same level of a run of consecutive patches. Byte tables: docs/formats/aqp.md. All integers
// little-endian.
//
// Meta:
//   char[8] "AQPMETA\0" | u32 version (4) | u32 finest level k | u32 patch count
//   u32 base vertices | u32 base triangles | u32 border edges | u32 flags (bit 0: colours)
//   f64 origin[3] | f64 step        world = origin + step * (patch origin + local), per axis
//   f64 bounds_min[3] | f64 bounds_max[3]   (world, of the samples)
//   u64 input vertices | u64 input triangles | f64 precision | f64 mean edge | u32 atlas columns
//   u32 up axis (version 2; version 1 has no field and reads as 0): 0 unknown, 1-6 = +x +y +z
//       -x -y -z, the numbering of catp/format.h's UpAxis (which the point format uses too)
//   u8 tile shift[k + 1] (version 4; older versions have none and read as 0): level l's tile t
//       holds patches t * 4^s .. (t + 1) * 4^s - 1 (s = shift[l], the last tile fewer),
//       shifts non-increasing with the level, so a tile lies in one tile of each coarser level
//   the patches (version 5): one zlib stream of varints, column by column: corner c of every
//       patch in turn (c = 0..3, quad vertex ids), then origin axis a (quantization grid), both
//       as zigzag differences from the previous patch's, then extent axis a (largest local
//       coordinate). No links: patch edge e runs from corner e to corner (e + 1) % 4, and the
//       two patch edges between the same quad vertices are linked (derive_patch_links).
//   (versions 1-4: per patch u32 corner[4] | 4 x (u32 neighbour patch or 0xFFFFFFFF, u8 its
//       edge, u8 reversed) | u32 origin[3] | u16 extent[3], 58 bytes)
//
// Node (key = tile << 8 | level, level = level, count = samples of its patches' grids, error =
// bound in world units, the largest of its patches'): the bytes of one PNG file (nothing else:
// the index names the node, the archive checksums it). Patches are numbered along a Morton curve
// over their boxes (by the converter), so a tile's patches lie together on the surface.
// Versions 3-4: an 8-bit grey image m * T wide and P high for T patches of n = 2^level + 1
// samples per side, row r the byte plane r of the stored samples of each patch in turn, m per
// patch in grid order (level 0: all n^2; a finer level only those with an odd coordinate, the
// others being the coarser level's): x high, x low, y high, y low, z high, z low (16-bit local
// position), normal u, normal v (the bytes of common_codec/octahedral.h), then red, green, blue
// with colours (P = 11, else 8); grid row j is v = j / 2^level, column i is u = i / 2^level.
// (Version 3 has one patch per tile.) Versions 1-2: one patch per node, RGB 16-bit, 2n x n
// pixels, every sample, pixel (i, j) local x y z, pixel (n + i, j) normal u << 8 | v,
// red << 8 | green, blue << 8.
// Level 0 stores the values; a finer level stores every channel's difference from its prediction
// by the coarser level (predict_from_coarser), modulo 2^16 (8-bit channels modulo 2^8), zigzag
// coded: decoding level l needs levels 0..l-1. (bench/aqp/node_bench measures the layouts:
// deltas in byte planes are 14-17% smaller than in RGB16 pixels, docs/formats/aqp.md; tiles pay
// a PNG's fixed costs once for several patches.)
#include <algorithm>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "aqp/quad_layout.h"
#include "mesh/mesh.h"

namespace catpaq::aqp {

// 1 (no up axis), 2 (RGB16 nodes), 3 (no tiles) and 4 (58-byte patch records) still read.
constexpr uint32_t kAqpMetaVersion = 5;
constexpr int kMaxPatchLevel = 10;
constexpr uint32_t kAqpColorFlag = 1;
constexpr int kMaxTileShift = 15;  // 4^15 patches: above any patch count the metadata allows

struct AqpPatchInfo {
    std::array<uint32_t, 4> corner{};
    std::array<PatchLink, 4> link;
    std::array<uint32_t, 3> origin{};  // in quantization steps from the dataset's origin
    std::array<uint16_t, 3> extent{};  // largest local coordinate per axis
};

// How a dataset's node images are laid out (AqpMeta::node_layout).
struct NodeLayout {
    bool colors = false;
    bool byte_planes = true;  // version 3: 8-bit grey byte planes; versions 1-2: RGB16 pixels
    // Version 5: a level-0 tile stores each quad vertex its patches' corners share once
    // (TilePatches); versions 3-4 store every patch's four.
    bool shared_corners = true;
};

// A tile's patches' records, in order: what a level-0 node with shared corners needs (the corner
// ids say which stored sample each patch has, the origins move a position from the frame of the
// patch it is stored for to another's).
using TilePatches = std::vector<AqpPatchInfo>;

struct AqpMeta {
    uint32_t version = kAqpMetaVersion;  // as read; encode_aqp_meta always writes the current one
    uint32_t patch_level = 0;  // finest level k: patches of (2^k + 1)^2 samples
    uint32_t base_vertices = 0, base_triangles = 0, border_edges = 0;
    uint32_t flags = 0;
    double origin[3] = {0, 0, 0};
    double step = 1;
    double bounds_min[3] = {0, 0, 0}, bounds_max[3] = {0, 0, 0};
    uint64_t input_vertices = 0, input_triangles = 0;
    double precision = 0;  // the quantization's largest distance, world units
    double mean_edge = 0;  // the input's mean edge length
    uint32_t atlas_columns = 1;  // patch p's images sit at column p % columns, row p / columns
    uint32_t up_axis = 0;        // 0 unknown, 1-6 = +x +y +z -x -y -z (catp/format.h's UpAxis)
    std::vector<uint8_t> tile_shift;  // per level 0..k (empty: one patch per tile, versions 1-3)
    std::vector<AqpPatchInfo> patches;

    bool has_colors() const { return flags & kAqpColorFlag; }
    NodeLayout node_layout() const { return {has_colors(), version >= 3, version >= 5}; }
    // Tiles: level l's tile t holds patches first_patch(t, l) .. + tile_patches(t, l) - 1.
    int shift(int level) const { return tile_shift.empty() ? 0 : tile_shift[size_t(level)]; }
    uint32_t tile_count(int level) const {
        const uint64_t size = uint64_t(1) << (2 * shift(level));
        return uint32_t((patches.size() + size - 1) / size);
    }
    uint32_t tile_of(uint32_t patch, int level) const { return patch >> (2 * shift(level)); }
    uint32_t first_patch(uint32_t tile, int level) const { return tile << (2 * shift(level)); }
    uint32_t tile_patches(uint32_t tile, int level) const {
        const uint64_t first = uint64_t(tile) << (2 * shift(level)), size = uint64_t(1) << (2 * shift(level));
        return uint32_t(std::min<uint64_t>(size, patches.size() - first));
    }
    TilePatches tile_patch_info(uint32_t tile, int level) const {
        const auto first = patches.begin() + first_patch(tile, level);
        return TilePatches(first, first + tile_patches(tile, level));
    }
    // World coordinate `axis` of local coordinate `local` of patch p.
    double world(uint32_t p, int axis, uint32_t local) const {
        return origin[axis] + step * double(uint64_t(patches[p].origin[axis]) + local);
    }
};

// Writes the current version (or version 4, for tests of older readers). Throws Error when the
// patches' links are not those their corners imply (version 5 stores none).
std::vector<uint8_t> encode_aqp_meta(const AqpMeta& meta, uint32_t version = kAqpMetaVersion);
// Empty string on success, else what is wrong. Checks every field a reader relies on (levels,
// counts, links pointing at patches that link back).
std::string decode_aqp_meta(const uint8_t* data, size_t size, AqpMeta& out);

// Sets every patch's links from the corners: patch edge e runs from corner e to corner
// (e + 1) % 4; two patch edges between the same two quad vertices are linked, reversed when they
// run it in opposite directions; an edge of one patch is on the border. An empty string, or
// what is wrong (a patch with a repeated corner, an edge of more than two patches).
std::string derive_patch_links(std::vector<AqpPatchInfo>& patches);

// A node's key: its tile at its level (with one patch per tile, the tile is the patch).
inline uint64_t aqp_node_key(uint32_t tile, int level) { return (uint64_t(tile) << 8) | uint64_t(level); }
inline uint32_t aqp_key_tile(uint64_t key) { return uint32_t(key >> 8); }
inline int aqp_key_level(uint64_t key) { return int(key & 0xff); }

// One patch at one level: (2^level + 1)^2 samples, row-major (index j * size + i).
struct PatchGrid {
    uint32_t patch = 0;
    int level = 0;
    int size = 1;  // samples per side
    std::vector<std::array<uint16_t, 3>> position;  // local quantized coordinates
    std::vector<uint16_t> normal;                   // octahedral code
    std::vector<Rgb8> color;                        // empty without colours

    size_t index(int i, int j) const { return size_t(j) * size_t(size) + size_t(i); }
};

// The prediction of channel value `channel` (0-2 position, 3-4 normal bytes u and v, 5-7 colour)
// of sample (i, j) of a level from `coarser` (the level below, every other sample): the coarse
// sample itself at even (i, j), else the floor of the mean of its two coarse neighbours along the
// row, the column or the (i,j)-(i+1,j+1) diagonal. Shared edges are predicted from edge samples
// only, so patches sharing an edge decode it identically.
int predict_from_coarser(const PatchGrid& coarser, int channel, int i, int j);

// The node payload of a tile: `grids` (consecutive patches, one level; PNG at zlib level
// `compression`) in the version-3 layout; `coarser` holds the same patches one level down
// (empty at level 0). At level 0, with `patches` (the grids' records, TilePatches), each quad
// vertex the corners share is stored once (version 5; without, every patch's four).
// Throws Error when a grid does not nest in its coarser level (it could not store the
// difference), or shared corners differ.
std::vector<uint8_t> encode_tile_node(const std::vector<const PatchGrid*>& grids, const std::vector<const PatchGrid*>& coarser,
                                      bool colors, int compression = 6, const TilePatches& patches = {});
// Decodes a tile node of `count` patches from `first_patch` at `level` (0 <= level <=
// kMaxPatchLevel) laid out as `layout` (colours exactly when layout.colors; byte planes: RGB16
// nodes hold one patch). Above level 0, `coarser` gives each patch's decoded coarser level
// (count pointers); a patch whose pointer is null is skipped (left empty in `out`: a reader
// after one patch of a tile need not have the others). At level 0 with layout.shared_corners,
// `patches` gives the tile's patch records (count of them). Safe on untrusted bytes: empty
// string on success, else what is wrong.
std::string decode_tile_node(const uint8_t* data, size_t size, uint32_t first_patch, uint32_t count, int level,
                             NodeLayout layout, const std::vector<const PatchGrid*>& coarser, std::vector<PatchGrid>& out,
                             const TilePatches& patches = {});

// One patch as a node of its own (a tile of one): `layout` may be the older RGB16 one, kept for
// tests of old datasets.
std::vector<uint8_t> encode_patch_node(const PatchGrid& grid, const PatchGrid* coarser, NodeLayout layout,
                                       int compression = 6);
std::string decode_patch_node(const uint8_t* data, size_t size, uint32_t patch, int level, NodeLayout layout,
                              const PatchGrid* coarser, PatchGrid& out);

}  // namespace catpaq::aqp
