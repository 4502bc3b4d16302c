#pragma once
// The CATP dataset: an archive (common_codec/archive.h) of kind Catp whose nodes are diamonds.
//
// Meta (little-endian):
//   char[8] "CATPMETA" | u32 version (2; 1 is read too) | u32 lattice_bits
//   f64 origin[3] | f64 cell            world = origin + lattice * cell (cell is a power of two)
//   u32 leaf_level | u32 flags (bit 0: input had colours, bit 1: input had normals)
//   u64 input_vertices | u64 input_triangles | f64 bounds_min[3] | f64 bounds_max[3] (world)
//   u32 default_rgb (0x00BBGGRR used when the input has no colours)
// version 2 adds:
//   u8 vertex layout (common_codec/packed_vertex.h) | u8 up axis (UpAxis) | u16 grid
//   f64 precision   the largest distance of the finest level from the input that the converter
//                   guaranteed (world units: its quantization step bound), as asked for
//   f64 mean_edge   the input's mean edge length (world units)
// version 3 adds the slot table, so that a client can fetch one slot's fragment of a node (a
// byte range inside the node) without the rest:
//   u32 n | n x varint size   per index entry in index order, per set bit s of its slot mask
//                             ascending: the byte size of slot s's fragment
// Version 1 datasets read as the Rgb24 layout with grid 463, up axis unknown, precision and mean
// edge 0 (not recorded); versions 1 and 2 have no slot table (nodes are fetched whole).
//
// Node (one diamond; key = DiamondId bits, level = diamond level, flags = slot mask (bits 0-7) |
// leaf (bit 8), count = triangles, error = object-space error bound in world units):
//   u8 slot_mask | for each set bit s, ascending: u32 size | fragment (common_codec/fragment_codec.h)
// A fragment's vertices are quantized in the canonical corners of tetrahedron `s` of the diamond
// (catp/lattice.h: diamond_tetrahedron + canonical_tetrahedron).
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "catp/lattice.h"
#include "common_codec/archive.h"
#include "common_codec/fragment_codec.h"
#include "mesh/up_axis.h"

namespace catpaq {

constexpr uint32_t kCatpMetaVersion = 4;

constexpr uint16_t kCatpLeafFlag = 1u << 8;

struct CatpMeta {
    uint32_t lattice_bits = kLatticeBits;
    double origin[3] = {0, 0, 0};
    double cell = 1.0;
    uint32_t leaf_level = 0;
    uint32_t flags = 0;
    uint64_t input_vertices = 0, input_triangles = 0;
    double bounds_min[3] = {0, 0, 0}, bounds_max[3] = {0, 0, 0};
    uint32_t default_rgb = 0x00b4b4b4;
    VertexLayout layout;  // of every fragment
    UpAxis up = UpAxis::Unknown;
    double precision = 0;  // world units; 0: not recorded
    double mean_edge = 0;  // world units; 0: not recorded
    // The slot table (versions 3 and 4): the fragment sizes of every entry's slots, in index
    // order, ascending slots; empty when the dataset has no slot table. In memory always every
    // slot's size: version 4 stores all but each entry's last (the entry's size implies it).
    std::vector<uint32_t> slot_bytes;
};

// `entries`: the dataset's index, which version 4 needs to leave each entry's last slot out
// (Error when a non-empty slot table does not match it). Versions 1-3 for tests of readers.
std::vector<uint8_t> encode_catp_meta(const CatpMeta& meta, const std::vector<ArchiveEntry>& entries = {},
                                      uint32_t version = kCatpMetaVersion);
// Empty string on success, else what is wrong. A version-4 slot table is completed from
// `entries` (and checked against them); without them it is left empty.
std::string decode_catp_meta(const uint8_t* data, size_t size, CatpMeta& out,
                             const std::vector<ArchiveEntry>* entries = nullptr);

// A diamond's decoded fragments, one per existing slot with geometry.
struct DiamondFragments {
    uint8_t slot_mask = 0;
    std::array<FragmentMesh, 8> slots;
};

// `slot_bytes`, when given, receives the byte size of each encoded slot fragment (ascending slots).
std::vector<uint8_t> encode_diamond_node(const DiamondFragments& fragments, std::vector<uint32_t>* slot_bytes = nullptr);
// Where slot s's fragment starts inside a node whose slots before it have the given sizes:
// after the mask byte and, per slot, a u32 size.
inline uint64_t diamond_slot_offset(uint64_t bytes_of_earlier_slots, int earlier_slots) {
    return 1 + bytes_of_earlier_slots + 4 * uint64_t(earlier_slots + 1);
}
// A node's encoded fragments, not decoded: for each slot in the mask, where its bytes are.
struct DiamondNodeSlots {
    uint8_t slot_mask = 0;
    std::array<const uint8_t*, 8> fragment{};
    std::array<uint32_t, 8> size{};
};
// Splits a node into its slots' fragment bytes (pointing into `data`): empty string on success,
// else what is wrong (truncated, trailing bytes).
std::string split_diamond_node(const uint8_t* data, size_t size, DiamondNodeSlots& out);
// Empty string on success, else what is wrong (truncated, corrupt fragment, a fragment of
// another vertex layout than the dataset's `layout` when given, ...).
std::string decode_diamond_node(const uint8_t* data, size_t size, const std::optional<VertexLayout>& layout,
                                DiamondFragments& out);

}  // namespace catpaq
